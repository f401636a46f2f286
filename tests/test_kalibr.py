"""Kalibr extrinsics (``gfimu convert ... --extrinsics``): T_i_b to positions and rotations, round trips, the
matching of entries to accelerometers, and bad YAML files refused with one line and nothing written."""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gfimu import io as gio
from gfimu.array import Accelerometer, SensorArray
from gfimu.cli import main
from gfimu.io.errors import LogFormatError
from gfimu.io.kalibr import apply_kalibr, kalibr_yaml, parse_kalibr, read_kalibr

yaml = pytest.importorskip("yaml")


def random_array(n: int, seed: int) -> SensorArray:
    rng = np.random.default_rng(seed)
    rots = Rotation.random(n, random_state=seed).as_matrix()
    return SensorArray(tuple(Accelerometer(f"imu{k}", rng.uniform(-0.05, 0.05, 3), rots[k]) for k in range(n)))


def unplaced(names) -> SensorArray:
    return SensorArray(tuple(Accelerometer(n, np.zeros(3)) for n in names))


def test_round_trip_through_kalibr_yaml(tmp_path):
    array = random_array(4, seed=3)
    (tmp_path / "chain.yaml").write_text(kalibr_yaml(array))
    placed, report = apply_kalibr(unplaced([a.name for a in array.accelerometers]), read_kalibr(tmp_path / "chain.yaml"))
    for a, b in zip(array.accelerometers, placed.accelerometers):
        np.testing.assert_allclose(b.position_m, a.position_m, rtol=0, atol=1e-12)
        np.testing.assert_allclose(b.rotation_body_sensor, a.rotation_body_sensor, rtol=0, atol=1e-12)
    assert "matched by name" in report[0]


def test_known_transform():
    """R_i_b a quarter turn about z, t_i_b = (1, 2, 3): the IMU's origin is at -R_i_bᵀ t_i_b = (-2, 1, -3) in the
    body, and its x axis is the body's -y axis (v_b = R_i_bᵀ v_i)."""
    t_i_b = [[0, -1, 0, 1], [1, 0, 0, 2], [0, 0, 1, 3], [0, 0, 0, 1]]
    imus = parse_kalibr({"imu0": {"T_i_b": t_i_b}}, "imu0:\n  T_i_b: ...\n", "k.yaml")
    array, report = apply_kalibr(unplaced(["a"]), imus)
    assert report[0].endswith("body frame = the frame T_i_b maps from (imu0's T_i_b is not the identity: imu0 is "
                              "not at its origin)")
    acc = array.accelerometers[0]
    assert acc.position_m.tolist() == [-2.0, 1.0, -3.0]
    assert (acc.rotation_body_sensor @ [1, 0, 0]).tolist() == [0.0, -1.0, 0.0]
    # the body point at the IMU's origin maps to the IMU frame's origin
    m = np.array(t_i_b, dtype=float)
    assert (m[:3, :3] @ acc.position_m + m[:3, 3]).tolist() == [0.0, 0.0, 0.0]


def test_matching_by_rostopic_name_and_order():
    array = random_array(3, seed=5)
    imus = parse_kalibr(yaml.safe_load(kalibr_yaml(array, topics=["/imu2", "/imu0", "/imu1"])), "", "k.yaml")
    placed, report = apply_kalibr(unplaced(["imu2", "imu0", "imu1"]), imus)  # entry imu0 carries /imu2 ...
    assert "matched by rostopic" in report[0]
    assert np.allclose(placed.accelerometers[0].position_m, array.accelerometers[0].position_m, atol=1e-12)
    placed, report = apply_kalibr(unplaced(["c", "a", "b"]), imus)
    assert "matched by order" in report[0]
    assert np.allclose(placed.accelerometers[1].position_m, array.accelerometers[1].position_m, atol=1e-12)


def snapshot(root: Path) -> dict[str, str]:
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(root.rglob("*"))
            if p.is_file()}


