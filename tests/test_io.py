"""Log format I/O: exact round trips, unit conversion, atomic writes."""

import math
import os

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gfimu import io as gio
from gfimu.io import tables, units

# the toy logs here have arbitrary timestamps and readings; plausibility is tested in test_bad_inputs.py
pytestmark = pytest.mark.filterwarnings("ignore::gfimu.io.errors.LogPlausibilityWarning")
from gfimu.array import Accelerometer, Body, Gyroscope, Inclinometer, SensorArray, cube_array, paper001_array
from gfimu.log import Log
from gfimu.motion import QUANTITIES, Motion
from gfimu.rotations import matrix_from_rotation_vector, quaternion_from_rotation_vector

T0_NS = 1_700_000_000_123_456_789  # epoch-scale timestamps do not fit a float64 exactly


def mixed_array() -> SensorArray:
    """1-, 2- and 3-axis sensors, rotated sensors, gyro, inclinometer and body."""
    rot = matrix_from_rotation_vector([0.3, -1.1, 0.7])
    accs = (
        Accelerometer("a1", [0.05, 0.05, 0.05], noise_std_mps2=0.07),
        Accelerometer("a2", [0.05, -0.05, -0.05], rot, ("y", "z"), 0.0123456789),
        Accelerometer("side 3", [-1e-3, 0.1, -0.05], matrix_from_rotation_vector([0, 0, math.pi / 2]), ("x",)),
        Accelerometer("a4", [-0.05, -0.05, 0.05], rot.T, ("z", "x", "y"), None),
    )
    return SensorArray(accs, 'bench "B" \\ ünïcode', Gyroscope(0.01), Inclinometer(None), Body((0.0116, 0.0185, 0.0225)))


def assert_same_array(a: SensorArray, b: SensorArray) -> None:
    assert a.name == b.name
    assert len(a.accelerometers) == len(b.accelerometers)
    for x, y in zip(a.accelerometers, b.accelerometers):
        assert x.name == y.name and x.axes == y.axes and x.noise_std_mps2 == y.noise_std_mps2
        assert np.array_equal(x.position_m, y.position_m)
        assert np.array_equal(x.rotation_body_sensor, y.rotation_body_sensor)
    assert a.gyroscope == b.gyroscope and a.inclinometer == b.inclinometer and a.body == b.body


def random_log(array: SensorArray, n: int = 50, seed: int = 0, truth: bool = True) -> Log:
    rng = np.random.default_rng(seed)
    t = T0_NS + np.cumsum(rng.integers(1_999_000, 2_001_000, n))
    motion = None
    if truth:
        q = quaternion_from_rotation_vector(rng.normal(size=(n, 3)))
        motion = Motion(t, rng.normal(size=(n, 3)), rng.normal(size=(n, 3)) * 1e3, rng.normal(size=(n, 3)),
                        rng.normal(size=(n, 3)) * 1e-300, q,
                        sigma={"omega_b_radps": rng.uniform(0, 1, (n, 3)), "quaternion_wb": rng.uniform(0, 1, (n, 4))})
    accel = rng.normal(size=(n, array.n_axes)) * 10.0 ** rng.integers(-20, 20, (n, array.n_axes))
    accel[0, 0] = 5e-324  # subnormal
    accel[1, 0] = -0.0
    gyro = rng.normal(size=(n, 3)) if array.gyroscope else None
    tilt = rng.normal(size=(n, 2)) if array.inclinometer else None
    return Log(array, t, accel, gyro, tilt, truth=motion)


def write(path, text: str):
    path.write_text(text, encoding="utf-8")
    return path


# --- round trips -------------------------------------------------------------------

def test_array_toml_round_trip_exact(tmp_path):
    for array in (mixed_array(), cube_array(0.0371), paper001_array()):
        gio.write_array_toml(array, tmp_path / "array.toml")
        assert_same_array(gio.read_array_toml(tmp_path / "array.toml"), array)


def test_array_toml_text_is_deterministic_and_uses_the_specified_keys(tmp_path):
    text = gio.format_array_toml(mixed_array())
    assert text == gio.format_array_toml(mixed_array())
    assert text.startswith('format = "gfimu-array/1"\nname = "bench \\"B\\" \\\\ ünïcode"\n')
    assert 'axes = ["y", "z"]' in text and "noise_std_mps2 = 0.0123456789" in text
    assert "[gyroscope]\nnoise_std_radps = 0.01" in text and "[inclinometer]" in text
    assert "principal_inertia_kgm2 = [0.0116, 0.0185, 0.0225]" in text
    # identity rotations are left to their default
    assert text.count("rotation_body_sensor") == 3


@settings(max_examples=40, deadline=None)
@given(st.lists(st.floats(min_value=-50.0, max_value=50.0, allow_nan=False, width=64), min_size=3, max_size=3),
       st.floats(min_value=0, max_value=1e300, allow_nan=False))
