"""Factors: analytic Jacobians against numerical derivatives, for the numpy
functions (vectorised) and the GTSAM CustomFactors (one instance)."""

import gtsam
import numpy as np
import pytest

from gfimu import rigid_body
from gfimu.array import Accelerometer, cube_array
from gfimu.factors import (
    so3 as _so3,
    accelerometer,
    euler,
    free_fall,
    gravity,
    gyroscope,
    inclinometer,
    kinematics,
    process,
    quadratic,
)
from gfimu.rotations import matrix_from_rotation_vector

RNG = np.random.default_rng(42)
UNIT = gtsam.noiseModel.Unit


def numeric_jacobian(fun, args, index, eps=1e-6, rotation=False):
    """Central differences of fun(*args) (N, m) w.r.t. args[index] (vector or right-perturbed rotation)."""
    x = np.asarray(args[index], dtype=float)
    n = x.shape[0]
    dim = 3 if rotation else x.shape[-1]
    cols = []
    for c in range(dim):
        out = []
        for sgn in (1, -1):
            a = list(args)
            if rotation:
                d = np.zeros((n, 3))
                d[:, c] = sgn * eps
                a[index] = x @ _so3.exp(d)
            else:
                xx = x.copy()
                xx[..., c] += sgn * eps
                a[index] = xx
            out.append(fun(*a)[0])
        cols.append((out[0] - out[1]) / (2 * eps))
    return np.stack(cols, axis=-1)


def random_rotations(n):
    return matrix_from_rotation_vector(RNG.normal(size=(n, 3)))


def check(fun, args, names, rotation_args=(), atol=1e-6):
    _, jac = fun(*args)
    for i, name in names.items():
        num = numeric_jacobian(fun, args, i, rotation=i in rotation_args)
        np.testing.assert_allclose(np.broadcast_to(jac[name], num.shape), num, atol=atol, rtol=1e-6, err_msg=name)


N = 7


def test_accelerometer_jacobians_and_value():
    acc = Accelerometer("s", RNG.uniform(-0.05, 0.05, 3), random_rotations(1)[0], axes=("x", "z"))
    dirs, pos = accelerometer.sensor_geometry(acc)
    w, dw, f = RNG.normal(size=(3, N, 3)) * [[[5]], [[20]], [[9]]]
    y = RNG.normal(size=(N, 2))
    bias, scale = RNG.normal(size=2) * 0.1, RNG.normal(size=2) * 0.01
    fun = lambda w, dw, f, b, s: accelerometer.accelerometer_residual(w, dw, f, y, dirs, pos, b[0], s[0])
    check(fun, (w, dw, f, bias[None], scale[None]), {0: "w", 1: "d", 2: "f", 3: "b", 4: "s"})
    r, _ = accelerometer.accelerometer_residual(w, dw, f, y, dirs, pos)
    direct = np.array([acc.rotation_body_sensor.T @ rigid_body.point_specific_force(f[k], dw[k], w[k], acc.position_m) for k in range(N)])
    np.testing.assert_allclose(r + y, direct[:, [0, 2]], atol=1e-12)


def test_quadratic_jacobian():
    w = RNG.normal(size=(N, 3)) * 3
    qm = RNG.normal(size=(N, 6))
    check(lambda w: quadratic.quadratic_residual(w, qm), (w,), {0: "w"})


def test_inversion_factor_jacobians():
    w, dw, f = RNG.normal(size=(3, N, 3)) * 3
    xm = RNG.normal(size=(N, 12))
    check(lambda a, b, c: quadratic.inversion_residual(a, b, c, xm), (w, dw, f), {0: "w", 1: "d", 2: "f"})


def test_quadratic_inversion_recovers_noise_free_terms():
    arr = cube_array(0.05)
    f, dw, w = RNG.normal(size=(3, N, 3)) * [[[9]], [[20]], [[4]]]
    x, cov = quadratic.inversion(arr, arr.predict_readings(f, dw, w))
    np.testing.assert_allclose(x[:, 6:], rigid_body.quadratic_terms(w), atol=1e-9)
    assert cov.shape == (12, 12) and np.all(np.linalg.eigvalsh(cov) > 0)


