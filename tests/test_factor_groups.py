"""A factor group added from outside reaches every consumer of the model: the batch solver, the
GTSAM graph, the noise tuner's evidence, the bound and the fixed-lag smoother with both its engines
(this file is the only one it touches)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from gfimu.array import paper001_array
from gfimu.factors import diagonal_noise, omega_key, process
from gfimu.methods import make_estimator
from gfimu.simulate import simulate
from gfimu.smoother.batch.bound import smoother_bound
from gfimu.smoother.model.problem import SmootherOptions, SmootherProblem
from gfimu.smoother.model.groups import FactorGroup, Term
from gfimu.smoother.model.layout import OMEGA
from gfimu.smoother.tuning.evidence import log_normaliser


class ZeroRatePrior(FactorGroup):
    """ω = 0 with std ``sigma_radps`` at the samples with timestamps in [start_ns, stop_ns)."""

    name = "zero rate"

    def __init__(self, start_ns: int, stop_ns: int, sigma_radps: float):
        self.start_ns, self.stop_ns, self.sigma = start_ns, stop_ns, sigma_radps

    def _span(self, problem) -> tuple[int, int]:
        t = problem.log.timestamps_ns
        return int(np.searchsorted(t, self.start_ns)), int(np.searchsorted(t, self.stop_ns))

    def applies(self, problem) -> bool:
        k0, k1 = self._span(problem)
        return k1 > k0

    def terms(self, problem, states, params):
        k0, k1 = self._span(problem)
        J = np.zeros((k1 - k0, 3, problem.layout.size))
        J[:, :, OMEGA] = np.eye(3) / self.sigma
        return [Term("unary", states[k0:k1, OMEGA] / self.sigma, {"x": J}, None, first=k0)]

    def gtsam_factors(self, problem):
        k0, k1 = self._span(problem)
        noise = diagonal_noise(np.full(3, self.sigma))
        return [process.make_prior_factor(omega_key(k), np.zeros(3), noise) for k in range(k0, k1)]

    def log_normaliser(self, problem):
        k0, k1 = self._span(problem)
        return 3 * (k1 - k0) * float(np.log(self.sigma))


@pytest.fixture(scope="module")
def spinning():
    log = simulate("turntable-constant", duration_s=0.25, seed=2)
    t = log.timestamps_ns
    group = ZeroRatePrior(int(t[100]), int(t[150]), 1e-4)
    return log, group


@pytest.mark.slow
def test_batch_and_gtsam_solvers_both_use_the_group(spinning):
    log, group = spinning
    inside = slice(100, 150)
    plain = make_estimator("smoother", tune_process_noise=False).estimate(log)
    assert np.min(np.linalg.norm(plain.motion.omega_b_radps[inside], axis=1)) > 1.0  # it spins
    a = make_estimator("smoother", tune_process_noise=False, factor_groups=(group,)).estimate(log)
    b = make_estimator("smoother", tune_process_noise=False, factor_groups=(group,), solver="gtsam").estimate(log)
    assert np.max(np.abs(a.motion.omega_b_radps[inside])) < 1e-3  # the prior holds ω at zero there
    assert a.report.guard.note.startswith("not checked: the smoother uses factor groups")  # the guard leaves it
    np.testing.assert_allclose(b.motion.omega_b_radps, a.motion.omega_b_radps, atol=1e-6)
    assert b.report.cost == pytest.approx(a.report.cost, rel=1e-8)


def test_tuner_and_bound_use_the_group(spinning):
    log, group = spinning
    opt = SmootherOptions()
    with_group = replace(opt, factor_groups=(group,))
    diff = log_normaliser(SmootherProblem.of(log, with_group)) - log_normaliser(SmootherProblem.of(log, opt))
    assert diff == pytest.approx(3 * 50 * np.log(1e-4))
    tuned = make_estimator("smoother", factor_groups=(group,), auto_model=False).estimate(log)  # the likelihood tuner
    assert len(tuned.report.tunings) == 1 and np.isfinite(tuned.report.tunings[0].log_evidence)
    sd = smoother_bound(log, with_group.model_groups, with_group.batch).sigma["omega_b_radps"]
    sd0 = smoother_bound(log, opt.model_groups, opt.batch).sigma["omega_b_radps"]
    assert np.max(sd[125]) < 1.1e-4 < np.min(sd0[125])


@pytest.fixture(scope="module")
def with_gyro():
    """Lu, Tsai & Lin 2010's array (gyroscope and accelerometers) turning at π rad/s; the prior holds ω at 0 over
    samples 150-174 (50 ms), where the gyroscope and the accelerometers say it spins."""
    log = simulate("turntable-constant", paper001_array(), rate_hz=500.0, duration_s=0.6, seed=2)
    t = log.timestamps_ns
    return log, ZeroRatePrior(int(t[150]), int(t[175]), 1e-4)


def omega_with_and_without(log, group, method, **options):
    with_group = make_estimator(method, tune_process_noise=False, factor_groups=(group,), **options).estimate(log)
    plain = make_estimator(method, tune_process_noise=False, **options).estimate(log)
    return with_group.motion.omega_b_radps, plain.motion.omega_b_radps


@pytest.mark.parametrize("engine", ["numpy", "gtsam"])
def test_fixed_lag_engines_use_the_group(with_gyro, engine):
    log, group = with_gyro
    lag_n = 25  # lag_s = 0.05 s at 500 Hz
    # hold_max_s=0: each state is final at the lag (a held start would be re-solved with the group's rows)
    a, plain = omega_with_and_without(log, group, "fixed-lag", engine=engine, lag_s=0.05, hold_max_s=0.0)
    inside = slice(150, 175)
    assert np.min(np.linalg.norm(plain[inside], axis=1)) > 3.1  # it spins
    assert np.max(np.linalg.norm(a[inside], axis=1)) < 5e-3  # the prior holds ω at zero there (gyroscope against it)
    # a state is final once it leaves the window: those that left before the interval came are untouched
    np.testing.assert_array_equal(a[:150 - lag_n], plain[:150 - lag_n])
    assert np.max(np.linalg.norm(a[150 - lag_n:150], axis=1) - np.linalg.norm(plain[150 - lag_n:150], axis=1)) < 0  # pulled down
    # 0.2 s after the interval the estimate is back on the measurements
    assert np.max(np.linalg.norm(a[275:] - plain[275:], axis=1)) < 2e-3


def test_batch_uses_the_group_as_the_fixed_lag_does(with_gyro):
    """(The GTSAM graph: test_batch_and_gtsam_solvers_both_use_the_group.)"""
    log, group = with_gyro
    a, plain = omega_with_and_without(log, group, "smoother")
    assert np.max(np.linalg.norm(a[150:175], axis=1)) < 5e-3
    d = np.linalg.norm(a - plain, axis=1)
    assert d[:50].max() < 2e-3 and d[275:].max() < 2e-3 and d[150:175].min() > 3.1  # 0.2 s away: unchanged
    f, _ = omega_with_and_without(log, group, "fixed-lag", lag_s=0.05)
    np.testing.assert_allclose(f[150:175], a[150:175], atol=5e-3)


class SpanMean(ZeroRatePrior):
    """Not per sample: the mean of ω over the span (one row on many states)."""

    name = "span mean"
    per_sample = False


def test_fixed_lag_refuses_groups_that_are_not_per_sample(spinning):
    log, group = spinning
    assert make_estimator("fixed-lag", factor_groups=(group,)).applicable(log.array) is None
    reason = make_estimator("fixed-lag", factor_groups=(SpanMean(0, 1, 1.0),)).applicable(log.array)
    assert reason is not None and "span mean" in reason and "per_sample" in reason


class ZeroRatePriorWithSetup(ZeroRatePrior):
    """The same prior with its noise level given by :meth:`noise`, as the model's groups do."""

    def noise(self, problem):
        return self.sigma  # read back as problem.noise.of(self)

    def terms(self, problem, states, params):
        assert problem.noise.of(self) == self.sigma
        return super().terms(problem, states, params)


