"""Closed-form torque-free motion (McGinnis, Perkins & King 2012, Table 1) and the free-flight scenarios."""

import numpy as np
import pytest
from scipy import special
from scipy.integrate import solve_ivp

from gfimu.array import Body, single_triad
from gfimu.rigid_body import point_specific_force
from gfimu.simulate import SensorErrors, simulate
from gfimu.simulate.free_flight import (
    TorqueFreeMotion,
    box_principal_inertia,
    energy_and_momentum,
    euler_rhs,
    small_oscillation_frequency_radps,
)
from gfimu.simulate.scenarios import FREE_FLIGHT_SENSOR_POSITION_M

BLOCK = box_principal_inertia()
# initial conditions covering both cases of Table 1, all sign patterns used
INITIAL = [
    [1.0, 2.0, 27.0],  # near the major axis (z)
    [27.0, -1.0, 2.0],  # near the minor axis (x)
    [-0.3, 20.0, 0.4],  # near the intermediate axis, major side
    [1.0, -20.0, 0.4],  # near the intermediate axis, minor side
    [-5.0, -3.0, -20.0],
    [3.0, 4.0, -5.0],
    [-8.0, 0.5, 6.0],
]
# the block's moments in both cyclic and anticyclic axis orders
INERTIAS = [BLOCK, BLOCK[[2, 0, 1]], BLOCK[[0, 2, 1]]]


def _euler(inertia, w0, t, rtol=1e-10):
    sol = solve_ivp(lambda _, w: euler_rhs(inertia, w), (t[0], t[-1]), w0, t_eval=t, rtol=rtol,
                    atol=1e-12 * np.linalg.norm(w0), method="DOP853")
    assert sol.success
    return sol.y.T


def test_block_inertia_from_box_formula():
    # I_x = m (b² + c²) / 12 with a, b, c = 0.201, 0.147, 0.102 m, m = 4.36 kg (worked by hand)
    np.testing.assert_allclose(BLOCK, [0.01163139, 0.01845915, 0.02253030], rtol=1e-6)
    assert BLOCK[0] < BLOCK[1] < BLOCK[2]  # x minor, z major


@pytest.mark.parametrize("inertia", INERTIAS, ids=["xyz", "zxy", "xzy"])
@pytest.mark.parametrize("w0", INITIAL)
def test_closed_form_conserves_constants_and_matches_euler(inertia, w0):
    t = np.linspace(0.0, 4.0, 2001)
    motion = TorqueFreeMotion.from_initial(inertia, w0)
    w = motion.omega(t)
    np.testing.assert_allclose(w[0], w0, rtol=0, atol=1e-12 * np.linalg.norm(w0))
    two_t, h2 = energy_and_momentum(inertia, w)
    two_t0, h20 = energy_and_momentum(inertia, np.asarray(w0))
    assert np.max(np.abs(two_t / two_t0 - 1)) < 1e-9
    assert np.max(np.abs(h2 / h20 - 1)) < 1e-9
    reference = _euler(inertia, np.asarray(w0, float), t)
    assert np.max(np.abs(w - reference)) < 1e-7 * np.linalg.norm(w0)


@pytest.mark.parametrize("w0", INITIAL[:4])
def test_omega_dot_is_the_derivative_and_solves_euler(w0):
    motion = TorqueFreeMotion.from_initial(BLOCK, w0)
    t = np.linspace(0.01, 2.0, 400)
    dw = motion.omega_dot(t)
    np.testing.assert_allclose(dw, euler_rhs(BLOCK, motion.omega(t)), rtol=0, atol=1e-10 * np.abs(dw).max())
    h = 1e-4  # fourth-order central difference
    w = motion.omega
    fd = (-w(t + 2 * h) + 8 * w(t + h) - 8 * w(t - h) + w(t - 2 * h)) / (12 * h)
    np.testing.assert_allclose(dw, fd, rtol=0, atol=1e-6 * np.abs(dw).max())


def test_table1_case_follows_h2_over_2t():
    i_mid = BLOCK[1]
    for w0 in INITIAL:
        two_t, h2 = energy_and_momentum(BLOCK, np.asarray(w0))
        motion = TorqueFreeMotion.from_initial(BLOCK, w0)
        assert motion.case == ("major" if h2 / two_t > i_mid else "minor")
        assert 0.0 <= motion.m < 1.0


def test_separatrix_is_the_k_equals_one_limit():
    # H² = 2T I_2 exactly: I_z (I_z − I_y) ω_z² = I_x (I_y − I_x) ω_x²
    ix, iy, iz = BLOCK
    wz = 10.0
    wx = np.sqrt(iz * (iz - iy) * wz**2 / (ix * (iy - ix)))
    for w0 in ([wx, 0.0, wz], [-wx, 0.5, -wz]):
        motion = TorqueFreeMotion.from_initial(BLOCK, w0)
        assert motion.m == pytest.approx(1.0, abs=1e-12)
        t = np.linspace(0.0, 1.0, 501)
        np.testing.assert_allclose(motion.omega(t), _euler(BLOCK, np.asarray(w0), t, rtol=1e-12), atol=1e-8)


def test_period_is_four_k_over_p():
    motion = TorqueFreeMotion.from_initial(BLOCK, INITIAL[0])
    t = np.linspace(0.0, 2.0, 101)
    np.testing.assert_allclose(motion.omega(t + motion.period_s), motion.omega(t), atol=1e-9)
    assert motion.period_s == pytest.approx(4 * special.ellipk(motion.m) / motion.p_radps)


