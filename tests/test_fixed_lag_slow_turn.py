"""A slow turn that each sample is too noisy to show (a car's yaw on a 0.3 m array at 50 Hz): the fixed-lag
smoother's stretches look still sample by sample, but their mean |ω|² tells the turn from rest
(model_choice.slow_turn), so the stream takes the densities tuned on them (FixedLagSmoother._slow_motion)
instead of the loose ones of a body at rest, which let ω wander through zero onto the other branch for many
seconds, and it looks for such a turn once a second while it keeps those loose densities
(FixedLagSmoother._turn_began)."""

import numpy as np
import pytest

from gfimu.array import cube_array
from gfimu.log import Log
from gfimu.methods import make_estimator
from gfimu.simulate import SensorErrors, motion_from_truth, sample_timestamps_ns
from gfimu.simulate.trajectory import BodyKinematics, integrate_attitude
from gfimu.smoother.stream.model_choice import SLOW_TURN_T, slow_turn

RATE_HZ, DURATION_S, NOISE_MPS2, HALF_EDGE_M = 50.0, 20.0, 0.01, 0.3


def _car(seed: int, creeping_s: float = 0.0) -> tuple[Log, np.ndarray]:
    """A car yawing at 0.15-0.25 rad/s, which changes slowly (0.02-0.05 Hz), rolling and pitching at 0.02 rad/s
    on its suspension (0.5-2 Hz), speeding up and slowing down along x and pushed sideways in its turns.
    ``creeping_s``: for that long first it creeps round at 0.03 rad/s (a yaw no stretch of readings tells
    from rest), then eases into the turn over 4 s."""
    rng = np.random.default_rng(seed)
    sign = rng.choice([-1.0, 1.0])
    f_yaw, ph_yaw = rng.uniform(0.02, 0.05), rng.uniform(0, 2 * np.pi)
    f_rp, ph_rp = rng.uniform(0.5, 2.0, 2), rng.uniform(0, 2 * np.pi, 2)

    def yaw(t, order):
        b = 2 * np.pi * f_yaw
        turn = (0.2 + 0.05 * np.sin(b * t + ph_yaw), 0.05 * b * np.cos(b * t + ph_yaw))
        if not creeping_s:
            return sign * turn[order]
        u = np.clip((t - creeping_s) / 4.0, 0.0, 1.0)  # smoothstep from the creep into the turn
        s, ds = u * u * (3 - 2 * u), np.where((u > 0) & (u < 1), 6 * u * (1 - u) / 4.0, 0.0)
        value = 0.03 + s * (turn[0] - 0.03)
        return sign * (value if order == 0 else ds * (turn[0] - 0.03) + s * turn[1])

    def omega(t, order=0):
        t = np.atleast_1d(t)[:, None]
        w = np.zeros((len(t), 3))
        a = 2 * np.pi * f_rp
        w[:, :2] = 0.02 * (np.sin(a * t + ph_rp) if order == 0 else a * np.cos(a * t + ph_rp))
        w[:, 2] = yaw(t[:, 0], order)
        return w

    def accel(t):
        a = np.zeros((np.size(t), 3))
        a[:, 0] = 1.5 * np.sin(2 * np.pi * 0.02 * np.atleast_1d(t))
        a[:, 1] = 10.0 * omega(t)[:, 2]  # 10 m/s through the turn
        return a

    ts = sample_timestamps_ns(RATE_HZ, DURATION_S)
    t = ts * 1e-9
    q = integrate_attitude(omega, t, np.array([1.0, 0.0, 0.0, 0.0]), omega_samples=omega(t))
    truth = motion_from_truth(ts, BodyKinematics(t, omega(t), omega(t, 1), accel(t), q))
    array = cube_array(HALF_EDGE_M, noise_std_mps2=NOISE_MPS2)
    y = SensorErrors(accel_noise_std_mps2=NOISE_MPS2).accel_readings(
        array, truth.specific_force_b_mps2, truth.omega_dot_b_radps2, truth.omega_b_radps, rng)
    return Log(array, ts, y), truth.omega_b_radps


