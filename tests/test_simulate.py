"""Simulator: exact readings, self-consistent truth, scenario geometry, sensor errors."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from gfimu import rotations
from gfimu.array import Accelerometer, Gyroscope, Inclinometer, SensorArray, cube_array, paper001_array
from gfimu.rigid_body import point_specific_force
from gfimu.simulate import SCENARIOS, SensorErrors, sample_timestamps_ns, simulate
from gfimu.simulate import scenarios as sc
from gfimu.simulate.sensor_errors import ADXL330_NOISE_XY_MPS2, ADXL330_NOISE_Z_MPS2
from gfimu.simulate.trajectory import (
    GRAVITY_W_MPS2,
    integrate_attitude,
    level_quaternion_from_specific_force,
    sum_of_sines,
    tilt_angles_rad,
)

G = 9.80665
ANALYTIC = ["turntable", "turntable-constant", "random3d", "reversal",
            "freeflight-major", "freeflight-intermediate", "freeflight-minor"]


def mixed_array():
    """Rotated sensors, a 2-axis and a 1-axis sensor, gyro and inclinometer."""
    rot = rotations.matrix_from_rotation_vector(np.array([0.3, -0.5, 0.9]))
    accs = (
        Accelerometer("a", [0.04, 0.03, -0.02], rotation_body_sensor=rot, noise_std_mps2=0.05),
        Accelerometer("b", [-0.05, 0.02, 0.04], axes=("x", "z")),
        Accelerometer("c", [0.01, -0.06, 0.03], rotation_body_sensor=rot.T, axes=("y",), noise_std_mps2=0.05),
    )
    return SensorArray(accs, "mixed", gyroscope=Gyroscope(0.02), inclinometer=Inclinometer(0.003))


def exact_readings(array, truth):
    """Readings from the rigid-body equation at each sensor, sensor by sensor (independent of S)."""
    cols = []
    for acc in array.accelerometers:
        f_b = point_specific_force(truth.specific_force_b_mps2, truth.omega_dot_b_radps2, truth.omega_b_radps,
                                   acc.position_m)
        f_s = f_b @ acc.rotation_body_sensor  # sensor frame: Rᵀ f
        cols += [f_s[:, "xyz".index(a)] for a in acc.axes]
    return np.stack(cols, axis=1)


def fd4(x, h):
    """Fourth-order central difference, interior samples [2:-2]."""
    return (-x[4:] + 8 * x[3:-1] - 8 * x[1:-3] + x[:-4]) / (12 * h)


def fd4_second(x, h):
    return (-x[4:] + 16 * x[3:-1] - 30 * x[2:-2] + 16 * x[1:-3] - x[:-4]) / (12 * h * h)


# --- exact readings and self-consistent truth ----------------------------------------

@pytest.mark.parametrize("scenario", ANALYTIC + ["euroc"])
def test_noise_free_readings_are_the_rigid_body_equation(scenario):
    array = mixed_array()
    log = simulate(scenario, array=array, noise=SensorErrors.none(), duration_s=1.0)
    assert log.accel_mps2.shape == (len(log), array.n_axes)
    np.testing.assert_allclose(log.accel_mps2, exact_readings(array, log.truth), rtol=0, atol=1e-12)
    np.testing.assert_array_equal(log.gyro_b_radps, log.truth.omega_b_radps)
    np.testing.assert_allclose(log.tilt_rad, tilt_angles_rad(log.truth.quaternion_wb), atol=0)


@pytest.mark.parametrize("scenario", SCENARIOS)
def test_specific_force_is_accel_minus_gravity_in_body(scenario):
    log = simulate(scenario, noise=SensorErrors.none(), duration_s=2.0)
    tr = log.truth
    r = rotations.matrix_from_quaternion(tr.quaternion_wb)
    np.testing.assert_allclose(tr.specific_force_b_mps2, tr.accel_b_mps2 - np.einsum("nji,j->ni", r, GRAVITY_W_MPS2),
                               rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(tr.quaternion_wb, axis=1), 1.0, atol=1e-12)
    assert log.timestamps_ns[0] == 0 and np.all(np.diff(log.timestamps_ns) > 0)


@pytest.mark.parametrize("scenario", ANALYTIC + ["euroc", "kitti"])
def test_omega_dot_is_the_derivative_of_omega(scenario):
    rate = 4000.0
    log = simulate(scenario, noise=SensorErrors.none(), rate_hz=rate, duration_s=1.5)
    w, dw = log.truth.omega_b_radps, log.truth.omega_dot_b_radps2
    scale = max(np.abs(dw).max(), 1.0)
    np.testing.assert_allclose(fd4(w, 1 / rate), dw[2:-2], rtol=0, atol=2e-5 * scale)


@pytest.mark.parametrize("scenario", ANALYTIC + ["euroc"])
def test_attitude_integrates_omega(scenario):
    # finite differences: q̇ = ½ q ⊗ (0, ω)
    rate = 4000.0
    log = simulate(scenario, noise=SensorErrors.none(), rate_hz=rate, duration_s=1.0)
    q, w = log.truth.quaternion_wb, log.truth.omega_b_radps
    qdot = 0.5 * rotations.quaternion_multiply(q, np.concatenate([np.zeros((len(w), 1)), w], axis=1))
    np.testing.assert_allclose(fd4(q, 1 / rate), qdot[2:-2], rtol=0, atol=1e-6 * max(1.0, np.abs(w).max()))


def test_magnus_integrator_matches_solve_ivp_and_analytic_rotation():
    amp, freq, phase = (np.array([[2.0, 2.5, 3.0]]), np.array([[0.55, 0.75, 0.95]]), np.array([[0.0, 1.0, 2.0]]))

    def omega(t):
        return sum_of_sines(np.atleast_1d(t), amp, freq, phase)

    t = np.arange(0.0, 8.0, 0.002)
    q = integrate_attitude(omega, t, np.array([1.0, 0, 0, 0]))
    sol = solve_ivp(lambda tt, qq: 0.5 * rotations.quaternion_multiply(qq, np.r_[0.0, omega(tt)[0]]),
                    (0, t[-1]), [1.0, 0, 0, 0], t_eval=t, rtol=1e-13, atol=1e-13, method="DOP853")
    np.testing.assert_allclose(q, sol.y.T, atol=1e-9)
    # rotation about a fixed axis: the angle is the integral of the rate
    axis = np.array([1.0, -2.0, 0.5]) / np.linalg.norm([1.0, -2.0, 0.5])
    q = integrate_attitude(lambda tt: np.outer(3 * np.cos(2 * tt), axis), t, np.array([1.0, 0, 0, 0]))
    expected = rotations.quaternion_from_rotation_vector(np.outer(1.5 * np.sin(2 * t), axis))
    np.testing.assert_allclose(q, expected, atol=1e-11)


@pytest.mark.parametrize("build", [sc.turntable, sc.turntable_constant, sc.random3d, sc.reversal, sc.freeflight_minor])
def test_acceleration_is_second_derivative_of_position(build):
    h = 1 / 4000.0
    t = np.arange(0.0, 1.0, h)
    kin, _ = build(t, np.random.default_rng(3), cube_array())
    r = rotations.matrix_from_quaternion(kin.quaternion_wb)
    accel_w = np.einsum("nij,nj->ni", r, kin.accel_b_mps2)
    scale = max(np.abs(accel_w).max(), 1.0)
    np.testing.assert_allclose(fd4_second(kin.position_w_m, h), accel_w[2:-2], rtol=0, atol=1e-5 * scale)


def test_seed_changes_random_motion_and_noise_keeps_it():
    a = simulate("random3d", seed=1, duration_s=1.0)
    b = simulate("random3d", seed=1, duration_s=1.0)
    c = simulate("random3d", seed=2, duration_s=1.0)
    d = simulate("random3d", seed=1, duration_s=1.0, noise=SensorErrors.none())
    np.testing.assert_array_equal(a.accel_mps2, b.accel_mps2)
    np.testing.assert_array_equal(a.truth.omega_b_radps, d.truth.omega_b_radps)
    assert np.abs(a.truth.omega_b_radps - c.truth.omega_b_radps).max() > 0.1


# --- scenario geometry -----------------------------------------------------------------

def test_turntable_geometry_of_paper001():
    log = simulate("turntable", noise=SensorErrors.none(), duration_s=4.0)
    tr, t = log.truth, log.times_s
    assert log.rate_hz == pytest.approx(1000.0)
    r = rotations.matrix_from_quaternion(tr.quaternion_wb)
    axis_w = r[:, :, 2]  # body z is the rotation axis
    np.testing.assert_allclose(np.degrees(np.arccos(axis_w[:, 2])), 12.0, atol=1e-9)
    np.testing.assert_allclose(tr.omega_b_radps[:, :2], 0.0, atol=1e-15)
    # the turning angle relative to t = 0 is θ(t) = 23.5° sin(2π t)
    rel = rotations.rotation_vector_from_matrix(np.einsum("ji,njk->nik", r[0], r))
    np.testing.assert_allclose(np.degrees(rel[:, 2]), 23.5 * np.sin(2 * np.pi * t), atol=1e-9)
    spectrum = np.abs(np.fft.rfft(tr.omega_b_radps[:, 2]))
    assert np.fft.rfftfreq(len(t), 1e-3)[np.argmax(spectrum)] == pytest.approx(1.0)
    # origin 30 mm off the axis: a = ω̇ × d + ω × (ω × d) with |d| = 30 mm along −y
    wz, dwz = tr.omega_b_radps[:, 2], tr.omega_dot_b_radps2[:, 2]
    np.testing.assert_allclose(tr.accel_b_mps2, np.stack([0.03 * dwz, 0.03 * wz**2, 0 * wz], axis=1), atol=1e-12)


def test_turntable_constant_rate_and_inclinometer_convention():
    log = simulate("turntable-constant", array=paper001_array(), noise=SensorErrors.none(), duration_s=2.0)
    tr = log.truth
    np.testing.assert_allclose(tr.omega_b_radps[:, 2], np.pi, atol=1e-15)
    np.testing.assert_allclose(tr.accel_b_mps2[:, 1], 0.03 * np.pi**2, atol=1e-12)  # centripetal, towards the axis
    # a still accelerometer aligned with B reads g cos(tilt); here f − a is exactly the gravity part
    gravity_part = tr.specific_force_b_mps2 - tr.accel_b_mps2
    np.testing.assert_allclose(gravity_part[:, :2], G * np.cos(log.tilt_rad), atol=1e-12)
    # half a turn apart, body x swings between 12° - ... the tilt of x spans 90° ± 12°
    assert np.degrees(log.tilt_rad[:, 0]).min() == pytest.approx(78.0, abs=0.01)
    assert np.degrees(log.tilt_rad[:, 0]).max() == pytest.approx(102.0, abs=0.01)


def test_reversal_crosses_zero_on_every_axis_every_second_or_so():
    log = simulate("reversal", noise=SensorErrors.none())
    w = log.truth.omega_b_radps
    for axis, f in enumerate((0.55, 0.75, 0.95)):
        crossings = np.nonzero(np.diff(np.sign(w[:, axis])) != 0)[0]
        assert abs(crossings.size - 2 * f * 10.0) <= 1
        assert np.max(np.diff(log.times_s[crossings])) < 1.0
    assert np.abs(w).max() <= 3.0 + 1e-12


def test_random3d_amplitudes_like_a_hand_held_device():
    log = simulate("random3d", noise=SensorErrors.none())
    tr = log.truth
    assert log.rate_hz == pytest.approx(500.0) and len(log) == 5000
    np.testing.assert_allclose(np.sqrt(np.mean(tr.omega_b_radps**2, axis=0)), 1.5, rtol=0.35)
    assert 2.0 < np.linalg.norm(tr.omega_b_radps, axis=1).max() < 8.0
    assert 10.0 < np.abs(tr.omega_dot_b_radps2).max() < 80.0
    assert 2.0 < np.abs(tr.accel_b_mps2).max() < 40.0


def test_level_attitude_from_specific_force():
    f = np.array([9.0, 0.2, -3.7])
    r = rotations.matrix_from_quaternion(level_quaternion_from_specific_force(f))
    # the quaternion's matrix (a few roundings per entry) times a unit vector (3 more): 16 ε of order-1 values
    np.testing.assert_allclose(r @ (f / np.linalg.norm(f)), [0, 0, 1], atol=16 * np.finfo(float).eps)
    with pytest.raises(ValueError, match="no gravity"):
        level_quaternion_from_specific_force([0.0, 0.0, 0.0])


# --- sensor errors ---------------------------------------------------------------------

def test_white_noise_statistics_follow_the_array_and_seed():
    array = cube_array(0.05, noise_std_mps2=0.07)
    log = simulate("random3d", array=array, duration_s=20.0)
    resid = log.accel_mps2 - exact_readings(array, log.truth)
    assert resid.std() == pytest.approx(0.07, rel=0.02)
    np.testing.assert_allclose(resid.std(axis=0), 0.07, rtol=0.06)
    assert abs(resid.mean()) < 0.002
    again = simulate("random3d", array=array, duration_s=20.0)
    np.testing.assert_array_equal(log.accel_mps2, again.accel_mps2)
    other = simulate("random3d", array=array, duration_s=20.0, seed=5)
    assert (other.accel_mps2 - exact_readings(array, other.truth)).std() == pytest.approx(0.07, rel=0.02)
    assert not np.array_equal(other.accel_mps2, log.accel_mps2)


def test_default_noise_uses_adxl330_figures_when_array_gives_none():
    array = cube_array(0.05, noise_std_mps2=None)
    log = simulate("reversal", array=array, duration_s=20.0)
    resid = log.accel_mps2 - exact_readings(array, log.truth)
    std = resid.std(axis=0).reshape(4, 3)
    np.testing.assert_allclose(std[:, :2], ADXL330_NOISE_XY_MPS2, rtol=0.06)
    np.testing.assert_allclose(std[:, 2], ADXL330_NOISE_Z_MPS2, rtol=0.06)


def test_gyro_and_inclinometer_noise():
    array = mixed_array()
    log = simulate("turntable", array=array, duration_s=10.0)
    assert (log.gyro_b_radps - log.truth.omega_b_radps).std() == pytest.approx(0.02, rel=0.03)
    assert (log.tilt_rad - tilt_angles_rad(log.truth.quaternion_wb)).std() == pytest.approx(0.003, rel=0.03)
    resid = log.accel_mps2 - exact_readings(array, log.truth)
    assert resid[:, [0, 1, 2, 5]].std() == pytest.approx(0.05, rel=0.03)  # array.toml value
    assert resid[:, 3].std() == pytest.approx(ADXL330_NOISE_XY_MPS2, rel=0.05)  # b_x: none given
    assert resid[:, 4].std() == pytest.approx(ADXL330_NOISE_Z_MPS2, rel=0.05)  # b_z


def test_explicit_noise_level_is_applied_and_recorded_in_the_array():
    log = simulate("random3d", noise=SensorErrors.white(0.2), duration_s=10.0)
    resid = log.accel_mps2 - exact_readings(log.array, log.truth)
    assert resid.std() == pytest.approx(0.2, rel=0.02)
    np.testing.assert_array_equal(log.array.noise_std_per_axis_mps2, 0.2)


def test_bias_scale_quantisation_and_saturation():
    array = cube_array(0.05)
    exact = simulate("random3d", array=array, noise=SensorErrors.none(), duration_s=4.0).accel_mps2
    lsb = 0.01
    errs = SensorErrors(accel_noise_std_mps2=0.0, accel_bias_std_mps2=0.3, accel_scale_std=0.02,
                        accel_quantisation_mps2=lsb, accel_range_mps2=12.0)
    y = simulate("random3d", array=array, noise=errs, duration_s=4.0).accel_mps2
    assert np.abs(y).max() == pytest.approx(12.0) and np.abs(exact).max() > 12.0
    np.testing.assert_allclose(y / lsb, np.round(y / lsb), atol=1e-9)
    inside = np.abs(y) < 12.0 - 1e-9
    # per axis, the reading is (1 + k) x + b up to half an LSB (plus the fit's own error):
    # recover k and b by least squares
    for j in range(array.n_axes):
        m = inside[:, j]
        a = np.stack([exact[m, j], np.ones(m.sum())], axis=1)
        (gain, bias), *_ = np.linalg.lstsq(a, y[m, j], rcond=None)
        assert np.abs(a @ [gain, bias] - y[m, j]).max() <= 0.55 * lsb
        assert abs(gain - 1) < 0.1 and abs(bias) < 1.5
    assert np.std([np.mean(y[:, j] - exact[:, j]) for j in range(12)]) > 0.05  # biases differ per axis


def test_misalignment_tilts_each_axis_by_the_given_std():
    accs = tuple(Accelerometer(f"s{i}", [0.0, 0.0, 0.0]) for i in range(200))
    array = SensorArray(accs, "many")
    sigma = 0.01
    d = SensorErrors(accel_misalignment_std_rad=sigma).misaligned_directions_b(array, np.random.default_rng(0))
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, atol=8 * np.finfo(float).eps)  # a normalised vector
    angles = np.arccos(np.clip(np.sum(d * array.axis_directions_b, axis=1), -1, 1))
    # two independent perpendicular components: RMS angle σ √2
    assert np.sqrt(np.mean(angles**2)) == pytest.approx(sigma * np.sqrt(2), rel=0.08)


def test_none_is_exactly_noise_free_and_bad_settings_are_refused():
    assert SensorErrors.none().accel_noise_per_axis_mps2(cube_array()).max() == 0.0
    with pytest.raises(ValueError, match="accel_bias_std_mps2"):
        SensorErrors(accel_bias_std_mps2=-1.0)
    with pytest.raises(ValueError, match="accel_range_mps2"):
        SensorErrors(accel_range_mps2=0.0)
    lsb = SensorErrors.adxl330().accel_quantisation_mps2
    assert lsb == pytest.approx(20 / 65536 / 0.3 * G)


# --- interface -------------------------------------------------------------------------

def test_scenario_defaults_and_options():
    log = simulate("freeflight-major")
    assert len(log) == 2000 and log.rate_hz == pytest.approx(1000.0)
    log = simulate("reversal", rate_hz=250.0, duration_s=2.0)
    assert len(log) == 500 and log.rate_hz == pytest.approx(250.0)
    log = simulate("turntable", amplitude_deg=10.0, duration_s=1.0, noise=SensorErrors.none())
    assert np.abs(log.truth.omega_b_radps[:, 2]).max() == pytest.approx(np.radians(10) * 2 * np.pi, rel=1e-6)
    assert set(SCENARIOS) >= {"turntable", "turntable-constant", "random3d", "reversal", "freeflight-major",
                              "freeflight-intermediate", "freeflight-minor", "euroc", "kitti"}


def test_bad_requests_name_the_problem():
    with pytest.raises(ValueError, match="unknown scenario 'spin'.*random3d"):
        simulate("spin")
    with pytest.raises(ValueError, match=r"no option\(s\) \['tilt_deg'\].*omega_rms_radps"):
        simulate("random3d", tilt_deg=3.0)
    with pytest.raises(ValueError, match="rate_hz"):
        simulate("random3d", rate_hz=-5.0)
    with pytest.raises(ValueError, match="at least 2"):
        simulate("random3d", duration_s=0.001)
    with pytest.raises(ValueError, match="beyond the recording"):
        simulate("euroc", duration_s=31.0)


def test_timestamps_are_integer_nanoseconds_at_the_rate():
    t = sample_timestamps_ns(300.0, 1.0)
    assert t.dtype == np.int64 and t.size == 300
    np.testing.assert_array_equal(t[:4], [0, 3333333, 6666667, 10000000])
