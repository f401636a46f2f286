"""The groups that add their normal equations in closed form (FactorGroup.accumulate: accelerometers,
white-jerk motion model, specific-force walk) give the same JᵀJ, Jᵀr, cost and row count as their
Jacobians from ``terms``, with uneven steps and robust weights."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from gfimu.array import cube_array
from gfimu.simulate import simulate
from gfimu.smoother.solve.banded import normal_equations, robust_reweighted
from gfimu.smoother.model.problem import SmootherOptions, SmootherProblem
from gfimu.smoother.model.groups import AccelerometerGroup, MotionModelGroup, SpecificForceWalkGroup


def _uneven(log):
    """The log with jittered timestamps (steps 1.5 to 2.5 ms) and one gap."""
    rng = np.random.default_rng(11)
    steps = rng.uniform(1.5e6, 2.5e6, len(log) - 1).astype(np.int64)
    steps[len(steps) // 2] = 40_000_000
    return replace(log, timestamps_ns=log.timestamps_ns[0] + np.concatenate([[0], np.cumsum(steps)]))


@pytest.mark.parametrize("robust", [False, True])
def test_closed_form_normal_equations_match_the_jacobians(robust):
    log = _uneven(simulate("random3d", cube_array(0.05, 0.07), rate_hz=500.0, duration_s=0.6, seed=4))
    options = SmootherOptions(process_axis_factors=(1.0, 3.0, 0.2))
    if robust:
        options = replace(options, process_robust_threshold=1.0, accel_robust_threshold=2.0, robust_loss="cauchy")
    problem = SmootherProblem.of(log, options)
    rng = np.random.default_rng(5)
    states = rng.normal(scale=[3.0] * 3 + [30.0] * 3 + [5.0] * 3, size=(len(log), 9))
    params = np.zeros(problem.n_global)
    if robust:
        problem = robust_reweighted(problem, states, params)
    closed = [g for g in problem.groups if isinstance(g, (AccelerometerGroup, MotionModelGroup, SpecificForceWalkGroup))]
    assert len(closed) == 3
    assert (problem.noise.accel.per_sample is not None) == robust  # per-sample whitening, or one for all
    m = problem.state_size
    for group in closed:
        diag, lower, grad = np.zeros((len(log), m, m)), np.zeros((len(log) - 1, m, m)), np.zeros((len(log), m))
        half_cost, rows = group.accumulate(problem, states, params, diag, lower, grad)
        terms = group.terms(problem, states, params)
        ref = normal_equations(problem, states, params, terms)
        scale = np.abs(ref.diag).max()
        np.testing.assert_allclose(diag, ref.diag, rtol=0, atol=1e-13 * scale)
        np.testing.assert_allclose(lower, ref.lower, rtol=0, atol=1e-13 * scale)
        np.testing.assert_allclose(grad, ref.grad, rtol=0, atol=1e-13 * np.abs(ref.grad).max())
        assert half_cost == pytest.approx(ref.cost, rel=1e-13)
        assert rows == ref.rows
        assert 2 * half_cost == pytest.approx(group.squared_norm(problem, states, params), rel=1e-13)
    # and the whole system: closed forms where they exist, Jacobians for the rest
    whole = normal_equations(problem, states, params)
    ref = normal_equations(problem, states, params, problem.terms(states, params))
    np.testing.assert_allclose(whole.diag, ref.diag, rtol=0, atol=1e-13 * np.abs(ref.diag).max())
    np.testing.assert_allclose(whole.grad, ref.grad, rtol=0, atol=1e-13 * np.abs(ref.grad).max())
    assert whole.cost == pytest.approx(ref.cost, rel=1e-13)
    assert whole.cost == pytest.approx(problem.cost(states, params), rel=1e-13)


def test_calibrated_accelerometers_keep_their_jacobians():
    log = simulate("random3d", cube_array(0.05, 0.07), rate_hz=500.0, duration_s=0.2, seed=4)
    problem = SmootherProblem.of(log, SmootherOptions(self_calibrate_bias=True))
    m, n = problem.state_size, len(log)
    out = problem.group(AccelerometerGroup).accumulate(problem, np.zeros((n, m)), np.zeros(problem.n_global), np.zeros((n, m, m)),
                                                       np.zeros((n - 1, m, m)), np.zeros((n, m)))
    assert out is None


def test_other_motion_models_keep_their_jacobians():
    log = simulate("random3d", cube_array(0.05, 0.07), rate_hz=500.0, duration_s=0.2, seed=4)
    for options in (SmootherOptions(motion_model="snap"), SmootherOptions(process_axis_frequencies_hz=(2.0, 0.0, 0.0))):
        problem = SmootherProblem.of(log, options)
        m = problem.state_size
        states = np.zeros((len(log), m))
        out = problem.group(MotionModelGroup).accumulate(problem, states, np.zeros(0), np.zeros((len(log), m, m)),
                                                         np.zeros((len(log) - 1, m, m)), np.zeros((len(log), m)))
        assert out is None
