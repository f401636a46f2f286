"""Every method's estimate(log) returns Estimate(motion, report), a value; the pipeline and the command
read the report, and the command builds the estimator once."""

from __future__ import annotations

import dataclasses
import shutil
from pathlib import Path

import numpy as np
import pytest

from gfimu import io as gio
from gfimu.array import Body, Gyroscope, cube_array
from gfimu.cli import main
from gfimu.estimate import Estimate, Report
from gfimu.methods import METHODS, make_estimator
from gfimu.motion import Motion
from gfimu.simulate import simulate


@pytest.fixture(scope="module")
def log():
    array = dataclasses.replace(cube_array(0.05, noise_std_mps2=0.05), gyroscope=Gyroscope(noise_std_radps=0.01),
                                body=Body((0.02, 0.03, 0.04)))
    return simulate("random3d", array, rate_hz=200.0, duration_s=1.0, seed=3)


@pytest.mark.parametrize("name", list(METHODS))
def test_every_method_returns_its_motion_and_report(log, name):
    est = make_estimator(name)
    if est.applicable(log.array):
        pytest.skip(f"{name}: {est.applicable(log.array)}")
    before = dataclasses.asdict(est)
    if name == "free-flight":  # its multi-start fit of a body not in free flight: 19 s on the 200 samples, 1.6 s on 8
        log = log.select(slice(0, 8))
    run = est.estimate(log)
    assert isinstance(run, Estimate) and isinstance(run.motion, Motion) and isinstance(run.report, Report)
    assert len(run.motion) == len(log) and np.array_equal(run.motion.timestamps_ns, log.timestamps_ns)
    report = run.report
    assert report.method == name == est.method
    assert dict(report.options) == {f.name: getattr(est, f.name) for f in dataclasses.fields(est) if f.init}
    assert report.timings and all(t >= 0 for t in report.timings.values())
    assert report.seconds == pytest.approx(sum(report.timings.values()))
    assert all(isinstance(w, str) for w in report.warnings)
    assert dataclasses.asdict(est) == before  # nothing of the run is kept on the estimator
    if name in ("smoother", "fixed-lag"):
        assert len(report.tunings) == 1 and report.iterations is not None
    else:
        assert list(report.timings) == ["estimate"] and report.tunings == () and report.model_check is None


def test_the_same_estimator_twice_gives_two_independent_values(log):
    est = make_estimator("smoother", window_s=0.6, overlap_s=0.1)
    a = est.estimate(log)
    b = est.estimate(log.select(slice(0, 100)))
    assert a.report.windows == 2 and b.report.windows == 1
    assert len(a.report.tunings) == 2 and len(b.report.tunings) == 1
    assert len(a.motion) == 200 and len(b.motion) == 100


def test_report_is_frozen_and_adds_timings():
    report = Report("inversion", {"compute_sigma": False}, timings={"estimate": 0.25})
    later = report.with_timings(read=0.5, estimate=0.75)
    assert dict(report.timings) == {"estimate": 0.25} and dict(later.timings) == {"estimate": 0.75, "read": 0.5}
    assert later.seconds == 1.25 and later.options == report.options
    with pytest.raises(dataclasses.FrozenInstanceError):
        report.method = "ml"
    with pytest.raises(TypeError):
        later.timings["read"] = 0.0
    assert report.describe() == []


@pytest.fixture
def log_dir(tmp_path, log) -> Path:
    d = tmp_path / "log"
    gio.write_log(log, d)
    return d


def test_pipeline_times_its_steps_around_the_methods(log_dir, tmp_path):
    from gfimu.calibration import Calibration, SensorCalibration, write_calibration
    from gfimu.pipeline import estimate_log

    cal = Calibration(tuple(SensorCalibration(a.name, a.axes, np.eye(3), np.zeros(3)) for a in
                            gio.read_log(log_dir).array.accelerometers), None)
    write_calibration(cal, tmp_path / "cal.toml")
    run = estimate_log(log_dir, "smoother", calibration=tmp_path / "cal.toml", orientation="gyro")
    assert list(run.report.timings) == ["read", "screen", "calibrate", "model check", "solve windows", "guard",
                                        "orientation"]
    assert run.report.method == run.method == "smoother" and run.samples == 200
    assert run.report.model_check is not None and run.motion.quaternion_wb is not None
    est = make_estimator("inversion")
    run = estimate_log(log_dir, est)
    assert list(run.report.timings) == ["read", "screen", "estimate"] and run.method == "inversion"
    with pytest.raises(ValueError, match="options go with a method name"):
        estimate_log(log_dir, est, {"compute_sigma": True})


def test_command_builds_the_estimator_once_and_prints_the_report(log_dir, tmp_path, capsys, monkeypatch):
    import gfimu.methods
    from gfimu.smoother.batch import engine as batch

    calls = []
    real_make = gfimu.methods.MethodOptions.estimator

    def counting(chosen):
        calls.append(chosen.method)
        return real_make(chosen)

    real_smooth = batch.smooth

    def smooth_with_a_note(*args, **kwargs):
        run = real_smooth(*args, **kwargs)
        note = "solve window 1 of 1 (samples 0..199) stopped after 50 iterations without converging"
        return dataclasses.replace(run, report=dataclasses.replace(run.report, warnings=(note,)))

    monkeypatch.setattr(gfimu.methods.MethodOptions, "estimator", counting)
    monkeypatch.setattr(batch, "smooth", smooth_with_a_note)
    snapshot = {p.name: p.read_bytes() for p in log_dir.iterdir()}
    assert main(["estimate", str(log_dir), "--out", str(tmp_path / "e.csv"), "--no-progress"]) == 0
    assert calls == ["smoother"]
    out, err = capsys.readouterr()
    assert ("gfimu estimate: warning: smoother: solve window 1 of 1 (samples 0..199) stopped after 50 iterations "
            "without converging") in err
    assert "smoother: readings consistent with a rigid body" in err  # the model check, from the report
    line = [ln for ln in out.splitlines() if "samples in" in ln]
    assert len(line) == 1 and line[0].startswith("smoother: 200 samples in ")
    assert "(read " in line[0] and ", screen " in line[0] and ", model check " in line[0] and ", solve windows " in line[0]
    assert {p.name: p.read_bytes() for p in log_dir.iterdir()} == snapshot
    assert len(gio.read_motion_csv(tmp_path / "e.csv")) == 200


def test_compare_bounds_the_smoother_with_the_noise_of_its_report(log, monkeypatch):
    """compare() hands the smoother's bound the tunings of the smoother's report (not of an estimator)."""
    import gfimu.compare as compare_module

    seen = {}
    real = compare_module.compute_bounds

    def spy(*args, **kwargs):
        seen["tunings"] = args[6] if len(args) > 6 else kwargs.get("smoother_tunings")
        return real(*args, **kwargs)

    monkeypatch.setattr(compare_module, "compute_bounds", spy)
    with pytest.raises(ValueError, match=r"unknown bound\(s\) \['smoother'\]; bounds are: crb, crb_gyro, smoother_bound"):
        compare_module.compare(log, methods=["inversion"], bounds=["smoother"])
    result = compare_module.compare(log, methods=["smoother"], bounds=["smoother_bound"])
    direct = make_estimator("smoother").estimate(log).report.tunings
    assert len(seen["tunings"]) == 1 and seen["tunings"][0] == direct[0]
    assert result.row("smoother")["status"] == "ok"
