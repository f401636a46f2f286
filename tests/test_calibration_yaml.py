"""Calibration YAML as users have it, through ``gfimu convert ... --extrinsics``: Kalibr's own files, OpenVINS's
``%YAML:1.0`` files and OpenCV FileStorage's ``!!opencv-matrix``, T_i_b rounded to a few decimals, and YAML built
to hurt (nested aliases, recursion, deep nesting, duplicate keys, wrong types): each read, or refused in one line
naming the file and key, in well under a second, with nothing written and the inputs unchanged."""

from __future__ import annotations

import hashlib
import shutil
import time
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from gfimu import io as gio
from gfimu.cli import main

yaml = pytest.importorskip("yaml")

DATA = Path(__file__).resolve().parent / "data"
ONE = "t [ms],x [g],y [g],z [g]\n0,0,0,1\n2,0,0,1\n4,0,0,1\n"
ONE_MAP = 'format = "gfimu-csv-map/1"\n[time]\ncolumn = "t"\n[[accelerometers]]\nname = "imu0"\nx = "x"\ny = "y"\nz = "z"\n'
TWO = "t [ms],l_x [g],l_y [g],l_z [g],r_x [g],r_y [g],r_z [g]\n0,0,0,1,0,0,1\n2,0,0,1,0,0,1\n4,0,0,1,0,0,1\n"
TWO_MAP = ('format = "gfimu-csv-map/1"\n[time]\ncolumn = "t"\n[[accelerometers]]\nname = "left"\nx = "l_x"\n'
           'y = "l_y"\nz = "l_z"\n[[accelerometers]]\nname = "right"\nx = "r_x"\ny = "r_y"\nz = "r_z"\n')


def snapshot(root: Path) -> dict[str, str]:
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(root.rglob("*"))
            if p.is_file()}


@pytest.fixture
def one(tmp_path) -> Path:
    (tmp_path / "f.csv").write_text(ONE)
    (tmp_path / "map.toml").write_text(ONE_MAP)
    return tmp_path


@pytest.fixture
def two(tmp_path) -> Path:
    (tmp_path / "f.csv").write_text(TWO)
    (tmp_path / "map.toml").write_text(TWO_MAP)
    return tmp_path


def convert(folder: Path, extrinsics: Path, capsys) -> tuple[int, str, str]:
    rc = main(["convert", "csv", str(folder / "f.csv"), "--map", str(folder / "map.toml"), "--extrinsics",
               str(extrinsics), "--out", str(folder / "log")])
    out, err = capsys.readouterr()
    return rc, out, err


def t_i_b(position_b, rotation_body_sensor) -> np.ndarray:
    """Kalibr's T_i_b of a sensor at ``position_b`` whose axes are ``rotation_body_sensor`` in the body."""
    r_i_b = np.asarray(rotation_body_sensor, float).T
    m = np.eye(4)
    m[:3, :3] = r_i_b
    m[:3, 3] = -r_i_b @ np.asarray(position_b, float)
    return m


# --- real layouts ------------------------------------------------------------------------------------

def test_kalibrs_own_imu_yaml(one, capsys):
    """tests/data/kalibr/imu-camera_imu.yaml, as Kalibr wrote it (noise densities, model, update_rate ...)."""
    src = DATA / "kalibr" / "imu-camera_imu.yaml"
    before = src.read_bytes()
    rc, out, err = convert(one, src, capsys)
    assert rc == 0, err
    assert "imu0 <- imu0 (/imu0): position [0.0, 0.0, 0.0] m" in out
    acc = gio.read_log(one / "log", check=False).array.accelerometers[0]
    assert acc.position_m.tolist() == [0.0, 0.0, 0.0] and np.array_equal(acc.rotation_body_sensor, np.eye(3))
    assert src.read_bytes() == before