def test_angular_velocity_kinematics_jacobians_and_exactness():
    w0, w1, d0, d1 = RNG.normal(size=(4, N, 3))
    h = RNG.uniform(1e-3, 1e-2, N)
    fun = lambda a, b, c, d: kinematics.angular_velocity_residual(a, b, c, d, h)
    check(fun, (w0, w1, d0, d1), {0: "w0", 1: "w1", 2: "d0", 3: "d1"})
    # exact for ω̇ linear in time: ω(t) = ω0 + α t + β t²/2
    alpha, beta = RNG.normal(size=(2, 3))
    t = 0.01
    r, _ = kinematics.angular_velocity_residual(w0[0], w0[0] + alpha * t + beta * t * t / 2, alpha, alpha + beta * t, t)
    np.testing.assert_allclose(r, 0, atol=1e-15)


def test_trapezoid_sigma_matches_white_jerk_monte_carlo():
    rng = np.random.default_rng(5)
    q, h, steps, n = 3.0, 0.01, 200, 4000
    dt = h / steps
    jerk = rng.normal(size=(n, steps)) * q / np.sqrt(dt)
    d = np.concatenate([np.zeros((n, 1)), np.cumsum(jerk * dt, axis=1)], axis=1)
    w_end = np.sum(0.5 * (d[:, 1:] + d[:, :-1]) * dt, axis=1)
    e = w_end - 0.5 * h * (d[:, 0] + d[:, -1])
    assert np.std(e) == pytest.approx(float(kinematics.trapezoid_sigma(q, h)), rel=0.05)
    assert abs(np.corrcoef(e, d[:, -1])[0, 1]) < 0.05


def test_white_snap_step_jacobians_covariance_and_exactness():
    args = tuple(RNG.normal(size=(6, N, 3)))
    h = RNG.uniform(1e-3, 1e-2, N)
    fun = lambda *a: kinematics.angular_motion_residual(*a, h)
    check(fun, args, {0: "w0", 1: "w1", 2: "d0", 3: "d1", 4: "j0", 5: "j1"})
    # exact for constant ω̈
    w0, d0, j = RNG.normal(size=(3, 3))
    t = 0.02
    r, _ = kinematics.angular_motion_residual(w0, w0 + d0 * t + j * t * t / 2, d0, d0 + j * t, j, j, t)
    np.testing.assert_allclose(r, 0, atol=1e-15)
    # covariance against a Monte Carlo of white snap
    rng = np.random.default_rng(11)
    q, steps, n = 5.0, 100, 4000
    dt = t / steps
    snap = rng.normal(size=(n, steps)) * q / np.sqrt(dt)
    jerk = np.concatenate([np.zeros((n, 1)), np.cumsum(snap * dt, axis=1)], axis=1)
    acc = np.concatenate([np.zeros((n, 1)), np.cumsum(0.5 * (jerk[:, 1:] + jerk[:, :-1]) * dt, axis=1)], axis=1)
    vel = np.sum(0.5 * (acc[:, 1:] + acc[:, :-1]) * dt, axis=1)
    sample = np.stack([vel, acc[:, -1], jerk[:, -1]], axis=1)
    expected = kinematics.snap_process_covariance(q, t)[0]
    np.testing.assert_allclose(np.cov(sample.T), expected, rtol=0.1, atol=0.02 * np.sqrt(np.outer(np.diag(expected), np.diag(expected))).max())


def test_attitude_kinematics_jacobians_and_zero_for_consistent_step():
    R0, R1 = random_rotations(N), random_rotations(N)
    w0, w1 = RNG.normal(size=(2, N, 3))
    h = np.full(N, 0.05)
    fun = lambda a, b, c, d: kinematics.attitude_residual(a, b, c, d, h)
    check(fun, (R0, R1, w0, w1), {0: "r0", 1: "r1", 2: "w0", 3: "w1"}, rotation_args=(0, 1))
    R1c = R0 @ _so3.exp(0.5 * h[:, None] * (w0 + w1))
    r, _ = kinematics.attitude_residual(R0, R1c, w0, w1, h)
    np.testing.assert_allclose(r, 0, atol=1e-12)


def test_random_walk_and_prior_jacobians():
    x0, x1 = RNG.normal(size=(2, N, 4))
    check(process.random_walk_residual, (x0, x1), {0: "x0", 1: "x1"})
    check(lambda x: process.prior_residual(x, x1), (x0,), {0: "x"})
    assert process.random_walk_sigma(2.0, 0.04) == pytest.approx(0.4)


def test_euler_jacobians_and_torque_free_solution():
    inertia = np.array([0.0116, 0.0185, 0.0225])
    w, dw = RNG.normal(size=(2, N, 3))
    check(lambda a, b: euler.euler_residual(a, b, inertia), (w, dw), {0: "w", 1: "d"})
    # ω̇ from Euler's equations satisfies the factor exactly
    dw_free = -np.cross(w, w * inertia) / inertia
    r, _ = euler.euler_residual(w, dw_free, inertia)
    np.testing.assert_allclose(r, 0, atol=1e-15)


