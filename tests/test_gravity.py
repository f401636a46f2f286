"""Gravity compensation (Lu, Tsai & Lin 2010, eqs. 12-13) and attitude propagation (Li et al. 2021, eqs. 9-10)."""

import functools

import numpy as np
import pytest

from gfimu.array import Gyroscope, Inclinometer, SensorArray, cube_array
from gfimu.methods import make_estimator
from gfimu.estimators.gravity import (
    STANDARD_GRAVITY_MPS2,
    add_orientation,
    gravity_b_from_tilt,
    propagate_quaternion,
    quaternion_from_up_b,
)
from gfimu.log import Log
from gfimu.motion import Motion
from gfimu.rotations import matrix_from_quaternion, matrix_from_rotation_vector, quaternion_multiply

G_W = np.array([0.0, 0.0, -STANDARD_GRAVITY_MPS2])
CUBE = cube_array(noise_std_mps2=None)
CUBE_INCL = SensorArray(CUBE.accelerometers, "cube+incl", inclinometer=Inclinometer(0.002))


def tilts_of(R_wb):
    """Inclinometer angles: between body x (y) and the upward vertical."""
    return np.array([np.arccos(R_wb[2, 0]), np.arccos(R_wb[2, 1])])


def static_log(array, R_wb, n=50, t0_ns=0, tilt=True):
    f_b = R_wb.T @ -G_W
    t = t0_ns + np.arange(n, dtype=np.int64) * 2_000_000
    acc = np.tile(array.predict_readings(f_b, np.zeros(3), np.zeros(3)), (n, 1))
    return Log(array, t, acc, tilt_rad=np.tile(tilts_of(R_wb), (n, 1)) if tilt else None,
               gyro_b_radps=np.zeros((n, 3)) if array.gyroscope else None)


R_TILTED = matrix_from_rotation_vector([0.3, -0.2, 1.1])


def test_static_tilted_array_inclinometer_compensation():
    assert R_TILTED[2, 2] > 0  # body z points upward, as the inclinometer convention assumes
    log = static_log(CUBE_INCL, R_TILTED)
    est = add_orientation(log, make_estimator("inversion").estimate(log).motion, "inclinometer")
    np.testing.assert_allclose(est.accel_b_mps2, 0.0, atol=1e-9)
    # roll and pitch right, yaw zero: R(q)ᵀ e_z is the body's up vector and body x has no world-y part
    R = matrix_from_quaternion(est.quaternion_wb)
    np.testing.assert_allclose(R[:, 2, :], np.tile(R_TILTED[2], (len(log), 1)), atol=1e-12)
    np.testing.assert_allclose(R[:, 1, 0], 0.0, atol=1e-12)


def test_gravity_from_tilt_direction_cosines():
    tilt = np.array([[np.pi / 2, np.pi / 2], [np.pi / 3, np.pi / 2], [np.pi / 2, 2 * np.pi / 3]])
    np.testing.assert_allclose(gravity_b_from_tilt(tilt), -STANDARD_GRAVITY_MPS2 * np.array(
        [[0, 0, 1], [0.5, 0, np.sqrt(0.75)], [0, -0.5, np.sqrt(0.75)]]), atol=1e-12)
    with pytest.raises(ValueError, match="sample 1 .*exceed 1"):
        gravity_b_from_tilt(np.array([[1.5, 1.5], [0.1, 0.2]]))


def test_static_gyro_and_estimate_sources_start_from_specific_force():
    arr = SensorArray(CUBE.accelerometers, "cube+gyro", gyroscope=Gyroscope(0.01))
    log = static_log(arr, R_TILTED, tilt=False)
    est = make_estimator("inversion").estimate(log).motion
    out = add_orientation(log, est, "gyro")
    np.testing.assert_allclose(out.accel_b_mps2, 0.0, atol=1e-9)
    # the accelerometer-derived ω at rest is sqrt(rounding) ≈ 1e-7 rad/s, hence a looser bound
    out = add_orientation(log, est, "estimate")
    np.testing.assert_allclose(out.accel_b_mps2, 0.0, atol=1e-6)


def test_restart_at_gaps_reinitialises_the_attitude():
    """Two still segments at different tilts, split by a gap: both compensate to zero."""
    first = static_log(CUBE, R_TILTED, tilt=False)
    second = static_log(CUBE, matrix_from_rotation_vector([-0.4, 0.5, 0.0]), t0_ns=10**9, tilt=False)
    log = Log(CUBE, np.concatenate([first.timestamps_ns, second.timestamps_ns]),
              np.vstack([first.accel_mps2, second.accel_mps2]))
    assert len(log.segments()) == 2
    out = add_orientation(log, make_estimator("inversion").estimate(log).motion, "estimate")
    np.testing.assert_allclose(out.accel_b_mps2, 0.0, atol=1e-6)  # without the restart: errors of metres/s²


def omega_fn(t):
    """Starts at rest (ω = ω̇ = 0 at t = 0), then tumbles."""
    t = np.asarray(t, float)
    ramp = 1 - np.cos(np.pi * t)
    dramp = np.pi * np.sin(np.pi * t)
    amp = np.array([2.0, -1.5, 2.5])
    phase = np.array([0.0, 1.0, 2.0])
    osc = 1 + 0.5 * np.sin(3 * t[:, None] + phase)
    dosc = 1.5 * np.cos(3 * t[:, None] + phase)
    return amp * ramp[:, None] * osc, amp * (dramp[:, None] * osc + ramp[:, None] * dosc)