def test_array_toml_round_trips_any_float(tmp_path_factory, position, noise):
    array = SensorArray((Accelerometer("a", position, noise_std_mps2=noise),))
    text = gio.format_array_toml(array)
    back = gio.parse_array_toml(text)
    assert np.array_equal(back.accelerometers[0].position_m, np.asarray(position))
    assert back.accelerometers[0].noise_std_mps2 == noise


def test_log_round_trip_exact(tmp_path):
    log = random_log(mixed_array(), n=64)
    log = log.replace(reference=log.truth.replace(quaternion_wb=None, sigma={}),
                      invalid_reference=np.arange(64) % 7 == 3)
    gio.write_log(log, tmp_path / "log")
    back = gio.read_log(tmp_path / "log")
    assert_same_array(back.array, log.array)
    assert back.timestamps_ns.dtype == np.int64 and np.array_equal(back.timestamps_ns, log.timestamps_ns)
    for name in ("accel_mps2", "gyro_b_radps", "tilt_rad", "invalid_reference"):
        assert np.array_equal(getattr(back, name), getattr(log, name)), name
    assert np.signbit(back.accel_mps2[1, 0]) and back.accel_mps2[0, 0] == 5e-324
    for which in ("truth", "reference"):
        a, b = getattr(back, which), getattr(log, which)
        assert a.available() == b.available()
        for name in b.available():
            assert np.array_equal(getattr(a, name), getattr(b, name)), (which, name)
        assert sorted(a.sigma) == sorted(b.sigma)
        for name in b.sigma:
            assert np.array_equal(a.sigma[name], b.sigma[name])
    header = (tmp_path / "log" / "imu.csv").read_text().splitlines()[0].split(",")
    assert header[0] == "#timestamp [ns]"
    assert header[1:5] == ["a1_x [m s^-2]", "a1_y [m s^-2]", "a1_z [m s^-2]", "a2_y [m s^-2]"]
    assert header[-5:] == ["w_x [rad s^-1]", "w_y [rad s^-1]", "w_z [rad s^-1]", "tilt_x [rad]", "tilt_y [rad]"]
    ref_header = (tmp_path / "log" / "reference.csv").read_text().splitlines()[0]
    assert ref_header.endswith(",valid []")


def test_estimate_csv_layout_and_digits(tmp_path):
    rng = np.random.default_rng(5)
    t = T0_NS + np.arange(20) * 1_000_000
    w = rng.normal(size=(20, 3))
    est = Motion(t, omega_b_radps=w, specific_force_b_mps2=w * 3, sigma={"omega_b_radps": np.abs(w) / 10})
    gio.write_motion_csv(est, tmp_path / "exact.csv")
    gio.write_motion_csv(est, tmp_path / "short.csv", digits=9)
    lines = (tmp_path / "exact.csv").read_text().splitlines()
    assert lines[0] == ("#timestamp [ns],w_x [rad s^-1],w_y [rad s^-1],w_z [rad s^-1],f_x [m s^-2],f_y [m s^-2],"
                        "f_z [m s^-2],sigma_w_x [rad s^-1],sigma_w_y [rad s^-1],sigma_w_z [rad s^-1]")
    assert len(lines) == 21 and lines[1].startswith(f"{T0_NS},")
    exact = gio.read_motion_csv(tmp_path / "exact.csv")
    assert exact.available() == ["omega_b_radps", "specific_force_b_mps2"]
    assert np.array_equal(exact.omega_b_radps, w) and np.array_equal(exact.sigma["omega_b_radps"], np.abs(w) / 10)
    short = gio.read_motion_csv(tmp_path / "short.csv")
    assert np.array_equal(short.timestamps_ns, t)
    np.testing.assert_allclose(short.omega_b_radps, w, rtol=6e-9, atol=0)
    assert not np.array_equal(short.omega_b_radps, w)


def test_estimate_with_nan_reads_back_only_when_allowed(tmp_path):
    t = np.arange(4) * 10
    w = np.array([[1.0, 2, 3], [np.nan, 0, 0], [4, 5, 6], [7, 8, 9]])
    gio.write_motion_csv(Motion(t, omega_b_radps=w), tmp_path / "e.csv")
    back = gio.read_motion_csv(tmp_path / "e.csv", allow_nan=True)
    assert np.array_equal(back.omega_b_radps, w, equal_nan=True)
    with pytest.raises(gio.LogFormatError, match=r"e\.csv:3: column 'w_x' is 'nan'; values must be finite"):
        gio.read_motion_csv(tmp_path / "e.csv")


def test_crlf_bom_extra_columns_and_keys_are_accepted(tmp_path):
    d = tmp_path / "log"
    d.mkdir()
    write(d / "array.toml", 'format = "gfimu-array/1"\nowner = "lab 3"\n[[accelerometers]]\nname = "s"\n'
                            'position_m = [0, 0, 0.01]\naxes = ["z"]\ncolour = "red"\n[[accelerometers]]\n'
                            'name = "t"\nposition_m = [0.0, 0.0, -0.01]\naxes = ["z"]\n[extra]\nx = 1\n')
    (d / "imu.csv").write_bytes("\ufeff#timestamp [ns],note,s_z [m s^-2],temp [degC],t_z [m/s²]\r\n"
                                "10,start,1.5,21.0,2.5\r\n20,,-1e-3,21.5,3\r\n\r\n".encode())
    log = gio.read_log(d)
    assert log.array.name == "array" and [a.axes for a in log.array.accelerometers] == [("z",), ("z",)]
    assert np.array_equal(log.timestamps_ns, [10, 20])
    assert np.array_equal(log.accel_mps2, [[1.5, 2.5], [-1e-3, 3.0]])


