"""gfimu diagnose: planted faults in simulated logs found and sized, a clean log left clean, a real recording."""

import json
import subprocess
import sys
import os
from pathlib import Path

import numpy as np
import pytest
from scipy.interpolate import CubicSpline

from gfimu import io as gio
from gfimu.array import Accelerometer, Gyroscope
from gfimu.diagnose import channel_faults, diagnose, timing_of
from gfimu.log import Log
from gfimu.simulate import SensorErrors, simulate

REPO = Path(__file__).resolve().parents[1]
G = 9.80665


@pytest.fixture(scope="module")
def base():
    return simulate("random3d", seed=3)


@pytest.fixture(scope="module")
def clean(base):
    return diagnose(base)


FLAT_KEYS = ["source", "array_name", "sensors", "axes", "timing", "model", "noise_floor_mps2", "stated_noise_mps2",
             "per_sensor", "bands", "calibration_share", "still_specific_force_mps2", "median_specific_force_mps2", "accel_unit_suspect",
             "accel_scale_to_mps2", "gyro_ratio", "gyro_unit_suspect", "position_scale_suspect", "array_extent_m",
             "array_max_distance_m", "faults", "screened_readings", "crb_omega_radps", "crb_omega_measured_radps",
             "crb_omega_dot_radps2", "omega_p50_radps", "omega_p90_radps", "resolved_share", "sign_window_share",
             "warnings", "fix_first", "verdict", "guard"]


def test_the_json_is_one_flat_object_whatever_the_parts(clean):
    """The diagnosis is held in parts (consistency, units, channels, accuracy); its JSON is the one flat object
    of these keys in this order, each the value read by that name, byte for byte."""
    from dataclasses import asdict, fields, is_dataclass

    from gfimu.diagnose import _json_clean

    doc = clean.as_dict()
    assert list(doc) == FLAT_KEYS
    flat = {}
    for k in FLAT_KEYS:
        v = getattr(clean, k)
        flat[k] = asdict(v) if is_dataclass(v) else ([asdict(x) for x in v] if k in ("per_sensor", "bands", "faults")
                                                     else v)
    assert json.dumps(doc, indent=2) == json.dumps(_json_clean(flat), indent=2)
    assert clean.gyro_ratio is clean.units.gyro_ratio and clean.bands is clean.consistency.bands
    assert clean.omega_p90_radps == clean.accuracy.omega_p90_radps > clean.omega_p50_radps > 0
    assert len(fields(clean)) < 15

def test_a_clean_log_reports_no_fault(clean):
    assert clean.warnings == () and clean.fix_first == () and clean.faults == ()
    assert clean.verdict.startswith("CLEAN")
    assert 0.85 < clean.model["noise_ratio"] < 1.15  # the simulated noise is the stated one
    assert abs(clean.noise_floor_mps2 - 0.07) < 0.01
    assert clean.timing.rate_hz == pytest.approx(500.0) and clean.timing.jitter_s == 0.0
    assert [s.name for s in clean.per_sensor] == ["a1", "a2", "a3", "a4"]
    assert all(0.9 < s.ratio_to_others < 1.1 and abs(s.skew_s) < 2e-4 for s in clean.per_sensor)
    assert clean.accel_unit_suspect is None and clean.position_scale_suspect is None
    # the bound of the 5 cm cube at 0.07 m/s² falls with |ω| (∂q/∂ω grows with ω)
    bounds = [b.crb_omega_radps for b in clean.bands if b.samples > 50]
    assert bounds == sorted(bounds, reverse=True) and len(bounds) >= 3
    assert clean.sign_window_share == 1.0
    # the default smoother fits the readings as its model allows: no span
    assert clean.guard["spans"] == [] and clean.guard["note"] == "" and clean.guard["usable_samples"] > 1000
    assert "0 span(s) where the smoother fits the readings worse than its model allows" in clean.to_text()