OPENVINS_IMU_CHAIN = """%YAML:1.0

imu0:
  T_i_b:
    - [{r0}]
    - [{r1}]
    - [{r2}]
    - [0.0, 0.0, 0.0, 1.0]
  accelerometer_noise_density: 2.0000e-3  # [ m / s^2 / sqrt(Hz) ]   ( accel "white noise" )
  accelerometer_random_walk: 3.0000e-3    # [ m / s^3 / sqrt(Hz) ].  ( accel bias diffusion )
  gyroscope_noise_density: 1.6968e-04     # [ rad / s / sqrt(Hz) ]   ( gyro "white noise" )
  gyroscope_random_walk: 1.9393e-05       # [ rad / s^2 / sqrt(Hz) ] ( gyro bias diffusion )
  rostopic: /imu0
  time_offset: 0.0
  update_rate: 200.0
  model: "kalibr" # calibrated (same as kalibr), kalibr, rpng
  Tw:
    - [ 1.0, 0.0, 0.0 ]
    - [ 0.0, 1.0, 0.0 ]
    - [ 0.0, 0.0, 1.0 ]
  R_IMUtoGYRO:
    - [ 1.0, 0.0, 0.0 ]
    - [ 0.0, 1.0, 0.0 ]
    - [ 0.0, 0.0, 1.0 ]
  Ta:
    - [ 1.0, 0.0, 0.0 ]
    - [ 0.0, 1.0, 0.0 ]
    - [ 0.0, 0.0, 1.0 ]
  R_IMUtoACC:
    - [ 1.0, 0.0, 0.0 ]
    - [ 0.0, 1.0, 0.0 ]
    - [ 0.0, 0.0, 1.0 ]
  Tg:
    - [ 0.0, 0.0, 0.0 ]
    - [ 0.0, 0.0, 0.0 ]
    - [ 0.0, 0.0, 0.0 ]
"""


def test_openvins_kalibr_imu_chain(one, capsys):
    """The layout of OpenVINS's config/*/kalibr_imu_chain.yaml: a '%YAML:1.0' first line, which plain YAML
    parsers refuse, and OpenVINS's IMU intrinsics next to T_i_b."""
    rot = Rotation.from_euler("zyx", [30, -10, 5], degrees=True).as_matrix()
    m = t_i_b([0.01, -0.02, 0.005], rot)
    rows = {f"r{k}": ", ".join(repr(float(v)) for v in m[k]) for k in range(3)}
    (one / "kalibr_imu_chain.yaml").write_text(OPENVINS_IMU_CHAIN.format(**rows))
    rc, out, err = convert(one, one / "kalibr_imu_chain.yaml", capsys)
    assert rc == 0, err
    acc = gio.read_log(one / "log", check=False).array.accelerometers[0]
    np.testing.assert_allclose(acc.position_m, [0.01, -0.02, 0.005], rtol=0, atol=1e-15)
    np.testing.assert_allclose(acc.rotation_body_sensor, rot, rtol=0, atol=1e-15)


OPENCV_CHAIN = """%YAML:1.0
---
imu0:
   T_i_b: !!opencv-matrix
      rows: 4
      cols: 4
      dt: d
      data: [ {d0} ]
   rostopic: "/left"
imu1:
   T_i_b: !!opencv-matrix
      rows: 4
      cols: 4
      dt: d
      data: [ {d1} ]
   rostopic: "/right"
"""


def opencv_numbers(m: np.ndarray) -> str:
    """As OpenCV's FileStorage writes doubles: '1.', '0.', '-2.1640145497500001e-02'."""
    def one_value(v: float) -> str:
        return f"{v:.0f}." if float(v).is_integer() else f"{v:.16e}"
    return ", ".join(one_value(v) for v in m.ravel())


def test_opencv_filestorage_matrices(two, capsys):
    rots = Rotation.from_euler("xyz", [[10, 20, 30], [-40, 5, 90]], degrees=True).as_matrix()
    pos = [[-0.03, 0.01, 0.0], [0.03, -0.01, 0.002]]
    text = OPENCV_CHAIN.format(d0=opencv_numbers(t_i_b(pos[0], rots[0])), d1=opencv_numbers(t_i_b(pos[1], rots[1])))
    (two / "chain.yaml").write_text(text)
    rc, out, err = convert(two, two / "chain.yaml", capsys)
    assert rc == 0, err
    assert "matched by rostopic" in out
    accs = gio.read_log(two / "log", check=False).array.accelerometers
    for k in range(2):
        np.testing.assert_allclose(accs[k].position_m, pos[k], rtol=0, atol=1e-15)
        np.testing.assert_allclose(accs[k].rotation_body_sensor, rots[k], rtol=0, atol=1e-15)
    # a matrix of the wrong size names the key and its line
    shutil.rmtree(two / "log")
    (two / "bad.yaml").write_text(text.replace("rows: 4", "rows: 3", 1))
    refused(two, "bad.yaml", capsys, "bad.yaml:4: imu0.T_i_b: expected a 4x4 !!opencv-matrix with 16 data values, "
                                     "got rows 3, cols 4, 16 value(s)")