# --- unit conversion -----------------------------------------------------------------

def one_axis_log(tmp_path, header_unit: str, values: list[str], time_unit: str = "ns", times=None, extra=""):
    d = tmp_path / "log"
    d.mkdir(exist_ok=True)
    write(d / "array.toml", 'format = "gfimu-array/1"\n[[accelerometers]]\nname = "a"\nposition_m = [0, 0, 0]\n'
                            'axes = ["x"]\n' + extra)
    times = times or [str(10 * (k + 1)) for k in range(len(values))]
    write(d / "imu.csv", f"#timestamp [{time_unit}],a_x [{header_unit}]\n"
                         + "".join(f"{t},{v}\n" for t, v in zip(times, values)))
    return d


@pytest.mark.parametrize("unit, factor", [("m s^-2", 1.0), ("m/s^2", 1.0), ("m/s²", 1.0), ("m·s⁻²", 1.0),
                                          ("g", 9.80665), ("mg", 9.80665e-3)])
def test_acceleration_units(tmp_path, unit, factor):
    log = gio.read_log(one_axis_log(tmp_path, unit, ["1", "-0.5", "2"]))
    assert np.array_equal(log.accel_mps2[:, 0], np.array([1.0, -0.5, 2.0]) * factor)


def test_g_converts_to_standard_gravity_exactly(tmp_path):
    log = gio.read_log(one_axis_log(tmp_path, "g", ["1", "0.5", "-2"]))
    assert log.accel_mps2[:, 0].tolist() == [9.80665, 4.903325, -19.6133]


def test_gyro_and_tilt_units(tmp_path):
    d = tmp_path / "log"
    gio.write_array_toml(paper001_array(), tmp_path / "array.toml")
    d.mkdir()
    os.replace(tmp_path / "array.toml", d / "array.toml")
    acc = ",".join(f"{c} [m s^-2]" for c in paper001_array().accel_columns)
    write(d / "imu.csv", f"#timestamp [ms],{acc},w_x [deg s^-1],w_y [deg/s],w_z [dps],tilt_x [deg],tilt_y [mrad]\n"
                         "1.5,1,2,3,4,5,6,180,-90,45,12,250\n2.5,1,2,3,4,5,6,0,360,1,0,-1\n")
    log = gio.read_log(d)
    assert np.array_equal(log.timestamps_ns, [1_500_000, 2_500_000])
    np.testing.assert_allclose(log.gyro_b_radps, [[math.pi, -math.pi / 2, math.pi / 4], [0, 2 * math.pi, math.pi / 180]],
                               rtol=1e-15)
    np.testing.assert_allclose(log.tilt_rad, [[12 * math.pi / 180, 0.25], [0, -1e-3]], rtol=1e-15)


@pytest.mark.parametrize("unit, times, expected", [
    ("s", ["1700000000.123456789", "1700000000.123456790"], [1_700_000_000_123_456_789, 1_700_000_000_123_456_790]),
    ("us", ["1.5", "2.0004"], [1_500, 2_000]),
    ("µs", ["3", "4"], [3_000, 4_000]),
    ("ms", ["0.000001", "1e-3"], [1, 1_000]),
    ("ns", ["-5", "1700000000123456789"], [-5, 1_700_000_000_123_456_789]),
])
def test_timestamp_units_convert_exactly(tmp_path, unit, times, expected):
    log = gio.read_log(one_axis_log(tmp_path, "m s^-2", ["1", "2"], unit, times))
    assert log.timestamps_ns.tolist() == expected


def test_reference_valid_column(tmp_path):
    d = one_axis_log(tmp_path, "m s^-2", ["1", "2", "3"])
    write(d / "reference.csv", "#timestamp [ns],w_x [deg s^-1],w_y [rad/s],w_z [rad s^-1],valid []\n"
                               "10,180,0,0,1\n20,nan,1,0,0\n30,0,0,1,1\n")
    log = gio.read_log(d)
    assert log.truth is None
    assert log.invalid_reference.tolist() == [False, True, False]
    np.testing.assert_allclose(log.reference.omega_b_radps[0], [math.pi, 0, 0], rtol=1e-15)
    assert np.isnan(log.reference.omega_b_radps[1, 0])  # allowed where valid is 0
    write(d / "reference.csv", "#timestamp [ns],w_x [rad s^-1],w_y [rad s^-1],w_z [rad s^-1],valid\n"
                               "10,1,0,0,1\n20,1,1,0,0\n30,0,inf,1,1\n")
    with pytest.raises(gio.LogFormatError, match=r"reference\.csv:4: column 'w_y' is 'inf'; values must be finite "
                                                   r"where valid is 1"):
        gio.read_log(d)