def test_fixed_lag_sets_the_group_up_on_each_sample(with_gyro):
    log, group = with_gyro
    same = ZeroRatePriorWithSetup(group.start_ns, group.stop_ns, group.sigma)
    a = make_estimator("fixed-lag", tune_process_noise=False, lag_s=0.05, factor_groups=(group,)).estimate(log)
    b = make_estimator("fixed-lag", tune_process_noise=False, lag_s=0.05, factor_groups=(same,)).estimate(log)
    np.testing.assert_array_equal(b.motion.omega_b_radps, a.motion.omega_b_radps)


class DeltaAngle(FactorGroup):
    """A measurement that ties two samples, defined here alone: the angle increments of a rate-integrating
    sensor sampled with the array, ``Δθ_k = h (ω_k + ω_{k+1}) / 2`` between samples k and k+1 (std
    ``sigma_rad``), for the steps that start at ``times_ns``."""

    name = "delta angle"
    per_sample = False
    steps = True

    def __init__(self, times_ns: np.ndarray, increments_rad: np.ndarray, sigma_rad: float):
        self.index = {int(t): i for i, t in enumerate(times_ns)}
        self.increments, self.sigma = np.asarray(increments_rad, dtype=float), sigma_rad

    def _steps(self, problem) -> tuple[np.ndarray, np.ndarray]:
        """(steps with an increment, its row in ``increments``)."""
        t = problem.log.timestamps_ns if hasattr(problem, "log") else problem.timestamps_ns
        pairs = [(k, self.index[int(t[k])]) for k in range(len(t) - 1) if int(t[k]) in self.index]
        k, i = np.array(pairs, dtype=int).reshape(-1, 2).T
        return k, i

    def applies(self, problem) -> bool:
        return self._steps(problem)[0].size > 0

    def noise(self, problem):
        return self.sigma

    def terms(self, problem, states, params):
        k, i = self._steps(problem)
        n, m, s = problem.n, problem.layout.size, problem.noise.of(self)
        r = np.zeros((n - 1, 3))
        J0, J1 = np.zeros((n - 1, 3, m)), np.zeros((n - 1, 3, m))
        h = problem.dt_s[k][:, None]
        r[k] = (0.5 * h * (states[k, OMEGA] + states[k + 1, OMEGA]) - self.increments[i]) / s
        J0[k, :, OMEGA] = J1[k, :, OMEGA] = (0.5 * h[:, :, None] * np.eye(3)) / s
        return [Term("binary", r, {"x0": J0, "x1": J1})]

    def gtsam_factors(self, problem):
        import gtsam

        out = []
        for k, i in zip(*self._steps(problem)):
            h, z = float(problem.dt_s[k]), self.increments[i]

            def error(this, values, jacobians, h=h, z=z, k=int(k)):
                if jacobians is not None:
                    jacobians[0] = jacobians[1] = 0.5 * h * np.eye(3)
                return 0.5 * h * (values.atVector(omega_key(k)) + values.atVector(omega_key(k + 1))) - z

            out.append(gtsam.CustomFactor(diagonal_noise(np.full(3, self.sigma)), [omega_key(int(k)), omega_key(int(k) + 1)],
                                          error))
        return out

    def log_normaliser(self, problem):
        return 3 * self._steps(problem)[0].size * float(np.log(self.sigma))