TWO = "t [ms],l_x [g],l_y [g],l_z [g],r_x [g],r_y [g],r_z [g]\n0,0,0,1,0,0,1\n2,0,0,1,0,0,1\n"
TWO_MAP = '''format = "gfimu-csv-map/1"
[time]
column = "t"
[[accelerometers]]
name = "left"
x = "l_x"
y = "l_y"
z = "l_z"
[[accelerometers]]
name = "right"
x = "r_x"
y = "r_y"
z = "r_z"
'''


@pytest.fixture
def recording(tmp_path) -> Path:
    (tmp_path / "f.csv").write_text(TWO)
    (tmp_path / "map.toml").write_text(TWO_MAP)
    return tmp_path


def test_convert_with_extrinsics_places_the_accelerometers(recording, capsys):
    array = SensorArray((Accelerometer("left", [-0.03, 0.01, 0.0], Rotation.from_euler("z", 30, degrees=True).as_matrix()),
                         Accelerometer("right", [0.03, -0.01, 0.002], Rotation.from_euler("xy", [10, -20], degrees=True).as_matrix())))
    (recording / "kalibr.yaml").write_text(kalibr_yaml(array, topics=["/left", "/right"]))
    rc = main(["convert", "csv", str(recording / "f.csv"), "--map", str(recording / "map.toml"), "--extrinsics",
               str(recording / "kalibr.yaml"), "--out", str(recording / "log")])
    out = capsys.readouterr().out
    assert rc == 0
    assert "matched by rostopic" in out and "left <- imu0 (/left)" in out
    log = gio.read_log(recording / "log", check=False)
    for a, b in zip(array.accelerometers, log.array.accelerometers):
        np.testing.assert_allclose(b.position_m, a.position_m, rtol=0, atol=1e-12)
        np.testing.assert_allclose(b.rotation_body_sensor, a.rotation_body_sensor, rtol=0, atol=1e-12)


def test_extrinsics_replace_the_places_of_array_toml_and_the_report_says_so(recording, capsys):
    """--array and --extrinsics together: the positions and rotations written are the extrinsics', the
    axes and names the array's, and one report line names both files."""
    given = SensorArray((Accelerometer("left", [-0.05, 0.0, 0.0]), Accelerometer("right", [0.05, 0.0, 0.0])))
    gio.write_array_toml(given, recording / "array.toml")
    chain = random_array(2, seed=7)
    (recording / "kalibr.yaml").write_text(kalibr_yaml(chain))
    rc = main(["convert", "csv", str(recording / "f.csv"), "--map", str(recording / "map.toml"), "--array",
               str(recording / "array.toml"), "--extrinsics", str(recording / "kalibr.yaml"), "--out",
               str(recording / "log")])
    out = capsys.readouterr().out
    assert rc == 0
    line = f"positions and rotations from {recording / 'kalibr.yaml'} replace those of {recording / 'array.toml'}"
    assert out.splitlines().count(line) == 1, out
    assert f"geometry: {recording / 'array.toml'}" not in out
    log = gio.read_log(recording / "log", check=False)
    assert [a.name for a in log.array.accelerometers] == ["left", "right"]
    for a, b in zip(chain.accelerometers, log.array.accelerometers):
        np.testing.assert_allclose(b.position_m, a.position_m, rtol=0, atol=1e-12)
        np.testing.assert_allclose(b.rotation_body_sensor, a.rotation_body_sensor, rtol=0, atol=1e-12)


GOOD = [[1.0, 0.0, 0.0, 0.01], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]]