# --- errors ------------------------------------------------------------------------

def cube_log_dir(tmp_path, n: int = 5) -> tuple:
    log = random_log(cube_array(), n=n, truth=True)
    gio.write_log(log, tmp_path / "log")
    return tmp_path / "log", log


def edit_line(path, line: int, fn) -> None:
    lines = path.read_text().split("\n")
    lines[line - 1] = fn(lines[line - 1])
    path.write_text("\n".join(lines))


def set_field(path, line: int, field: int, value: str) -> None:
    def fn(text):
        parts = text.split(",")
        parts[field] = value
        return ",".join(parts)
    edit_line(path, line, fn)


@pytest.mark.parametrize("value, message", [
    ("abc", r"imu\.csv:4: column 'a2_y' \(field 6\) value 'abc' is not a number"),
    ("", r"imu\.csv:4: column 'a2_y' \(field 6\) is empty"),
    ("0x12", r"imu\.csv:4: column 'a2_y' \(field 6\) value '0x12' is not a number"),
])
def test_text_where_a_reading_belongs_names_line_and_column(tmp_path, value, message):
    d, _ = cube_log_dir(tmp_path)
    set_field(d / "imu.csv", 4, 5, value)
    with pytest.raises(gio.LogFormatError, match=message):
        gio.read_log(d)


@pytest.mark.parametrize("value, expected", [("nan", math.nan), ("-inf", -math.inf), ("1e999", math.inf),
                                             ("1e300", 1e300)])
def test_non_finite_and_huge_readings_are_let_through(tmp_path, value, expected):
    d, log = cube_log_dir(tmp_path)
    set_field(d / "imu.csv", 4, 5, value)
    if math.isfinite(expected):
        back = gio.read_log(d)
    else:
        with pytest.warns(gio.LogPlausibilityWarning, match=r"imu\.csv:4: 1 accelerometer reading\(s\) are NaN or "
                          r"infinite \(first in column 'a2_y'\)"):
            back = gio.read_log(d)
    got = back.accel_mps2[2, 4]
    assert (math.isnan(got) and math.isnan(expected)) or got == expected
    mask = np.ones_like(log.accel_mps2, dtype=bool)
    mask[2, 4] = False
    assert np.array_equal(back.accel_mps2[mask], log.accel_mps2[mask])


@pytest.mark.parametrize("value, message", [
    ("nan", r"truth\.csv:4: column 'w_y' is 'nan'; values must be finite"),
    ("1e999", r"truth\.csv:4: column 'w_y' is '1e999' = inf; values must be finite"),
])
def test_truth_must_be_finite(tmp_path, value, message):
    d, _ = cube_log_dir(tmp_path)
    set_field(d / "truth.csv", 4, 2, value)
    with pytest.raises(gio.LogFormatError, match=message):
        gio.read_log(d)


@settings(max_examples=25, deadline=None)
@given(st.data())
def test_random_nan_positions_are_reported_at_the_first(tmp_path_factory, data):
    d, log = cube_log_dir(tmp_path_factory.mktemp("nan"), n=30)
    cells = data.draw(st.lists(st.tuples(st.integers(0, 29), st.integers(0, 11)), min_size=1, max_size=5, unique=True))
    lines = (d / "imu.csv").read_text().split("\n")
    for row, col in cells:
        parts = lines[row + 1].split(",")
        parts[col + 1] = data.draw(st.sampled_from(["nan", "NaN", "inf", "-inf"]))
        lines[row + 1] = ",".join(parts)
    (d / "imu.csv").write_text("\n".join(lines))
    row, col = min(cells)
    with pytest.warns(gio.LogPlausibilityWarning) as record:
        back = gio.read_log(d)
    text = " ".join(str(w.message) for w in record)
    assert f"imu.csv:{row + 2}: {len(cells)} accelerometer reading(s) are NaN or infinite (first in column " \
           f"'{log.array.accel_columns[col]}')" in text
    bad = ~np.isfinite(back.accel_mps2)
    assert sorted(zip(*np.nonzero(bad))) == sorted(cells)


@settings(max_examples=25, deadline=None)
@given(st.lists(st.integers(0, 10**12), min_size=3, max_size=30))
def test_random_timestamps_must_strictly_increase(tmp_path_factory, stamps):
    d = one_axis_log(tmp_path_factory.mktemp("t"), "m s^-2", ["1"] * len(stamps), times=[str(s) for s in stamps])
    bad = [k for k in range(1, len(stamps)) if stamps[k] <= stamps[k - 1]]
    if not bad:
        assert gio.read_log(d).timestamps_ns.tolist() == stamps
        return
    with pytest.raises(gio.LogFormatError, match="strictly increasing") as info:
        gio.read_log(d)
    assert info.value.line == bad[0] + 2
    assert f"imu.csv:{bad[0] + 2}: timestamp {stamps[bad[0]]} is not after the previous one ({stamps[bad[0] - 1]} " \
           f"on line {bad[0] + 1})" in str(info.value)


