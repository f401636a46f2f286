"""``gfimu convert rosbag``: bags written here with rosbags' own writers from simulated logs.

The asynchronous streams are taken from one simulated log at 10 times the stream rate: each
triad keeps every 10th sample from its own phase, with a random jitter of one fine step, so the
truth readings at every time of the converted log's grid are known exactly.
"""

from __future__ import annotations

import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from gfimu import io as gio
from gfimu.array import Accelerometer, SensorArray, cube_array
from gfimu.cli import main
from gfimu.io.errors import LogFormatError, LogGapWarning
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
            # received 0.3 ms after the stamp unless given
            record = s.get("record_ns", np.asarray(s["stamps_ns"]) + 300_000)
            for k, t in enumerate(s["stamps_ns"]):
                gyro = None if s.get("gyro") is None else s["gyro"][k]
                accel_cov, gyro_cov = s.get("accel_cov"), s.get("gyro_cov")
                accel_cov = accel_cov[k] if np.ndim(accel_cov) == 2 else accel_cov  # one per message
                gyro_cov = gyro_cov[k] if np.ndim(gyro_cov) == 2 else gyro_cov
                msg = imu_message(ts, int(t), s["frame_id"], s["accel"][k], gyro, accel_cov, gyro_cov)
                events.append((int(record[k]), conns[s["topic"]], ser(msg)))
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

    motion = make_estimator("smoother").estimate(log).motion
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


@pytest.mark.slow
def test_asynchronous_bag_smoother_accuracy_10s(tmp_path, capsys):
    via_bag, direct = interpolation_cost(tmp_path, capsys, 10.0)
    print(f"omega RMSE: converted {via_bag:.4f} rad/s, direct {direct:.4f} rad/s, ratio {via_bag / direct:.3f}")
    assert via_bag < 1.5 * direct


def test_asynchronous_bag_smoother_accuracy_short(tmp_path, capsys):
    via_bag, direct = interpolation_cost(tmp_path, capsys, 2.0)
    print(f"omega RMSE: converted {via_bag:.4f} rad/s, direct {direct:.4f} rad/s, ratio {via_bag / direct:.3f}")
    assert via_bag < 1.5 * direct


# --- matching, gyro, covariances, gaps -------------------------------------------------------------

def rotated_log(duration_s: float = 0.5, gyro: bool = False):
    """Four triads turned every way, synchronous readings (and the true ω as the gyro)."""
    from gfimu.array import Gyroscope

    rng = np.random.default_rng(3)
    accs = tuple(Accelerometer(f"s{i}", rng.uniform(-0.03, 0.03, 3), matrix_from_rotation_vector(rng.normal(size=3)),
                               noise_std_mps2=NOISE_MPS2) for i in range(4))
    array = SensorArray(accs, "rotated", Gyroscope(0.01) if gyro else None)
    return simulate("random3d", array=array, rate_hz=500.0, duration_s=duration_s, seed=2)


def sync_streams(log, topic=None, gyro_from=(), accel_cov=None, gyro_cov=None):
    out = []
    for i, a in enumerate(log.array.accelerometers):
        s = {"topic": topic or f"/imu/{a.name}", "frame_id": a.name, "stamps_ns": log.timestamps_ns + T0_NS,
             "accel": log.accel_mps2[:, 3 * i:3 * i + 3], "accel_cov": accel_cov, "gyro_cov": gyro_cov}
        if i in gyro_from:  # angular velocity in the sensor frame: R_BS^T ω_B
            s["gyro"] = log.truth.omega_b_radps @ np.asarray(a.rotation_body_sensor)
        out.append(s)
    return out


@pytest.mark.parametrize("one_topic", [True, False])
def test_frame_id_matches_the_accelerometer_name(tmp_path, one_topic, capsys):
    log = rotated_log()
    streams = sync_streams(log, topic="/imu" if one_topic else None)[::-1]  # written in another order
    bag = write_bag(tmp_path / "bag", "ros1", streams)
    arr = array_file(tmp_path / "array.toml", log.array, topics=False)
    rc, out, err = convert([str(bag), "--array", str(arr), "--out", str(tmp_path / "log")], capsys)
    assert rc == 0, err
    back = gio.read_log(tmp_path / "log")
    assert np.array_equal(back.accel_mps2, log.accel_mps2)
    assert back.array.gyroscope is None and back.gyro_b_radps is None
    assert ("s2: frame_id 's2' on /imu (frame_id 's2')" if one_topic else "s2: frame_id 's2' on /imu/s2") in out