def test_an_openvins_estimator_config_names_its_imu_chain(one, capsys):
    (one / "estimator_config.yaml").write_text(
        '%YAML:1.0 # need to specify the file type at the top!\n\nverbosity: "INFO"\nuse_fej: true\n'
        'init_dyn_bias_g: [ 0.0, 0.0, 0.0 ]\nrelative_config_imu: "kalibr_imu_chain.yaml"\n'
        'relative_config_imucam: "kalibr_imucam_chain.yaml"\n')
    refused(one, "estimator_config.yaml", capsys, "estimator_config.yaml: no IMU entries",
            "an OpenVINS estimator config, whose IMU chain is the file its relative_config_imu names "
            "(kalibr_imu_chain.yaml)")


def test_a_camera_imu_chain_is_not_an_imu_chain(one, capsys):
    (one / "camchain.yaml").write_text(
        "%YAML:1.0\n\ncam0:\n  T_imu_cam:\n    - [0.0148655429818, -0.999880929698, 0.00414029679422, -0.0216401454975]\n"
        "    - [0.999557249008, 0.0149672133247, 0.025715529948, -0.064676986768]\n"
        "    - [-0.0257744366974, 0.00375618835797, 0.999660727178, 0.00981073058949]\n"
        "    - [0.0, 0.0, 0.0, 1.0]\n  camera_model: pinhole\n  rostopic: /cam0/image_raw\n")
    refused(one, "camchain.yaml", capsys, "camchain.yaml:3: cam0: has no T_i_b",
            "transforms found: T_imu_cam) (a camera entry of a camera-IMU chain: --extrinsics needs the IMU chain)")


# --- rounded digits ------------------------------------------------------------------------------------

def rounded_chain(decimals: int) -> tuple[str, np.ndarray]:
    rot = Rotation.from_euler("zyx", [37, -21, 64], degrees=True).as_matrix()
    m = np.round(t_i_b([0.02, 0.01, -0.03], rot), decimals)
    text = "imu0:\n  T_i_b:\n" + "".join(f"  - [{', '.join(f'{v:.{decimals}f}' for v in row)}]\n" for row in m)
    return text + "  rostopic: /imu0\n", rot


@pytest.mark.parametrize("decimals", [5, 6])
def test_t_i_b_rounded_to_a_few_decimals_is_repaired_with_a_warning(one, capsys, decimals):
    text, rot = rounded_chain(decimals)
    (one / "k.yaml").write_text(text)
    written = np.array(yaml.safe_load(text)["imu0"]["T_i_b"])[:3, :3]
    deviation = np.max(np.abs(written.T @ written - np.eye(3)))
    assert 1e-6 < deviation < 1e-4  # what the rounding costs, and why the file was refused before
    rc, out, err = convert(one, one / "k.yaml", capsys)
    assert rc == 0, err
    assert err.count("\n") == 1 and f"gfimu convert: warning: {one / 'k.yaml'}:2: imu0.T_i_b: rotation orthonormal " \
                                   f"only to {deviation:.2g}" in err, err
    got = gio.read_log(one / "log", check=False).array.accelerometers[0].rotation_body_sensor
    # the nearest rotation U Vᵀ of a backward-stable SVD is orthonormal to a small multiple of n·ε (n = 3), and
    # the product checking it adds n roundings per entry: 8·n·ε, not the last bit one BLAS kernel happens to give
    assert np.max(np.abs(got @ got.T - np.eye(3))) < 8 * 3 * np.finfo(float).eps
    assert np.max(np.abs(got - rot)) < 10 ** -decimals  # the nearest rotation is at least as close as the digits


def test_t_i_b_rounded_too_far_is_refused(one, capsys):
    text, _ = rounded_chain(2)
    (one / "k.yaml").write_text(text)
    refused(one, "k.yaml", capsys, "k.yaml:2: imu0.T_i_b: not a rigid transform: its rotation part is not a "
                                   "rotation (RᵀR differs from the identity by", "up to 0.0001 is taken as rounding")