@pytest.mark.parametrize("header_edit, message", [
    (lambda h: h.replace("a2_y [m s^-2]", "a2_y [ft s^-2]"),
     r"imu\.csv:1: column 'a2_y' has unit \[ft s\^-2\], which is not understood here; expected \[m s\^-2\] "
     r"\(or, converted: \[g\], \[mg\]\)"),
    (lambda h: h.replace("a2_y [m s^-2]", "a2_y"), r"imu\.csv:1: column 'a2_y' has no unit; expected 'a2_y \[m s\^-2\]"),
    (lambda h: h.replace("a2_y [m s^-2]", "a2_q [m s^-2]"),
     r"imu\.csv:1: column 'a2_y \[m s\^-2\]' is missing \(accelerometer 'a2' lists axes x, y, z in array\.toml\)"),
    (lambda h: h.replace("a3", "b3"), r"imu\.csv:1: accelerometer 'a3' of array\.toml has no columns here; "
                                      r"expected 'a3_x \[m s\^-2\]'"),
    (lambda h: h.replace("a2_y [m s^-2]", "a2_x [m s^-2]"), r"imu\.csv:1: column 'a2_x' appears 2 times \(fields 5, 6\)"),
    (lambda h: h.replace("#timestamp [ns]", "#timestamp [s]").replace("a1_x", "time [s],a1_x"), None),
    (lambda h: h.replace("[ns]", "[min]"), r"imu\.csv:1: timestamp unit \[min\] not understood; expected \[ns\]"),
    (lambda h: h.replace("#timestamp [ns]", "time [ns]"), r"imu\.csv:1: the first column must be '#timestamp \[ns\]'"),
    (lambda h: h.replace(",", ";"), r"imu\.csv:1: the first column .* \(columns must be separated by commas\)"),
    (lambda h: ",".join(f'"{f}"' for f in h.split(",")).replace("a2_y", "a2_x"),
     r"imu\.csv:1: column 'a2_x' appears 2 times"),
])
def test_bad_headers(tmp_path, header_edit, message):
    d, _ = cube_log_dir(tmp_path)
    edit_line(d / "imu.csv", 1, header_edit)
    if message is None:  # the header grew a column: rows are now ragged
        message = r"imu\.csv:2: row has 13 fields, the header has 14 \(ragged rows: 5\)"
    with pytest.raises(gio.LogFormatError, match=message):
        gio.read_log(d)


def test_gyroscope_declared_but_absent(tmp_path):
    d = one_axis_log(tmp_path, "m s^-2", ["1", "2"], extra="[gyroscope]\nnoise_std_radps = 0.01\n")
    with pytest.raises(gio.LogFormatError, match=r"imu\.csv:1: array\.toml has a \[gyroscope\] but column "
                                                   r"'w_x \[rad s\^-1\]' is missing"):
        gio.read_log(d)


@pytest.mark.parametrize("body, message, line", [
    ("#timestamp [ns],a_x [m s^-2]\n1,2\n2,3,4\n3,4\n", r"imu\.csv:3: row has 3 fields, the header has 2", 3),
    ("#timestamp [ns],a_x [m s^-2]\n1,2\n\n3,4\n", r"imu\.csv:3: row is empty, the header has 2", 3),
    ("#timestamp [ns],a_x [m s^-2]\n1,2\n1.4,3\n", r"imu\.csv:3: timestamp 1\.4 and the previous one \(1 on line 2\) are "
                                                    r"the same nanosecond in \[ns\]; is the time unit right\?", 3),
    ("#timestamp [ns],a_x [m s^-2]\n1,2\nx,3\n", r"imu\.csv:3: timestamp 'x' is not a number", 3),
    ("#timestamp [ns],a_x [m s^-2]\n5,2\n5,3\n", r"imu\.csv:3: timestamp 5 is not after the previous one", 3),
    ("#timestamp [ns],a_x [m s^-2]\n", r"imu\.csv:2: has a header but no data rows", 2),
    ("", r"imu\.csv: file is empty", None),
    ("  \n\n", r"imu\.csv: file is empty", None),
])
def test_bad_imu_files(tmp_path, body, message, line):
    d = one_axis_log(tmp_path, "m s^-2", ["1"])
    write(d / "imu.csv", body)
    with pytest.raises(gio.LogFormatError, match=message) as info:
        gio.read_log(d)
    assert info.value.line == line and info.value.path.endswith("imu.csv")


TOML_OK = ('format = "gfimu-array/1"\nname = "x"\n\n[[accelerometers]]\nname = "a1"\nposition_m = [0.1, 0, 0]\n\n'
           '[[accelerometers]]\nname = "a2"\nposition_m = [0, 0.1, 0]\nrotation_body_sensor = [[1,0,0],[0,1,0],[0,0,1]]\n'
           'axes = ["x", "y"]\n')


