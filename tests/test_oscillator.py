"""The driven-oscillator motion model ω̈ = -Ω² ω + white jerk: its exact step, its choice from
the data, and what it gives on periodic motion (turntable, reversal)."""

import gtsam
import numpy as np
import pytest
from dense_evidence import dense_log_evidence
from scipy.linalg import expm

from gfimu import factors as F
from gfimu.array import cube_array
from gfimu.factors import process
from gfimu.simulate import simulate
from gfimu.smoother.batch import engine as batch
from gfimu.smoother.stream.array_model import ArrayModel
from gfimu.smoother.batch.engine import BatchSmootherEstimator
from gfimu.smoother.model.problem import SmootherOptions, SmootherProblem
from gfimu.smoother.solve.initialise import initial_states
from gfimu.smoother.tuning.evidence import Tuning, dominant_frequency_hz, linearised_log_evidence

CUBE_5CM = cube_array(0.025, noise_std_mps2=0.07)  # 5 cm edge
RNG = np.random.default_rng(11)


def omega_rmse(motion, truth):
    return float(np.sqrt(np.mean(np.sum((motion.omega_b_radps - truth.omega_b_radps) ** 2, axis=1))))


def van_loan(q, h, omega):
    """Transition and noise covariance of x' = F x + e₂ w for one axis, by the matrix exponential."""
    Fm = np.array([[0.0, 1.0], [-omega**2, 0.0]])
    Qc = np.array([[0.0, 0.0], [0.0, q * q]])
    M = np.block([[-Fm, Qc], [np.zeros((2, 2)), Fm.T]]) * h
    E = expm(M)
    phi = E[2:, 2:].T
    return phi, phi @ E[:2, 2:]


