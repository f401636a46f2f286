"""gfimu.array_misfit: constant calibration errors read off the rigid-body residual, and the warning the smoothers'
σ carries where they are most of the misfit (the fit itself: tests/test_diagnose.py)."""

import re
from dataclasses import replace

import numpy as np
import pytest

from gfimu.array_misfit import calibration_errors, misfit_warning, rigid_body_residual
from gfimu.estimators.ml import MLEstimator
from gfimu.methods import make_estimator
from gfimu.noise import accel_noise_std
from gfimu.simulate import SensorErrors, simulate


def _moved(log, offsets_m: dict):
    """``log`` with array.toml's positions moved by ``offsets_m`` (name -> (3,)), the readings as they were."""
    accs = tuple(replace(a, position_m=np.asarray(a.position_m) + offsets_m.get(a.name, 0.0))
                 for a in log.array.accelerometers)
    return log.replace(array=replace(log.array, accelerometers=accs))


@pytest.fixture(scope="module")
def logs():
    """random3d (5 cm cube, 0.002 m/s² of noise, 24 s: 12,000 samples, more than the warning's subsample) as
    recorded, and with array.toml's a2 2 mm and a4 1 mm off."""
    base = simulate("random3d", seed=3, duration_s=24.0, noise=SensorErrors(accel_noise_std_mps2=0.002))
    return base, _moved(base, {"a2": np.array([0.0, -0.002, 0.0]), "a4": np.array([0.0, 0.0, 0.001])})


def test_the_warnings_subsample_gives_the_share_of_the_whole_log(logs):
    """misfit_warning takes every second sample of 12,000: its share (in the text) is the whole log's within a
    percent point, and the rigid-body residual is the readings less S [f, ω̇, q(ω)] of the fit."""
    _, moved = logs
    motion = MLEstimator().estimate_motion(moved)
    residual = rigid_body_residual(moved.array, moved.accel_mps2, motion)
    whole = calibration_errors(moved, motion, accel_noise_std(moved.array), residual).share
    assert whole > 0.9
    note = misfit_warning(moved, motion)
    assert note is not None and "gfimu diagnose" in note
    share = float(re.search(r"misfit is (\d+) %", note).group(1)) / 100
    assert abs(share - whole) <= 0.015  # (printed to the percent)
    # the residual by hand, on one sample
    S = moved.array.structure_matrix()
    w = motion.omega_b_radps[7]
    q = np.array([w[0] ** 2 + w[1] ** 2, w[0] ** 2 + w[2] ** 2, w[1] ** 2 + w[2] ** 2, w[0] * w[1], w[0] * w[2],
                  w[1] * w[2]])
    x = np.concatenate([motion.specific_force_b_mps2[7], motion.omega_dot_b_radps2[7], q])
    np.testing.assert_allclose(residual[7], moved.accel_mps2[7] - S @ x, atol=1e-12 * np.max(np.abs(moved.accel_mps2)))


@pytest.mark.parametrize("method", ["smoother", pytest.param("fixed-lag", marks=pytest.mark.slow)])
def test_sigma_says_when_the_misfit_is_a_calibration_error(logs, method):
    """Both smoothers, with σ: the moved log's report warns that σ does not cover the calibration error and
    names gfimu diagnose; the log as recorded gets no such warning, nor the moved one without σ (nothing
    computed)."""
    base, moved = logs
    part = moved.select(slice(0, 5000))
    with_sigma = make_estimator(method, compute_sigma=True).estimate(part).report.warnings
    assert [w for w in with_sigma if w.startswith("sigma does not cover an error of the array's calibration")]
    assert not [w for w in make_estimator(method).estimate(part).report.warnings if "calibration" in w]
    clean = make_estimator(method, compute_sigma=True).estimate(base.select(slice(0, 5000))).report.warnings
    assert not [w for w in clean if "calibration" in w]