@pytest.mark.parametrize("old, new, message", [
    ('"gfimu-array/1"', '"gfimu-array/2"', r"array\.toml:1: format: unknown format 'gfimu-array/2'; this version of "
                                           r"gfimu reads 'gfimu-array/1'"),
    ('format = "gfimu-array/1"\n', "", r"array\.toml: format: key is missing"),
    ("position_m = [0, 0.1, 0]", "position_m = [0, 0.1]",
     r"array\.toml:10: accelerometers\[1\]\.position_m: expected a list of 3 numbers, got \[0, 0\.1\]"),
    ("position_m = [0, 0.1, 0]", 'position_m = [0, "a", 0]', r"array\.toml:10: accelerometers\[1\]\.position_m"),
    ("position_m = [0, 0.1, 0]", "position_m = [0, true, 0]", r"array\.toml:10: accelerometers\[1\]\.position_m"),
    ("position_m = [0, 0.1, 0]", "position_m = [0, nan, 0]",
     r"array\.toml:10: accelerometers\[1\]\.position_m: values must be finite"),
    ("position_m = [0, 0.1, 0]\n", "", r"array\.toml:8: accelerometers\[1\]: accelerometer 'a2' has no position_m"),
    ("[[1,0,0],[0,1,0],[0,0,1]]", "[[1,0,0],[0,1,0],[0,0,-1]]",
     r"array\.toml:11: accelerometers\[1\]\.rotation_body_sensor: .* a reflection, not a rotation"),
    ("[[1,0,0],[0,1,0],[0,0,1]]", "[[1,0.1,0],[0,1,0],[0,0,1]]",
     r"array\.toml:11: accelerometers\[1\]\.rotation_body_sensor: .* is not a rotation matrix \(R Rᵀ differs from the "
     r"identity by 0\.1"),
    ("[[1,0,0],[0,1,0],[0,0,1]]", "[[1,0,0],[0,1,0]]",
     r"array\.toml:11: accelerometers\[1\]\.rotation_body_sensor: expected a 3x3 matrix"),
    ('axes = ["x", "y"]', 'axes = ["x", "x"]', r"array\.toml:12: accelerometers\[1\]\.axes: expected a list of distinct"),
    ('axes = ["x", "y"]', 'axes = ["x", "w"]', r"array\.toml:12: accelerometers\[1\]\.axes"),
    ('axes = ["x", "y"]', "axes = []", r"array\.toml:12: accelerometers\[1\]\.axes"),
    ('name = "a2"', 'name = "a1"', r"array\.toml:9: accelerometers\[1\]\.name: 'a1' is also the name of "
                                    r"accelerometers\[0\]"),
    ('name = "a2"', 'name = "w"', r"array\.toml:9: accelerometers\[1\]\.name: 'w' is reserved"),
    ('name = "a2"', 'name = "a,2"', r"array\.toml:9: accelerometers\[1\]\.name: 'a,2' cannot be a CSV column prefix"),
    ('name = "a2"', "name = 2", r"array\.toml:9: accelerometers\[1\]\.name: expected a non-empty string"),
    ('name = "a2"\n', 'name = "a2"\nnoise_std_mps2 = -1\n',
     r"array\.toml:10: accelerometers\[1\]\.noise_std_mps2: expected a finite number >= 0, got -1"),
    ("position_m = [0.1, 0, 0]", "position_m = [0.1, 0, 0",
     r"array\.toml:8: not valid TOML: Unclosed array \(at line 8, column 1\)"),
    ('axes = ["x", "y"]\n', 'axes = ["x", "y"]\n[body]\nprincipal_inertia_kgm2 = [1, 1, 3]\n',
     r"array\.toml:14: body\.principal_inertia_kgm2: .*triangle inequality"),
    ('axes = ["x", "y"]\n', 'axes = ["x", "y"]\n[body]\nprincipal_inertia_kgm2 = [1, 1]\n',
     r"array\.toml:14: body\.principal_inertia_kgm2: expected a list of 3 numbers"),
    ('axes = ["x", "y"]\n', 'axes = ["x", "y"]\n[gyroscope]\nnoise_std_radps = "low"\n',
     r"array\.toml:14: gyroscope\.noise_std_radps: expected a finite number >= 0, got 'low'"),
])
def test_bad_array_toml_names_key_and_line(tmp_path, old, new, message):
    assert old in TOML_OK
    path = write(tmp_path / "array.toml", TOML_OK.replace(old, new, 1))
    with pytest.raises(gio.LogFormatError, match=message):
        gio.read_array_toml(path)


def test_missing_accelerometers_and_empty_array_toml(tmp_path):
    with pytest.raises(gio.LogFormatError, match=r"array\.toml: file is empty"):
        gio.read_array_toml(write(tmp_path / "array.toml", "\n"))
    with pytest.raises(gio.LogFormatError, match=r"array\.toml: accelerometers: no \[\[accelerometers\]\] table"):
        gio.read_array_toml(write(tmp_path / "array.toml", 'format = "gfimu-array/1"\n'))


