"""The fixed-lag smoother's model, chosen from the stream's own recent past as the batch smoother
chooses it for a whole log (:mod:`gfimu.smoother.tuning.model_choice`).

A stream cannot see its future, and its first seconds are often still (a sensor is switched on
at rest), so a model chosen once at the start is chosen on the wrong data. The fixed-lag
smoother therefore keeps the last ``model_window_s`` of readings and chooses again on them
every ``retune_every_s``, and at once when the motion outgrows the model in use
(:class:`LocalDensity`). Each choice is the batch smoother's, on that stretch:

1. the per-sample maximum-likelihood fit (:class:`gfimu.estimators.ml.MLEstimator`) and the
   model check (:func:`gfimu.smoother.tuning.model_choice.check_model`): do the readings follow the rigid-body
   model up to white noise, and with which noise floor and growth with |ω|;
2. a consistent stretch: the process noise by marginal likelihood
   (:func:`gfimu.smoother.tuning.evidence.tuned_problem`); a still one (:func:`is_still`) keeps the densities
   of the motion seen before, else those tuned on it where its mean |ω|² tells a turn from rest
   (:func:`slow_turn`), else the densities as given;
3. an inconsistent stretch: the robust model (:func:`gfimu.smoother.tuning.model_choice.misfit_options`: the
   measured noise floor and slope, Cauchy weights on the accelerometer axes, per-sample ML
   initialisation with its sign chain) and the process densities of the motion seen so far
   (:func:`gfimu.smoother.tuning.model_choice.motion_densities`), never lower than those of earlier choices
   (a still stretch keeps the densities of the motion seen before).

Options the user set away from their defaults are kept, as in the batch smoother.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from ...log import Log
from ..tuning.model_choice import (CHECK_SAMPLES, ModelCheck, check_model, estimate_noise_variances, misfit_options, motion_densities,
                   user_set, with_densities, with_user_set)
from ..model.option_groups import ModelGroups
from ..solve.initialise import sign_chain_scale
from ..solve.restarts import branch
from ..tuning.evidence import Tuning, tuned_problem



@dataclass(frozen=True)
class StreamModel:
    """One choice of the fixed-lag smoother's model (frozen; a new choice is a new value)."""

    groups: ModelGroups
    """The option groups of the smoother's model with the chosen noise levels and model."""
    accel_noise_scale: float
    """Factor on the accelerometer noise std of every axis."""
    check: ModelCheck | None
    """The model check of the stretch (None when it could not be made: no ML fit on this array)."""
    tuning: Tuning | None
    """The process-noise selection (consistent stretches), else None."""
    chosen_at_ns: int
    """Timestamp of the newest sample of the stretch it was chosen on [ns]."""
    samples: int
    """Samples of that stretch."""
    moving: bool = True
    """Whether the process densities are those of motion (False: of the noise, on a still stretch)."""
    sign_scale_radps: float | None = None
    """Cauchy scale of the sign chain's steps (:func:`gfimu.smoother.solve.initialise.sign_chain_scale` of the
    stretch's per-sample estimate; None: no sign chain)."""

    @property
    def robust(self) -> bool:
        """Whether this is the robust model of an inconsistent stretch."""
        return self.check is not None and not self.check.consistent