def test_pure_spin_is_steady():
    for axis in range(3):
        w0 = np.zeros(3)
        w0[axis] = 12.0
        motion = TorqueFreeMotion.from_initial(BLOCK, w0)
        t = np.linspace(0.0, 3.0, 50)
        np.testing.assert_allclose(motion.omega(t), np.tile(w0, (50, 1)), atol=1e-12)
        np.testing.assert_allclose(motion.omega_dot(t), 0.0, atol=1e-12)


def test_needs_three_distinct_moments():
    with pytest.raises(ValueError, match="distinct"):
        TorqueFreeMotion.from_initial([0.02, 0.02, 0.03], [1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match="3 finite"):
        TorqueFreeMotion.from_initial(BLOCK, [1.0, np.nan, 3.0])


def _zero_crossing_period(t, x):
    """Mean period from linearly interpolated upward zero crossings."""
    k = np.nonzero((x[:-1] < 0) & (x[1:] >= 0))[0]
    tc = t[k] - x[k] * (t[k + 1] - t[k]) / (x[k + 1] - x[k])
    assert tc.size >= 3
    return (tc[-1] - tc[0]) / (tc.size - 1)


@pytest.mark.parametrize("scenario,axis", [("freeflight-major", 2), ("freeflight-minor", 0)])
def test_off_axis_oscillation_frequency_of_footnote_2(scenario, axis):
    spin = 27.4
    log = simulate(scenario, noise=SensorErrors.none(), duration_s=3.0, rate_hz=2000.0,
                   spin_radps=spin, off_axis_fraction=0.01)
    w = log.truth.omega_b_radps
    assert np.all(np.abs(w[:, axis]) > 0.99 * spin)  # stable: stays near the spin axis
    expected = small_oscillation_frequency_radps(BLOCK, axis, spin)
    for other in [j for j in range(3) if j != axis]:
        measured = 2 * np.pi / _zero_crossing_period(log.times_s, w[:, other])
        assert measured == pytest.approx(expected, rel=0.01)
    # and the exact period of the closed form (4K/p) agrees to the sampling accuracy
    motion = TorqueFreeMotion.from_initial(BLOCK, w[0])
    assert 2 * np.pi / motion.period_s == pytest.approx(expected, rel=0.01)
    period = _zero_crossing_period(log.times_s, w[:, [j for j in range(3) if j != axis][0]])
    assert period == pytest.approx(motion.period_s, rel=1e-5)


def test_small_oscillation_frequency_refuses_intermediate_axis():
    with pytest.raises(ValueError, match="intermediate"):
        small_oscillation_frequency_radps(BLOCK, 1, 10.0)


def test_intermediate_axis_spin_flips():
    log = simulate("freeflight-intermediate", noise=SensorErrors.none())
    wy = log.truth.omega_b_radps[:, 1]
    assert wy[0] > 0.99 * 27.0
    assert np.min(wy) < -0.9 * wy[0]  # the block turns over: ω_y reverses
    two_t, h2 = energy_and_momentum(BLOCK, log.truth.omega_b_radps)
    assert np.ptp(two_t) / two_t[0] < 1e-9 and np.ptp(h2) / h2[0] < 1e-9


@pytest.mark.parametrize("scenario", ["freeflight-major", "freeflight-intermediate", "freeflight-minor"])
def test_free_flight_log_is_a_falling_spinning_block(scenario):
    log = simulate(scenario, noise=SensorErrors.none())
    assert log.rate_hz == pytest.approx(1000.0)
    assert log.array.n_axes == 3 and log.array.body is not None
    np.testing.assert_allclose(log.array.body.principal_inertia_kgm2, BLOCK)
    np.testing.assert_allclose(log.array.accelerometers[0].position_m, FREE_FLIGHT_SENSOR_POSITION_M)
    tr = log.truth
    np.testing.assert_allclose(tr.specific_force_b_mps2, 0.0, atol=1e-12)  # free fall
    np.testing.assert_allclose(np.linalg.norm(tr.accel_b_mps2, axis=1), 9.80665, rtol=1e-12)
    r = FREE_FLIGHT_SENSOR_POSITION_M
    expected = np.cross(tr.omega_dot_b_radps2, r) + np.cross(tr.omega_b_radps, np.cross(tr.omega_b_radps, r))
    np.testing.assert_allclose(log.accel_mps2, expected, rtol=0, atol=1e-12)
    np.testing.assert_allclose(tr.omega_dot_b_radps2, euler_rhs(BLOCK, tr.omega_b_radps), atol=1e-9)


def test_free_flight_uses_the_array_body_when_given():
    body = Body((0.01, 0.02, 0.025))
    log = simulate("freeflight-major", array=single_triad((0.05, 0.0, 0.02), body=body),
                   noise=SensorErrors.none(), duration_s=0.5)
    assert log.array.body == body
    w = log.truth.omega_b_radps
    assert np.argmax(np.abs(w[0])) == 2
    np.testing.assert_allclose(log.truth.omega_dot_b_radps2, euler_rhs(body.principal_inertia_kgm2, w), atol=1e-9)
    np.testing.assert_allclose(log.accel_mps2, point_specific_force(0.0, log.truth.omega_dot_b_radps2, w,
                                                                     np.array([0.05, 0.0, 0.02])), atol=1e-12)