@pytest.mark.slow
def test_readings_in_g_are_found_with_their_factor(base):
    d = diagnose(base.replace(accel_mps2=base.accel_mps2 / G))
    assert d.accel_unit_suspect == "g" and d.accel_scale_to_mps2 == pytest.approx(G)
    assert d.verdict.startswith("FIX FIRST") and "in g" in d.verdict


def test_readings_in_mg_of_a_still_array_found_from_the_still_stretch():
    array = simulate("random3d", seed=3).array
    n = 1000
    f_b = np.array([0.0, 0.0, G])
    y = np.tile(np.concatenate([a.rotation_body_sensor.T @ f_b for a in array.accelerometers]), (n, 1))
    y = y + np.random.default_rng(0).normal(size=y.shape) * 0.07
    log = Log(array, np.arange(n) * 2_000_000, y * 1000 / G)
    d = diagnose(log)
    assert d.still_specific_force_mps2 == pytest.approx(1000, rel=0.01)
    assert d.accel_unit_suspect == "mg" and d.accel_scale_to_mps2 == pytest.approx(G / 1000)


@pytest.mark.slow
def test_positions_in_mm_found_and_the_residual_does_not_depend_on_a_common_scale(base, clean):
    arr = base.array.with_accelerometers([Accelerometer(a.name, a.position_m * 1000, a.rotation_body_sensor, a.axes,
                                                        a.noise_std_mps2) for a in base.array.accelerometers])
    d = diagnose(base.replace(array=arr))
    assert d.position_scale_suspect == 1e-3 and "multiply the positions by 0.001" in d.verdict
    # readings S(c r) x are fitted exactly by ω̇ / c and ω / √c: same residual, ω smaller by √1000
    assert d.model["noise_ratio"] == pytest.approx(clean.model["noise_ratio"], rel=0.02)
    assert d.omega_p50_radps == pytest.approx(clean.omega_p50_radps / np.sqrt(1000), rel=0.02)


def test_a_stuck_channel_is_found_with_its_rows(base):
    y = base.accel_mps2.copy()
    y[2000:3000, 4] = y[2000, 4]
    d = diagnose(base.replace(accel_mps2=y))
    (fault,) = d.faults
    assert (fault.column, fault.kind, fault.samples, fault.first_row, fault.last_row) == ("a2_y", "stuck", 1000, 2000, 2999)
    assert not any("skew" in w for w in d.warnings)
    assert d.verdict.startswith("USE WITH CARE") and "a2_y stuck" in d.verdict


def test_a_clipped_channel_is_found_and_counted(base):
    y = base.accel_mps2.copy()
    c = 7
    limit = 0.8 * np.abs(y[:, c]).max()
    beyond = int(np.sum(np.abs(y[:, c]) >= limit))
    y[:, c] = np.clip(y[:, c], -limit, limit)
    d = diagnose(base.replace(accel_mps2=y))
    (fault,) = d.faults
    assert (fault.column, fault.kind, fault.samples) == ("a3_y", "clipped", beyond)
    assert abs(fault.value_mps2) == pytest.approx(limit)


def test_a_stated_range_finds_readings_pinned_at_it():
    y = np.random.default_rng(1).normal(size=(600, 3))
    y[100:110, 1] = 20.0
    y[300, 1] = -20.0
    faults, mask = channel_faults(y, ["x", "y", "z"], 100.0, range_mps2=np.array([np.nan, 20.0, np.nan]))
    (f,) = faults
    assert (f.column, f.kind, f.samples, f.first_row, f.last_row) == ("y", "clipped", 11, 100, 300)
    assert mask.sum() == 11


def test_a_sensor_with_a_time_skew_is_found_and_sized():
    exact = simulate("random3d", seed=3, noise=SensorErrors.none())
    t = exact.times_s
    y = exact.accel_mps2.copy()
    y[:, 3:6] = CubicSpline(t, y[:, 3:6], axis=0)(t + 0.004)  # a2 reads 4 ms ahead
    y += np.random.default_rng(5).normal(size=y.shape) * 0.07
    d = diagnose(exact.replace(accel_mps2=y))
    skews = {s.name: s.skew_s for s in d.per_sensor}
    assert 0.0035 < skews["a2"] < 0.0045, skews
    skew_warnings = [w for w in d.warnings if "time skew" in w]
    assert len(skew_warnings) == 1 and skew_warnings[0].startswith("a2 reads +")