def test_free_fall_and_gyroscope_jacobians():
    f = RNG.normal(size=(N, 3))
    check(free_fall.free_fall_residual, (f,), {0: "f"})
    w, m, b = RNG.normal(size=(3, N, 3))
    check(lambda w, b: gyroscope.gyroscope_residual(w, m, b[0]), (w, b[:1]), {0: "w", 1: "g"})


def test_gravity_jacobians_and_still_body():
    R = random_rotations(N)
    f, a = RNG.normal(size=(2, N, 3))
    check(gravity.gravity_residual, (f, a, R), {0: "f", 1: "a", 2: "r"}, rotation_args=(2,))
    # still body: a = 0, f = -Rᵀ g; level body reads +9.81 on z
    r, _ = gravity.gravity_residual(np.array([[0, 0, 9.80665]]), np.zeros((1, 3)), np.eye(3))
    np.testing.assert_allclose(r, 0, atol=1e-12)


def test_accel_random_walk_and_attitude_prior_jacobians():
    R0, R1, P = random_rotations(N), random_rotations(N), random_rotations(N)
    f0, f1 = RNG.normal(size=(2, N, 3)) * 9
    check(gravity.accel_random_walk_residual, (f0, f1, R0, R1), {0: "f0", 1: "f1", 2: "r0", 3: "r1"}, rotation_args=(2, 3))
    check(lambda r: process.attitude_prior_residual(r, P), (R0,), {0: "r"}, rotation_args=(0,))
    # a still body: f = -Rᵀ g in every attitude, so the acceleration does not change
    r, _ = gravity.accel_random_walk_residual(np.einsum("nji,j->ni", R0, [0, 0, 9.80665]),
                                              np.einsum("nji,j->ni", R1, [0, 0, 9.80665]), R0, R1)
    np.testing.assert_allclose(r, 0, atol=1e-12)


def test_inclinometer_jacobian_and_log_format_convention():
    R = random_rotations(N)
    tilt = RNG.uniform(0.5, 2.5, (N, 2))
    num = numeric_jacobian(inclinometer.inclinometer_residual, (R, tilt), 0, rotation=True)
    _, jac = inclinometer.inclinometer_residual(R, tilt)
    np.testing.assert_allclose(jac["r"], num, atol=1e-6)
    # a still accelerometer aligned with B reads g cos(tilt_x) on x
    f_b = np.einsum("nji,j->ni", R, [0, 0, 9.80665])
    r, _ = inclinometer.inclinometer_residual(R, np.zeros((N, 2)))
    np.testing.assert_allclose(9.80665 * np.cos(r), f_b[:, :2], atol=1e-12)


# --- the GTSAM CustomFactors call the same maths -----------------------------

def factor_jacobians(factor, values):
    lin = factor.linearize(values)
    A, b = lin.jacobian()
    return A, -b


def numeric_factor_jacobian(factor, values, keys):
    cols = []
    eps = 1e-6
    for key in keys:
        try:
            base = values.atRot3(key)
            dim, rot = 3, True
        except RuntimeError:
            base = values.atVector(key)
            dim, rot = base.size, False
        for c in range(dim):
            out = []
            for sgn in (1, -1):
                v = gtsam.Values(values)
                d = np.zeros(dim)
                d[c] = sgn * eps
                v.erase(key)
                v.insert(key, base.retract(d) if rot else base + d)
                out.append(factor.unwhitenedError(v))
            cols.append((out[0] - out[1]) / (2 * eps))
    return np.column_stack(cols)