@pytest.fixture(scope="module")
def delta_angles():
    """A noisy 2 cm cube (0.3 m/s² per axis: ω from the accelerometers alone is poor) tumbling for 0.4 s at
    500 Hz, with the angle increments of its true ω (std 1e-5 rad) on every step."""
    from gfimu.array import cube_array

    log = simulate("random3d", cube_array(0.02, 0.3), rate_hz=500.0, duration_s=0.4, seed=4)
    w, h = log.truth.omega_b_radps, log.dt_s[:, None]
    increments = 0.5 * h * (w[:-1] + w[1:]) + np.random.default_rng(1).normal(scale=1e-5, size=(len(log) - 1, 3))
    return log, DeltaAngle(log.timestamps_ns[:-1], increments, 1e-5)


def test_a_group_that_ties_two_samples_reaches_every_consumer(delta_angles):
    """Defined in this file alone, the angle increments reach the batch solver, its GTSAM graph, the tuner's
    evidence, the bound and both fixed-lag engines, and each gets ω far closer to the truth with them."""
    log, group = delta_angles
    truth = log.truth.omega_b_radps

    def rmse(method, groups=(), **options):
        est = make_estimator(method, tune_process_noise=False, factor_groups=groups, **options).estimate(log)
        return float(np.sqrt(np.mean(np.sum((est.motion.omega_b_radps - truth) ** 2, axis=1)))), est

    plain, _ = rmse("smoother")
    batch, a = rmse("smoother", (group,))
    assert batch < 0.05 * plain and batch < 0.01
    _, b = rmse("smoother", (group,), solver="gtsam")  # the GTSAM graph of the same groups
    np.testing.assert_allclose(b.motion.omega_b_radps, a.motion.omega_b_radps, atol=1e-6)
    for engine in ("numpy", "gtsam"):
        streamed_plain, _ = rmse("fixed-lag", engine=engine, lag_s=0.05)
        streamed, _ = rmse("fixed-lag", (group,), engine=engine, lag_s=0.05)
        assert streamed < 0.05 * streamed_plain and streamed < 2 * batch, engine
    opt = SmootherOptions()
    with_group = replace(opt, factor_groups=(group,))
    diff = log_normaliser(SmootherProblem.of(log, with_group)) - log_normaliser(SmootherProblem.of(log, opt))
    assert diff == pytest.approx(3 * (len(log) - 1) * np.log(1e-5))
    sd = smoother_bound(log, with_group.model_groups, with_group.batch).sigma["omega_b_radps"]
    sd0 = smoother_bound(log, opt.model_groups, opt.batch).sigma["omega_b_radps"]
    assert np.max(sd[100]) < 0.05 * np.min(sd0[100])