@pytest.mark.parametrize("omega_radps", [0.0, 1e-3, 0.3, 6.283, 40.0, 400.0])
def test_step_transition_and_covariance_match_the_matrix_exponential(omega_radps):
    h, q = 0.002, 7.0
    phi = process.oscillator_transition(h, [omega_radps] * 3)[0, 0]
    cov = process.oscillator_covariance(q, h, [omega_radps] * 3)[0, 0]
    phi_ref, cov_ref = van_loan(q, h, omega_radps)
    np.testing.assert_allclose(phi, phi_ref, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(cov, cov_ref, rtol=1e-9, atol=0)
    if omega_radps == 0.0:  # white jerk
        np.testing.assert_allclose(cov, q * q * np.array([[h**3 / 3, h**2 / 2], [h**2 / 2, h]]), rtol=1e-14)


def test_a_sinusoid_at_the_natural_frequency_leaves_no_residual():
    om = np.array([2 * np.pi * 1.0, 2 * np.pi * 0.55, 0.0])
    t = np.linspace(0.0, 3.0, 301)
    h = np.diff(t)
    w = np.column_stack([2.0 * np.cos(om[0] * t + 0.3), 1.5 * np.sin(om[1] * t), 0.7 + 0.2 * t])
    d = np.column_stack([-2.0 * om[0] * np.sin(om[0] * t + 0.3), 1.5 * om[1] * np.cos(om[1] * t), np.full_like(t, 0.2)])
    r, _ = process.oscillator_residual(w[:-1], w[1:], d[:-1], d[1:], h, om)
    assert np.max(np.abs(r)) < 1e-12


def test_oscillator_jacobians_and_custom_factor():
    om = np.array([3.0, 0.0, 9.0])
    args = [RNG.normal(size=(4, 3)) for _ in range(4)]
    h = np.full(4, 0.004)
    r, jac = process.oscillator_residual(*args, h, om)
    eps = 1e-6
    for i, name in enumerate(("w0", "w1", "d0", "d1")):
        for c in range(3):
            plus = [a.copy() for a in args]
            minus = [a.copy() for a in args]
            plus[i][:, c] += eps
            minus[i][:, c] -= eps
            num = (process.oscillator_residual(*plus, h, om)[0] - process.oscillator_residual(*minus, h, om)[0]) / (2 * eps)
            np.testing.assert_allclose(jac[name][:, :, c], num, atol=1e-8)
    keys = [F.omega_key(0), F.omega_key(1), F.omega_dot_key(0), F.omega_dot_key(1)]
    values = gtsam.Values()
    for k, a in zip(keys, args):
        values.insert(k, a[0])
    factor = process.make_oscillator_factor(*keys, 0.004, om, gtsam.noiseModel.Unit.Create(6))
    np.testing.assert_allclose(factor.unwhitenedError(values), r[0], atol=1e-14)
    lin = factor.linearize(values)
    A = np.hstack([lin.jacobian()[0][:, 3 * i:3 * i + 3] for i in range(4)])
    np.testing.assert_allclose(A, np.hstack([jac[n][0] for n in ("w0", "w1", "d0", "d1")]), atol=1e-14)


@pytest.fixture(scope="module")
def turntable_log():
    return simulate("turntable", CUBE_5CM, rate_hz=500.0, duration_s=6.0, seed=1)


@pytest.mark.slow
def test_graph_path_equals_fast_path_with_the_oscillator(turntable_log):
    log = turntable_log.select(slice(0, 150))
    opt = SmootherOptions(process_axis_frequencies_hz=(0.0, 0.8, 1.0), process_axis_factors=(1.0, 0.1, 0.01),
                          relative_tolerance=1e-16, max_iterations=50)
    problem = SmootherProblem.of(log, opt)
    x0 = initial_states(log, opt.model_groups)
    fast = batch.solve(problem, x0, method="gn")
    states, _ = batch.solve_with_gtsam(problem, x0, iterations=30, tolerance=0.0)
    np.testing.assert_allclose(states, fast.states, atol=5e-8)
    graph = problem.gtsam_graph()
    assert graph.error(problem.gtsam_values(states, np.zeros(0))) == pytest.approx(problem.cost(fast.states, fast.params), rel=1e-9)


def test_evidence_with_the_oscillator_equals_the_dense_gaussian_integral():
    log = simulate("reversal", CUBE_5CM, rate_hz=500.0, duration_s=0.06, seed=3)
    problem = SmootherProblem.of(log, SmootherOptions(omega_dot_random_walk_radps2_per_sqrt_s=12.0, process_axis_factors=(0.5, 1.0, 2.0),
                                                   process_axis_frequencies_hz=(0.55, 0.0, 3.0)))
    x = initial_states(log, problem.options) + 0.01
    dense = dense_log_evidence(problem, x)
    assert linearised_log_evidence(problem, x) == pytest.approx(dense, abs=1e-6 * abs(dense))


def test_dominant_frequency():
    t = np.arange(5000) / 500.0
    rng = np.random.default_rng(0)
    x = 2.0 * np.sin(2 * np.pi * 1.234 * t + 0.4) + rng.normal(size=t.size) * 0.3
    assert dominant_frequency_hz(x, 500.0, 0.2, 25.0, min_share=0.8) == pytest.approx(1.234, rel=1e-3)
    # two equal lines: neither holds 80 % of the power
    y = np.sin(2 * np.pi * 0.7 * t) + np.sin(2 * np.pi * 1.9 * t)
    assert dominant_frequency_hz(y, 500.0, 0.2, 25.0, min_share=0.8) is None
    assert dominant_frequency_hz(y, 500.0, 0.2, 25.0) is not None
    # a peak only at the edge of the band is no peak
    assert dominant_frequency_hz(np.sin(2 * np.pi * 0.1 * t), 500.0, 0.2, 25.0) is None


def test_tuner_finds_the_turntable_frequency_and_beats_20_mrad(turntable_5cm_smoother):
    """Lu, Tsai & Lin 2010's 1 Hz turntable on a 5 cm cube: z oscillates at 1 Hz, x and y do not move."""
    log, report, m = turntable_5cm_smoother
    t = report.tunings[0]
    assert t.axis_frequencies_hz[:2] == (0.0, 0.0), t
    assert t.axis_frequencies_hz[2] == pytest.approx(1.0, rel=2e-3), t
    assert 0 < t.axis_frequency_std_hz[2] < 2e-3 and t.axis_amplitude_radps[2] == pytest.approx(np.deg2rad(23.5) * 2 * np.pi, rel=0.02)
    rmse = omega_rmse(m, log.truth)
    plain = omega_rmse(BatchSmootherEstimator(tune_axis_frequencies=False).estimate(log).motion, log.truth)
    assert rmse < 0.02 and rmse < 0.8 * plain, (rmse, plain)
    z = float(np.sqrt(np.mean((m.omega_b_radps[:, 2] - log.truth.omega_b_radps[:, 2]) ** 2)))
    assert z < 0.006, z


def test_reversal_frequencies_and_accuracy():
    log = simulate("reversal", CUBE_5CM, rate_hz=500.0, duration_s=6.0, seed=2)
    estimate = BatchSmootherEstimator().estimate(log)
    m = estimate.motion
    np.testing.assert_allclose(estimate.report.tunings[0].axis_frequencies_hz, (0.55, 0.75, 0.95), rtol=2e-3)
    assert omega_rmse(m, log.truth) < 0.012
    big = np.abs(log.truth.omega_b_radps) > 0.1
    assert np.all(np.sign(m.omega_b_radps[big]) == np.sign(log.truth.omega_b_radps[big]))


@pytest.mark.slow
def test_random_motion_keeps_the_white_jerk():
    """Band-limited random motion has no dominant line: no oscillator, same result as without."""
    log = simulate("random3d", CUBE_5CM, rate_hz=500.0, duration_s=10.0, seed=1)
    estimate = BatchSmootherEstimator().estimate(log)
    m = estimate.motion
    assert estimate.report.tunings[0].axis_frequencies_hz == (0.0, 0.0, 0.0)
    np.testing.assert_allclose(m.omega_b_radps, BatchSmootherEstimator(tune_axis_frequencies=False).estimate(log).motion.omega_b_radps)


def test_stream_density_floor():
    """``for_stream`` raises an oscillator axis's density to √(2τ) A Ω δΩ, leaves the others."""
    t = Tuning("jerk", 2.0, 1.0, 0.0, 1, (1e-4, 0.5, 1e-5), 0.3, (0.0, 0.0, 1.0), (0.0, 0.0, 1e-3), (0.0, 0.0, 2.5))
    model = t.apply(SmootherOptions().model_groups).model
    out = t.for_stream(model)
    floor = np.sqrt(2.0) * 2.5 * (2 * np.pi) * (2 * np.pi * 1e-3)
    assert out.process_axis_factors[:2] == (1e-4, 0.5)
    assert out.process_axis_factors[2] * 2.0 == pytest.approx(floor, rel=1e-12)
    assert out.process_axis_frequencies_hz == (0.0, 0.0, 1.0)


@pytest.mark.parametrize("fast", [True, False])
def test_fixed_lag_model_adds_the_oscillator_step(fast):
    opt = SmootherOptions(process_axis_frequencies_hz=(0.0, 2.0, 0.5), process_axis_factors=(1.0, 0.1, 0.01))
    model = ArrayModel(CUBE_5CM, opt.model_groups, fast_measurement=fast)
    graph = gtsam.NonlinearFactorGraph()
    model.add_process(graph, 0, 1, 0.002)
    assert graph.size() == 1  # oscillator step and specific-force random walk, one factor of the step's rows
    from gfimu.smoother.stream.array_model import keys

    values = gtsam.Values()
    states = [RNG.normal(size=(3, 3)) for _ in range(2)]
    for k in range(2):
        for key, v in zip(keys(k), states[k]):
            values.insert(key, v)
    r, _ = process.oscillator_residual(states[0][0], states[1][0], states[0][1], states[1][1], 0.002,
                                       2 * np.pi * np.array([0.0, 2.0, 0.5]))
    cov = process.oscillator_step_covariance(opt.omega_dot_random_walk_radps2_per_sqrt_s, 0.002,
                                             2 * np.pi * np.array([0.0, 2.0, 0.5]), (1.0, 0.1, 0.01))[0]
    s_f = process.random_walk_sigma(opt.specific_force_random_walk_mps2_per_sqrt_s, 0.002)
    walk = 0.5 * np.sum(((states[1][2] - states[0][2]) / s_f) ** 2)
    assert graph.at(0).error(values) == pytest.approx(0.5 * r[0] @ np.linalg.solve(cov, r[0]) + walk, rel=1e-9)
    # the transition the numpy engine predicts with: the oscillator's Φ, its covariance
    step = model.step(0.002)
    phi = process.oscillator_transition(0.002, 2 * np.pi * np.array([0.0, 2.0, 0.5]))[0]
    for i in range(3):
        np.testing.assert_allclose(step.F[np.ix_([i, 3 + i], [i, 3 + i])], phi[i], atol=1e-12)
    np.testing.assert_allclose(step.Q[:6, :6], cov, rtol=1e-8, atol=1e-14)
