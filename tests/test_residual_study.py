"""The candidate-cause fits of tools/residual_study.py on synthetic readings with known causes."""

import importlib.util
from pathlib import Path

import numpy as np

from gfimu import rigid_body
from gfimu.array import MIMU4444_POSITIONS_M as POS
from gfimu.array import mimu4444_array

_spec = importlib.util.spec_from_file_location("residual_study", Path(__file__).resolve().parents[1] / "tools" / "residual_study.py")
study = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(study)

S = mimu4444_array().structure_matrix()


def motion(n=600, seed=0):
    rng = np.random.default_rng(seed)
    return 20 * rng.standard_normal((n, 3)), 300 * rng.standard_normal((n, 3)), 10 * rng.standard_normal((n, 3))


def readings(w, dw, f, positions=POS):
    return np.stack([rigid_body.point_specific_force(f, dw, w, r) for r in positions], axis=1)


def test_residuals_vanish_on_rigid_readings():
    w, dw, f = motion()
    y = readings(w, dw, f)
    r6, f6, dw6 = study.residual6(y, w, POS)
    r12, x = study.residual12(y, S)
    assert np.max(np.abs(r6)) < 1e-9 and np.max(np.abs(r12)) < 1e-9
    assert np.allclose(dw6, dw, atol=1e-6) and np.allclose(x[:, :3], f, atol=1e-8)


def test_dynamic_gains_remove_per_sensor_gain_errors_without_gyro():
    rng = np.random.default_rng(3)
    w, dw, f = motion(seed=1)
    y_true = readings(w, dw, f)
    G = np.eye(3) + 0.02 * rng.standard_normal((8, 3, 3))
    G = np.linalg.inv(G.mean(axis=0))[None] @ G  # the gauge: mean gain identity, mean bias zero
    b = 0.3 * rng.standard_normal((8, 3))
    b -= b.mean(axis=0)
    # the sensors read y = G⁻¹ (y_true - b): the correction G y + b gives back a rigid body
    y = np.einsum("kij,nkj->nki", np.linalg.inv(G), y_true - b)
    before = study.var(study.residual12(y, S)[0])
    fit = np.arange(len(y) // 2)
    G_fit, b_fit, correct = study.dynamic_gains(y, S, fit, iterations=30)
    after = study.var(study.residual12(correct(y[len(y) // 2:]), S)[0])
    assert before > 0.1
    assert after < 1e-4 * before
    assert np.max(np.abs(G_fit - G)) < 1e-3


def test_time_offsets_recover_delays_of_a_residual_along_the_reading_rate():
    rng = np.random.default_rng(5)
    ydot = 500 * rng.standard_normal((1000, 8, 3))
    tau = 1e-4 * np.arange(8)
    res = -tau[None, :, None] * ydot + 0.01 * rng.standard_normal(ydot.shape)
    fitted, corrected = study.time_offsets(res, ydot)
    assert np.allclose(fitted, tau, atol=2e-6)
    assert study.var(corrected) < 1.1 * 0.01**2


def test_variance_models_prefer_the_true_rate_dependence():
    rng = np.random.default_rng(7)
    n = 4000
    w = 15 * rng.standard_normal((n, 3))
    sigma = np.sqrt(0.05**2 + (0.04 * np.linalg.norm(w, axis=1)) ** 2)
    res = sigma[:, None, None] * rng.standard_normal((n, 8, 3))
    ydot = rng.standard_normal((n, 8, 3))
    nyq = np.abs(rng.standard_normal(n))
    fit, test = study.halves(n)
    m = study.variance_models(res, w, ydot, nyq, 1.0, fit, test)
    # the Gaussian log-likelihood gain of the true variance model: ½ E[log(mean σ² / σ_k²)] = 0.18 here
    assert m["omega"]["loglik"] > m["constant"]["loglik"] + 0.15
    assert m["omega"]["loglik"] > m["near Nyquist"]["loglik"] + 0.15
    assert m["constant"]["kurtosis"] > 4.5
    assert abs(np.sqrt(m["omega"]["coef"][1]) - 0.04) < 0.004
    assert m["omega"]["tail"] < 1e-3 and abs(m["omega"]["kurtosis"] - 3.0) < 0.3