def test_with_gyro_mean_in_the_body_frame_and_covariances_as_stds(tmp_path, capsys):
    log = rotated_log(gyro=True)
    gyro_cov = np.diag([1e-4, 4e-4, 2.5e-5]).ravel()
    streams = sync_streams(log, gyro_from=(0, 1, 3), accel_cov=np.diag([0.0025, 0.0049, 0.0121]).ravel(),
                           gyro_cov=gyro_cov)
    bag = write_bag(tmp_path / "bag", "sqlite3", streams)
    arr = array_file(tmp_path / "array.toml", replace(log.array, gyroscope=None), noise=False)
    rc, out, err = convert([str(bag), "--array", str(arr), "--out", str(tmp_path / "log"), "--with-gyro"], capsys)
    assert rc == 0, err
    back = gio.read_log(tmp_path / "log")
    np.testing.assert_allclose(back.gyro_b_radps, log.truth.omega_b_radps, rtol=0, atol=1e-12)
    assert "gyro: mean angular velocity in B of 3 stream(s) (s0, s1, s3)" in out
    assert "not provided (angular_velocity_covariance[0] = -1, or not finite) by s2" in out
    std = float(np.sqrt((0.0025 + 0.0049 + 0.0121) / 3))
    assert [a.noise_std_mps2 for a in back.array.accelerometers] == [pytest.approx(std, rel=1e-12)] * 4
    # the mean of 3 gyros: variance (mean of the diagonal) / 3
    assert back.array.gyroscope.noise_std_radps == pytest.approx(float(np.sqrt(np.mean(np.diag(gyro_cov.reshape(3, 3))) / 3)))
    # without --with-gyro: no gyro channels; a noise_std_mps2 given in array.toml is kept
    arr = array_file(tmp_path / "array2.toml", log.array, noise=True)
    rc, out, err = convert([str(bag), "--array", str(arr), "--out", str(tmp_path / "log2")], capsys)
    assert rc == 0, err
    back = gio.read_log(tmp_path / "log2")
    assert back.gyro_b_radps is None and back.array.gyroscope is None
    assert [a.noise_std_mps2 for a in back.array.accelerometers] == [NOISE_MPS2] * 4
    assert f"s0: noise_std_mps2 0.07 kept from {arr} (linear_acceleration_covariance says {std:.6g})" in out


def test_with_gyro_needs_a_gyro(tmp_path, capsys):
    log = rotated_log()
    bag = write_bag(tmp_path / "bag", "mcap", sync_streams(log))
    arr = array_file(tmp_path / "array.toml", log.array)
    rc, out, err = convert([str(bag), "--array", str(arr), "--out", str(tmp_path / "log"), "--with-gyro"], capsys)
    assert rc == 2 and not (tmp_path / "log").exists()
    assert err.count("\n") == 1 and f"error: {bag}: --with-gyro: no Imu stream of the array provides angular_velocity" in err


def test_gaps_are_counted_and_long_ones_become_log_gaps(tmp_path, capsys):
    log = simulate("random3d", array=cube_array(0.025, noise_std_mps2=NOISE_MPS2), rate_hz=500.0, duration_s=1.0,
                   seed=1)
    streams = sync_streams(log)
    streams[1] = {**streams[1], "stamps_ns": np.delete(streams[1]["stamps_ns"], [100]),
                  "accel": np.delete(streams[1]["accel"], [100], axis=0)}  # one message dropped: bridged
    cut = np.arange(300, 320)
    streams[2] = {**streams[2], "stamps_ns": np.delete(streams[2]["stamps_ns"], cut),
                  "accel": np.delete(streams[2]["accel"], cut, axis=0)}  # 20 dropped: a gap of the log
    bag = write_bag(tmp_path / "bag", "ros1", streams)
    arr = array_file(tmp_path / "array.toml", log.array)
    rc, out, err = convert([str(bag), "--array", str(arr), "--out", str(tmp_path / "log")], capsys)
    assert rc == 0, err
    assert "a2: topic /imu/a2 (frame_id 'a2'), 499 message(s) at 500.00 Hz; 1 gap(s), 1 message(s) missing (1 at 0.198 s)" in out
    assert "a3: topic /imu/a3 (frame_id 'a3'), 480 message(s) at 500.00 Hz; 1 gap(s), 20 message(s) missing (20 at 0.598 s)" in out
    assert "gaps over 3 periods: 1, left out as time gaps of the log: 0.598 s to 0.640 s (20 sample(s))" in out
    with pytest.warns(LogGapWarning, match="1 gap"):
        back = gio.read_log(tmp_path / "log")
    assert len(back) == 480
    assert np.array_equal(back.timestamps_ns, np.delete(log.timestamps_ns, cut) + T0_NS)
    keep = np.delete(np.arange(500), cut)
    # a2's dropped message is interpolated from its neighbours; everything else is read as written
    expected = log.accel_mps2[keep].copy()
    expected[100, 3:6] = 0.5 * (log.accel_mps2[99, 3:6] + log.accel_mps2[101, 3:6])
    np.testing.assert_allclose(back.accel_mps2, expected, rtol=0, atol=1e-12)
    assert [(s.start, s.stop) for s in back.segments()] == [(0, 300), (300, 480)]
    # a longer bridge: --max-gap-periods 30 interpolates over the 20 missing messages too
    rc, out, err = convert([str(bag), "--array", str(arr), "--out", str(tmp_path / "log2"), "--max-gap-periods", "30"],
                           capsys)
    assert rc == 0 and len(gio.read_log(tmp_path / "log2")) == 500 and "gaps over 30 periods: none" in out


