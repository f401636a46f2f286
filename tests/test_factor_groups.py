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
from gfimu.smoother.bound import smoother_bound
from gfimu.smoother.graph import SmootherOptions, SmootherProblem
from gfimu.smoother.groups import FactorGroup, Term
from gfimu.smoother.layout import OMEGA
from gfimu.smoother.tuning import log_normaliser


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
        J = np.zeros((k1 - k0, 3, problem.state_size))
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


def test_batch_and_gtsam_solvers_both_use_the_group(spinning):
    log, group = spinning
    inside = slice(100, 150)
    plain = make_estimator("smoother", tune_process_noise=False).result(log)
    assert np.min(np.linalg.norm(plain.motion.omega_b_radps[inside], axis=1)) > 1.0  # it spins
    a = make_estimator("smoother", tune_process_noise=False, factor_groups=(group,)).result(log)
    b = make_estimator("smoother", tune_process_noise=False, factor_groups=(group,), solver="gtsam").result(log)
    assert np.max(np.abs(a.motion.omega_b_radps[inside])) < 1e-3  # the prior holds ω at zero there
    np.testing.assert_allclose(b.motion.omega_b_radps, a.motion.omega_b_radps, atol=1e-6)
    assert b.cost == pytest.approx(a.cost, rel=1e-8)


def test_tuner_and_bound_use_the_group(spinning):
    log, group = spinning
    opt = SmootherOptions()
    with_group = replace(opt, factor_groups=(group,))
    diff = log_normaliser(SmootherProblem(log, with_group)) - log_normaliser(SmootherProblem(log, opt))
    assert diff == pytest.approx(3 * 50 * np.log(1e-4))
    tuned = make_estimator("smoother", factor_groups=(group,), auto_model=False).result(log)  # the likelihood tuner
    assert len(tuned.tunings) == 1 and np.isfinite(tuned.tunings[0].log_evidence)
    sd = smoother_bound(log, with_group).sigma["omega_b_radps"]
    sd0 = smoother_bound(log, opt).sigma["omega_b_radps"]
    assert np.max(sd[125]) < 1.1e-4 < np.min(sd0[125])


@pytest.fixture(scope="module")
def with_gyro():
    """Paper 001's array (gyroscope and accelerometers) turning at π rad/s; the prior holds ω at 0 over
    samples 150-174 (50 ms), where the gyroscope and the accelerometers say it spins."""
    log = simulate("turntable-constant", paper001_array(), rate_hz=500.0, duration_s=0.6, seed=2)
    t = log.timestamps_ns
    return log, ZeroRatePrior(int(t[150]), int(t[175]), 1e-4)


def omega_with_and_without(log, group, method, **options):
    with_group = make_estimator(method, tune_process_noise=False, factor_groups=(group,), **options).result(log)
    plain = make_estimator(method, tune_process_noise=False, **options).result(log)
    return with_group.motion.omega_b_radps, plain.motion.omega_b_radps


@pytest.mark.parametrize("engine", ["numpy", "gtsam"])
def test_fixed_lag_engines_use_the_group(with_gyro, engine):
    log, group = with_gyro
    lag_n = 25  # lag_s = 0.05 s at 500 Hz
    a, plain = omega_with_and_without(log, group, "fixed-lag", engine=engine, lag_s=0.05)
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
    """The same prior with its noise set on the problem by :meth:`setup`, as the model's groups do."""

    def setup(self, problem):
        problem.zero_rate_sigma = self.sigma

    def terms(self, problem, states, params):
        assert problem.zero_rate_sigma == self.sigma
        return super().terms(problem, states, params)


def test_fixed_lag_sets_the_group_up_on_each_sample(with_gyro):
    log, group = with_gyro
    same = ZeroRatePriorWithSetup(group.start_ns, group.stop_ns, group.sigma)
    a = make_estimator("fixed-lag", tune_process_noise=False, lag_s=0.05, factor_groups=(group,)).result(log)
    b = make_estimator("fixed-lag", tune_process_noise=False, lag_s=0.05, factor_groups=(same,)).result(log)
    np.testing.assert_array_equal(b.motion.omega_b_radps, a.motion.omega_b_radps)