def _rmse(log: Log, omega_true: np.ndarray, method: str) -> float:
    w = make_estimator(method).estimate(log).motion.omega_b_radps
    return float(np.sqrt(np.mean(np.sum((w - omega_true) ** 2, axis=1))))


@pytest.mark.parametrize("seed", [2, pytest.param(1, marks=pytest.mark.slow), pytest.param(3, marks=pytest.mark.slow)])
def test_a_slow_yaw_is_followed_on_its_branch_from_the_start(seed):
    """Per sample the yaw is at the noise's |ω| (the per-sample ML estimate's error is about 0.1 rad/s);
    smoothed over seconds it is known to about 0.005 rad/s. The fixed-lag smoother stays within a tenth
    of the per-sample error (a wrong branch for a few seconds alone costs more: 0.2 rad/s over a fifth of
    the log is 0.09 rad/s RMSE)."""
    log, omega_true = _car(seed)
    ml, fixed = _rmse(log, omega_true, "ml"), _rmse(log, omega_true, "fixed-lag")
    assert ml > 0.05  # the per-sample answer cannot see the turn
    assert fixed < 0.1 * ml


@pytest.mark.parametrize("seed", [4, pytest.param(1, marks=pytest.mark.slow), pytest.param(2, marks=pytest.mark.slow),
                                  pytest.param(3, marks=pytest.mark.slow)])
def test_a_yaw_that_creeps_before_it_turns_is_taken_up_on_its_branch(seed):
    """The car creeps round at 0.03 rad/s for 6 s (the stream keeps the densities as given: no stretch tells
    it from rest), then eases into its turn: the stream looks for a turn once a second (not only at its
    next scheduled choice, up to 10 s later) and takes the turn's densities before the loose ones carry the
    turn the wrong way round (as they carry seed 4 when only the scheduled choices look): over the turn
    the per-sample ML error is about 0.1 rad/s, the wrong branch's 0.4."""
    log, omega_true = _car(seed, creeping_s=6.0)
    w = make_estimator("fixed-lag").estimate(log).motion.omega_b_radps
    w_ml = make_estimator("ml").estimate(log).motion.omega_b_radps
    turning = np.abs(omega_true[:, 2]) > 0.1
    wrong = np.mean(w[turning, 2] * omega_true[turning, 2] < 0)
    turned = log.times_s - log.times_s[0] >= 10.0  # the turn, after the creep and the easing into it

    def rmse(x):
        return float(np.sqrt(np.mean(np.sum((x[turned] - omega_true[turned]) ** 2, axis=1))))

    assert wrong < 0.02
    assert rmse(w) < 0.25 * rmse(w_ml)


def test_the_threshold_is_students_t_9_at_0_999():
    """SLOW_TURN_T is Student's t with 9 degrees of freedom (ten block means) at 0.999."""
    from scipy.stats import t

    assert SLOW_TURN_T == pytest.approx(t.ppf(0.999, 9), abs=5e-4)


def test_rest_is_no_turn_and_the_car_is_one():
    """At rest the t statistic of 2|ω|² is Student's: over 200 draws of 3 s of white noise at rest, about
    0.2 are above the 0.999 quantile (a binomial 99.9 % bound of 4); the car's first 3 s are a turn."""
    rng = np.random.default_rng(7)
    array = cube_array(HALF_EDGE_M, noise_std_mps2=NOISE_MPS2)
    S = array.structure_matrix()
    y0 = S @ np.array([0.0, 0.0, 9.81] + [0.0] * 9)
    ts = sample_timestamps_ns(RATE_HZ, 3.0)
    turns = sum(slow_turn(Log(array, ts, y0 + NOISE_MPS2 * rng.standard_normal((len(ts), len(y0)))))
                for _ in range(200))
    assert turns <= 4
    log, _ = _car(1)
    assert slow_turn(log.select(slice(0, int(3 * RATE_HZ))))
