"""The batch smoother's two solvers on one model: the vectorised banded numpy solver (default) and
the GTSAM graph built from the same problem, eliminated in time order; and the estimate with its report."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from gfimu.methods import make_estimator
from gfimu.simulate import simulate
from gfimu.estimate import Estimate

REPO = Path(__file__).resolve().parents[1]


def _same(a, b, omega_tol: float, force_tol: float) -> None:
    # the noise is chosen on the numpy core in both (NaN log-evidence where it was not by likelihood)
    np.testing.assert_equal([t.as_dict() for t in a.report.tunings], [t.as_dict() for t in b.report.tunings])
    np.testing.assert_allclose(a.motion.omega_b_radps, b.motion.omega_b_radps, atol=omega_tol, rtol=0)
    np.testing.assert_allclose(a.motion.omega_dot_b_radps2, b.motion.omega_dot_b_radps2, atol=20 * omega_tol, rtol=0)
    np.testing.assert_allclose(a.motion.specific_force_b_mps2, b.motion.specific_force_b_mps2, atol=force_tol, rtol=0)
    assert a.report.cost == pytest.approx(b.report.cost, rel=1e-6)


def test_numpy_and_gtsam_solvers_agree_on_a_simulated_log():
    log = simulate("random3d", duration_s=0.4, seed=3)
    a = make_estimator("smoother", compute_sigma=True).estimate(log)
    b = make_estimator("smoother", compute_sigma=True, solver="gtsam").estimate(log)
    assert isinstance(a, Estimate) and a.report.iterations > 0 and np.isfinite(a.report.cost)
    assert a.report.warnings == () and a.report.guard.spans == ()  # nothing for the guard to mend
    _same(a, b, 1e-6, 1e-5)
    np.testing.assert_allclose(a.motion.sigma["omega_b_radps"], b.motion.sigma["omega_b_radps"], rtol=1e-6)
    # and both are right: the truth within a few sigma
    err = np.abs(a.motion.omega_b_radps - log.truth.omega_b_radps) / a.motion.sigma["omega_b_radps"]
    assert np.sqrt(np.mean(err**2)) < 3.0


def test_estimate_returns_the_run_as_a_value():
    """estimate() gives the motion with everything the run reports, the guard's finding added, and leaves
    the estimator as it was (equal to a fresh one): nothing of a run is kept on it."""
    import dataclasses

    log = simulate("turntable", duration_s=0.3, seed=1)
    est = make_estimator("smoother")
    unguarded = make_estimator("smoother", guard="off").estimate(log)
    run = est.estimate(log)
    np.testing.assert_array_equal(run.motion.omega_b_radps, unguarded.motion.omega_b_radps)
    report, plain = run.report, unguarded.report
    assert report.method == "smoother" and report.options["solver"] == "numpy" and report.options["auto_model"] is True
    assert report.options["guard"] == "replace" and plain.options["guard"] == "off"
    assert report.guard is not None and report.guard.spans == () and plain.guard is None
    assert report.tunings == plain.tunings and len(report.tunings) == 1
    assert (report.iterations, report.cost, report.windows) == (plain.iterations, plain.cost, 1)
    assert report.iterations > 0 and np.isfinite(report.cost)
    assert report.model_check is not None and report.model_check == plain.model_check
    assert list(plain.timings) == ["model check", "solve windows"]
    assert list(report.timings) == ["model check", "solve windows", "guard"] and all(t > 0 for t in report.timings.values())
    assert est == make_estimator("smoother") and vars(est) == vars(make_estimator("smoother"))
    with pytest.raises(dataclasses.FrozenInstanceError):
        run.report = report
    with pytest.raises(TypeError):  # the options recorded are read-only
        report.options["solver"] = "gtsam"


def test_a_log_shorter_than_the_motion_period_runs():
    """A 0.5 s log the model check finds inconsistent with a rigid body (the constant turntable's
    noise-free rotation against the stated noise): the local density factors fit its length."""
    log = simulate("turntable-constant", duration_s=0.5, seed=2)
    res = make_estimator("smoother", tune_process_noise=False).estimate(log)
    assert np.all(np.isfinite(res.motion.omega_b_radps))
    err = np.linalg.norm(res.motion.omega_b_radps - log.truth.omega_b_radps, axis=1)
    assert np.sqrt(np.mean(err**2)) < 0.5


def test_unknown_solver_is_refused_by_name():
    with pytest.raises(ValueError, match="solver"):
        make_estimator("smoother", solver="cholmod")


@pytest.mark.slow
def test_cli_solver_option(tmp_path):
    env = dict(os.environ, PYTHONPATH=str(REPO))
    sim = subprocess.run([sys.executable, "-m", "gfimu", "simulate", "turntable", "--duration-s", "0.15",
                          "--out", str(tmp_path / "log")], env=env, capture_output=True, text=True)
    assert sim.returncode == 0, sim.stderr
    outs = {}
    for solver in ("numpy", "gtsam"):
        out = tmp_path / f"{solver}.csv"
        r = subprocess.run([sys.executable, "-m", "gfimu", "estimate", str(tmp_path / "log"), "--solver", solver,
                            "--out", str(out), "--no-progress"], env=env, capture_output=True, text=True)
        assert r.returncode == 0, r.stderr
        outs[solver] = np.genfromtxt(out, delimiter=",", names=True)
    for name in outs["numpy"].dtype.names:
        np.testing.assert_allclose(outs["gtsam"][name], outs["numpy"][name], atol=1e-5)
    bad = subprocess.run([sys.executable, "-m", "gfimu", "estimate", str(tmp_path / "log"), "--method", "ml",
                          "--solver", "gtsam", "--out", str(tmp_path / "x.csv")], env=env, capture_output=True, text=True)
    assert bad.returncode != 0 and "--solver applies to --method smoother" in bad.stderr
    assert "Traceback" not in bad.stderr


@pytest.mark.slow
def test_numpy_and_gtsam_solvers_agree_on_a_real_log(mimu4444_dir):
    from gfimu.io.readers.mimu4444 import read_mimu4444

    log, _ = read_mimu4444(mimu4444_dir / "exp_1" / "data.bin", with_gyro=False)
    start = int(60 * log.rate_hz)
    part = log.select(slice(start, start + int(20 * log.rate_hz)))  # a 20 s slice
    a = make_estimator("smoother").estimate(part)
    b = make_estimator("smoother", solver="gtsam").estimate(part)
    _same(a, b, 1e-4, 1e-3)