@pytest.mark.parametrize("text, message", [
    ("imu0:\n  T_i_b: {good}\nimu1:\n  T_cam_imu: {good}\n  rostopic: /imu1\n",
     "kalibr.yaml:3: imu1: has no T_i_b"),
    ("imu0:\n  T_i_b: {good}\nimu1:\n  T_i_b: [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0.5, 1]]\n",
     "kalibr.yaml:4: imu1.T_i_b: not a rigid transform: its bottom row is [0.0, 0.0, 0.5, 1.0]"),
    ("imu0:\n  T_i_b: {good}\nimu1:\n  T_i_b: [[1, 0.1, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]\n",
     "imu1.T_i_b: not a rigid transform: its rotation part is not a rotation"),
    ("imu0:\n  T_i_b: {good}\nimu1:\n  T_i_b: [[1, 0, 0], [0, 1, 0], [0, 0, 1]]\n",
     "imu1.T_i_b: expected a 4x4 matrix"),
    ("imu0:\n  T_i_b: {good}\n", "has 1 IMU entry (imu0) but the array has 2 accelerometer(s)"),
    ("imu0: [unclosed\n", "not valid YAML"),
    ("just text\n", "expected a Kalibr IMU chain"),
])
def test_bad_kalibr_yaml_via_the_cli(recording, capsys, text, message):
    (recording / "kalibr.yaml").write_text(text.replace("{good}", str(GOOD)))
    before = snapshot(recording)
    rc = main(["convert", "csv", str(recording / "f.csv"), "--map", str(recording / "map.toml"), "--extrinsics",
               str(recording / "kalibr.yaml"), "--out", str(recording / "log")])
    err = capsys.readouterr().err.strip()
    assert rc == 2, err
    assert message in err, err
    assert len(err.splitlines()) == 1 and "Traceback" not in err
    assert snapshot(recording) == before and not (recording / "log").exists()


def test_a_missing_extrinsics_file(recording):
    with pytest.raises(LogFormatError, match="file not found"):
        read_kalibr(recording / "nothere.yaml")
    assert main(["convert", "csv", str(recording / "f.csv"), "--map", str(recording / "map.toml"), "--extrinsics",
                 str(recording / "nothere.yaml"), "--out", str(recording / "log")]) == 2
    assert not (recording / "log").exists()


def test_extrinsics_apply_to_every_format(tmp_path, capsys):
    """The MIMU4444 reader's eight accelerometers placed from a Kalibr chain (matched by order)."""
    import struct

    from gfimu.array import mimu4444_array

    raw = np.zeros((8, 6), dtype=np.int16)
    raw[:, 2] = 2048

    def packet(k: int) -> bytes:
        body = struct.pack(">BHBI", 0xAA, k, 100, k * 1_024_000) + raw.astype(">i2").tobytes()
        return body + struct.pack(">H", sum(body) % 65536)

    (tmp_path / "data.bin").write_bytes(b"".join(packet(k) for k in range(20)))
    target = random_array(8, seed=11)
    (tmp_path / "kalibr.yaml").write_text(kalibr_yaml(target))
    assert main(["convert", "mimu4444", str(tmp_path / "data.bin"), "--extrinsics", str(tmp_path / "kalibr.yaml"),
                 "--out", str(tmp_path / "log")]) == 0
    assert "matched by order" in capsys.readouterr().out
    log = gio.read_log(tmp_path / "log", check=False)
    assert [a.name for a in log.array.accelerometers] == [a.name for a in mimu4444_array().accelerometers]
    for a, b in zip(target.accelerometers, log.array.accelerometers):
        np.testing.assert_allclose(b.position_m, a.position_m, rtol=0, atol=1e-12)
        np.testing.assert_allclose(b.rotation_body_sensor, a.rotation_body_sensor, rtol=0, atol=1e-12)


def test_the_documented_example():
    import re

    text = (Path(__file__).resolve().parents[1] / "docs" / "convert.md").read_text(encoding="utf-8")
    block = re.search(r"```yaml\n(.*?)```", text, flags=re.DOTALL).group(1)
    array, report = apply_kalibr(unplaced(["imu0", "imu1"]), parse_kalibr(yaml.safe_load(block), block, "doc"))
    np.testing.assert_allclose(array.accelerometers[1].position_m, [-0.02, 0.01, 0.0], rtol=0, atol=1e-15)
    assert (array.accelerometers[1].rotation_body_sensor @ [1.0, 0.0, 0.0]).tolist() == [0.0, -1.0, 0.0]
    assert report[0].endswith("body frame = the frame of imu0 (Kalibr's reference IMU)")
    assert "matched by rostopic" in report[0] and any("time_offset 0.0012 s is not applied" in r for r in report)