def test_custom_factors_match_numpy_and_numerical_derivatives():
    from gfimu import factors as F

    arr = cube_array(0.05)
    acc = arr.accelerometers[1]
    dirs, pos = accelerometer.sensor_geometry(acc)
    v = gtsam.Values()
    for k in range(2):
        v.insert(F.omega_key(k), RNG.normal(size=3) * 3)
        v.insert(F.omega_dot_key(k), RNG.normal(size=3) * 10)
        v.insert(F.specific_force_key(k), RNG.normal(size=3) * 9)
        v.insert(F.accel_key(k), RNG.normal(size=3))
        v.insert(F.omega_ddot_key(k), RNG.normal(size=3) * 30)
        v.insert(F.attitude_key(k), gtsam.Rot3(random_rotations(1)[0]))
    v.insert(F.bias_key(1), RNG.normal(size=3) * 0.1)
    v.insert(F.scale_key(1), RNG.normal(size=3) * 0.01)
    v.insert(F.gyro_bias_key(), RNG.normal(size=3) * 0.01)
    w, d, f, a, r = F.omega_key, F.omega_dot_key, F.specific_force_key, F.accel_key, F.attitude_key
    cases = [
        (accelerometer.make_accelerometer_factor(w(0), d(0), f(0), RNG.normal(size=3), dirs, pos, UNIT.Create(3), F.bias_key(1), F.scale_key(1)),
         [w(0), d(0), f(0), F.bias_key(1), F.scale_key(1)]),
        (quadratic.make_quadratic_factor(w(0), RNG.normal(size=6), UNIT.Create(6)), [w(0)]),
        (quadratic.make_inversion_factor(w(0), d(0), f(0), RNG.normal(size=12), UNIT.Create(12)), [w(0), d(0), f(0)]),
        (kinematics.make_angular_velocity_factor(w(0), w(1), d(0), d(1), 0.002, UNIT.Create(3)), [w(0), w(1), d(0), d(1)]),
        (kinematics.make_attitude_factor(r(0), r(1), w(0), w(1), 0.05, UNIT.Create(3)), [r(0), r(1), w(0), w(1)]),
        (process.make_random_walk_factor(d(0), d(1), UNIT.Create(3)), [d(0), d(1)]),
        (kinematics.make_angular_motion_factor(w(0), w(1), d(0), d(1), F.omega_ddot_key(0), F.omega_ddot_key(1), 0.01, UNIT.Create(9)),
         [w(0), w(1), d(0), d(1), F.omega_ddot_key(0), F.omega_ddot_key(1)]),
        (process.make_prior_factor(F.bias_key(1), np.ones(3), UNIT.Create(3)), [F.bias_key(1)]),
        (euler.make_euler_factor(w(1), d(1), [0.0116, 0.0185, 0.0225], UNIT.Create(3)), [w(1), d(1)]),
        (free_fall.make_free_fall_factor(f(1), UNIT.Create(3)), [f(1)]),
        (gravity.make_gravity_factor(f(1), a(1), r(1), UNIT.Create(3)), [f(1), a(1), r(1)]),
        (inclinometer.make_inclinometer_factor(r(0), [1.2, 1.9], UNIT.Create(2)), [r(0)]),
        (gravity.make_accel_random_walk_factor(f(0), f(1), r(0), r(1), UNIT.Create(3)), [f(0), f(1), r(0), r(1)]),
        (process.make_attitude_prior_factor(r(1), random_rotations(1)[0], UNIT.Create(3)), [r(1)]),
        (gyroscope.make_gyroscope_factor(w(0), RNG.normal(size=3), UNIT.Create(3), F.gyro_bias_key()), [w(0), F.gyro_bias_key()]),
    ]
    for factor, keys in cases:
        A, _ = factor_jacobians(factor, v)
        num = numeric_factor_jacobian(factor, v, keys)
        np.testing.assert_allclose(A, num, atol=1e-6, rtol=1e-6)
    # the accelerometer factor's error is the numpy residual
    y = RNG.normal(size=3)
    fac = accelerometer.make_accelerometer_factor(w(0), d(0), f(0), y, dirs, pos, UNIT.Create(3))
    expected, _ = accelerometer.accelerometer_residual(v.atVector(w(0)), v.atVector(d(0)), v.atVector(f(0)), y[None], dirs, pos)
    np.testing.assert_allclose(fac.unwhitenedError(v), expected[0], atol=1e-12)


def test_array_geometry_follows_the_reading_columns():
    from gfimu.array import mimu4444_array, paper001_array

    for arr in (paper001_array(), mimu4444_array(0.05)):
        geo = accelerometer.array_geometry(arr)
        assert len(geo) == len(arr.accelerometers)
        assert [(g[2].start, g[2].stop) for g in geo] == [(int(s), int(s + g[0].shape[0])) for s, g in
                                                         zip(np.cumsum([0] + [g[0].shape[0] for g in geo[:-1]]), geo)]
        assert geo[-1][2].stop == arr.n_axes
        rows = np.vstack([accelerometer.axis_rows(d, p) for d, p, _ in geo])
        np.testing.assert_allclose(rows, arr.structure_matrix(), rtol=0, atol=1e-15)