def check_of(part: Log, ml_motion) -> ModelCheck | None:
    """The model check of the stretch ``part`` from its per-sample ML estimate (None: no check)."""
    if ml_motion is None:
        return None
    step = max(1, len(part) // CHECK_SAMPLES)
    if step == 1:
        return check_model(part, ml_motion)
    sl = slice(0, None, step)
    return check_model(part.select(sl), ml_motion.select(sl))


def gaussian(part: Log, given: ModelGroups, check: ModelCheck | None) -> StreamModel:
    """The Gaussian model of a consistent stretch: the process noise by marginal likelihood."""
    tunings: list = []
    problem, _ = tuned_problem(part, given._replace(tuning=replace(given.tuning, tune_process_noise=True)), tunings)
    return from_tuning(tunings[-1], given._replace(model=problem.model, batch_model=problem.batch_model), check, part)


def from_tuning(tuning: Tuning, groups: ModelGroups, check: ModelCheck | None, part: Log) -> StreamModel:
    """The model that carries ``tuning`` (the model groups it was chosen with) on a stream."""
    chosen = groups._replace(model=tuning.for_stream(groups.model),
                             tuning=replace(groups.tuning, tune_process_noise=False))
    return StreamModel(chosen, float(tuning.accel_noise_scale), check, tuning, int(part.timestamps_ns[-1]), len(part))


def robust(part: Log, given: ModelGroups, check: ModelCheck, ml_motion, tune: bool,
           previous: StreamModel | None = None) -> StreamModel:
    """The robust model of an inconsistent stretch (module docstring); ``tune``: its process densities
    from the motion (else those of the model ``given``)."""
    chosen = misfit_options(given, check)
    moving = True
    if tune:
        x = np.hstack([ml_motion.omega_b_radps, ml_motion.omega_dot_b_radps2, ml_motion.specific_force_b_mps2])
        jerk, force, moving = motion_densities(x, part.dt_s, *estimate_noise_variances(
            part.array, check, ml_motion.omega_b_radps), with_motion=True)
        if not moving and previous is not None and previous.robust and previous.moving:
            o = previous.groups.model  # a still stretch: the motion seen before still counts
            jerk = o.omega_dot_random_walk_radps2_per_sqrt_s * np.asarray(o.process_axis_factors)
            force = o.specific_force_random_walk_mps2_per_sqrt_s
            moving = True
        chosen = chosen._replace(model=with_densities(chosen.model, jerk, force))
    # no robust weights on the readings: a recursive update weighs each sample's axes once, at the
    # estimate that sample itself moved, and a poor prediction (fast motion between samples) would
    # have the informative axes weighted down (on the MIMU4444 recordings the Cauchy weights made the
    # stream's error worse, a trial not kept as a script); the measured floor and slope carry the noise level
    chosen = chosen._replace(batch_model=replace(chosen.batch_model, accel_robust_threshold=0.0))
    chosen = with_user_set(chosen, user_set(given, chosen))
    chosen = chosen._replace(tuning=replace(chosen.tuning, tune_process_noise=False))
    scale = 1.0
    if math.isfinite(check.stated_noise_mps2) and check.stated_noise_mps2 > 0 and check.noise_floor_mps2 > 0:
        scale = check.noise_floor_mps2 / check.stated_noise_mps2
    return StreamModel(chosen, float(scale), check, None, int(part.timestamps_ns[-1]), len(part), moving,
                       sign_scale(part, ml_motion))


def has_motion(part: Log, ml_motion, check: ModelCheck | None) -> bool:
    """Whether the per-sample ML estimate of ``part`` shows motion above its own noise
    (:func:`gfimu.smoother.tuning.model_choice.motion_densities`); True when it cannot tell (no ML estimate)."""
    if ml_motion is None or check is None:
        return True
    x = np.hstack([ml_motion.omega_b_radps, ml_motion.omega_dot_b_radps2, ml_motion.specific_force_b_mps2])
    return bool(motion_densities(x, part.dt_s, *estimate_noise_variances(part.array, check, ml_motion.omega_b_radps),
                                 with_motion=True)[2])


STILL_OMEGA_NOISE = 2.0
"""A stretch is still when the 90th percentile of its per-sample |ω| is below this many times the
|ω| that the readings' noise alone gives (and its ω̇ shows no motion above the noise). At rest the
90th percentile is about 1.2 times it (a 5 cm cube of four triads with white noise: 1.02 against
0.83 rad/s), a slow turntable's (±23.5° at 1 Hz) 3.1 times."""


def is_still(part: Log, ml_motion, check: ModelCheck) -> bool:
    """Whether ``part`` shows the body at rest (or turning too slowly for its readings to tell): no
    motion of ω̇ above the noise (:func:`has_motion`) and |ω| within :data:`STILL_OMEGA_NOISE` times
    the |ω| of noise alone, ``√σ_q`` with ``σ_q`` the std the floor puts on the quadratic terms
    (Ho & Lin 2009, eq. 6)."""
    if has_motion(part, ml_motion, check):
        return False
    S = part.array.structure_matrix()
    c_q = float(np.mean(np.diag(np.linalg.pinv(S.T @ S))[6:9]))
    omega_noise = math.sqrt(check.noise_floor_mps2 * math.sqrt(max(c_q, 0.0)))
    return check.omega_p90_radps < STILL_OMEGA_NOISE * omega_noise


SLOW_TURN_T = 4.297
"""A stretch turns when the mean over it of 2|ω|² (:func:`slow_turn`) exceeds this many of its standard
errors: Student's t with 9 degrees of freedom (ten blocks) at 0.999, which a body at rest, whose mean is
zero, passes once in a thousand stretches."""

SLOW_TURN_BLOCKS = 10
"""Blocks of a stretch whose means give the standard error of its mean |ω|² (:func:`slow_turn`): the
readings' noise may be correlated over a few samples, the blocks' means are not."""


def slow_turn(part: Log) -> bool:
    """Whether the readings of ``part`` show the body turning, however slowly: the per-sample least-squares
    fit of the rigid-body model, linear in [f, ω̇, q(ω)] (Ho & Lin 2009, eq. 2), gives an unbiased sum of
    its three square terms, 2|ω|², which is zero at rest whatever the noise; its mean over the stretch
    against its standard error from :data:`SLOW_TURN_BLOCKS` block means (t test, :data:`SLOW_TURN_T`).
    A car turning at 0.11-0.15 rad/s on a 0.3 m array at 50 Hz and 0.01 m/s² is at the per-sample noise's
    |ω| and :func:`is_still`, but its mean |ω|² over 3 s stands 9-10 standard errors above zero."""
    return turning(part.accel_mps2, squares_row(part.array))


def squares_row(array) -> np.ndarray:
    """The row of the least-squares inverse of ``array``'s structure matrix that gives 2|ω|² (the sum of q's
    three square terms) from one sample's readings (:func:`turning`)."""
    return np.linalg.pinv(array.structure_matrix())[6:9].sum(axis=0)


def turning(accel_mps2: np.ndarray, row: np.ndarray) -> bool:
    """:func:`slow_turn`'s test on the readings ``accel_mps2`` (N, axes) with ``row`` (:func:`squares_row`)."""
    n = len(accel_mps2)
    if n < 2 * SLOW_TURN_BLOCKS:
        return False
    two_w2 = np.asarray(accel_mps2, dtype=float) @ row
    means = np.array([b.mean() for b in np.array_split(two_w2, SLOW_TURN_BLOCKS)])
    se = float(np.std(means, ddof=1)) / math.sqrt(SLOW_TURN_BLOCKS)
    return bool(se > 0 and float(np.mean(two_w2)) > SLOW_TURN_T * se)


def sign_scale(part: Log, ml_motion) -> float | None:
    """The sign chain's Cauchy scale on ``part`` from its per-sample ML estimate (None without one)."""
    if ml_motion is None:
        return None
    return sign_chain_scale(ml_motion.omega_b_radps, ml_motion.omega_dot_b_radps2, part.dt_s)


OUTGROWN_FACTOR = 2.0
"""The model is chosen again at once (at most once a second) when the local motion density exceeds
its jerk density this many times (a factor four in power: the body moves faster than the model allows)."""

RESOLVED_FACTOR = 4.0
"""The local motion is resolved when its step power exceeds this many times the noise's (a motion
density above the noise's by √3 in std): below, the local density is the noise's, which says
nothing about the motion."""


class LocalDensity:
    """The local motion density of a stream, causally: the step power of the per-sample inversion's
    ω̇ (Ho & Lin 2009, eq. 7: linear in the readings) above what its own noise gives, averaged over the
    last ``period_s`` — the trailing form of :func:`gfimu.smoother.tuning.model_choice.local_density_factors`.

    :meth:`push` takes each sample's readings and the |ω| expected there (which sets the noise of a
    robust model) and returns the local jerk density [rad/s²/√s], or None until two samples came.
    Needs an array whose structure matrix has full column rank (12 unknowns); :attr:`available`
    says whether it has."""

    resolved = False
    """Whether the last period's steps stand clearly above what the noise gives (:data:`RESOLVED_FACTOR`)."""

    def __init__(self, array, period_s: float = 0.5) -> None:
        S = array.structure_matrix()
        self.available = S.shape[0] >= 12 and np.linalg.matrix_rank(S) == 12
        self.period_s = float(period_s)
        if self.available:
            self._pinv_dw = np.ascontiguousarray(np.linalg.pinv(S)[3:6])
            self._c_dw = float(np.sum(np.diag(np.linalg.pinv(S.T @ S))[3:6]))
        self._period_ns = int(self.period_s * 1e9)
        self._ring(256)

    def _ring(self, size: int) -> None:
        """A ring of ``size`` steps (t_ns; step and noise powers) and the running state
        (:func:`gfimu.smoother.stream.kernels.local_density_push`), empty."""
        self._t = np.zeros(size, dtype=np.int64)
        self._s = np.zeros((size, 2))
        self._i = np.zeros(4, dtype=np.int64)  # oldest slot, count, previous sample kept, its time
        self._f = np.zeros(3)  # Σ step, Σ noise, the previous sample's noise variance
        self._dw = np.zeros(3)  # the previous sample's ω̇

    def reset(self) -> None:
        self._i[:] = 0
        self._f[:] = 0.0

    def _grown(self) -> None:
        """The ring twice as long, its steps kept in order."""
        n, first = int(self._i[1]), int(self._i[0])
        order = (first + np.arange(n)) % len(self._t)
        t, s, i, f, dw = self._t[order], self._s[order], self._i.copy(), self._f.copy(), self._dw.copy()
        self._ring(2 * len(self._t))
        self._t[:n], self._s[:n] = t, s
        self._i[:] = (0, n, i[2], i[3])
        self._f[:], self._dw[:] = f, dw

    def push(self, t_ns: int, y: np.ndarray, noise_var_mps2: float) -> float | None:
        if not self.available:
            return None
        global _density_push
        if _density_push is None:  # the compiled step, imported on first use
            from .kernels import local_density_push as _density_push
        while True:
            density, resolved, room = _density_push(int(t_ns), y, float(noise_var_mps2), self._pinv_dw, self._c_dw,
                                                    self._dw, self._t, self._s, self._i, self._f, self._period_ns,
                                                    RESOLVED_FACTOR)
            if room:
                break
            self._grown()
        if density < 0.0:
            return None
        self.resolved = resolved
        return density


_density_push = None
""":func:`gfimu.smoother.stream.kernels.local_density_push`, once imported."""


_chain_push = None
""":func:`gfimu.smoother.stream.kernels.chain_push`, once imported."""

_FLOAT = np.dtype(np.float64)


class StreamSignChain:
    """The sign chain of :func:`gfimu.smoother.solve.initialise.sign_chain` over a stream, fixed-lag, over the
    four branches of the readings' ambiguity (:func:`branch`: ω flipped, mirrored through a planar
    array's plane, both).

    The accelerometers see ω only through q(ω) = q(-ω), and a planar array also confuses ω with its
    mirror image; the trapezoid of ω̇ tells them apart (a mirrored run of ω does not integrate its
    own moved ω̇). The batch smoother starts from per-sample estimates whose signs follow the
    trapezoid best over the whole log (dynamic programming, a Cauchy loss of scale c on each step's
    misfit ``||ω_{k+1} - ω_k - h/2 (ω̇_k + ω̇_{k+1})||``) and restarts runs on the other branches. A
    recursive estimate carries its branch by the motion model instead, and where the motion model is
    loose (real arrays: a large jerk density) it can go over to another branch where the rotation
    slows through zero or the normal component of ω does.

    Here the same dynamic programme runs on the smoother's own filtered states, each state's branch
    relative to the smoother's: :meth:`push` takes the newest state and returns ``(first, kind)``
    when the best path ends on another branch and beats keeping the smoother's by more than
    ``margin`` (in units of c²): the states from ``first`` (the best path's last run on that branch,
    within the window) are to be moved onto branch ``kind``; they then count as the smoother's own
    (the costs are relabelled) and the chain starts again from them.
    """

    def __init__(self, window: int, normal: np.ndarray, margin: float = 1.0, branches: int = 4) -> None:
        self.window = max(int(window), 2)
        self.normal = np.asarray(normal, dtype=float)
        self.margin = float(margin)
        self.branches = int(branches)
        self._st = np.zeros(5, dtype=np.int64)  # ring head and count, newest time, whether there is one, moves
        self._out = np.zeros(2, dtype=np.int64)
        self.reset()

    @property
    def flips(self) -> int:
        """Moves so far (every segment)."""
        return int(self._st[4])

    def reset(self) -> None:
        n = self.branches
        self._cost = np.zeros(n)
        self._w, self._dw = np.zeros((n, 3)), np.zeros((n, 3))  # the newest state's (ω, ω̇) per branch
        # the best earlier branch per later branch of the newest ``window`` steps, a ring (oldest at its head),
        # with the later state's k
        self._backs = np.zeros((self.window, n), dtype=np.int64)
        self._ks = np.zeros(self.window, dtype=np.int64)
        self._st[:4] = 0  # (no state yet: its time unset)

    def push(self, k: int, t_ns: int, omega: np.ndarray, omega_dot: np.ndarray, scale_radps: float,
             oldest_k: int) -> tuple[int, int] | None:
        global _chain_push
        if _chain_push is None:  # the compiled step, imported on first use
            from .kernels import chain_push as _chain_push

        if not (type(omega) is np.ndarray and omega.dtype is _FLOAT and type(omega_dot) is np.ndarray
                and omega_dot.dtype is _FLOAT):
            omega, omega_dot = np.array(omega, dtype=float), np.array(omega_dot, dtype=float)
        st = self._st
        if not st[3]:
            for b in range(self.branches):
                self._w[b], self._dw[b] = branch(b, omega, omega_dot, self.normal)
            st[2], st[3] = t_ns, 1
            return None
        # from branch a (at k-1) to branch b (at k): the Cauchy loss of the trapezoid's misfit, the lowest
        # total kept per b (only the differences matter, and they stay bounded); the moves: kernels.chain_push
        if not _chain_push(k, t_ns, omega, omega_dot, scale_radps * scale_radps, oldest_k, self.margin, self.normal,
                           self._w, self._dw, self._cost, self._backs, self._ks, st, self._out):
            return None
        return int(self._out[0]), int(self._out[1])