def test_nearly_orthonormal_rotation_is_projected_with_a_warning(tmp_path):
    text = TOML_OK.replace("[[1,0,0],[0,1,0],[0,0,1]]", "[[0.7071, -0.7071, 0], [0.7071, 0.7071, 0], [0, 0, 1]]")
    with pytest.warns(gio.LogFormatWarning, match=r"array\.toml:11: accelerometers\[1\]\.rotation_body_sensor: "
                                                    r"orthonormal only to 1\.9e-05"):
        array = gio.parse_array_toml(text, tmp_path / "array.toml")
    c = math.sqrt(0.5)
    np.testing.assert_allclose(array.accelerometers[1].rotation_body_sensor, [[c, -c, 0], [c, c, 0], [0, 0, 1]],
                               atol=1e-15)


def test_missing_log_files(tmp_path):
    with pytest.raises(gio.LogFormatError, match="log folder not found"):
        gio.read_log(tmp_path / "nope")
    (tmp_path / "log").mkdir()
    with pytest.raises(gio.LogFormatError, match=r"log: log folder has no array\.toml"):
        gio.read_log(tmp_path / "log")


def test_truth_must_share_the_imu_timestamps(tmp_path):
    d, _ = cube_log_dir(tmp_path)
    stamp = int((d / "truth.csv").read_text().split("\n")[3].split(",")[0])
    set_field(d / "truth.csv", 4, 0, str(stamp + 1))
    with pytest.raises(gio.LogFormatError, match=r"truth\.csv:4: timestamp .* differs from imu\.csv line 4"):
        gio.read_log(d)
    edit_line(d / "truth.csv", 4, lambda s: "")
    (d / "truth.csv").write_text((d / "truth.csv").read_text().replace("\n\n", "\n"))
    with pytest.raises(gio.LogFormatError, match=r"truth\.csv: has 4 rows but imu\.csv has 5"):
        gio.read_log(d)


@pytest.mark.parametrize("header, row, message", [
    ("w_x [rad s^-1],w_y [rad s^-1]", "1,2", r"m\.csv:1: column 'w_z \[rad s\^-1\]' is missing \(a quantity needs all "
                                             r"of w_x, w_y, w_z\)"),
    ("q_w [],q_x [],q_y [],q_z []", "1,0.1,0,0", r"m\.csv:2: quaternion q_w\.\.q_z has norm 1\.00498756"),
    ("dw_x [rad s^-1],dw_y [rad s^-2],dw_z [rad s^-2]", "1,2,3", r"m\.csv:1: column 'dw_x' has unit \[rad s\^-1\]"),
    ("w_x [rad s^-1],w_y [rad s^-1],w_z [rad s^-1],valid []", "1,2,3,0.5",
     r"m\.csv:2: column 'valid' is 0\.5; expected 1 \(valid\) or 0 \(invalid\)"),
    ("other [m]", "1", r"m\.csv:1: no motion columns"),
])
def test_bad_motion_csv(tmp_path, header, row, message):
    path = write(tmp_path / "m.csv", f"#timestamp [ns],{header}\n0,{row}\n")
    with pytest.raises(gio.LogFormatError, match=message):
        gio.read_motion_table(path)


def test_gaps_are_reported_as_warnings(tmp_path):
    times = [str(v) for v in (0, 10, 20, 30, 75, 85, 95, 200, 210)]
    d = one_axis_log(tmp_path, "m s^-2", ["1"] * len(times), times=times)
    with pytest.warns(gio.LogGapWarning, match=r"imu\.csv: 2 gap\(s\) in time .*the largest, 1\.05e-07 s, is before "
                                                 r"line 9; estimators restart at each gap"):
        log = gio.read_log(d)
    assert [s.start for s in log.segments()] == [0, 4, 7]


def test_error_is_a_value_error_with_location_attributes(tmp_path):
    d, _ = cube_log_dir(tmp_path)
    set_field(d / "imu.csv", 3, 2, "abc")
    with pytest.raises(ValueError) as info:
        gio.read_log(d)
    assert isinstance(info.value, gio.LogFormatError)
    assert info.value.path == str(d / "imu.csv") and info.value.line == 3


# --- atomic writing ---------------------------------------------------------------

def test_failed_write_leaves_the_old_file_intact(tmp_path, monkeypatch):
    path = tmp_path / "est.csv"
    t = np.arange(10) * 1000
    old = Motion(t, omega_b_radps=np.ones((10, 3)))
    gio.write_motion_csv(old, path)
    before = path.read_bytes()
    real = tables._format_block

    def failing(timestamps, *args, **kwargs):
        if timestamps[0] == t[4]:  # the third block: two were written to the temporary file before
            raise RuntimeError("disk on fire")
        return real(timestamps, *args, **kwargs)

    monkeypatch.setattr(tables, "_ROWS_PER_BLOCK", 2)
    monkeypatch.setattr(tables, "_format_block", failing)
    with pytest.raises(RuntimeError, match="disk on fire"):
        gio.write_motion_csv(Motion(t, omega_b_radps=np.zeros((10, 3))), path)
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["est.csv"]


def test_written_file_gets_ordinary_permissions(tmp_path):
    path = tmp_path / "array.toml"
    gio.write_array_toml(cube_array(), path)
    umask = os.umask(0)
    os.umask(umask)
    assert (path.stat().st_mode & 0o777) == (0o666 & ~umask)


