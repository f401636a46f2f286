"""The typed noise levels (gfimu.smoother.model.noise_levels): what a factor group reads of a problem, the same for the
batch problem and the stream's view; the accelerometer noise given with ``-O default_accel_noise_std_mps2`` reaches
every group that whitens with it, the tuner, the restarts and the fixed-lag smoother's model as one value (and
the gyroscope's and the first-state prior's the same way)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from gfimu.array import Gyroscope, cube_array
from gfimu.cli.options import method_options
from gfimu.methods import make_estimator
from gfimu.noise import DEFAULT_GYRO_NOISE_STD_RADPS
from gfimu.simulate import simulate
from gfimu.smoother.model.groups import AccelerometerGroup, FactorGroup, MotionModelGroup
from gfimu.smoother.model.layout import OMEGA_DOT, SPECIFIC_FORCE
from gfimu.smoother.model.noise_levels import AccelNoise, ModelView, MotionNoise, NoiseLevels
from gfimu.smoother.model.problem import SmootherOptions, SmootherProblem
from gfimu.smoother.solve.banded import robust_reweighted
from gfimu.smoother.solve.restarts import FrozenObjective
from gfimu.smoother.stream.array_model import ArrayModel, StreamView
from gfimu.smoother.tuning.evidence import make_problem

SIGMA = 0.3


@pytest.fixture(scope="module")
def log():
    """A short log whose array.toml states no accelerometer noise (the option's default then applies)."""
    made = simulate("reversal", array=cube_array(0.025, noise_std_mps2=0.07), rate_hz=200.0, duration_s=0.5, seed=2)
    return made.replace(array=cube_array(0.025, noise_std_mps2=None))


def _options(method: str):
    chosen = method_options(method, [f"default_accel_noise_std_mps2={SIGMA}"])
    assert chosen.options == {"default_accel_noise_std_mps2": SIGMA}
    return chosen.estimator().model_groups


def test_the_accel_noise_option_reaches_every_group_that_whitens_with_it(log):
    problem = SmootherProblem(log, _options("smoother"))
    np.testing.assert_array_equal(problem.noise.accel.sigma, np.full(log.array.n_axes, SIGMA))
    # the measurement's whitening: the rows on [ω̇, f] are the structure matrix's over σ
    t = log.truth
    states = np.hstack([t.omega_b_radps, t.omega_dot_b_radps2, t.specific_force_b_mps2])
    params = np.zeros(problem.n_global)
    group = problem.group(AccelerometerGroup)
    J = group.terms(problem, states, params)[0].jac["x"]
    np.testing.assert_allclose(J[:, :, SPECIFIC_FORCE], np.broadcast_to(problem.all_rows[:, 0:3] / SIGMA, J[:, :, 0:3].shape),
                               rtol=1e-15)
    np.testing.assert_allclose(J[:, :, OMEGA_DOT], np.broadcast_to(problem.all_rows[:, 3:6] / SIGMA, J[:, :, 0:3].shape),
                               rtol=1e-15)
    assert group.log_normaliser(problem) == pytest.approx(len(log) * log.array.n_axes * np.log(SIGMA), rel=1e-14)
    # the motion-dependent noise, the tuner's scale, the restarts' objective start from it
    slope = 0.2
    moving = problem.with_noise(accel=problem.noise.accel.motion_dependent(t.omega_b_radps, slope))
    wn = np.linalg.norm(t.omega_b_radps, axis=1)
    np.testing.assert_allclose(moving.noise.accel.per_sample[:, 0], np.sqrt(SIGMA**2 + (slope * wn) ** 2), rtol=1e-15)
    np.testing.assert_allclose(make_problem(log, problem.options, 2.0).noise.accel.sigma, 2 * SIGMA, rtol=1e-15)
    np.testing.assert_array_equal(FrozenObjective(problem).accel_sigma, SIGMA)
    # re-weighted: the robust weights divide the same σ
    robust = robust_reweighted(SmootherProblem(log, problem.options._replace(batch_model=dataclasses.replace(
        problem.batch_model, accel_robust_threshold=2.0))), states)
    assert np.all(robust.noise.accel.per_sample >= SIGMA) and robust.noise.accel.base is None


def test_the_fixed_lag_smoother_takes_the_same_value(log):
    options = _options("fixed-lag")
    model = ArrayModel(log.array, options)
    np.testing.assert_array_equal(model.accel_sigma_mps2, np.full(log.array.n_axes, SIGMA))
    np.testing.assert_allclose(ArrayModel(log.array, options, accel_noise_scale=2.0).accel_sigma_mps2, 2 * SIGMA,
                               rtol=1e-15)
    # an array stating some axes' noise: the stream's value is the batch problem's, to the bit
    accs = list(log.array.accelerometers)
    accs[0] = dataclasses.replace(accs[0], noise_std_mps2=0.05)
    accs[3] = dataclasses.replace(accs[3], noise_std_mps2=0.11)
    mixed = log.replace(array=dataclasses.replace(log.array, accelerometers=tuple(accs)))
    batch = SmootherProblem(mixed, options).noise.accel.sigma
    assert len(set(batch.tolist())) == 3
    np.testing.assert_array_equal(ArrayModel(mixed.array, options).accel_sigma_mps2, batch)
    np.testing.assert_array_equal(ArrayModel(mixed.array, options).first_sigma,
                                  SmootherProblem(mixed, options).noise.first_state.sigma)
    # the gyroscope's noise too, from the same group
    gyro = simulate("reversal", array=dataclasses.replace(log.array, gyroscope=Gyroscope(noise_std_radps=0.004)),
                    rate_hz=200.0, duration_s=0.2, seed=3)
    assert ArrayModel(gyro.array, options).gyro_sigma_radps == SmootherProblem(gyro, options).noise.gyro.sigma == 0.004
    assert ArrayModel(log.array, options).gyro_sigma_radps == DEFAULT_GYRO_NOISE_STD_RADPS  # none stated


def test_the_batch_problem_and_the_stream_view_are_both_what_a_group_reads(log):
    problem = SmootherProblem.of(log, SmootherOptions())
    view = StreamView.of(log.array, SmootherOptions().model_groups, log.timestamps_ns[:2]).with_levels((MotionModelGroup(),))
    assert isinstance(problem, ModelView) and isinstance(view, ModelView)
    assert isinstance(problem.noise.motion, MotionNoise) and isinstance(view.noise.motion, MotionNoise)
    np.testing.assert_array_equal(view.noise.motion.trapezoid_sigma, problem.noise.motion.trapezoid_sigma[:1])
    assert view.noise.accel is None  # only the groups asked for
    with pytest.raises(AttributeError):
        problem.accel_sigma  # noqa: B018 - no level is reached by its name any more


def test_levels_are_frozen_and_replaced_whole(log):
    problem = SmootherProblem.of(log, SmootherOptions())
    levels = problem.noise
    with pytest.raises(dataclasses.FrozenInstanceError):
        levels.accel = AccelNoise(np.ones(3))
    with pytest.raises(ValueError):
        levels.accel.sigma[0] = 1.0
    scaled = problem.with_noise(accel=problem.noise.accel.scaled(2.0))
    assert scaled.noise.motion is levels.motion and scaled.noise.accel is not levels.accel
    np.testing.assert_array_equal(problem.noise.accel.sigma * 2.0, scaled.noise.accel.sigma)


class _Twice(FactorGroup):
    name = "twice"

    def noise(self, problem):
        return AccelNoise(np.ones(problem.array.n_axes))


def test_a_kind_of_level_given_twice_is_refused(log):
    with pytest.raises(ValueError, match="two factor groups give the accel noise levels"):
        NoiseLevels.gather((AccelerometerGroup(), _Twice()), SmootherProblem.of(log, SmootherOptions()))
