"""The rigid-body residual tools of tools/mimu4444_study.py on noise-free synthetic readings."""

import importlib.util
from pathlib import Path

import numpy as np

from gfimu import rigid_body

_spec = importlib.util.spec_from_file_location("mimu4444_study", Path(__file__).resolve().parents[1] / "tools" / "mimu4444_study.py")
study = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(study)


def rigid_readings(positions, omega, omega_dot, f):
    return np.stack([rigid_body.point_specific_force(f, omega_dot, omega, r) for r in positions], axis=1)


def motion(n=400, seed=0):
    rng = np.random.default_rng(seed)
    return 20 * rng.standard_normal((n, 3)), 300 * rng.standard_normal((n, 3)), 10 * rng.standard_normal((n, 3))


def test_rigid_residual_zero_on_rigid_data_and_omega_dot_recovered():
    from gfimu.array import MIMU4444_POSITIONS_M as pos

    w, dw, f = motion()
    y = rigid_readings(pos, w, dw, f)
    res, f_fit, dw_fit = study.rigid_residual(y, w, pos)
    assert np.max(np.abs(res)) < 1e-9
    assert np.allclose(dw_fit, dw, atol=1e-6) and np.allclose(f_fit, f, atol=1e-9)
    res2, _, _ = study.rigid_residual(y, w, pos, omega_dot=dw)
    assert np.max(np.abs(res2)) < 1e-9


def test_fit_positions_recovers_displaced_sensors():
    from gfimu.array import MIMU4444_POSITIONS_M as pos

    rng = np.random.default_rng(4)
    shift = 3e-4 * rng.standard_normal(pos.shape)
    shift -= shift.mean(axis=0)  # the gauge: centroid at the nominal one
    true = pos + shift
    w, dw, f = motion(seed=1)
    y = rigid_readings(true, w, dw, f)
    before = study._rms(study.rigid_residual(y, w, pos)[0])
    fitted = study.fit_positions(y, w, pos, iterations=60)
    assert before > 0.05
    assert np.max(np.abs(fitted - true)) < 1e-7
    assert study._rms(study.rigid_residual(y, w, fitted)[0]) < 1e-5