def _moved(log, name: str, offset_m) -> Log:
    """``log`` with array.toml's position of accelerometer ``name`` moved by ``offset_m`` (the readings as they were)."""
    from dataclasses import replace

    accs = tuple(replace(a, position_m=np.asarray(a.position_m) + offset_m) if a.name == name else a
                 for a in log.array.accelerometers)
    return log.replace(array=replace(log.array, accelerometers=accs))


def test_sensor_positions_off_are_found_named_and_taken_off():
    """Readings of random3d (5 cm cube, 0.002 m/s² of noise) with array.toml's position of a2 2 mm off (−y) and
    of a4 1 mm off (+z): the misfit is almost all (> 90 %) that of constant position errors and the warning
    names a2 first; array.toml's positions with the fitted errors added (the true ones less a shift and a
    scale common to all sensors, which are changes of f, ω̇ and ω and do not show) leave a residual at the
    noise level: the model check consistent and under 1 % of it a calibration error's, as on the log before
    the positions were moved."""
    base = simulate("random3d", seed=3, noise=SensorErrors(accel_noise_std_mps2=0.002))
    true = {"a2": np.array([0.0, 0.002, 0.0]), "a4": np.array([0.0, 0.0, -0.001])}  # true less stated
    log = _moved(_moved(base, "a2", -true["a2"]), "a4", -true["a4"])
    d = diagnose(log)
    assert d.calibration_share > 0.9 and not d.model["consistent"]
    warning = [w for w in d.warnings if "calibration errors" in w]
    assert len(warning) == 1 and "sensor positions off array.toml's by up to" in warning[0]
    assert warning[0].index("a2 ") < warning[0].index("a4 ")
    corrected = log
    for s in d.per_sensor:
        corrected = _moved(corrected, s.name, np.array(s.position_offset_mm) * 1e-3)
    for again in (diagnose(corrected), diagnose(base)):
        assert again.model["consistent"] and again.calibration_share < 0.01
        assert not [w for w in again.warnings if "calibration errors" in w]


def test_a_clean_log_shows_no_calibration_error(clean):
    assert clean.calibration_share < 0.01
    assert all(np.all(np.abs(np.array(s.position_offset_mm)) < 5 * np.array(s.position_offset_std_mm))
               for s in clean.per_sensor)
    assert "position error [mm]" in clean.to_text()


@pytest.mark.slow
def test_a_gyroscope_in_deg_per_s_is_found():
    from gfimu.array import cube_array

    arr = cube_array()
    arr = arr.with_accelerometers(arr.accelerometers)
    arr = type(arr)(arr.accelerometers, arr.name, Gyroscope(0.01))
    log = simulate("random3d", array=arr, seed=2)
    assert diagnose(log).gyro_unit_suspect is None
    d = diagnose(log.replace(gyro_b_radps=log.gyro_b_radps * 180 / np.pi))
    assert d.gyro_unit_suspect == "deg/s" and d.gyro_ratio == pytest.approx(180 / np.pi, rel=0.1)


def test_timing_counts_jitter_gaps_repeats_and_backward_steps():
    t = np.arange(1000, dtype=np.int64) * 10_000_000  # 100 Hz
    t[500:] += 35_000_000  # one gap of 45 ms
    t[200] = t[199]  # a repeated timestamp
    t[300], t[301] = t[301], t[300]  # a backward step
    tm = timing_of(t)
    assert tm.rate_hz == pytest.approx(100.0)
    # the repeat leaves one 20 ms step after it, the swap two around it
    assert (tm.gaps, tm.duplicates, tm.backwards) == (4, 1, 1)
    assert tm.largest_gap_s == pytest.approx(0.045)
    rng = np.random.default_rng(0)
    jittered = np.arange(5000, dtype=np.int64) * 10_000_000 + rng.normal(0, 200_000, 5000).astype(np.int64)
    assert timing_of(jittered).jitter_s == pytest.approx(np.sqrt(2) * 200e-6, rel=0.1)  # steps: difference of two


