"""The smoother's model as one list of factor groups (gfimu.smoother.model.groups) gives the numbers of the
model written out in SmootherProblem before it: cost, log-normaliser and a Levenberg-Marquardt solve
on short simulated logs for every motion model, measurement and optional group, to 1e-9. The
reference values were computed by that earlier code. Each group's Jacobian is also checked against
numerical derivatives, its GTSAM factors against its vectorised residuals, and the fixed-lag
smoother's own per-sample factors against the groups."""

from __future__ import annotations

import numpy as np
import pytest

from gfimu.array import cube_array, paper001_array
from gfimu.factors import so3 as _so3
from gfimu.rotations import matrix_from_quaternion
from gfimu.simulate import simulate
from gfimu.smoother.model import groups
from gfimu.smoother.solve.banded import solve
from gfimu.smoother.model.problem import SmootherOptions, SmootherProblem
from gfimu.smoother.tuning.evidence import log_normaliser

REFERENCE = {  # cost at the test states, Σ log σ, cost and iterations of the solve, ω at the middle sample
    "jerk": [809793.0275842558, -2506.875049544373, 58.18048768428306, 4.0, -1.5883261407558473, -0.4907107319125135, 0.34736386538685776],
    "snap": [125559200171.8545, -3724.36367228765, 72.78545117691768, 4.0, -1.5899545817813878, -0.48923726767608183, 0.3458880225509655],
    "oscillator": [429450.5629435622, -2506.8776287944, 59.243354002455206, 4.0, -1.590646787075927, -0.4815339981617914, 0.3466851497266845],
    "quadratic": [429471.4809706049, -1678.6559118650357, 139.906648363388, 4.0, -1.5916559773932155, -0.48914833491042675, 0.3468702454202093],
    "calibration": [432664.7435261324, -2450.306294857308, 68.37747937606387, 4.0, -0.006726201043952073, -0.012504913427861471, 2.4525496504140767],
    "inclinometer": [171549730.39008102, -4488.941927263389, 125.42445601092504, 4.0, 0.0032547156747772376, -0.000357951183040578, 2.452374036341833],
    "free flight": [3673823.6146922354, -3583.764963884233, 7.693110969749316, 3.0, 0.3043125837344564, 27.403469153635147, 0.3152752679292005],
}


def case(name):
    if name == "free flight":
        return simulate("freeflight-intermediate", seed=1, duration_s=0.05), SmootherOptions(free_flight=True)
    if name in ("calibration", "inclinometer"):
        log = simulate("turntable", paper001_array(), rate_hz=500.0, duration_s=0.1, seed=3)
        if name == "calibration":
            return log, SmootherOptions(self_calibrate_bias=True, self_calibrate_scale=True)
        return log, SmootherOptions(use_inclinometer=True)
    log = simulate("random3d", cube_array(0.05), rate_hz=500.0, duration_s=0.1, seed=5)
    return log, {
        "jerk": SmootherOptions(process_axis_factors=(0.5, 1.0, 2.0)),
        "snap": SmootherOptions(motion_model="snap", process_axis_factors=(0.5, 1.0, 2.0)),
        "oscillator": SmootherOptions(process_axis_frequencies_hz=(0.0, 2.0, 1.0)),
        "quadratic": SmootherOptions(measurement="quadratic"),
    }[name]


def test_states(log, problem):
    """The truth in the problem's layout, perturbed."""
    t = log.truth
    x = problem.layout.resize(np.hstack([t.omega_b_radps, t.omega_dot_b_radps2, t.specific_force_b_mps2]))
    if problem.layout.attitude:
        x[:, problem.layout.rotation] = _so3.log(matrix_from_quaternion(t.quaternion_wb))
    return x + 0.05 * np.random.default_rng(1).normal(size=x.shape)


test_states.__test__ = False


