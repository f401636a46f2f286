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


def test_error_breakdown_shares():
    """Known errors: 2 rad/s on the 3 samples either side of a saturated sample, 1 rad/s elsewhere,
    and one estimate pointing to the other hemisphere."""
    from gfimu.array import mimu4444_array
    from gfimu.log import Log
    from gfimu.motion import Motion

    n = 200
    t = np.arange(n, dtype=np.int64) * 16_000_000
    ref = np.tile([12.0, 0.0, 0.0], (n, 1))
    invalid = np.zeros(n, dtype=bool)
    invalid[100] = True
    est = ref + np.array([0.0, 1.0, 0.0])
    near = np.abs(np.arange(n) - 100) <= 3
    est[near] = ref[near] + np.array([0.0, 2.0, 0.0])
    est[10] = -ref[10]  # error 24 rad/s, opposite
    arr = mimu4444_array()
    log = Log(arr, t, np.zeros((n, arr.n_axes)), reference=Motion(t, omega_b_radps=ref), invalid_reference=invalid)
    mask = ~invalid
    b = study.error_breakdown(Motion(t, omega_b_radps=est), log, mask)
    err2 = np.where(near, 4.0, 1.0)
    err2[10] = 24.0**2
    total = err2[mask].sum()
    c = b["by_distance_to_saturation"]["1-4"]
    assert c["n"] == 6 and np.isclose(c["rmse_norm"], 2.0) and np.isclose(c["share_sse"], 24.0 / total)
    far = b["by_distance_to_saturation"]["30-1000000000"]
    assert np.isclose(far["opposite"], 1.0 / far["n"])
    assert np.isclose(b["by_omega_radps"]["10-20"]["share_sse"], 1.0)
    assert np.isclose(b["top_1pc_share_sse"], 24.0**2 / total)  # 199 samples: the single largest
    assert np.isclose(b["top_5pc_share_sse"], (24.0**2 + 6 * 4.0 + 2 * 1.0) / total)  # the 9 largest