@pytest.mark.slow
def test_cli_text_json_figure_and_refusals(tmp_path, base, capsys):
    env = {**os.environ, "PYTHONPATH": str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    folder = tmp_path / "log"
    y = base.accel_mps2.copy()
    y[2000:3000, 4] = y[2000, 4]
    gio.write_log(base.replace(accel_mps2=y), folder)
    from gfimu.cli import main

    assert main(["diagnose", str(folder), "--quiet"]) == 0  # text, in this process; the json run below is a new one
    text = capsys.readouterr()
    assert "verdict: USE WITH CARE" in text.out and "a2_y: stuck" in text.out, text.err
    cmd = [sys.executable, "-m", "gfimu", "diagnose", str(folder), "--quiet"]
    out, fig = tmp_path / "d.json", tmp_path / "d.png"
    run = subprocess.run(cmd + ["--format", "json", "--out", str(out), "--figure", str(fig)], env=env,
                         capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    doc = json.loads(out.read_text())
    assert doc["faults"][0]["column"] == "a2_y" and doc["timing"]["rate_hz"] == pytest.approx(500.0)
    assert fig.read_bytes()[:4] == b"\x89PNG"
    before = (folder / "imu.csv").read_bytes()
    assert main(["diagnose", str(folder), "--quiet", "--out", str(folder / "imu.csv")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "is an input" in err and (folder / "imu.csv").read_bytes() == before
    kept = out.read_bytes()
    assert main(["diagnose", str(folder), "--quiet", "--out", str(out), "--figure", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"--figure {out}: the same file as --out" in err and out.read_bytes() == kept
    assert main(["diagnose", str(tmp_path / "nowhere"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "gfimu diagnose: error:" in err and "log folder not found" in err and err.count("\n") == 1


@pytest.mark.slow
def test_real_recording(mimu4444_dir, tmp_path):
    from gfimu.cli import main

    log_dir = tmp_path / "exp1"
    assert main(["convert", "mimu4444", str(mimu4444_dir / "exp_1" / "data.bin"), "--out", str(log_dir),
                 "--with-gyro"]) == 0
    d = diagnose(gio.read_log(log_dir, check=False))
    assert d.timing.rate_hz == pytest.approx(62.5, rel=0.01)
    assert d.fix_first == ()  # units in m/s², positions in metres, gyroscope in rad/s
    assert d.gyro_ratio == pytest.approx(1.0, abs=0.2)
    assert d.accel_unit_suspect is None and d.position_scale_suspect is None
    assert not d.model["consistent"]  # the board's residual is several times its datasheet noise


@pytest.mark.slow
def test_positions_in_cm_of_a_small_array_found_by_the_gyroscope():
    """Sizes that look plausible (35 cm) but are in cm: the accelerometers' ω is √100 times too small."""
    from gfimu.array import SensorArray, cube_array

    small = cube_array(0.002, noise_std_mps2=0.001)
    array = SensorArray(small.accelerometers, "small", Gyroscope(0.01))
    log = simulate("random3d", array=array, seed=2, duration_s=4.0)
    assert diagnose(log).position_scale_suspect is None
    cm = array.with_accelerometers([Accelerometer(a.name, a.position_m * 100, noise_std_mps2=a.noise_std_mps2)
                                    for a in array.accelerometers])
    d = diagnose(log.replace(array=cm))
    assert d.gyro_ratio == pytest.approx(10.0, rel=0.05) and d.position_scale_suspect == 0.01
    assert d.gyro_unit_suspect is None and "multiply the positions by 0.01" in d.verdict