# --- YAML built to hurt ----------------------------------------------------------------------------------

LAUGHS = """a: &a ["lol","lol","lol","lol","lol","lol","lol","lol","lol"]
b: &b [*a,*a,*a,*a,*a,*a,*a,*a,*a]
c: &c [*b,*b,*b,*b,*b,*b,*b,*b,*b]
d: &d [*c,*c,*c,*c,*c,*c,*c,*c,*c]
e: &e [*d,*d,*d,*d,*d,*d,*d,*d,*d]
f: &f [*e,*e,*e,*e,*e,*e,*e,*e,*e]
g: &g [*f,*f,*f,*f,*f,*f,*f,*f,*f]
h: &h [*g,*g,*g,*g,*g,*g,*g,*g,*g]
imu0: {T_i_b: [*h,*h,*h,*h,*h,*h,*h,*h,*h]}
"""


def refused(folder: Path, name: str, capsys, *parts: str) -> str:
    before = snapshot(folder)
    start = time.perf_counter()
    rc, out, err = convert(folder, folder / name, capsys)
    elapsed = time.perf_counter() - start
    assert rc == 2, err
    assert err.count("\n") == 1 and err.startswith("gfimu convert: error: ") and "Traceback" not in err, err
    for part in parts:
        assert part in err, err
    assert snapshot(folder) == before and not (folder / "log").exists()
    # refused before any expansion: the full expansion (9^9 nodes) takes far longer than this on any machine,
    # loaded or not, so a bound this loose still tells the two apart
    assert elapsed < 30.0, elapsed
    return err


@pytest.mark.parametrize("text, parts", [
    (LAUGHS, ["k.yaml:6: its aliases (*name) expand to more than 200000 nodes"]),
    ("imu0: &x\n  T_i_b: [*x]\n", ["k.yaml:2: alias *x refers to a node that contains it"]),
    ("imu0:\n  T_i_b: " + "[" * 20000 + "]" * 20000 + "\n", ["k.yaml:2: nested deeper than 64 levels"]),
    ("imu0:\n  T_i_b: [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]\nimu0:\n  T_i_b: 3\n",
     ["k.yaml:3: imu0: given twice (lines 1 and 3)"]),
    ("imu0: 5\n", ["k.yaml:1: imu0: expected an IMU entry (T_i_b, rostopic, ...), got 5"]),
    ("imu0:\n  T_i_b: 5\n", ["k.yaml:2: imu0.T_i_b: expected a 4x4 matrix of finite numbers (four rows of four), got 5"]),
    ("imu0:\n  T_i_b: [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]\n  rostopic: 5\n",
     ["k.yaml:3: imu0.rostopic: expected a topic name, got 5"]),
    ("imu0:\n  T_i_b: [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]\n  time_offset: soon\n",
     ["k.yaml:3: imu0.time_offset: expected a number of seconds, got 'soon'"]),
    ("imu0:\n  T_i_b: [[1.0e+300, 0, 0, 0], [0, 1.0e+300, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]\n",
     ["k.yaml:2: imu0.T_i_b: not a rigid transform: its rotation part holds 1e+300"]),
    ("imu0:\n  T_i_b: [[1, 0, 0, 1.0e+200], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]\n",
     ["k.yaml:2: imu0.T_i_b: translation [1e+200, 0.0, 0.0] m puts the IMU 1e+200 m from the body origin"]),
    ("imu0:\n  T_i_b: [[.nan, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]\n",
     ["k.yaml:2: imu0.T_i_b: expected a 4x4 matrix of finite numbers"]),
    ("imu0:\n  T_i_b: [[true, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]\n",
     ["k.yaml:2: imu0.T_i_b: expected a 4x4 matrix of finite numbers"]),
    ("imu0:\n  ? [1, 2]\n  : 3\n", ["k.yaml:2: a key that is not a name ([1, 2])"]),
])
def test_hostile_yaml_is_refused_quickly_naming_file_and_key(one, capsys, text, parts):
    (one / "k.yaml").write_text(text)
    refused(one, "k.yaml", capsys, *parts)