def test_out_of_order_repeated_and_zero_stamps(tmp_path, capsys):
    log = simulate("random3d", array=cube_array(0.025, noise_std_mps2=NOISE_MPS2), rate_hz=500.0, duration_s=0.5,
                   seed=1)
    streams = sync_streams(log)
    s = streams[0]
    order = np.arange(250)
    order[[10, 11]] = [11, 10]  # recorded in swapped order
    order = np.concatenate([order[:41], [40, 40], order[41:]])  # message 40 recorded three times
    streams[0] = {**s, "stamps_ns": s["stamps_ns"][order], "accel": s["accel"][order],
                  "record_ns": T0_NS + 1_000 * np.arange(order.size)}
    for k in (1, 2, 3):  # header stamps never set: the record times are the sample times
        streams[k] = {**streams[k], "record_ns": streams[k]["stamps_ns"], "stamps_ns": np.zeros(250, np.int64)}
    bag = write_bag(tmp_path / "bag", "mcap", streams)
    arr = array_file(tmp_path / "array.toml", log.array)
    rc, out, err = convert([str(bag), "--array", str(arr), "--out", str(tmp_path / "log")], capsys)
    assert rc == 0, err
    assert "a1: topic /imu/a1 (frame_id 'a1'), 250 message(s) at 500.00 Hz; 0 gap(s), 0 message(s) missing; " \
           "2 duplicate stamp(s) dropped; 1 out of order (sorted)" in out
    assert out.count("header stamps all zero: the bag's record times are used") == 3
    back = gio.read_log(tmp_path / "log")
    assert np.array_equal(back.timestamps_ns, log.timestamps_ns + T0_NS)
    assert np.array_equal(back.accel_mps2, log.accel_mps2)


# --- bad inputs: one line naming the file, exit 2, nothing written ----------------------------------

@pytest.fixture(scope="module")
def good(tmp_path_factory):
    d = tmp_path_factory.mktemp("good")
    log = simulate("random3d", array=cube_array(0.025, noise_std_mps2=NOISE_MPS2), rate_hz=500.0, duration_s=0.2,
                   seed=1)
    return log, {kind: write_bag(d / kind, kind, sync_streams(log)) for kind in KINDS}


def refused(argv: list[str], out_dir: Path, capsys, *parts: str, status: int = 2) -> str:
    rc, out, err = convert([*argv, "--out", str(out_dir)], capsys)
    assert rc == status, err
    assert err.count("\n") == 1 and err.startswith("gfimu convert: error: ") and "Traceback" not in err, err
    for part in parts:
        assert part in err, err
    assert not out_dir.exists()
    return err


def test_a_ros2_bag_named_by_its_metadata_yaml(tmp_path, capsys):
    """BAG/metadata.yaml reads as the bag folder BAG, as ros2 bag info takes either."""
    log = simulate("random3d", array=cube_array(0.025, noise_std_mps2=NOISE_MPS2), rate_hz=500.0, duration_s=0.2,
                   seed=1)
    streams = [{"topic": f"/imu/{a.name}", "frame_id": a.name, "stamps_ns": log.timestamps_ns + T0_NS,
                "accel": log.accel_mps2[:, 3 * i:3 * i + 3]} for i, a in enumerate(log.array.accelerometers)]
    bag = write_bag(tmp_path / "bag", "mcap", streams)
    rc, out, err = convert([str(bag / "metadata.yaml"), "--array", str(array_file(tmp_path / "array.toml", log.array)),
                            "--out", str(tmp_path / "log")], capsys)
    assert rc == 0, err
    assert np.array_equal(gio.read_log(tmp_path / "log").accel_mps2, log.accel_mps2)


def test_bag_without_imu_topics(tmp_path, capsys):
    bag = tmp_path / "strings.bag"
    with Writer1(bag) as w:
        c = w.add_connection("/status", "std_msgs/msg/String", typestore=TS1)
        w.write(c, 1, TS1.serialize_ros1(TS1.types["std_msgs/msg/String"](data="x"), "std_msgs/msg/String"))
    arr = array_file(tmp_path / "array.toml", cube_array(0.025))
    refused([str(bag), "--array", str(arr)], tmp_path / "log", capsys,
            f"{bag}: no sensor_msgs/msg/Imu topic in this ROS 1 bag (topics: /status [std_msgs/msg/String])")


@pytest.mark.parametrize("kind", KINDS)
def test_topic_missing_from_the_bag(tmp_path, good, kind, capsys):
    log, bags = good
    accs = list(log.array.accelerometers)
    accs[2] = Accelerometer("a3", accs[2].position_m, topic="/imu/a9")
    arr = tmp_path / "array.toml"
    gio.write_array_toml(SensorArray(tuple(accs)), arr)
    refused([str(bags[kind]), "--array", str(arr)], tmp_path / "log", capsys,
            f"{arr}: accelerometers[2].topic: '/imu/a9' (accelerometer 'a3') is not in {bags[kind]}",
            "Imu topics: /imu/a1, /imu/a2, /imu/a3, /imu/a4")


