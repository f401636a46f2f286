"""The per-sample ML fit's compiled iterations against the numpy expressions they replace (the oracle)."""

import numpy as np
import pytest

from gfimu.array import cube_array, mimu4444_array
from gfimu.estimators import ml, ml_kernels
from gfimu.estimators.ml import MLEstimator, _ProjectedModel
from gfimu.simulate import simulate


@pytest.fixture(autouse=True)
def _counted_kernel(monkeypatch):
    """Count the compiled kernel's calls (numba is loaded by this module's import of the kernels, so the
    estimator takes the compiled path)."""
    calls = []
    kernel = ml_kernels.iterate

    def counted(*args):
        calls.append(len(args[2]))
        return kernel(*args)

    monkeypatch.setattr(ml_kernels, "iterate", counted)
    return calls


def _problem(array, n, seed, noise):
    """Reduced readings of n random states on ``array`` and starts near and far from them."""
    rng = np.random.default_rng(seed)
    S = array.structure_matrix()
    sigma = MLEstimator()._axis_sigma(array)
    model = _ProjectedModel.build(array, sigma)
    w = rng.normal(size=(n, 3)) * 5.0
    x = np.hstack([rng.normal(size=(n, 3)) * 9.0, rng.normal(size=(n, 3)) * 30.0,
                   np.column_stack([w[:, 0] ** 2 + w[:, 1] ** 2, w[:, 0] ** 2 + w[:, 2] ** 2, w[:, 1] ** 2 + w[:, 2] ** 2,
                                    w[:, 0] * w[:, 1], w[:, 0] * w[:, 2], w[:, 1] * w[:, 2]])])
    y = x @ S.T + rng.normal(size=(n, S.shape[0])) * noise
    b, c = model.readings(y)
    starts = np.vstack([w[: n // 2] + rng.normal(size=(n // 2, 3)) * 0.5, rng.normal(size=(n - n // 2, 3)) * 20.0])
    return model, b, c, starts, w


@pytest.mark.parametrize("array_name, noise", [("cube", 0.05), ("cube", 2.0), ("mimu", 0.05)])
def test_compiled_iterations_are_the_numpy_iterations(monkeypatch, _counted_kernel, array_name, noise):
    array = cube_array(0.05, noise_std_mps2=0.05) if array_name == "cube" else mimu4444_array()
    model, b, c, starts, _ = _problem(array, 400, 7, noise)
    est = MLEstimator()
    got = est._iterate(model, b, c, starts, None, None)
    assert _counted_kernel == [400]  # the compiled path ran
    monkeypatch.setattr(MLEstimator, "compiled", False)
    want = est._iterate(model, b, c, starts, None, None)
    assert _counted_kernel == [400]  # and the oracle did not
    # the same iterations, each product summed in another order: each sample's minimum to rounding (its
    # Levenberg–Marquardt stops at a step of 1e-12 rad/s, or where the cost settles to rounding)
    cost_got = ml._cost(model, b, got, None, None)
    cost_want = ml._cost(model, b, want, None, None)
    np.testing.assert_allclose(cost_got, cost_want, rtol=1e-9, atol=1e-12)
    same = np.abs(got - want).max(axis=1) <= 1e-6 * (1.0 + np.abs(want).max(axis=1))
    assert same.all(), f"{(~same).sum()} of {len(same)} samples ended elsewhere"


def test_compiled_iterations_with_a_gyro_are_the_numpy_iterations(monkeypatch):
    array = cube_array(0.05, noise_std_mps2=0.05)
    model, b, c, starts, w = _problem(array, 200, 9, 0.05)
    gyro = w + np.random.default_rng(1).normal(size=w.shape) * 0.01
    est = MLEstimator()
    got = est._iterate(model, b, c, starts, gyro, 1e-4)
    monkeypatch.setattr(MLEstimator, "compiled", False)
    want = est._iterate(model, b, c, starts, gyro, 1e-4)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-6 * (1.0 + np.abs(want).max()))


def test_noise_free_readings_are_fitted_exactly():
    """Started near the truth, the compiled iterations recover ω of noise-free readings (up to its sign)."""
    array = cube_array(0.05, noise_std_mps2=0.05)
    model, b, c, starts, w = _problem(array, 100, 3, 0.0)
    got = MLEstimator()._iterate(model, b[:50], c[:50], starts[:50], None, None)
    err = np.minimum(np.abs(got - w[:50]).max(axis=1), np.abs(got + w[:50]).max(axis=1))
    assert err.max() < 1e-6


def test_a_whole_ml_estimate_is_the_numpy_estimate(monkeypatch):
    log = simulate("random3d", array=cube_array(0.025, noise_std_mps2=0.07), rate_hz=500.0, duration_s=2.0, seed=2)
    got = MLEstimator(workers=1).estimate_motion(log)
    monkeypatch.setattr(MLEstimator, "compiled", False)
    want = MLEstimator(workers=1).estimate_motion(log)
    np.testing.assert_allclose(got.omega_b_radps, want.omega_b_radps, rtol=0, atol=1e-6)
    np.testing.assert_allclose(got.omega_dot_b_radps2, want.omega_dot_b_radps2, rtol=0, atol=1e-3)