def rk4_attitude(q0, t_end, h=1e-3):
    """Reference attitude by classic RK4 (at h = 1 ms within 2e-12 rad of h = 0.1 ms over 1 s, far below the
    second-order errors compared with it)."""
    q = np.asarray(q0, float)
    f = lambda tt, qq: 0.5 * quaternion_multiply(qq, np.r_[0.0, omega_fn([tt])[0][0]])
    t = 0.0
    for _ in range(int(round(t_end / h))):
        k1 = f(t, q); k2 = f(t + h / 2, q + h / 2 * k1); k3 = f(t + h / 2, q + h / 2 * k2); k4 = f(t + h, q + h * k3)
        q = q + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        t += h
    return q / np.linalg.norm(q)


def angle_between(q1, q2):
    d = quaternion_multiply(q1 * [1, -1, -1, -1], q2)
    return 2 * np.arctan2(np.linalg.norm(d[..., 1:], axis=-1), np.abs(d[..., 0]))


Q0 = quaternion_from_up_b(R_TILTED[2])[0]  # zero-yaw start, as add_orientation builds it


def test_improved_euler_propagation_is_second_order():
    t_end = 1.0
    q_ref = rk4_attitude(Q0, t_end)
    errs = []
    for h in (0.01, 0.005, 0.0025):
        t_ns = np.round(np.arange(int(round(t_end / h)) + 1) * h * 1e9).astype(np.int64)
        q = propagate_quaternion(Q0, omega_fn(t_ns * 1e-9)[0], t_ns)
        errs.append(angle_between(q[-1], q_ref))
    ratios = np.array(errs[:-1]) / np.array(errs[1:])
    np.testing.assert_allclose(ratios, 4.0, rtol=0.05)
    assert errs[0] < 1e-3


def test_prefix_product_equals_sequential_update():
    rng = np.random.default_rng(1)
    w = rng.normal(size=(1000, 3)) * 3
    t = np.arange(1000, dtype=np.int64) * 2_000_000
    q = propagate_quaternion(Q0, w, t)
    from gfimu.estimators.gravity import improved_euler_increments

    dq = improved_euler_increments(w, np.full(999, 0.002))
    seq = [Q0]
    for d in dq:
        seq.append(quaternion_multiply(seq[-1], d))
    np.testing.assert_allclose(q, np.array(seq), atol=1e-12)


@functools.lru_cache(maxsize=1)
def tumbling_log(rate_hz=500.0, duration_s=2.0):
    t_ns = np.round(np.arange(int(rate_hz * duration_s)) * 1e9 / rate_hz).astype(np.int64)
    t = t_ns * 1e-9
    w, dw = omega_fn(t)
    # attitude truth by RK4 between samples; the body origin stays still (a = 0)
    q = [Q0]
    for k in range(1, len(t)):
        q.append(rk4_stage(q[-1], t[k - 1], t[k]))
    q = np.array(q)
    f_b = np.einsum("nji,j->ni", matrix_from_quaternion(q), -G_W)
    acc = CUBE.predict_readings(f_b, dw, w)
    arr = SensorArray(CUBE.accelerometers, "cube+gyro", gyroscope=Gyroscope(0.01))
    return Log(arr, t_ns, acc, gyro_b_radps=w,
               truth=Motion(t_ns, omega_b_radps=w, omega_dot_b_radps2=dw, specific_force_b_mps2=f_b,
                            accel_b_mps2=np.zeros_like(f_b), quaternion_wb=q))


def rk4_stage(q, ta, tb, steps=4):
    h = (tb - ta) / steps
    f = lambda tt, qq: 0.5 * quaternion_multiply(qq, np.r_[0.0, omega_fn([tt])[0][0]])
    t = ta
    for _ in range(steps):
        k1 = f(t, q); k2 = f(t + h / 2, q + h / 2 * k1); k3 = f(t + h / 2, q + h / 2 * k2); k4 = f(t + h, q + h * k3)
        q = q + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        t += h
    return q / np.linalg.norm(q)


@pytest.mark.parametrize("source, method", [("gyro", "inversion"), ("estimate", "integration")])
def test_tumbling_body_gravity_removed(source, method):
    log = tumbling_log()
    est = make_estimator(method).estimate(log).motion
    out = add_orientation(log, est, source, initial_window_s=0.0)
    assert angle_between(out.quaternion_wb, log.truth.quaternion_wb).max() < 5e-5
    np.testing.assert_allclose(out.accel_b_mps2, 0.0, atol=5e-4)


def test_add_orientation_errors():
    log = static_log(CUBE, R_TILTED, tilt=False)
    est = make_estimator("inversion").estimate(log).motion
    with pytest.raises(ValueError, match="needs tilt_x"):
        add_orientation(log, est, "inclinometer")
    with pytest.raises(ValueError, match="needs gyroscope"):
        add_orientation(log, est, "gyro")
    with pytest.raises(ValueError, match="source must be"):
        add_orientation(log, est, "compass")
    with pytest.raises(ValueError, match="no specific force"):
        add_orientation(log, Motion(log.timestamps_ns, omega_b_radps=est.omega_b_radps), "estimate")


def test_moving_start_takes_the_vertical_from_the_inclinometer():
    """A log starting mid-tumble: the inclinometer's first sample fixes the initial tilt."""
    full = tumbling_log()
    R = matrix_from_quaternion(full.truth.quaternion_wb)
    log = full.replace(tilt_rad=np.arccos(R[:, 2, :2])).select(slice(300, None))
    assert np.abs(log.gyro_b_radps[0]).max() > 1.0
    out = add_orientation(log, make_estimator("inversion").estimate(log).motion, "gyro")
    np.testing.assert_allclose(out.accel_b_mps2, 0.0, atol=5e-4)
    # heading is not observable: the attitude differs from the truth by a rotation about the vertical only
    up_est = matrix_from_quaternion(out.quaternion_wb)[:, 2, :]
    np.testing.assert_allclose(up_est, R[300:, 2, :], atol=5e-5)
