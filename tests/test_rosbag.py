"""``gfimu convert rosbag``: bags written here with rosbags' own writers from simulated logs.

The asynchronous streams are taken from one simulated log at 10 times the stream rate: each
triad keeps every 10th sample from its own phase, with a random jitter of one fine step, so the
truth readings at every time of the converted log's grid are known exactly.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from gfimu import io as gio
from gfimu.array import Accelerometer, SensorArray, cube_array
from gfimu.cli import main
from gfimu.io.errors import LogFormatError
from gfimu.io.readers import rosbag as rb
from gfimu.log import Log
from gfimu.rotations import matrix_from_rotation_vector
from gfimu.simulate import simulate

NOISE_MPS2 = 0.07
FINE = 10  # the simulated log runs at FINE x the stream rate


# --- array.toml: the topic key (no rosbags needed) ------------------------------------------------

def test_array_toml_topic_round_trip_and_old_files(tmp_path):
    accs = (Accelerometer("a1", [0.1, 0.0, 0.0], topic="/imu/a1"),
            Accelerometer("a2", [0.0, 0.1, 0.0], topic="imu2/data_raw"),
            Accelerometer("a3", [0.0, 0.0, 0.1]))
    gio.write_array_toml(SensorArray(accs, "topics"), tmp_path / "array.toml")
    text = (tmp_path / "array.toml").read_text()
    assert 'topic = "/imu/a1"' in text and text.count("topic =") == 2
    back = gio.read_array_toml(tmp_path / "array.toml")
    assert [a.topic for a in back.accelerometers] == ["/imu/a1", "imu2/data_raw", None]
    old = text.replace('topic = "/imu/a1"\n', "").replace('topic = "imu2/data_raw"\n', "")
    (tmp_path / "old.toml").write_text(old)
    assert [a.topic for a in gio.read_array_toml(tmp_path / "old.toml").accelerometers] == [None, None, None]


@pytest.mark.parametrize("value", ['""', '" /imu"', "3", '["/a"]'])
def test_array_toml_bad_topic_names_the_key(tmp_path, value):
    (tmp_path / "array.toml").write_text(
        f'format = "gfimu-array/1"\n[[accelerometers]]\nname = "a"\nposition_m = [0, 0, 0]\ntopic = {value}\n')
    with pytest.raises(LogFormatError, match=r"array.toml:5: accelerometers\[0\].topic: expected the message topic"):
        gio.read_array_toml(tmp_path / "array.toml")


# --- alignment (pure) ------------------------------------------------------------------------------

def test_align_streams_is_exact_on_the_grid_and_linear_between():
    t = np.arange(0, 100, dtype=np.int64) * 1_000_000
    v = np.random.default_rng(0).normal(size=(100, 3))
    shifted = t + 400_000  # 0.4 of a period later
    w = 2.0 * shifted[:, None] * 1e-9 * np.ones((1, 2)) - 1.0  # a line: interpolated exactly
    al = rb.align_streams([t, shifted], [v, w])
    assert al.period_ns == 1_000_000 and al.overlap_ns == (400_000, 99_000_000)
    assert np.array_equal(al.timestamps_ns, np.arange(99, dtype=np.int64) * 1_000_000 + 400_000)
    np.testing.assert_allclose(al.values[1], 2.0 * al.timestamps_ns[:, None] * 1e-9 * np.ones((1, 2)) - 1.0,
                               rtol=0, atol=1e-14)
    np.testing.assert_allclose(al.values[0], 0.6 * v[:99] + 0.4 * v[1:100], rtol=0, atol=1e-14)
    assert al.max_offset_ns == 400_000
    al = rb.align_streams([t, t], [v, 2 * v])  # stamps on the grid: copied exactly
    assert np.array_equal(al.values[0], v) and np.array_equal(al.values[1], 2 * v)


def test_align_streams_leaves_long_gaps_out_and_bridges_short_ones():
    t = np.arange(0, 200, dtype=np.int64) * 2_000_000
    short = np.delete(t, [50, 51])  # 2 missing: 3 periods, bridged at the default 3
    long = np.delete(t, np.arange(120, 130))  # 10 missing: left out
    v = np.arange(200, dtype=float)
    al = rb.align_streams([t, short, long], [v, np.delete(v, [50, 51]), np.delete(v, np.arange(120, 130))])
    assert al.n_grid == 200 and al.timestamps_ns.size == 190
    assert al.long_gaps == ((int(t[119]), int(t[130]), 10),)
    kept = al.timestamps_ns // 2_000_000
    assert np.array_equal(kept, np.delete(np.arange(200), np.arange(120, 130)))
    for values in al.values:  # a line stays a line across the bridged gap
        np.testing.assert_allclose(values[:, 0], kept, rtol=0, atol=1e-12)
    log = Log(cube_array(0.025), al.timestamps_ns, np.zeros((190, 12)))
    assert [(s.start, s.stop) for s in log.segments()] == [(0, 120), (120, 190)]
    gaps = rb.stream_gaps(long)
    assert gaps.period_ns == 2_000_000 and gaps.missing.tolist() == [10] and gaps.n_missing == 10
    with pytest.raises(ValueError, match="do not overlap"):
        rb.align_streams([t[:50], t[100:]], [v[:50], v[100:]])


# --- writing bags ----------------------------------------------------------------------------------

rosbags = pytest.importorskip("rosbags")
from rosbags.rosbag1 import Writer as Writer1  # noqa: E402
from rosbags.rosbag2 import StoragePlugin, Writer as Writer2  # noqa: E402
from rosbags.typesys import Stores, get_typestore  # noqa: E402

KINDS = ("ros1", "sqlite3", "mcap", "bare-mcap")
TS1 = get_typestore(Stores.ROS1_NOETIC)
TS2 = get_typestore(Stores.ROS2_HUMBLE)


def imu_message(ts, stamp_ns: int, frame_id: str, accel, gyro=None, accel_cov=None, gyro_cov=None):
    t = ts.types
    header = {"stamp": t["builtin_interfaces/msg/Time"](sec=int(stamp_ns // 1_000_000_000),
                                                        nanosec=int(stamp_ns % 1_000_000_000)),
              "frame_id": frame_id}
    if "seq" in t["std_msgs/msg/Header"].__dataclass_fields__:
        header["seq"] = 0
    vec = t["geometry_msgs/msg/Vector3"]
    no_cov = np.zeros(9)
    no_cov[0] = -1.0
    return t["sensor_msgs/msg/Imu"](
        header=t["std_msgs/msg/Header"](**header),
        orientation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0), orientation_covariance=no_cov,
        angular_velocity=vec(*(float(x) for x in (np.zeros(3) if gyro is None else gyro))),
        angular_velocity_covariance=no_cov if gyro is None else np.asarray(gyro_cov if gyro_cov is not None
                                                                           else np.zeros(9), float),
        linear_acceleration=vec(*(float(x) for x in accel)),
        linear_acceleration_covariance=np.zeros(9) if accel_cov is None else np.asarray(accel_cov, float))


def write_bag(path: Path, kind: str, streams: list[dict], extra_topic: bool = True) -> Path:
    """A bag of ``kind`` with one Imu connection per stream (dict: topic, frame_id, stamps_ns, accel,
    and optionally gyro, accel_cov, gyro_cov); messages written in record-time order."""
    ts = TS1 if kind == "ros1" else TS2
    ser = (lambda m: ts.serialize_ros1(m, rb.IMU_TYPE)) if kind == "ros1" else (lambda m: ts.serialize_cdr(m, rb.IMU_TYPE))
    if kind == "ros1":
        bag = path.with_suffix(".bag")
        writer = Writer1(bag)
    else:
        bag = path
        writer = Writer2(path, version=9,
                         storage_plugin=StoragePlugin.SQLITE3 if kind == "sqlite3" else StoragePlugin.MCAP)
    events = []
    with writer as w:
        kw = {"typestore": ts}
        conns = {}
        for s in streams:
            if s["topic"] not in conns:
                conns[s["topic"]] = w.add_connection(s["topic"], rb.IMU_TYPE, **kw)
        if extra_topic:
            other = w.add_connection("/status", "std_msgs/msg/String", **kw)
            data = (ts.serialize_ros1 if kind == "ros1" else ts.serialize_cdr)(
                ts.types["std_msgs/msg/String"](data="ok"), "std_msgs/msg/String")
            w.write(other, int(streams[0]["stamps_ns"][0]), data)
        for s in streams:
            for k, t in enumerate(s["stamps_ns"]):
                gyro = None if s.get("gyro") is None else s["gyro"][k]
                msg = imu_message(ts, int(t), s["frame_id"], s["accel"][k], gyro, s.get("accel_cov"), s.get("gyro_cov"))
                events.append((int(t) + 300_000, conns[s["topic"]], ser(msg)))  # received 0.3 ms after the stamp
        events.sort(key=lambda e: e[0])
        for record_ns, conn, data in events:
            w.write(conn, record_ns, data)
    if kind == "bare-mcap":
        (mcap,) = path.glob("*.mcap")
        bare = path.parent / f"{path.name}-bare.mcap"
        shutil.move(mcap, bare)
        shutil.rmtree(path)
        return bare
    return bag


def fine_log(duration_s: float, seed: int = 1, rate_hz: float = 500.0, **kw):
    return simulate("random3d", array=cube_array(0.025, noise_std_mps2=NOISE_MPS2), rate_hz=FINE * rate_hz,
                    duration_s=duration_s, seed=seed, **kw)


def async_streams(log, phases=(0, 3, 7, 5), jitter: bool = True, seed: int = 0, topics: bool = True):
    """One stream per triad of the fine ``log``: every FINE-th sample from the triad's phase, each
    stamp moved by -1, 0 or +1 fine step when ``jitter``; the stamps are the true sample times."""
    rng = np.random.default_rng(seed)
    n = len(log)
    streams = []
    for i, acc in enumerate(log.array.accelerometers):
        idx = np.arange(phases[i] + FINE, n - FINE, FINE)
        if jitter:
            idx = idx + rng.integers(-1, 2, idx.size)
        streams.append({"topic": f"/imu/{acc.name}" if topics else "/imu", "frame_id": acc.name,
                        "stamps_ns": log.timestamps_ns[idx] + T0_NS, "accel": log.accel_mps2[idx, 3 * i:3 * i + 3],
                        "index": idx})
    return streams


T0_NS = 1_700_000_000_000_000_000  # epoch-scale stamps


def array_file(path: Path, array: SensorArray, topics: bool = True, noise: bool = True) -> Path:
    accs = tuple(Accelerometer(a.name, a.position_m, a.rotation_body_sensor, a.axes,
                               a.noise_std_mps2 if noise else None, f"/imu/{a.name}" if topics else None)
                 for a in array.accelerometers)
    gio.write_array_toml(SensorArray(accs, array.name, array.gyroscope), path)
    return path


def convert(argv: list[str], capsys) -> tuple[int, str, str]:
    rc = main(["convert", "rosbag", *argv])
    out, err = capsys.readouterr()
    return rc, out, err


# --- round trips -----------------------------------------------------------------------------------

@pytest.mark.parametrize("kind", KINDS)
def test_synchronous_stamps_round_trip_exactly(tmp_path, kind, capsys):
    log = simulate("random3d", array=cube_array(0.025, noise_std_mps2=NOISE_MPS2), rate_hz=500.0, duration_s=1.0,
                   seed=1)
    streams = [{"topic": f"/imu/{a.name}", "frame_id": a.name, "stamps_ns": log.timestamps_ns + T0_NS,
                "accel": log.accel_mps2[:, 3 * i:3 * i + 3]} for i, a in enumerate(log.array.accelerometers)]
    bag = write_bag(tmp_path / "bag", kind, streams)
    rc, out, err = convert([str(bag), "--array", str(array_file(tmp_path / "array.toml", log.array)),
                            "--out", str(tmp_path / "log")], capsys)
    assert rc == 0, err
    back = gio.read_log(tmp_path / "log")
    assert np.array_equal(back.timestamps_ns, log.timestamps_ns + T0_NS)
    assert np.array_equal(back.accel_mps2, log.accel_mps2)  # float64 through the bag and the CSV
    assert [a.topic for a in back.array.accelerometers] == [f"/imu/{a.name}" for a in log.array.accelerometers]
    assert "0 gap(s), 0 message(s) missing" in out and "gaps over 3 periods: none" in out
    assert "at most 0.000 ms from a stamp" in out


@pytest.mark.parametrize("kind", KINDS)
def test_asynchronous_stamps_cost_less_than_the_noise(tmp_path, kind, capsys):
    """Noise-free readings: the interpolation error alone, against the truth readings at the grid."""
    fine = fine_log(2.0, noise=_no_noise())
    streams = async_streams(fine)
    bag = write_bag(tmp_path / "bag", kind, streams)
    rc, out, err = convert([str(bag), "--array", str(array_file(tmp_path / "array.toml", fine.array)),
                            "--out", str(tmp_path / "log")], capsys)
    assert rc == 0, err
    back = gio.read_log(tmp_path / "log")
    start = max(s["stamps_ns"][0] for s in streams)
    assert back.timestamps_ns[0] == start and np.all(np.diff(back.timestamps_ns) == 2_000_000)
    fine_index = (back.timestamps_ns - T0_NS) // (2_000_000 // FINE)
    error = back.accel_mps2 - fine.accel_mps2[fine_index]
    rms = float(np.sqrt(np.mean(error ** 2)))
    # measured: 8.7e-5 m/s² RMS on these 2 s (9.6e-5 RMS, 5.8e-4 max on 10 s), 1/800 of the sensor noise
    assert 1e-6 < rms < 1e-3
    assert float(np.abs(error).max()) < 0.03 * NOISE_MPS2


def _no_noise():
    from gfimu.simulate import SensorErrors

    return SensorErrors.none()


def smoother_rmse(log) -> float:
    from gfimu.methods import make_estimator

    motion = make_estimator("smoother").estimate(log)
    err = motion.omega_b_radps - log.truth.omega_b_radps
    return float(np.sqrt(np.mean(np.sum(err ** 2, axis=1))))


def interpolation_cost(tmp_path, capsys, duration_s: float) -> tuple[float, float]:
    """(ω RMSE of the smoother on the converted asynchronous bag, on the same readings sampled synchronously)."""
    fine = fine_log(duration_s)
    streams = async_streams(fine)
    bag = write_bag(tmp_path / "bag", "mcap", streams)
    rc, out, err = convert([str(bag), "--array", str(array_file(tmp_path / "array.toml", fine.array)),
                            "--out", str(tmp_path / "log")], capsys)
    assert rc == 0, err
    converted = gio.read_log(tmp_path / "log")
    fine_index = (converted.timestamps_ns - T0_NS) // (2_000_000 // FINE)
    truth = fine.truth.select(fine_index)
    converted = converted.replace(truth=truth.replace(timestamps_ns=converted.timestamps_ns))
    direct = fine.select(fine_index)
    return smoother_rmse(converted), smoother_rmse(direct)


def test_asynchronous_bag_smoother_accuracy_short(tmp_path, capsys):
    via_bag, direct = interpolation_cost(tmp_path, capsys, 3.0)
    print(f"omega RMSE: converted {via_bag:.4f} rad/s, direct {direct:.4f} rad/s, ratio {via_bag / direct:.3f}")
    assert via_bag < 1.5 * direct


@pytest.mark.slow
def test_asynchronous_bag_smoother_accuracy_10s(tmp_path, capsys):
    via_bag, direct = interpolation_cost(tmp_path, capsys, 10.0)
    print(f"omega RMSE: converted {via_bag:.4f} rad/s, direct {direct:.4f} rad/s, ratio {via_bag / direct:.3f}")
    assert via_bag < 1.5 * direct