def test_units_table_is_consistent_with_motion_quantities():
    for _, (prefix, unit, _) in QUANTITIES.items():
        kind = units.KIND_OF_UNIT[unit]
        assert gio.UNITS[kind][0] == unit
        assert gio.unit_factor(unit, kind) == 1.0


@settings(max_examples=30, deadline=None)
@given(st.lists(st.lists(st.floats(allow_nan=False, allow_infinity=False, width=64), min_size=5, max_size=5),
                min_size=1, max_size=20),
       st.integers(-(2**62), 2**62))
def test_any_finite_readings_and_timestamps_round_trip(tmp_path_factory, rows, t0):
    array = SensorArray((Accelerometer("a", [0, 0, 0], axes=("x", "y")), Accelerometer("b", [0, 0, 1.0], axes=("z",))),
                        gyroscope=Gyroscope())
    values = np.array(rows)
    t = t0 + np.arange(len(rows), dtype=np.int64) * 7
    log = Log(array, t, values[:, :3], values[:, 2:])
    d = tmp_path_factory.mktemp("rt")
    gio.write_log(log, d)
    back = gio.read_log(d)
    assert np.array_equal(back.timestamps_ns, t)
    assert np.array_equal(back.accel_mps2, log.accel_mps2) and np.array_equal(back.gyro_b_radps, log.gyro_b_radps)
    assert np.array_equal(np.signbit(back.accel_mps2), np.signbit(log.accel_mps2))


def test_read_log_accepts_the_path_of_a_file_in_the_folder(tmp_path):
    d, log = cube_log_dir(tmp_path)
    assert np.array_equal(gio.read_log(d / "imu.csv").accel_mps2, log.accel_mps2)


@pytest.mark.parametrize("unit, kind, factor", [
    ("m s^-2", "acceleration", 1.0), ("m.s-2", "acceleration", 1.0), ("m/s/s", "acceleration", 1.0),
    ("m s⁻²", "acceleration", 1.0), ("mg", "acceleration", 9.80665e-3),
    ("rad/s", "angular_rate", 1.0), ("rad·s⁻¹", "angular_rate", 1.0), ("°/s", "angular_rate", math.pi / 180),
    ("degrees/s", "angular_rate", math.pi / 180), ("rpm", "angular_rate", math.pi / 30),
    ("deg/s^2", "angular_acceleration", math.pi / 180), ("°", "angle", math.pi / 180), ("1", "dimensionless", 1.0),
])
def test_accepted_unit_spellings(unit, kind, factor):
    assert gio.unit_factor(unit, kind) == factor


@pytest.mark.parametrize("unit, kind", [("m/s", "acceleration"), ("G", "acceleration"), ("ft/s^2", "acceleration"),
                                        ("rad/s^2", "angular_rate"), ("Hz", "angular_rate"), ("rad", "angular_rate"),
                                        ("m s^-2", "angle"), ("%", "dimensionless")])
def test_refused_units(unit, kind):
    with pytest.raises(KeyError):
        gio.unit_factor(unit, kind)


def test_an_output_under_a_file_is_refused_by_name(tmp_path):
    from gfimu.io.atomic import destination
    from gfimu.io.errors import OutputError
    from gfimu.io.outputs import prepare_log_folder

    f = tmp_path / "file"
    f.write_text("x")
    with pytest.raises(OutputError, match=r"file/x\.csv: a part of this path is a file, not a folder"):
        destination(f / "x.csv")
    with pytest.raises(OutputError, match=r"^--out .*file/log: a part of this path is a file, not a folder"):
        prepare_log_folder(f / "log")
    assert prepare_log_folder(tmp_path / "new") == tmp_path / "new"  # missing: fine


def test_range_mps2_round_trips_and_a_bad_one_names_its_key(tmp_path):
    array = SensorArray((Accelerometer("a1", [0.05, 0, 0], noise_std_mps2=0.07, range_mps2=156.9066),
                         Accelerometer("a2", [0, 0.05, 0])))
    text = gio.format_array_toml(array)
    assert "range_mps2 = 156.9066" in text and text.count("range_mps2") == 1
    back = gio.parse_array_toml(text)
    assert back.accelerometers[0].range_mps2 == 156.9066 and back.accelerometers[1].range_mps2 is None
    assert np.array_equal(back.range_per_axis_mps2, [156.9066] * 3 + [np.nan] * 3, equal_nan=True)
    for bad in ("0", "-5", '"16 g"', "nan"):
        path = write(tmp_path / "array.toml", text.replace("range_mps2 = 156.9066", f"range_mps2 = {bad}"))
        with pytest.raises(gio.LogFormatError, match=r"array\.toml:\d+: accelerometers\[0\]\.range_mps2: expected the "
                                                     r"full scale in m/s², a finite number > 0"):
            gio.read_array_toml(path)


def test_the_mimu4444_array_states_its_16_g_range():
    from gfimu.array import mimu4444_array

    assert all(a.range_mps2 == pytest.approx(16 * 9.80665) for a in mimu4444_array().accelerometers)
    assert "range_mps2 = 156.9064" in gio.format_array_toml(mimu4444_array())