def test_topic_of_another_type(tmp_path, good, capsys):
    log, bags = good
    accs = list(log.array.accelerometers)
    accs[0] = Accelerometer("a1", accs[0].position_m, topic="/status")
    arr = tmp_path / "array.toml"
    gio.write_array_toml(SensorArray(tuple(accs)), arr)
    refused([str(bags["mcap"]), "--array", str(arr)], tmp_path / "log", capsys,
            f"{arr}: accelerometers[0].topic: '/status' (accelerometer 'a1') holds std_msgs/msg/String")


def test_no_frame_id_matches_an_accelerometer(tmp_path, good, capsys):
    log, bags = good
    accs = tuple(Accelerometer(n, a.position_m) for n, a in zip(("a1", "a2", "left", "a4"), log.array.accelerometers))
    arr = tmp_path / "array.toml"
    gio.write_array_toml(SensorArray(accs), arr)
    refused([str(bags["bare-mcap"]), "--array", str(arr)], tmp_path / "log", capsys,
            f"{bags['bare-mcap']}: no Imu message has header.frame_id 'left', the name of accelerometer 'left' of {arr}",
            "frame_ids in the bag: 'a1', 'a2', 'a3', 'a4'")


@pytest.mark.parametrize("kind", KINDS)
def test_truncated_bag(tmp_path, good, kind, capsys):
    log, bags = good
    bag = bags[kind]
    if bag.is_file():
        target = tmp_path / bag.name
        data = bag.read_bytes()
        target.write_bytes(data[: len(data) * 3 // 4])
        storage = target
    else:
        target = tmp_path / bag.name
        shutil.copytree(bag, target)
        (storage,) = [p for p in target.iterdir() if p.suffix != ".yaml"]
        data = storage.read_bytes()
        storage.write_bytes(data[: len(data) * 3 // 4])
    arr = array_file(tmp_path / "array.toml", log.array)
    refused([str(target), "--array", str(arr)], tmp_path / "log", capsys, f"{target}: cannot read this",
            "(corrupt or truncated?)")


@pytest.mark.parametrize("name, content, message", [
    ("notes.txt", b"hello", "not a ROS bag (expected a ROS 1 .bag file"),
    ("empty.bag", b"", "not a ROS bag (expected a ROS 1 .bag file"),
    ("folder", None, "not a ROS bag: a folder without metadata.yaml"),
    ("noise.bag", b"#ROSBAG V2.0\n" + bytes(range(256)) * 8, "cannot read this ROS 1 bag (corrupt or truncated?)"),
    ("bag.mcap.bak", b"\x89MCAP0\r\n" + bytes(64), "an MCAP file whose name does not end in .mcap"),
])
def test_a_path_that_is_not_a_bag(tmp_path, good, name, content, message, capsys):
    log, _ = good
    path = tmp_path / name
    if content is None:
        path.mkdir()
    else:
        path.write_bytes(content)
    arr = array_file(tmp_path / "array.toml", log.array)
    refused([str(path), "--array", str(arr)], tmp_path / "log", capsys, f"{path}: {message}")


@pytest.mark.parametrize("value", ["1", "nan", "-3"])
def test_max_gap_periods_out_of_range(tmp_path, good, value, capsys):
    log, bags = good
    arr = array_file(tmp_path / "array.toml", log.array)
    refused([str(bags["ros1"]), "--array", str(arr), "--max-gap-periods", value], tmp_path / "log", capsys,
            "--max-gap-periods: expected a number >= 1.5")


def test_missing_bag_and_array(tmp_path, good, capsys):
    log, bags = good
    refused([str(tmp_path / "none.bag"), "--array", str(tmp_path / "a.toml")], tmp_path / "log", capsys,
            f"{tmp_path / 'none.bag'}: no such file or folder")
    refused([str(bags["ros1"]), "--array", str(tmp_path / "a.toml")], tmp_path / "log", capsys,
            f"{tmp_path / 'a.toml'}: file not found")


def test_the_array_file_is_an_input_never_overwritten(tmp_path, good, capsys):
    log, bags = good
    out = tmp_path / "log"
    out.mkdir()
    arr = array_file(out / "array.toml", log.array)
    before = arr.read_bytes()
    rc, _, err = convert([str(bags["ros1"]), "--array", str(arr), "--out", str(out), "--force"], capsys)
    assert rc == 2 and "is an input of this command" in err and arr.read_bytes() == before
    assert sorted(p.name for p in out.iterdir()) == ["array.toml"]


def test_without_the_rosbags_package(tmp_path, good, monkeypatch, capsys):
    log, bags = good
    arr = array_file(tmp_path / "array.toml", log.array)
    for name in [m for m in list(__import__("sys").modules) if m == "rosbags" or m.startswith("rosbags.")]:
        monkeypatch.delitem(__import__("sys").modules, name)
    monkeypatch.setitem(__import__("sys").modules, "rosbags", None)
    refused([str(bags["ros1"]), "--array", str(arr)], tmp_path / "log", capsys,
            "reading ROS bags needs rosbags, which is not installed: pip install 'gfimu[rosbag]'", status=1)


# --- REP-145 "not provided", bag folders without metadata, tf1 frame ids, a gyro reference ----------

def snapshot(root: Path) -> dict[str, bytes]:
    """Every file under ``root`` (or ``root`` itself) with its bytes: inputs must stay byte-identical."""
    files = [root] if root.is_file() else sorted(p for p in root.rglob("*") if p.is_file())
    return {str(p): p.read_bytes() for p in files}


NO_ACCEL = np.array([-1.0, 0, 0, 0, 0, 0, 0, 0, 0])


def test_a_topic_without_linear_acceleration_named_by_topic_is_refused(tmp_path, capsys):
    log = rotated_log()
    streams = sync_streams(log)
    streams[2] = {**streams[2], "accel": np.zeros_like(streams[2]["accel"]), "accel_cov": NO_ACCEL}
    bag = write_bag(tmp_path / "bag", "mcap", streams)
    arr = array_file(tmp_path / "array.toml", log.array)
    before = snapshot(bag) | snapshot(arr)
    refused([str(bag), "--array", str(arr)], tmp_path / "log", capsys,
            f"{bag}: topic '/imu/s2' (accelerometer 's2', accelerometers[2].topic of {arr}) is not an accelerometer: "
            "its 250 messages give linear_acceleration_covariance[0] = -1, the REP-145 mark for linear acceleration "
            "not provided (message 0 is the first)")
    assert snapshot(bag) | snapshot(arr) == before


def test_a_topic_without_linear_acceleration_matched_by_frame_id(tmp_path, capsys):
    """A gyro-only topic whose frame_id is an accelerometer's name is not read as that accelerometer; when it is
    the only one with that frame_id, the accelerometer is refused."""
    log = rotated_log(gyro=True)
    streams = sync_streams(log)
    gyro_only = {**streams[0], "topic": "/gyro", "accel": np.zeros_like(streams[0]["accel"]), "accel_cov": NO_ACCEL,
                 "gyro": log.truth.omega_b_radps @ np.asarray(log.array.accelerometers[0].rotation_body_sensor)}
    bag = write_bag(tmp_path / "bag", "ros1", [*streams, gyro_only])
    arr = array_file(tmp_path / "array.toml", replace(log.array, gyroscope=None), topics=False)
    rc, out, err = convert([str(bag), "--array", str(arr), "--out", str(tmp_path / "log")], capsys)
    assert rc == 0, err
    assert np.array_equal(gio.read_log(tmp_path / "log").accel_mps2, log.accel_mps2)  # no zeros from /gyro
    assert ("s0: topic /gyro: its 250 message(s) with header.frame_id 's0' leave linear_acceleration out "
            "(linear_acceleration_covariance[0] = -1): not read as an accelerometer") in out
    assert "s0: frame_id 's0' on /imu/s0 (frame_id 's0')" in out
    bag = write_bag(tmp_path / "only", "ros1", [*streams[1:], gyro_only])
    refused([str(bag), "--array", str(arr)], tmp_path / "log2", capsys,
            f"{bag}: the Imu messages with header.frame_id 's0' (accelerometer 's0' of {arr}) are no accelerometer's: "
            "on /gyro, its 250 messages give linear_acceleration_covariance[0] = -1",
            "(message 0 of /gyro is the first)")


@pytest.mark.parametrize("kind", ["ros1", "sqlite3"])
def test_messages_without_linear_acceleration_are_dropped_and_counted(tmp_path, kind, capsys):
    log = rotated_log()
    streams = sync_streams(log)
    cov = np.zeros((250, 9))
    cov[[40, 41, 200], 0] = -1.0
    accel = streams[1]["accel"].copy()
    accel[[40, 41, 200]] = 0.0  # what such a message carries: 0, which is no reading
    streams[1] = {**streams[1], "accel": accel, "accel_cov": cov}
    bag = write_bag(tmp_path / "bag", kind, streams)
    arr = array_file(tmp_path / "array.toml", log.array)
    rc, out, err = convert([str(bag), "--array", str(arr), "--out", str(tmp_path / "log")], capsys)
    assert rc == 0, err
    assert ("s1: topic /imu/s1: 3 of its 250 message(s) dropped for linear_acceleration_covariance[0] = -1 "
            "(not provided; message index 40, 41, 200)") in out
    assert "s1: topic /imu/s1 (frame_id 's1'), 247 message(s) at 500.00 Hz; 2 gap(s), 3 message(s) missing" in out
    back = gio.read_log(tmp_path / "log")
    expected = log.accel_mps2.copy()
    a = log.accel_mps2[:, 3:6]
    expected[40, 3:6] = (2 * a[39] + a[42]) / 3  # bridged linearly between the kept neighbours
    expected[41, 3:6] = (a[39] + 2 * a[42]) / 3
    expected[200, 3:6] = (a[199] + a[201]) / 2
    np.testing.assert_allclose(back.accel_mps2, expected, rtol=0, atol=1e-12)
    assert not np.any(np.all(back.accel_mps2[:, 3:6] == 0.0, axis=1))


@pytest.mark.parametrize("kind", ["sqlite3", "mcap"])
def test_a_ros2_bag_folder_without_metadata_yaml(tmp_path, kind, capsys):
    log = rotated_log()
    bag = write_bag(tmp_path / "bag", kind, sync_streams(log))
    (bag / "metadata.yaml").unlink()
    (storage,) = bag.iterdir()
    before = snapshot(tmp_path)
    arr = array_file(tmp_path / "array.toml", log.array)
    before = snapshot(bag) | snapshot(arr)
    rc, out, err = convert([str(bag), "--array", str(arr), "--out", str(tmp_path / "log")], capsys)
    assert rc == 0, err
    assert np.array_equal(gio.read_log(tmp_path / "log").accel_mps2, log.accel_mps2)
    assert f"{bag}: ROS 2 bag folder without metadata.yaml ({storage.name} read on its own" in out
    assert snapshot(bag) | snapshot(arr) == before  # nothing written into the bag folder
    # two storage files and no metadata: their order is unknown
    shutil.copy(storage, bag / f"second{storage.suffix}")
    refused([str(bag), "--array", str(arr)], tmp_path / "log2", capsys,
            f"{bag}: a ROS 2 bag folder without metadata.yaml holding 2 storage files")


def test_ros1_frame_ids_with_a_leading_slash(tmp_path, capsys):
    log = rotated_log()
    streams = [{**s, "frame_id": "/" + s["frame_id"], "topic": "/imu"} for s in sync_streams(log)]
    bag = write_bag(tmp_path / "bag", "ros1", streams)
    arr = array_file(tmp_path / "array.toml", log.array, topics=False)
    rc, out, err = convert([str(bag), "--array", str(arr), "--out", str(tmp_path / "log")], capsys)
    assert rc == 0, err
    assert np.array_equal(gio.read_log(tmp_path / "log").accel_mps2, log.accel_mps2)
    assert "s3: frame_id 's3' on /imu (frame_id '/s3')" in out


def test_gyro_as_reference_from_a_topic_of_the_bag(tmp_path, capsys):
    log = rotated_log(gyro=True)
    streams = sync_streams(log, gyro_from=(1,))
    # a reference gyro on its own topic, frame 'ref' (no accelerometer): its axes are the body axes;
    # it starts later and ends earlier than the accelerometers
    ref = {"topic": "/ref", "frame_id": "ref", "stamps_ns": log.timestamps_ns[20:230] + T0_NS,
           "accel": np.zeros((210, 3)), "accel_cov": NO_ACCEL, "gyro": log.truth.omega_b_radps[20:230]}
    bag = write_bag(tmp_path / "bag", "mcap", [*streams, ref])
    arr = array_file(tmp_path / "array.toml", replace(log.array, gyroscope=None))
    before = snapshot(bag) | snapshot(arr)
    rc, out, err = convert([str(bag), "--array", str(arr), "--out", str(tmp_path / "log"), "--gyro-as-reference",
                            "/ref", "--with-gyro"], capsys)
    assert rc == 0, err
    assert snapshot(bag) | snapshot(arr) == before
    back = gio.read_log(tmp_path / "log")
    assert len(back) == 250 and back.reference is not None
    valid = ~back.invalid_reference
    assert valid.tolist() == [False] * 20 + [True] * 210 + [False] * 20
    np.testing.assert_allclose(back.reference.omega_b_radps[valid], log.truth.omega_b_radps[20:230], rtol=0, atol=1e-12)
    np.testing.assert_allclose(back.gyro_b_radps, log.truth.omega_b_radps, rtol=0, atol=1e-12)  # from s1
    assert "reference: angular velocity of /ref (210 message(s) at 500.00 Hz), its axes (frame_id 'ref') taken as " \
           "the body axes" in out
    assert "reference: 40 sample(s) outside its messages or in their gaps over 3 periods marked not valid" in out
    # the gyro of an accelerometer's topic: turned into the body frame by that accelerometer's rotation, and no
    # longer a gyroscope of the array; without a topic, the one topic providing angular velocity
    bag2 = write_bag(tmp_path / "bag2", "sqlite3", streams)
    rc, out, err = convert([str(bag2), "--array", str(arr), "--out", str(tmp_path / "log2"), "--gyro-as-reference"],
                           capsys)
    assert rc == 0, err
    back = gio.read_log(tmp_path / "log2")
    assert back.gyro_b_radps is None and back.invalid_reference is None
    np.testing.assert_allclose(back.reference.omega_b_radps, log.truth.omega_b_radps, rtol=0, atol=1e-12)
    assert "turned into the body frame by the rotation of accelerometer 's1'" in out
    refused([str(bag2), "--array", str(arr), "--gyro-as-reference", "/imu/s1", "--with-gyro"], tmp_path / "log3",
            capsys, "--with-gyro: no Imu stream of the array provides angular_velocity",
            "the messages on /imu/s1 are the reference")
    refused([str(bag2), "--array", str(arr), "--gyro-as-reference", "/imu/s2"], tmp_path / "log3", capsys,
            f"{bag2}: --gyro-as-reference: topic '/imu/s2' provides no angular_velocity")
    refused([str(bag2), "--array", str(arr), "--gyro-as-reference", "/nope"], tmp_path / "log3", capsys,
            f"{bag2}: --gyro-as-reference: '/nope' is not an Imu topic of this bag")


def test_extrinsics_from_openvins_and_hostile_yaml_with_a_bag(tmp_path, good, capsys):
    """--extrinsics on `convert rosbag`: an OpenCV/OpenVINS file places the accelerometers (matched by rostopic);
    a 'billion laughs' file is refused in well under a second, the bag and the YAML unchanged."""
    import time

    log, bags = good
    arr = array_file(tmp_path / "array.toml", log.array)
    rots = [matrix_from_rotation_vector(v) for v in np.random.default_rng(4).normal(size=(4, 3))]
    pos = np.random.default_rng(5).uniform(-0.05, 0.05, (4, 3))
    text = "%YAML:1.0\n---\n"
    for k, a in enumerate(log.array.accelerometers):
        m = np.eye(4)
        m[:3, :3] = rots[k].T
        m[:3, 3] = -rots[k].T @ pos[k]
        text += (f"imu{k}:\n   T_i_b: !!opencv-matrix\n      rows: 4\n      cols: 4\n      dt: d\n      data: [ "
                 + ", ".join(f"{v:.17g}" for v in m.ravel()) + f" ]\n   rostopic: \"/imu/{a.name}\"\n")
    (tmp_path / "chain.yaml").write_text(text)
    rc, out, err = convert([str(bags["mcap"]), "--array", str(arr), "--extrinsics", str(tmp_path / "chain.yaml"),
                            "--out", str(tmp_path / "log")], capsys)
    assert rc == 0, err
    assert "Kalibr entries matched by rostopic" in out
    for k, a in enumerate(gio.read_log(tmp_path / "log").array.accelerometers):
        np.testing.assert_allclose(a.position_m, pos[k], rtol=0, atol=1e-15)
        np.testing.assert_allclose(a.rotation_body_sensor, rots[k], rtol=0, atol=1e-15)
    laughs = "a: &a [" + ",".join(['"lol"'] * 9) + "]\n"
    for prev, name in zip("abcdefgh", "bcdefghi"):
        laughs += f"{name}: &{name} [" + ",".join([f"*{prev}"] * 9) + "]\n"
    (tmp_path / "laughs.yaml").write_text(laughs)
    assert len(laughs) < 400
    before = snapshot(bags["mcap"]) | snapshot(tmp_path / "laughs.yaml")
    start = time.perf_counter()
    refused([str(bags["mcap"]), "--array", str(arr), "--extrinsics", str(tmp_path / "laughs.yaml")],
            tmp_path / "log2", capsys, f"{tmp_path / 'laughs.yaml'}:6: its aliases (*name) expand to more than "
                                       "200000 nodes")
    assert time.perf_counter() - start < 1.0
    assert snapshot(bags["mcap"]) | snapshot(tmp_path / "laughs.yaml") == before


def test_non_finite_readings_are_dropped_and_counted(tmp_path, capsys):
    """A nan or inf linear_acceleration is no reading: dropped, counted, bridged like a gap; a stream whose
    angular velocity is not finite somewhere is no gyro for --with-gyro."""
    log = rotated_log()
    streams = sync_streams(log, gyro_from=(0,))
    accel = streams[0]["accel"].copy()
    accel[10] = np.nan
    accel[20, 1] = np.inf
    gyro = streams[0]["gyro"].copy()
    gyro[5, 2] = np.nan
    streams[0] = {**streams[0], "accel": accel, "gyro": gyro}
    bag = write_bag(tmp_path / "bag", "mcap", streams)
    arr = array_file(tmp_path / "array.toml", log.array)
    rc, out, err = convert([str(bag), "--array", str(arr), "--out", str(tmp_path / "log")], capsys)
    assert rc == 0, err
    assert "s0: topic /imu/s0: 2 message(s) dropped for a linear_acceleration that is not finite (nan or inf; " \
           "message index 10, 20)" in out
    back = gio.read_log(tmp_path / "log")
    assert np.all(np.isfinite(back.accel_mps2))
    a = log.accel_mps2[:, 0:3]
    np.testing.assert_allclose(back.accel_mps2[[10, 20], 0:3], [(a[9] + a[11]) / 2, (a[19] + a[21]) / 2], rtol=0,
                               atol=1e-12)
    refused([str(bag), "--array", str(arr), "--with-gyro"], tmp_path / "log2", capsys,
            "--with-gyro: no Imu stream of the array provides angular_velocity",
            "or a message's angular_velocity is not finite")


LAUGHS = "a: &a [" + ",".join(['"lol"'] * 9) + "]\n" + "".join(
    f"{n}: &{n} [" + ",".join([f"*{p}"] * 9) + "]\n" for p, n in zip("abcdefg", "bcdefgh")) + \
    "rosbag2_bagfile_information: {version: 9, topics_with_message_count: [*h, *h, *h]}\n"


@pytest.mark.parametrize("edit, parts", [
    (lambda m: m.replace("  version: 9", "  version: '9'"),
     ["metadata.yaml: rosbag2_bagfile_information.version: expected an integer, got '9'"]),
    (lambda m: m.replace("rosbag2_bagfile_information:", "rosbag2_bagfile_information: 5\nx:"),
     ["metadata.yaml: rosbag2_bagfile_information: expected a mapping, got 5"]),
    (lambda m: m.replace("      name: /imu/s1", "      name: [1]"),
     ["metadata.yaml: rosbag2_bagfile_information.topics_with_message_count[1].topic_metadata.name: expected text"]),
    (lambda m: m.replace("\n  message_count: ", "\n  message_count: many #", 1),
     ["metadata.yaml: rosbag2_bagfile_information.message_count: expected an integer, got 'many'"]),
    (lambda m: LAUGHS, ["metadata.yaml:6: its aliases (*name) expand to more than 200000 nodes"]),
    (lambda m: "rosbag2_bagfile_information: " + "[" * 5000 + "]" * 5000 + "\n",
     ["metadata.yaml:1: nested deeper than 64 levels"]),
    (lambda m: "just text\n", ["metadata.yaml: expected the key rosbag2_bagfile_information at the top"]),
])
def test_a_damaged_metadata_yaml_names_the_file_and_key(tmp_path, edit, parts, capsys):
    """Damaged metadata.yaml: one line naming metadata.yaml and the key (rosbags itself said 'Invalid bag
    metadata: ... not subscriptable' or 'maximum recursion depth exceeded' about the folder), in under a second."""
    import time

    log = rotated_log(0.1)
    bag = write_bag(tmp_path / "bag", "sqlite3", sync_streams(log))
    text = (bag / "metadata.yaml").read_text()
    changed = edit(text)
    assert changed != text
    (bag / "metadata.yaml").write_text(changed)
    arr = array_file(tmp_path / "array.toml", log.array)
    before = snapshot(bag) | snapshot(arr)
    start = time.perf_counter()
    err = refused([str(bag), "--array", str(arr)], tmp_path / "log", capsys, *parts)
    assert time.perf_counter() - start < 1.0
    assert err.startswith(f"gfimu convert: error: {bag / 'metadata.yaml'}")
    assert snapshot(bag) | snapshot(arr) == before


def test_gyro_as_reference_on_a_topic_several_accelerometers_share(tmp_path, capsys):
    """A board publishing its accelerometers on one topic, the chips mounted alike (one rotation): the gyro of
    that topic is the reference, turned by the rotation they share; with different rotations, refused naming
    them."""
    from gfimu.array import Gyroscope

    rng = np.random.default_rng(5)
    turn = matrix_from_rotation_vector(np.array([0.3, -1.1, 0.7]))
    accs = tuple(Accelerometer(f"s{i}", rng.uniform(-0.03, 0.03, 3), turn, noise_std_mps2=NOISE_MPS2)
                 for i in range(4))
    log = simulate("random3d", array=SensorArray(accs, "alike", Gyroscope(0.01)), rate_hz=500.0, duration_s=0.5,
                   seed=2)
    streams = sync_streams(log, topic="/imu", gyro_from=(1,))
    bag = write_bag(tmp_path / "bag", "ros1", streams)
    shared = SensorArray(tuple(replace(a, topic="/imu") for a in accs), "alike")
    arr = tmp_path / "array.toml"
    gio.write_array_toml(shared, arr)
    rc, out, err = convert([str(bag), "--array", str(arr), "--out", str(tmp_path / "log"), "--gyro-as-reference"],
                           capsys)
    assert rc == 0, err
    back = gio.read_log(tmp_path / "log")
    # the sensor-frame gyro R^T ω turned back by R: a 3x3 product of numbers below 10 rad/s, a few ulps
    np.testing.assert_allclose(back.reference.omega_b_radps, log.truth.omega_b_radps, rtol=0, atol=1e-12)
    assert "turned into the body frame by the rotation its accelerometers 's0', 's1', 's2', 's3' share" in out
    other = SensorArray((replace(accs[0], topic="/imu", rotation_body_sensor=np.eye(3)),
                         *(replace(a, topic="/imu") for a in accs[1:])), "unlike")
    gio.write_array_toml(other, tmp_path / "other.toml")
    refused([str(bag), "--array", str(tmp_path / "other.toml"), "--gyro-as-reference"], tmp_path / "log2", capsys,
            "carry the frame_ids of several accelerometers (s0, s1, s2, s3) with different rotations")