@pytest.mark.parametrize("name", list(REFERENCE))
def test_the_model_of_groups_gives_the_earlier_numbers(name):
    log, opt = case(name)
    problem = SmootherProblem.of(log, opt)
    x = test_states(log, problem)
    p = 0.01 * np.ones(problem.n_global)
    got = [problem.cost(x, p), log_normaliser(problem)]
    if name != "free flight":
        problem = problem.with_noise(accel=problem.noise.accel.motion_dependent(x[:, :3], 0.05))
    res = solve(problem, x, p)
    got += [res.cost, float(res.iterations), *res.states[len(log) // 2, :3]]
    np.testing.assert_allclose(got, REFERENCE[name], rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("name", list(REFERENCE))
def test_every_group_jacobian_and_gtsam_factors_agree(name):
    """Each group: analytic Jacobian = central differences of its whitened residual (on the manifold for
    the attitude), and its GTSAM factors' error = half its squared residual norm."""
    log, opt = case(name)
    problem = SmootherProblem.of(log.select(slice(0, 6)), opt)
    x = test_states(log, problem)[:6]
    p = 0.01 * np.ones(problem.n_global)
    values = problem.gtsam_values(x, p)
    assert {type(g) for g in problem.groups} >= {groups.FirstStatePriorGroup, groups.MotionModelGroup}
    N, M = x.shape
    for group in problem.groups:
        terms = group.terms(problem, x, p)
        eps = 1e-6
        for ti, t in enumerate(terms):
            n, r = t.residual.shape
            dense = np.zeros((n, r, N, M))  # d residual[k] / d x[j] from the term's blocks
            for k in range(n):
                if t.kind == "unary" and "x" in t.jac:
                    dense[k, :, t.first + k] = t.jac["x"][k]
                elif t.kind == "binary":
                    dense[k, :, k], dense[k, :, k + 1] = t.jac["x0"][k], t.jac["x1"][k]
            num = np.zeros_like(dense)
            for j in range(N):
                for i in range(M):
                    d = np.zeros_like(x)
                    d[j, i] = eps
                    plus = group.terms(problem, problem.retract(x, d), p)[ti].residual
                    minus = group.terms(problem, problem.retract(x, -d), p)[ti].residual
                    num[:, :, j, i] = (plus - minus) / (2 * eps)
            np.testing.assert_allclose(num, dense, rtol=1e-5, atol=1e-6 * (1 + np.max(np.abs(dense))), err_msg=group.name)
            if t.jac_global is not None:
                for i in range(problem.n_global):
                    d = np.zeros_like(p)
                    d[i] = eps
                    num = (group.terms(problem, x, p + d)[ti].residual - group.terms(problem, x, p - d)[ti].residual) / (2 * eps)
                    np.testing.assert_allclose(num, t.jac_global[:, :, i], rtol=1e-5, atol=1e-8, err_msg=group.name)
        half = 0.5 * sum(float(np.sum(t.residual**2)) for t in terms)
        graph_error = sum(f.error(values) for f in group.gtsam_factors(problem))
        assert graph_error == pytest.approx(half, rel=1e-9, abs=1e-12), group.name


@pytest.mark.parametrize("fast", [True, False])
@pytest.mark.parametrize("options", [
    SmootherOptions(process_axis_factors=(0.5, 1.0, 2.0)),
    SmootherOptions(process_axis_frequencies_hz=(0.0, 2.0, 1.0)),
    SmootherOptions(use_gyro=False),
], ids=["jerk", "oscillator", "no gyroscope"])
def test_the_fixed_lag_stream_is_the_batch_model(options, fast):
    """The fixed-lag smoother's own factors (measurement, gyroscope, process step, first-state priors) have
    the error of the batch model's groups on the same three samples."""
    import gtsam

    from gfimu.smoother.stream import array_model as model

    log = simulate("turntable", paper001_array(), rate_hz=500.0, duration_s=0.1, seed=3).select(slice(10, 13))
    problem = SmootherProblem.of(log, options)
    x = test_states(log, problem)
    am = model.ArrayModel(log.array, options.model_groups, fast_measurement=fast)
    graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
    am.add_priors(graph, 0)
    for k in range(3):
        gyro = log.gyro_b_radps[k] if problem.use_gyro else None
        am.add_measurement(graph, k, log.accel_mps2[k], gyro)
        if k:
            am.add_process(graph, k - 1, k, float(log.dt_s[k - 1]))
        model.insert_state(values, k, x[k, 0:3], x[k, 3:6], x[k, 6:9])
    assert {type(g) for g in problem.groups} == ({groups.AccelerometerGroup, groups.FirstStatePriorGroup, groups.SpecificForceWalkGroup,
                                                  groups.MotionModelGroup} | ({groups.GyroscopeGroup} if options.use_gyro else set()))
    assert graph.error(values) == pytest.approx(problem.cost(x, np.zeros(0)), rel=1e-9)
