"""Fixed-lag smoothing of the window in numpy: a Kalman filter that carries cross-covariances.

The factors of :mod:`gfimu.smoother.stream.array_model` written as a state-space
model of the state ``x = [ω, ω̇, f]`` (9 values, body frame):

- process: the trapezoid ``ω_{k+1} = ω_k + h/2 (ω̇_k + ω̇_{k+1}) + n_int`` and the
  random walk ``ω̇_{k+1} = ω̇_k + n_ω̇`` are, substituting the second in the first,
  ``ω_{k+1} = ω_k + h ω̇_k + h/2 n_ω̇ + n_int``: ``x_{k+1} = F x_k + n`` with
  ``Q_ωω = σ_int² + h²/4 σ_ω̇²``, ``Q_ωω̇ = h/2 σ_ω̇²``, ``Q_ω̇ω̇ = σ_ω̇²`` per body axis
  (the change of variables has unit Jacobian, so the density of the factor graph
  and of this model are the same); f is a random walk; with
  ``process_axis_frequencies_hz`` the exact oscillator step (Φ, its covariance);
- measurement (Ho & Lin 2009, eq. 6): ``y = S_f f + S_ω̇ ω̇ + S_q q(ω) + v``, and the
  gyroscope ``ω + v_g``; priors on the first state of a segment; the whitened rows
  of the factor groups given in the options (:meth:`ArrayModel.sample_terms`:
  "readings" 0 with unit noise).

The measurement is linearised by a Gauss-Newton (iterated extended Kalman) update
of the newest state, started from the prediction, or from the sign-resolving
initial values during the warm-up of a segment. Every state ``i`` of the window
keeps its mean given all data so far, its marginal variances and
``C_i = Cov(x_i, x_newest)``; one measurement of the newest state moves them all
by ``m_i += C_i Hᵀ S⁻¹ ν``, ``C_i ← C_i (I - Hᵀ S⁻¹ H P)``: the fixed-lag
smoother as a Kalman filter on the state augmented with the window, keeping only
the cross-covariances the newest measurement needs (O(window) 9×9 products, all
vectorised). For a linear measurement this is exactly the minimum of the
window's least-squares problem given the marginalised past (what gtsam's
fixed-lag smoother solves); with the quadratic term, each measurement keeps the
linearisation of its own update (gtsam relinearises ω when it moves by more
than its threshold, 0.1 rad/s by default).

The window lives in preallocated arrays; states leave from the old end
(exact marginalisation: the filter already carries the marginal), and the
arrays are compacted when the new end reaches their capacity.
"""

from __future__ import annotations

import math

import numpy as np

from ...rigid_body import quadratic_terms, quadratic_terms_jacobian
from .array_model import ArrayModel, Step
from ..model.parts import delegated
from ..model.problem import robust_loss, robust_weight
from ..solve.restarts import branch, plane_normal


class _Kernels:
    """:mod:`gfimu.smoother.stream.kernels`, imported when a filter first needs it: importing this module
    does not import numba (the command's start; :mod:`gfimu.smoother.preload` loads it meanwhile)."""

    def __getattr__(self, name: str):
        from . import kernels as module

        globals()["kernels"] = module  # (later calls find the module itself)
        return getattr(module, name)


kernels = _Kernels()


LAZY_STEPS = None
"""Updates gathered into one epoch of the window's older states (:meth:`WindowFilter._boundary`); None: chosen
from the window's capacity (:func:`lazy_steps`)."""


def lazy_steps(capacity: int) -> int:
    """The epoch's length (updates) for a window of ``capacity`` slots (about four lags of states, L = capacity / 4):
    an update moves the newest B states at once (9×9 products, about B/2 states on average) and, where a run of
    B older states is read, composes the L / B epochs since (three 9×9 products each) for them: per update
    ``c_s B / 2 + c_e L / B²`` with ``c_e ≈ 1.5 c_s``, least at ``B = (6 L)^(1/3)`` (8 at 500 Hz with a 0.2 s lag,
    30 at 20 kHz), between 4 and 64."""
    return int(min(max(round((1.5 * capacity) ** (1.0 / 3.0)), 4), 64))

SETTLE_FALSE_ALARM = 1e-3
"""A motion-model step is outlying when its whitened residual over the six ω, ω̇ rows (χ²₆ under the
model) exceeds the χ²₆ quantile at this probability (22.5, an RMS over the rows of 1.93): only a state
entered by such a step is decided again on its branch (:meth:`WindowFilter.settle`)."""


def _chi2_6_quantile(p: float) -> float:
    """The χ²₆ quantile at upper tail probability ``p``: ``P(χ²₆ > x) = e^(-x/2) (1 + x/2 + x²/8)``
    (even degrees of freedom: a Poisson sum), solved by bisection."""
    lo, hi = 0.0, 1000.0
    for _ in range(100):
        x = 0.5 * (lo + hi)
        tail = math.exp(-0.5 * x) * (1.0 + 0.5 * x + 0.125 * x * x)
        lo, hi = (x, hi) if tail > p else (lo, x)
    return 0.5 * (lo + hi)


OUTLYING_STEP2 = _chi2_6_quantile(SETTLE_FALSE_ALARM)
"""That quantile (22.46 at 1e-3)."""

SETTLE_STATES = 64
"""States after the oldest that the branch decision weighs at most (:meth:`WindowFilter.settle`; the last
of them held on its own branch): the runs it moves are a few samples long (one to five on the MIMU4444
recordings at 62.5 Hz), and the states beyond add only more samples whose branch must agree, at O(states)
per decision (a 0.2 s lag at 20 kHz holds 4,000)."""
SETTLE_MARGIN = 4
"""States after a moved run re-solved with it (:meth:`WindowFilter._resolve_run`)."""
SETTLE_ITERATIONS = 5
"""Gauss-Newton steps of that re-solve at most."""

BRANCH_PRIOR_MARGIN = 25.0
"""A branch of an update's minimum is tried only when its distance from the prediction (squared,
in the prediction's covariance) is within this of the minimum's cost (5 σ): further away, the
readings, which fit both branches alike, cannot make up for it."""


_ZERO9 = np.zeros(9)
_NEVER = 1 << 62  # the fused kernel's own flush, not used: the epochs are kept here (WindowFilter._boundary)


class Epochs:
    """The epochs of the window's older states (:meth:`WindowFilter._boundary`): each epoch's factors
    ``(T, u, W)`` (its :attr:`WindowFilter.lazy_steps` updates' share of the older states, ``C ← C T``, ``m += C u``,
    ``v -= diag(C W Cᵀ)``), kept while a state still waits for them, and the runs of states that wait:
    ``[k_first, k_stop, epoch]``, states ``k_first … k_stop - 1`` up to date as of the start of ``epoch``
    (their runs contiguous, oldest first), in a ring (``stale``). Arrays throughout, which the compiled kernels
    read and write (:func:`kernels.epochs_close <gfimu.smoother.stream.kernels.epochs_close>`,
    :func:`kernels.epochs_bring_up <gfimu.smoother.stream.kernels.epochs_bring_up>`): ``ep`` holds the
    epochs kept, the number of the epoch in row 0, the first run's slot and the runs' count."""

    def __init__(self, capacity: int = 16) -> None:
        self.T = np.empty((capacity, 9, 9))  # each epoch's factors, the oldest kept first
        self.u = np.empty((capacity, 9))
        self.W = np.empty((capacity, 9, 9))
        self.stale = np.zeros((capacity + 4, 3), dtype=np.int64)
        self.ep = np.zeros(4, dtype=np.int64)

    @property
    def n(self) -> int:
        """Epochs kept."""
        return int(self.ep[0])

    @property
    def first(self) -> int:
        """The number of the epoch in row 0."""
        return int(self.ep[1])

    def waits(self, k: int) -> bool:
        """Whether state ``k`` waits for epochs (is not up to date as of the current epoch's start)."""
        ep = self.ep
        count = ep[3]
        if not count:
            return False
        stale, head = self.stale, ep[2]
        return bool(stale[head, 0] <= k < stale[(head + count - 1) % len(stale), 1])

    def close(self, T: np.ndarray, u: np.ndarray, W: np.ndarray, k_lo: int, k_split: int) -> None:
        """An epoch ends with factors ``(T, u, W)``: the older states ``[k_lo, k_split)`` that were up to date
        as of its start (the others wait already) now wait for it (the rows no waiting state needs dropped
        when all are taken; the arrays grown when that is not enough)."""
        while True:
            status = kernels.epochs_close(self.T, self.u, self.W, self.ep, self.stale, T, u, W, int(k_lo),
                                          int(k_split))
            if status == 0:
                return
            if status == 1:
                self.T, self.u, self.W = (np.concatenate([a, np.empty_like(a)]) for a in (self.T, self.u, self.W))
            else:
                self.grow_runs()

    def grow_runs(self) -> None:
        """A ring of runs twice as long, the runs kept in order from its first slot."""
        count, head, R = int(self.ep[3]), int(self.ep[2]), len(self.stale)
        runs = self.stale[(head + np.arange(count)) % R]
        self.stale = np.zeros((2 * R, 3), dtype=np.int64)
        self.stale[:count] = runs
        self.ep[2] = 0

    def take(self, k_stop: float, k_lo: int, least: int):
        """The runs of waiting states before ``k_stop`` (at least ``least`` states of a run; the rest of it goes
        on waiting), no longer waiting: ``(k_first, k_stop, row)`` each, ``row`` the first of its epochs (the
        numpy path's; :func:`kernels.epochs_bring_up <gfimu.smoother.stream.kernels.epochs_bring_up>` is the
        compiled one)."""
        ep, stale, R = self.ep, self.stale, len(self.stale)
        while ep[3] and stale[ep[2], 0] < k_stop:
            k0, k1, epoch = (int(v) for v in stale[ep[2]])
            ep[2], ep[3] = (ep[2] + 1) % R, ep[3] - 1
            k0 = max(k0, k_lo)
            if k1 <= k0:
                continue
            cut = max(k_stop, k0 + least)
            if cut < k1:
                ep[2], ep[3] = (ep[2] + R - 1) % R, ep[3] + 1
                stale[ep[2]] = (int(cut), k1, epoch)
                k1 = int(cut)
            yield k0, k1, epoch - int(ep[1])

    def forget_before(self, k_lo: int) -> None:
        """States before ``k_lo`` left the window."""
        ep, stale, R = self.ep, self.stale, len(self.stale)
        while ep[3] and stale[ep[2], 1] <= k_lo:
            ep[2], ep[3] = (ep[2] + 1) % R, ep[3] - 1

    def clear(self) -> None:
        """No state waits (all brought up to date): no epoch kept."""
        ep = self.ep
        ep[3] = 0
        ep[1] += ep[0]
        ep[0] = 0


class FilterFailure(RuntimeError):
    """A numerical failure of an update (a singular innovation covariance, non-finite values)."""


class WindowStore:
    """The window's storage: each slot's mean, marginal variances and cross-covariance with the newest
    state (``mean`` (cap, 9), ``var`` (cap, 9), ``cross`` (cap, 9, 9); ``tmp`` scratch of the shape of
    ``cross``), the step into its state (``F``, ``Q`` (cap, 9, 9), where ``has_step``: the branch decision's
    (:meth:`WindowFilter.settle`)) and its sample's time (``t_ns``), ``cap`` slots; the states in slots ``[lo, hi)``, those in ``[lo, split)``
    updated lazily (:meth:`WindowFilter._flush`), ``[split, hi)`` at once; ``base`` the index k of slot 0."""

    __slots__ = ("mean", "var", "cross", "tmp", "F", "Q", "has_step", "t_ns", "cap", "lo", "hi", "split", "base")
    ARRAYS = ("mean", "var", "cross", "F", "Q", "has_step", "t_ns")
    """The arrays of one value per slot (moved and grown together, :meth:`WindowFilter._make_room`)."""

    def __init__(self, capacity: int) -> None:
        self.cap = capacity
        self.mean = np.zeros((capacity, 9))
        self.var = np.zeros((capacity, 9))
        self.cross = np.zeros((capacity, 9, 9))
        self.tmp = np.empty((capacity, 9, 9))
        self.F = np.zeros((capacity, 9, 9))
        self.Q = np.zeros((capacity, 9, 9))
        self.has_step = np.zeros(capacity, dtype=bool)
        self.t_ns = np.zeros(capacity, dtype=np.int64)
        self.lo = self.hi = self.split = self.base = 0

    def keep_step(self, k: int, F: np.ndarray, Q: np.ndarray, t_ns: int) -> None:
        """The step into state ``k`` (in the window), its sample at ``t_ns``."""
        s = k - self.base
        self.F[s] = F
        self.Q[s] = Q
        self.has_step[s] = True
        self.t_ns[s] = t_ns

    def step(self, k: int):
        """(F, Q) of the step into state ``k`` (views of the store's arrays), or None where it has none."""
        s = k - self.base
        return (self.F[s], self.Q[s]) if self.has_step[s] else None


class LazyFactors:
    """The lazy older states' share of the updates: the open epoch's factors since the last flush
    (``C_i T`` their cross-covariances, ``m_i + C_i u`` their means, ``v_i - diag(C_i W C_iᵀ)`` their
    variances) and the closed epochs they still wait for (``epochs``, :class:`Epochs`)."""

    __slots__ = ("T", "u", "W", "epochs")

    def __init__(self) -> None:
        self.T = np.eye(9)
        self.u = np.zeros(9)
        self.W = np.zeros((9, 9))
        self.epochs = Epochs()


class NewestStep:
    """The newest state's covariance ``P`` and the step into it: its transition ``F`` and process noise
    ``Q`` (None before the segment's first step)."""

    __slots__ = ("P", "Q", "F")

    def __init__(self) -> None:
        self.P = np.zeros((9, 9))
        self.Q = self.F = None


class StepRecord:
    """Whether an update of the segment used rows the branch decision (:meth:`WindowFilter.settle`) cannot
    evaluate (``unsettled``: gyroscope, factor groups, given step groups); the steps themselves are the
    store's (:class:`WindowStore`)."""

    __slots__ = ("unsettled",)

    def __init__(self) -> None:
        self.unsettled = False


class FilterOperands:
    """The model's numbers as the updates use them: the first-state prior's variances ``prior_var``, the
    accelerometers' ``R`` and the gyroscope's ``gyro_var`` (``Rg`` both), the compiled kernels' operands
    (``kernel_model``: R, the structure matrix's blocks, the robust model; ``kernel_options``: iterations,
    tolerance, branches and their margin, the process's robust loss), and the Jacobian buffers ``H``, ``Hg``
    (with the gyroscope rows) with the indices of their innovation covariances' diagonals ``diag``,
    ``diag_g``."""

    __slots__ = ("prior_var", "R", "gyro_var", "Rg", "kernel_model", "kernel_options", "H", "Hg", "diag", "diag_g")

    def __init__(self, model: ArrayModel) -> None:
        structure = model.structure
        m = structure.S_q.shape[0]
        # Jacobian buffers: the ω̇ and f columns are constant; the gyroscope rows select ω
        self.H = np.zeros((m, 9))
        self.H[:, 3:6], self.H[:, 6:] = structure.S_dw, structure.S_f
        self.Hg = np.zeros((m + 3, 9))
        self.Hg[:m] = self.H
        self.Hg[m + np.arange(3), np.arange(3)] = 1.0
        self.diag = (np.arange(m), np.arange(m))
        self.diag_g = (np.arange(m + 3), np.arange(m + 3))
        self.prior_var = self.R = self.gyro_var = self.Rg = self.kernel_model = self.kernel_options = None


class Counters:
    """Updates made (``updates``) and runs of states moved onto another branch by :meth:`WindowFilter.settle`
    (``settled``)."""

    __slots__ = ("updates", "settled")

    def __init__(self) -> None:
        self.updates = self.settled = 0


class WindowFilter:
    """The window of one segment: means, marginal variances and cross-covariances with the newest state.

    Besides its settings (``model``, ``iterations``, ``step_tolerance_radps``, :attr:`branches`, the array's
    plane normal ``_normal``, ``lazy_steps``), what it holds is in six parts:

    - ``_store`` (:class:`WindowStore`): the window's arrays (means, variances, cross-covariances) and its
      slots (in use, lazy, the index of slot 0);
    - ``_lazy`` (:class:`LazyFactors`): the open epoch's factors ``T``, ``u``, ``W`` and the closed
      :class:`Epochs` the older states wait for;
    - ``_newest`` (:class:`NewestStep`): the newest state's covariance and the step into it;
    - ``_record`` (:class:`StepRecord`): the steps into the window's states, and whether the branch
      decision can evaluate the segment's updates;
    - ``_ops`` (:class:`FilterOperands`): the model's noise as variances, the compiled kernels' operands,
      the Jacobian buffers;
    - ``_counts`` (:class:`Counters`): updates made, runs settled (:attr:`n_updates`, :attr:`n_settled`).

    The hot paths (:meth:`advance`, :meth:`mean`, :meth:`settle`, :meth:`drop_oldest`) read the parts
    directly; the properties ``_P``, ``_mean``, ``_cross``, ``_lo``, ``_hi``, ``_base``, ``_epochs`` and
    ``_kernel_model`` give their fields under the names the tests read."""

    replays = True
    """Whether the stream may solve the window again from its raw samples (a new window, each state
    predicted from the one before it)."""

    compiled = True
    """Updates of the accelerometer readings alone through the compiled kernels
    (:mod:`gfimu.smoother.stream.kernels`); False: the numpy expressions they replace (the tests' oracle)."""

    deferred = True
    """The older states brought up to date only when read (:meth:`_boundary`); False: all of them at every
    epoch's end (the tests' oracle)."""

    def __init__(self, model: ArrayModel, capacity: int = 256, iterations: int = 4,
                 step_tolerance_radps: float = 1e-6, branches: bool = False) -> None:
        self.iterations = int(iterations)
        self.step_tolerance_radps = float(step_tolerance_radps)
        self._branches = bool(branches)
        self._normal = plane_normal(np.concatenate([np.atleast_2d(pos) for _, pos, _ in model.structure.geometry]))
        self._ops = FilterOperands(model)
        self.set_model(model)
        self._store = WindowStore(max(int(capacity), 8))
        self.lazy_steps = LAZY_STEPS or lazy_steps(self._store.cap)
        """Updates gathered into one epoch of the older states (:meth:`_boundary`)."""
        self._lazy = LazyFactors()
        self._newest = NewestStep()
        self._record = StepRecord()
        self._counts = Counters()

    # --- the parts' fields under the names read elsewhere (the tests) ---------------------
    n_updates = delegated("_counts", "updates", "Updates made.")
    n_settled = delegated("_counts", "settled", "Runs of states moved onto another branch by :meth:`settle`.")
    _P = delegated("_newest", "P")
    _mean = delegated("_store", "mean")
    _cross = delegated("_store", "cross")
    _lo = delegated("_store", "lo")
    _hi = delegated("_store", "hi")
    _base = delegated("_store", "base")
    _kernel_model = delegated("_ops", "kernel_model")
    _epochs = delegated("_lazy", "epochs")

    @property
    def branches(self) -> bool:
        """Try the other branches of each update's minimum (see :meth:`measure`)."""
        return self._branches

    @branches.setter
    def branches(self, value: bool) -> None:
        self._branches = bool(value)
        self.set_model(self.model)

    def set_model(self, model: ArrayModel) -> None:
        """Go on with the noise levels of ``model`` (the same array): the steps and readings to come
        are weighted by it, the window keeps what it has."""
        self.model = model
        ops, noise, structure, robust = self._ops, model.noise, model.structure, model.robust
        ops.prior_var = np.asarray(noise.first_sigma[:9], dtype=float) ** 2
        ops.R = noise.accel_sigma_mps2 ** 2
        ops.gyro_var = noise.gyro_sigma_radps ** 2
        ops.Rg = np.concatenate([ops.R, np.full(3, ops.gyro_var)])
        # the kernels' operands: contiguous copies of the structure matrix's blocks, the loss as a code
        ops.kernel_model = (np.ascontiguousarray(ops.R, dtype=float),
                            np.ascontiguousarray(structure.S_q, dtype=float),
                            np.ascontiguousarray(structure.S_dw, dtype=float),
                            np.ascontiguousarray(structure.S_f, dtype=float),
                            float(robust.accel_noise_slope_mps2_per_radps), float(robust.accel_robust_threshold),
                            kernels.loss_code(robust.accel_robust_threshold, robust.robust_loss))
        c_process = float(robust.process_robust_threshold)
        ops.kernel_options = (max(self.iterations, 1) + (1 if robust.accel_robust_threshold > 0 else 0),
                              self.step_tolerance_radps, self.branches, self._normal, BRANCH_PRIOR_MARGIN, c_process,
                              kernels.loss_code(c_process, robust.robust_loss))

    # --- window -------------------------------------------------------------------------
    def __len__(self) -> int:
        return self._store.hi - self._store.lo

    def _slot(self, k: int) -> int:
        store = self._store
        s = k - store.base
        if not store.lo <= s < store.hi:
            raise KeyError(f"state {k} is not in the window")
        return s

    def mean(self, k: int) -> np.ndarray:
        store = self._store
        s = k - store.base
        if s >= store.split:
            if s < store.hi:
                return store.mean[s]
        elif s >= store.lo:
            lazy = self._lazy
            if lazy.epochs.waits(k):
                self._bring_up(k + 1)
            return kernels.lazy_mean(store.mean[s], store.cross[s], lazy.u)
        raise KeyError(f"state {k} is not in the window")

    def sigma(self, k: int) -> np.ndarray:
        store = self._store
        s = self._slot(k)
        var = store.var[s]
        if s < store.split:
            if self._lazy.epochs.waits(k):
                self._bring_up(k + 1)
                var = store.var[s]
            C = store.cross[s]
            var = var - np.einsum("ij,jk,ik->i", C, self._lazy.W, C)
        return np.sqrt(np.clip(var, 0.0, None))

    def drop_oldest(self) -> None:
        store = self._store
        lo = store.lo
        if store.hi > lo:
            lo += 1
            store.lo = lo
            if store.split < lo:
                store.split = lo
            epochs = self._lazy.epochs
            if epochs.ep[3]:  # (no run waits: nothing to forget)
                epochs.forget_before(store.base + lo)

    # --- the older states: brought up to date when read ----------------------------------
    def _boundary(self) -> None:
        """:attr:`lazy_steps` updates gathered in T, u, W: the end of an epoch.

        Bringing every older state up to date at each epoch's end (:meth:`_flush`) costs O(window) per
        epoch, O(window / lazy_steps) per update: at 20 kHz a 0.2 s lag holds 4,000 states and that is
        most of an update. The states are read only where they leave the window (or where the branch
        decision looks, or a move flushes all), so the epoch's factors are kept instead and the lazy
        states marked as up to date as of its start; a state read later is brought up to date through
        the epochs since (:meth:`_bring_up`, their factors composed: :func:`kernels.compose_epochs
        <gfimu.smoother.stream.kernels.compose_epochs>`). That costs O(window / lazy_steps) per block
        of lazy_steps states read, O(window / lazy_steps²) per update: the same numbers to rounding."""
        if not self.deferred:
            self._flush()
            return
        store, lazy = self._store, self._lazy
        if store.split > store.lo:
            lazy.epochs.close(lazy.T, lazy.u, lazy.W, store.base + store.lo, store.base + store.split)
        lazy.T = np.eye(9)
        lazy.u = np.zeros(9)
        lazy.W = np.zeros((9, 9))
        store.split = store.hi

    def _bring_up(self, k_stop: float) -> None:
        """The waiting states before ``k_stop`` (and at least :attr:`lazy_steps` of a run) brought up to date
        as of the current epoch's start: each run's epochs since composed into one ``(T, u, W)`` and applied."""
        ep, base = self._lazy.epochs, self._store.base
        if not ep.ep[3] or ep.stale[ep.ep[2], 0] >= k_stop:  # no state before k_stop waits
            return
        if self.compiled:
            store = self._store
            kernels.epochs_bring_up(ep.T, ep.u, ep.W, ep.ep, ep.stale, _NEVER if k_stop == math.inf else int(k_stop),
                                    base + store.lo, self.lazy_steps, base, store.mean, store.var, store.cross)
            return
        Ts, us, Ws = ep.T[:ep.n], ep.u[:ep.n], ep.W[:ep.n]
        for k0, k1, first in ep.take(k_stop, base + self._store.lo, self.lazy_steps):
            T, u, W = Ts[first].copy(), us[first].copy(), Ws[first].copy()
            for e in range(first + 1, len(Ts)):
                u = u + T @ us[e]
                W = W + T @ Ws[e] @ T.T
                T = T @ Ts[e]
            self._apply(T, u, W, k0 - base, k1 - base)

    def _apply(self, T: np.ndarray, u: np.ndarray, W: np.ndarray, a: int, b: int) -> None:
        """The factors ``(T, u, W)`` applied to the states in slots ``[a, b)``: ``m += C u``, ``v -= diag(C W Cᵀ)``,
        ``C ← C T``."""
        store = self._store
        if self.compiled:
            kernels.flush_window(T, u, W, store.mean[a:b], store.var[a:b], store.cross[a:b])
            return
        C = store.cross[a:b]
        store.mean[a:b] += np.einsum("lij,j->li", C, u)
        store.var[a:b] -= np.einsum("lij,jk,lik->li", C, W, C)
        n = b - a
        tmp = np.matmul(C.reshape(9 * n, 9), T, out=store.tmp[a:b].reshape(9 * n, 9))
        store.cross[a:b] = tmp.reshape(n, 9, 9)

    def _flush(self) -> None:
        """Bring the old states up to date: every update moves each state of the window by products
        with 9×9 matrices common to all of them (``C_i ← C_i M``, ``m_i += C_i g``, ``v_i -= diag(C_i A
        C_iᵀ)``), so the old states' share of :attr:`lazy_steps` updates is gathered in T, u and W and
        applied to them at once: O(window / lazy_steps + lazy_steps) per update instead of O(window),
        the same numbers to rounding. The stale states are brought up to date first (:meth:`_bring_up`)."""
        store, lazy = self._store, self._lazy
        if self.compiled:  # (the block of samples flushes so too: gfimu.smoother.stream.block)
            ep = lazy.epochs
            kernels.flush_lazy(store.lo, store.split, store.base, self.lazy_steps, store.mean, store.var, store.cross,
                               lazy.T, lazy.u, lazy.W, ep.T, ep.u, ep.W, ep.ep, ep.stale)
        else:
            self._bring_up(math.inf)
            lazy.epochs.clear()
            if store.split > store.lo:
                self._apply(lazy.T, lazy.u, lazy.W, store.lo, store.split)
            lazy.T = np.eye(9)
            lazy.u = np.zeros(9)
            lazy.W = np.zeros((9, 9))
        store.split = store.hi

    def _make_room(self) -> None:
        store = self._store
        if store.hi < store.cap:
            return
        self._flush()
        n = store.hi - store.lo
        if n >= store.cap // 2:  # a window longer than expected (irregular steps): grow
            cap = 2 * store.cap
            for name in store.ARRAYS:
                old = getattr(store, name)
                new = np.zeros((cap,) + old.shape[1:], dtype=old.dtype)
                new[:n] = old[store.lo:store.hi]
                setattr(store, name, new)
            store.tmp = np.empty((cap, 9, 9))
            store.cap = cap
        else:
            kernels.move_to_start(store.lo, store.hi, *(getattr(store, name) for name in store.ARRAYS))
        store.base += store.lo
        store.lo, store.hi = 0, n
        store.split = n

    # --- model --------------------------------------------------------------------------
    def _measure(self, x: np.ndarray, gyro):
        """Prediction ``h(x)`` and Jacobian H of the readings (and gyroscope) at ``x``."""
        S_q = self.model.structure.S_q
        H = self._ops.H if gyro is None else self._ops.Hg
        n = S_q.shape[0]
        H[:n, :3] = S_q @ quadratic_terms_jacobian(x[:3])
        pred = H[:n, 3:] @ x[3:] + S_q @ quadratic_terms(x[:3])
        if gyro is None:
            return pred, H
        return np.concatenate([pred, x[:3]]), H

    def move_branch(self, k_first: int, kind: int, k_stop: int | None = None) -> None:
        """The states from ``k_first`` to the newest (or to ``k_stop``, excluded) onto branch ``kind`` of
        the readings' ambiguity (:func:`gfimu.smoother.solve.restarts.branch`: bit 1 ω flipped, bit 2 mirrored
        through the array's plane): their means, and the covariances by the linear part
        ``D = diag(A, I, I)`` (A = -I, the mirror I - 2nnᵀ, or both) on each moved state.

        A flip (``kind`` 1) is linear in the state, ``x' = D x`` with D diagonal (±1), so it moves the
        stored means and cross-covariances of the lazy states as it moves their values (``D m + D C u =
        D (m + C u)``; ``diag(D C W Cᵀ D) = diag(C W Cᵀ)``), and a moved newest state moves the factors
        still to come (T ← T Dᵀ): nothing is brought up to date first. A mirror moves ω̇ by a product
        with ω, so the window is brought up to date before it."""
        store = self._store
        if kind == 1 and self.deferred:
            self._flip(k_first, k_stop)
            return
        self._flush()
        first = self._slot(k_first)
        lo, hi = store.lo, store.hi
        stop = hi if k_stop is None else self._slot(k_stop)
        for i in range(first, stop):
            w, dw = branch(kind, store.mean[i, 0:3], store.mean[i, 3:6], self._normal)
            store.mean[i, 0:3], store.mean[i, 3:6] = w, dw
        A = np.eye(3)
        if kind & 2:
            A = A - 2.0 * np.outer(self._normal, self._normal)
        if kind & 1:
            A = -A
        D = np.eye(9)
        D[0:3, 0:3] = A
        # C_i = Cov(x_i, x_newest): the moved ones get D on their left; when the newest is moved, every
        # C_i gets Dᵀ on its right too
        store.cross[first:stop] = D @ store.cross[first:stop]
        if stop == hi:
            store.cross[lo:hi] = store.cross[lo:hi] @ D.T
            self._newest.P = D @ self._newest.P @ D.T

    def _means(self, a: int, b: int) -> np.ndarray:
        """The means of the states in slots ``[a, b)`` (a copy), the lazy ones given the updates since."""
        store = self._store
        self._bring_up(store.base + b)
        X = store.mean[a:b].copy()
        lazy = min(b, store.split) - a
        if lazy > 0:
            X[:lazy] += store.cross[a:a + lazy] @ self._lazy.u
        return X

    def _flip(self, k_first: int, k_stop: int | None) -> None:
        """:meth:`move_branch` of kind 1 (ω → -ω) on the stored values, lazy or not."""
        store = self._store
        a = self._slot(k_first)
        hi = store.hi
        b = hi if k_stop is None else self._slot(k_stop)
        store.mean[a:b, 0:3] *= -1.0
        store.cross[a:b, 0:3, :] *= -1.0  # D C
        if b == hi:  # the newest moved: C_i Dᵀ for every state (the lazy ones through T), P → D P Dᵀ
            store.cross[store.split:hi, :, 0:3] *= -1.0
            self._lazy.T[:, 0:3] *= -1.0
            P = self._newest.P.copy()
            P[0:3, :] *= -1.0
            P[:, 0:3] *= -1.0
            self._newest.P = P

    def _step_costs(self, X: np.ndarray, F: np.ndarray, Q_inv: np.ndarray) -> np.ndarray:
        """(4, 4, n - 1) costs of the motion-model steps between the n states ``X`` (ω, ω̇ columns
        first; ``F``, ``Q_inv``: the ω, ω̇ block of each step's transition and of its covariance's inverse,
        (n - 1, 6, 6)), from branch a of state j to branch b of state j + 1: the
        model's loss (:func:`gfimu.smoother.model.problem.robust_loss`, the Cauchy loss of the robust model at
        its threshold) of the RMS over the six ω, ω̇ rows of the step's whitened residual, times six."""
        n = len(X)
        W = np.empty((4, n, 6))
        for b in range(4):
            W[b, :, 0:3], W[b, :, 3:6] = branch(b, X[:, 0:3], X[:, 3:6], self._normal)
        pred = np.einsum("jkl,ajl->ajk", F, W[:, :-1])  # F x_j on each branch a
        d = W[None, :, 1:] - pred[:, None]  # (a, b, j, 6)
        e2 = np.einsum("abjk,jkl,abjl->abj", d, Q_inv, d) / 6.0
        robust = self.model.robust
        return 6.0 * robust_loss(e2, robust.process_robust_threshold, robust.robust_loss)

    def _readings_costs(self, X: np.ndarray, Y: np.ndarray) -> np.ndarray:
        """(4, n) costs of the readings ``Y`` of the n states ``X`` on each branch: half the squared
        residual over the accelerometer variances at each state's |ω| (the same on every branch: the
        branches keep |ω|). A planar array's readings fit all four alike; the flip always."""
        m, rb = self.model.structure, self.model.robust
        R = self._ops.R[None, :] + (rb.accel_noise_slope_mps2_per_radps ** 2) * np.sum(X[:, 0:3] ** 2, axis=1)[:, None]
        out = np.empty((4, len(X)))
        for b in range(4):
            w, dw = branch(b, X[:, 0:3], X[:, 3:6], self._normal)
            r = Y - (dw @ m.S_dw.T + X[:, 6:9] @ m.S_f.T + quadratic_terms(w) @ m.S_q.T)
            out[b] = np.sum(robust_loss(r * r / R, rb.accel_robust_threshold, rb.robust_loss), axis=1)
        return out

    def _settle_path(self, X: np.ndarray, steps: list, Y: np.ndarray) -> np.ndarray:
        """The branch of each of the states ``X[1:]`` that minimises the window's objective over the states
        ``X`` (the oldest first, held), the steps between them and the readings ``Y`` of ``X[1:]``, the newest on
        its own branch: dynamic programming (Viterbi) over :meth:`_step_costs` and :meth:`_readings_costs`; in
        one compiled call (:func:`kernels.settle_path <gfimu.smoother.stream.kernels.settle_path>`) unless
        :attr:`compiled` is off (these numpy expressions, its oracle)."""
        F = np.ascontiguousarray(np.stack([f[:6, :6] for f, _ in steps]), dtype=float)
        Q_inv = np.ascontiguousarray(np.linalg.inv(np.stack([q[:6, :6] for _, q in steps])))
        if self.compiled:
            R0, S_q, S_dw, S_f, slope, c_accel, accel_loss = self._ops.kernel_model
            c_process, process_loss = self._ops.kernel_options[5:7]
            return kernels.settle_path(np.ascontiguousarray(X, dtype=float), F, Q_inv, Y, R0, slope, S_q, S_dw, S_f,
                                       self._normal, c_process, process_loss, c_accel, accel_loss)
        step_cost = self._step_costs(X, F, Q_inv)
        node = self._readings_costs(X[1:], Y)
        node = node - node[0][None, :]  # only the differences between branches count
        # Viterbi from the oldest (branch 0) to the newest (branch 0)
        n = len(X) - 1
        cost = step_cost[0, :, 0] + node[:, 0]
        back = np.zeros((n, 4), dtype=np.int8)
        for j in range(1, n):
            total = cost[:, None] + step_cost[:, :, j]
            back[j] = np.argmin(total, axis=0)
            cost = total[back[j], np.arange(4)] + node[:, j]
        path = np.zeros(n, dtype=np.int8)
        state = 0
        for j in range(n - 1, 0, -1):
            state = int(back[j][state])
            path[j - 1] = state
        return path

    def settle(self, readings) -> int:
        """Decide again the branch of the state after the oldest, before the oldest leaves the window:
        where the step into it from the oldest is outlying (:data:`SETTLE_FALSE_ALARM`), the branches of
        the window's states after the oldest (four each: ω flipped, mirrored, both) that minimise the
        window's objective — the motion-model steps (:meth:`_step_costs`) and the readings
        (:meth:`_readings_costs`) — with the oldest and the newest state (or the last of
        :data:`SETTLE_STATES` after the oldest) on their own branch, by dynamic
        programming (exact over the 4ⁿ choices: the objective is a chain); if that puts the state after
        the oldest on another branch, its run on that branch moves there (:meth:`move_branch`) and is
        re-solved with the states next to it (:meth:`_resolve_run`). Every state is so decided once,
        with the window's data on both sides, before it becomes the oldest and leaves.

        The filter carries one branch per state; a run of states that went over to another branch
        (fast motion between samples leads the prediction, and so each update's minimum, onto it) and
        came back is a local minimum a Gaussian update cannot leave, and one that the lag's data on
        both sides of the run tell apart: the batch smoother's restarts
        (:mod:`gfimu.smoother.solve.restarts`) over a window that ends at the newest state.

        ``readings``: the accelerometer readings of the window's i-th state (0: the oldest),
        ``readings(i)``. Nothing is done with :attr:`branches` off, when the segment's updates used a
        gyroscope or factor groups (rows this decision does not evaluate), or with fewer than three
        states. Returns the number of states moved."""
        store, record = self._store, self._record
        lo, hi = store.lo, store.hi
        hi = min(hi, lo + 1 + SETTLE_STATES)
        if not self._branches or record.unsettled or hi - lo < 3:
            return 0
        k0 = store.base + lo
        step = store.step(k0 + 1)
        if step is None:
            return 0
        F, Q = step
        self._bring_up(k0 + 2)
        if self.compiled:
            e2 = kernels.window_step_residual2(F, Q, store.mean, store.cross, self._lazy.u, store.split, lo)
            if e2 < 0:  # singular
                return 0
        else:
            d = self.mean(k0 + 1)[:6] - F[:6, :6] @ self.mean(k0)[:6]
            try:
                e2 = float(d @ np.linalg.solve(Q[:6, :6], d))
            except np.linalg.LinAlgError:
                return 0
        if not e2 > OUTLYING_STEP2:
            return 0
        X = self._means(lo, hi)  # the oldest (held), then the states decided
        steps = [store.step(store.base + i) for i in range(lo + 1, hi)]
        if any(s is None for s in steps):
            return 0
        Y = np.vstack([np.asarray(readings(i), dtype=float) for i in range(1, hi - lo)])
        n = hi - lo - 1
        path = self._settle_path(X, steps, Y)
        kind = int(path[0])
        if kind == 0:
            return 0
        stop = 1
        while stop < n and path[stop] == kind:
            stop += 1
        self._flush()  # the re-solve reads and writes the means as stored
        self.move_branch(k0 + 1, kind, k0 + 1 + stop)
        self._resolve_run(min(stop + SETTLE_MARGIN, n - 1), steps, Y)
        self._counts.settled += 1
        return stop

    def _resolve_run(self, m: int, steps: list, Y: np.ndarray) -> None:
        """Gauss-Newton on the means of the ``m`` states after the oldest (a run just moved onto another
        branch, and the states after it) in the window's objective (``steps``: (F, Q) of the steps from
        the oldest on; ``Y``: the readings of the states after the oldest), the oldest and the state after
        them held: the filter fitted their ω̇ and f to the run's former branch, and the move carries over
        only the part of that fit that the branch map moves."""
        store = self._store
        if m < 1:
            return
        lo = store.lo + 1
        x_prev = store.mean[lo - 1]
        mdl = self.model.robust
        c_proc, loss = mdl.process_robust_threshold, mdl.robust_loss
        X = store.mean[lo:lo + m].copy()
        x_next = store.mean[lo + m]
        # whitening of each step (ω, ω̇ and f rows): L with Lᵀ L = Q⁻¹
        Ls = []
        Fs = []
        for j in range(m + 1):
            F, Q = steps[j]
            Ls.append(np.linalg.cholesky(np.linalg.inv(Q)).T)
            Fs.append(F)
        N = 9 * m
        for _ in range(SETTLE_ITERATIONS):
            A = np.zeros((N, N))
            g = np.zeros(N)
            for j in range(m):  # readings
                pred, H = self._measure(X[j], None)
                R = self._ops.R + (mdl.accel_noise_slope_mps2_per_radps ** 2) * float(X[j, 0:3] @ X[j, 0:3])
                r = Y[j] - pred
                sl = slice(9 * j, 9 * j + 9)
                HR = H.T / R
                A[sl, sl] += HR @ H
                g[sl] += HR @ r
            chain = [x_prev] + list(X) + [x_next]
            for j in range(m + 1):  # steps j -> j + 1 of the chain (the held ends are chain 0 and m + 1)
                L, F = Ls[j], Fs[j]
                e = L @ (chain[j + 1] - F @ chain[j])
                w = 1.0
                if c_proc > 0:
                    w = float(robust_weight(np.sqrt(float(e[:6] @ e[:6]) / 6.0), c_proc, loss))
                Jb, Ja = L, -L @ F  # d e / d x_{j+1}, d e / d x_j
                if j >= 1:
                    sa = slice(9 * (j - 1), 9 * j)
                    A[sa, sa] += w * Ja.T @ Ja
                    g[sa] -= w * Ja.T @ e
                if j < m:
                    sb = slice(9 * j, 9 * j + 9)
                    A[sb, sb] += w * Jb.T @ Jb
                    g[sb] -= w * Jb.T @ e
                if 1 <= j < m:
                    A[sa, sb] += w * Ja.T @ Jb
                    A[sb, sa] += w * Jb.T @ Ja
            try:
                dx = np.linalg.solve(A, g)
            except np.linalg.LinAlgError:
                return
            if not np.all(np.isfinite(dx)):
                return
            X += dx.reshape(m, 9)
            if np.max(np.abs(dx.reshape(m, 9)[:, 0:3])) < 1e-3:
                break
        store.mean[lo:lo + m] = X

    # --- the window interface both engines share (gfimu.smoother.stream.gtsam_window.GtsamWindow) ----
    def begin(self, k: int, t_ns: int, y, gyro=None, start=None, extra=None, once: bool = False) -> None:
        """The first state of a segment, index ``k``: the weak priors, then its readings (linearised
        from ``start``; ``once``: at ``start`` alone, :meth:`measure`)."""
        self.start(k)
        self._store.t_ns[0] = t_ns
        self.measure(y, gyro, start=start, extra=extra, once=once)

    def advance(self, k: int, step: Step, t_ns: int, y, gyro=None, extra=None, start=None, prev=None,
                once: bool = False) -> None:
        """State ``k``, one ``step`` (:meth:`ArrayModel.step`) after the newest: predict, then its readings
        (linearised from ``start``, else from the prediction and the other branches of the update's
        minimum; ``once``: at ``start`` alone, :meth:`measure`)."""
        record = self._record
        if not isinstance(step, Step):
            step = self.model.step(float(step))
        if step.c is not None or step.H0 is not None:
            record.unsettled = True  # rows of given step groups, which the branch decision does not evaluate
        if self.compiled and gyro is None and extra is None and start is None and step.H0 is None:
            self._advance_compiled(k, step, y)  # the prediction and the update in one compiled call
            self._store.keep_step(k, step.F, step.Q, t_ns)
            return
        self.predict(k, step)
        self._store.keep_step(k, step.F, step.Q, t_ns)
        self.measure(y, gyro, start=start, extra=extra, once=once)

    def _advance_compiled(self, k: int, step: Step, y) -> None:
        """:meth:`predict` then :meth:`measure` from the prediction, on the readings alone, through
        :func:`kernels.advance_update <gfimu.smoother.stream.kernels.advance_update>`: the same numbers as the
        two compiled calls it fuses, without their Python in between."""
        store, lazy, newest, ops = self._store, self._lazy, self._newest, self._ops
        hi = store.hi
        if k != store.base + hi:
            raise ValueError(f"state {k} does not follow the window's newest state")
        if hi >= store.cap:
            self._make_room()
            hi = store.hi
        F, Q = step.F, step.Q
        # (the factors T, u, W and the newest covariance P written in place by the call)
        split, ok = kernels.advance_update(
            F if F.flags.c_contiguous else np.ascontiguousarray(F, dtype=float),
            Q if Q.flags.c_contiguous else np.ascontiguousarray(Q, dtype=float),
            _ZERO9 if step.c is None else np.asarray(step.c, dtype=float), newest.P, lazy.T, lazy.u, lazy.W,
            store.mean, store.var, store.cross, store.lo, store.split, hi, _NEVER,
            np.ascontiguousarray(y, dtype=float), *ops.kernel_model, *ops.kernel_options)
        newest.Q, newest.F = Q, F
        hi += 1
        store.hi = hi
        if not ok:
            raise FilterFailure("singular innovation covariance or non-finite values in the update")
        store.split = split
        self._counts.updates += 1  # (the update's covariance written into the window: :meth:`_updated` in the kernel)
        if hi - split >= self.lazy_steps:
            self._boundary()

    def commit(self) -> None:
        """Nothing to do: every update is already solved."""

    @property
    def n_keys(self) -> int:
        return 3 * len(self)

    @property
    def n_slots(self) -> int:
        """The slots the window's arrays hold (they grow when the window outgrows them)."""
        return self._store.cap

    # --- updates ------------------------------------------------------------------------
    def start(self, k: int) -> None:
        """First state of a segment, index ``k``: the weak zero-mean priors."""
        store, lazy, newest = self._store, self._lazy, self._newest
        store.lo = store.hi = 0
        store.split = 0
        lazy.T = np.eye(9)
        lazy.u = np.zeros(9)
        lazy.W = np.zeros((9, 9))
        lazy.epochs = Epochs()
        store.base = k
        store.mean[0] = 0.0
        store.var[0] = self._ops.prior_var
        newest.P = np.diag(self._ops.prior_var)
        newest.Q = None
        newest.F = None
        store.has_step[0] = False
        self._record.unsettled = False
        store.cross[0] = newest.P
        store.hi = 1

    def predict(self, k: int, step: Step | float) -> None:
        """Append state ``k`` one ``step`` after the newest (:class:`~gfimu.smoother.stream.array_model.Step`:
        the step groups' rows as the transition ``x1 = F x0 + c + n``, n ~ N(0, Q), and their rows on the
        newest state alone, applied to it first; a float: :meth:`ArrayModel.step` of that many seconds)."""
        store, lazy = self._store, self._lazy
        if k != store.base + store.hi:
            raise ValueError(f"state {k} does not follow the window's newest state")
        if not isinstance(step, Step):
            step = self.model.step(float(step))
        if step.H0 is not None:
            self.update_linear(step.H0, step.z0)
        F, FT, Q = step.F, step.FT, step.Q
        self._make_room()
        lo, hi = store.split, store.hi  # the recent states at once, the old ones through T
        if self.compiled:
            x, P, lazy.T = kernels.predict_window(np.ascontiguousarray(F, dtype=float),
                                                  np.ascontiguousarray(Q, dtype=float),
                                                  _ZERO9 if step.c is None else np.asarray(step.c, dtype=float),
                                                  self._newest.P, self.mean(store.base + hi - 1), lazy.T,
                                                  store.cross[lo:hi])
        else:
            x = F @ self.mean(store.base + hi - 1)
            if step.c is not None:
                x = x + step.c
            P = F @ self._newest.P @ FT + Q
            P = 0.5 * (P + P.T)
            n = hi - lo
            if n:
                tmp = np.matmul(store.cross[lo:hi].reshape(9 * n, 9), FT, out=store.tmp[lo:hi].reshape(9 * n, 9))
                store.cross[lo:hi] = tmp.reshape(n, 9, 9)
            lazy.T = lazy.T @ FT
        store.mean[hi] = x
        store.var[hi] = np.diagonal(P)
        store.cross[hi] = P
        self._newest.P = P
        self._newest.Q = Q
        self._newest.F = F
        store.hi = hi + 1

    def _branch_starts(self, x: np.ndarray) -> list[np.ndarray]:
        """x on the other branches: ω flipped, ω mirrored through the array's plane (ω̇ moved so that a
        planar array's readings stay fitted), both (:func:`gfimu.smoother.solve.restarts.branch`)."""
        out = []
        for kind in (1, 2, 3):
            y = x.copy()
            y[0:3], y[3:6] = branch(kind, x[0:3], x[3:6], self._normal)
            out.append(y)
        return out

    def _solve(self, y: np.ndarray, gyro, xp: np.ndarray, P: np.ndarray, x: np.ndarray, extra,
               iterations: int | None = None):
        """Gauss-Newton on J from ``x`` (at most ``iterations`` steps; None: :attr:`iterations`): (x, H,
        S⁻¹ [H, ν] at the last linearisation, J at x)."""
        ops = self._ops
        R = ops.Rg if gyro is not None else ops.R
        diag = ops.diag_g if gyro is not None else ops.diag
        m = self.model.robust
        slope, c_robust = m.accel_noise_slope_mps2_per_radps, m.accel_robust_threshold
        n_acc = self.model.structure.S_q.shape[0]
        if extra is not None:
            n_extra = extra(x)[0].size
            y = np.concatenate([y, np.zeros(n_extra)])
            R = np.concatenate([R, np.ones(n_extra)])
            diag = (np.arange(R.size), np.arange(R.size))
        elif slope > 0 or c_robust > 0:
            R = R.copy()
        rhs = np.empty((R.size, 10))
        if iterations is None:
            iterations = max(self.iterations, 1) + (1 if c_robust > 0 else 0)
        for it in range(iterations):
            if slope > 0 or c_robust > 0:  # the accelerometer variances at x (motion-dependent, robust)
                base = ops.R if slope <= 0 else ops.R + (slope * slope) * float(x[0] * x[0] + x[1] * x[1] + x[2] * x[2])
                R[:n_acc] = base
                if c_robust > 0 and it > 0:
                    r = y[:n_acc] - self._measure(x, None)[0]
                    R[:n_acc] = base / robust_weight(r / np.sqrt(base), c_robust, m.robust_loss)
            pred, H = self._measure(x, gyro)
            if extra is not None:  # the groups' whitened rows: readings 0, prediction r(x), unit noise
                r_e, J_e = extra(x)
                H = np.vstack([H, J_e])
                pred = np.concatenate([pred, r_e])
            rhs[:, :9] = H
            rhs[:, 9] = y - pred + H @ (x - xp)  # innovation of the linearisation at x
            PHt = P @ H.T
            S = H @ PHt
            S[diag] += R
            try:
                Z = np.linalg.solve(S, rhs)  # S⁻¹ [H, ν]
            except np.linalg.LinAlgError as err:
                raise FilterFailure(f"singular innovation covariance ({err})") from err
            x_new = xp + PHt @ Z[:, -1]
            step = abs(x_new[0] - x[0]) + abs(x_new[1] - x[1]) + abs(x_new[2] - x[2])
            x = x_new
            if step < self.step_tolerance_radps and (c_robust <= 0 or it > 0):
                break
        H = H.copy()
        if not self.branches:
            return x, H, Z, 0.0
        pred = self._measure(x, gyro)[0]
        if extra is not None:
            pred = np.concatenate([pred, extra(x)[0]])
        r = y - pred
        d = x - xp
        try:
            prior = float(d @ np.linalg.solve(P, d))
        except np.linalg.LinAlgError:
            prior = 0.0
        return x, H, Z, float(np.sum(r * r / R)) + prior

    def _measure_compiled(self, y, xp, P, x0, from_prediction: bool, iterations: int | None = None) -> None:
        """:meth:`measure` on the readings alone through :func:`kernels.measure_update
        <gfimu.smoother.stream.kernels.measure_update>` (the branches and the robust step only from the
        prediction, as :meth:`measure` tries them; at most ``iterations``, None: :attr:`iterations`)."""
        R0, S_q, S_dw, S_f, slope, c_robust, loss = self._ops.kernel_model
        if iterations is None:
            iterations = max(self.iterations, 1) + (1 if c_robust > 0 else 0)
        robust, store, lazy, Q = self.model.robust, self._store, self._lazy, self._newest.Q
        c_process = float(robust.process_robust_threshold)
        robust_step = from_prediction and Q is not None and c_process > 0
        hi, lo = store.hi, store.split
        T, u, W, P_after, P_before, ok = kernels.measure_update(
            np.ascontiguousarray(y, dtype=float), xp, np.ascontiguousarray(P), np.array(x0, dtype=float), R0, S_q,
            S_dw, S_f, slope, c_robust, loss, iterations, self.step_tolerance_radps, self.branches and from_prediction,
            self._normal, BRANCH_PRIOR_MARGIN, c_process, kernels.loss_code(c_process, robust.robust_loss),
            Q if robust_step else P, robust_step, lazy.T, lazy.u, lazy.W, store.mean[lo:hi], store.var[lo:hi],
            store.cross[lo:hi])
        if not ok:
            raise FilterFailure("singular innovation covariance or non-finite values in the update")
        lazy.T, lazy.u, lazy.W = T, u, W
        self._updated(P_after)

    def measure(self, y: np.ndarray, gyro=None, start=None, extra=None, once: bool = False) -> None:
        """Gauss-Newton update of the newest state with its readings, moving every state of the window.

        The update is the minimum of ``J(x) = ||y - h(x)||²_R + ||x - x̂||²_P`` (the readings and the
        prediction x̂): Gauss-Newton from the prediction (or ``start``), and, with :attr:`branches`,
        from the other branches of that minimum too (ω sign-flipped, ω mirrored through the array's
        plane, both: :mod:`gfimu.smoother.solve.restarts`), keeping the lowest J. The readings see ω only
        through q(ω), and a planar array confuses ω with its mirror image; a prediction far from the
        truth (fast motion between samples) otherwise leads Gauss-Newton onto such a branch.

        ``extra``: the factor groups' rows at this sample (:meth:`ArrayModel.sample_terms`), or None.

        ``once``: the update linearised at ``start`` alone, not iterated from it: a stretch whose states are
        decided already (re-solved whole), filtered again to carry its information on. Iterated, each update
        goes to the filter's own minimum of that sample, which early in the stretch (the weak priors, ω seen
        through q(ω) alone, ill-posed near rest) can lie far from the decided state, and the error is carried
        on for seconds."""
        store = self._store
        hi = store.hi
        xp = store.mean[hi - 1].copy()
        P = self._newest.P
        if gyro is not None or extra is not None:
            self._record.unsettled = True
        if gyro is not None:
            y = np.concatenate([y, gyro])
        x0 = xp if start is None else np.asarray(start, dtype=float)
        once = once and start is not None
        if self.compiled and gyro is None and extra is None:  # the whole update in one compiled call
            self._measure_compiled(y, xp, P, x0, start is None, 1 if once else None)
            return
        best = self._solve(y, gyro, xp, P, x0, extra, iterations=1 if once else None)
        if self.branches and start is None and gyro is None:
            try:
                P_inv = np.linalg.inv(P)
            except np.linalg.LinAlgError:
                P_inv = None
            for branch in self._branch_starts(best[0]):
                if P_inv is not None:  # a branch the prediction rules out by more than 5 σ is not tried
                    d = branch - xp
                    if float(d @ P_inv @ d) > best[3] + BRANCH_PRIOR_MARGIN:
                        continue
                # two steps tell a branch that loses; one that may win is solved to the end
                candidate = self._solve(y, gyro, xp, P, branch, extra, iterations=2)
                if candidate[3] < best[3]:
                    candidate = self._solve(y, gyro, xp, P, candidate[0], extra)
                if candidate[3] < best[3]:
                    best = candidate
        robust = self.model.robust
        c = robust.process_robust_threshold
        if c > 0 and start is None and self._newest.Q is not None:
            # the robust loss of the motion-model step (the batch smoother's IRLS weight of the step's
            # whitened residual, its norm over √rows): a sudden jerk widens this step's process noise
            d = best[0] - xp
            try:
                e2 = float(d @ np.linalg.solve(P, d)) / d.size
            except np.linalg.LinAlgError:
                e2 = 0.0
            w = float(robust_weight(np.sqrt(e2), c, robust.robust_loss))
            if w < 1.0:
                P = P + (1.0 / w - 1.0) * self._newest.Q
                P = 0.5 * (P + P.T)
                self._newest.P = P
                store.cross[hi - 1] = P
                store.var[hi - 1] = np.diagonal(P)
                best = self._solve(y, gyro, xp, P, best[0], extra)
        _, H, Z, _ = best
        self._update(H, Z, P)  # the last linearisation moves the whole window

    def update_linear(self, H: np.ndarray, z: np.ndarray) -> None:
        """A linear measurement ``H x = z`` (unit noise) of the newest state, moving the whole window."""
        P = self._newest.P
        xp = self.mean(self._store.base + self._store.hi - 1)
        S = H @ P @ H.T + np.eye(len(z))
        rhs = np.column_stack([H, z - H @ xp])
        try:
            Z = np.linalg.solve(S, rhs)
        except np.linalg.LinAlgError as err:
            raise FilterFailure(f"singular innovation covariance ({err})") from err
        self._update(H, Z, P)

    def _update(self, H: np.ndarray, Z: np.ndarray, P: np.ndarray) -> None:
        """Move every state of the window by the update ``S⁻¹ [H, ν]`` (``Z``) of the newest state, whose
        covariance before it is ``P``."""
        store, lazy = self._store, self._lazy
        hi = store.hi
        if self.compiled:
            lo = store.split
            T, u, W, P_new, ok = kernels.update_window(np.ascontiguousarray(H.T @ Z, dtype=float), P, lazy.T,
                                                       lazy.u, lazy.W, store.mean[lo:hi], store.var[lo:hi],
                                                       store.cross[lo:hi])
            if not ok:
                raise FilterFailure("non-finite values in the update")
            lazy.T, lazy.u, lazy.W = T, u, W
            self._updated(P_new)
            return
        g = H.T @ Z[:, -1]  # Hᵀ S⁻¹ ν
        A = H.T @ Z[:, :-1]  # Hᵀ S⁻¹ H
        if not (np.all(np.isfinite(g)) and np.all(np.isfinite(A))):
            raise FilterFailure("non-finite values in the update")
        lo = store.split  # the recent states at once; the old ones through T, u, W (_flush)
        lazy.u = lazy.u + lazy.T @ g
        TA = lazy.T @ A
        lazy.W = lazy.W + TA @ lazy.T.T
        lazy.T = lazy.T - TA @ P
        n = hi - lo
        cross = store.cross[lo:hi].reshape(9 * n, 9)  # the stack as one matrix: one BLAS call per product
        # (einsum, not BLAS gemv: OpenBLAS threads a gemv this size, and on a busy machine waiting for its
        # second thread costs milliseconds)
        store.mean[lo:hi] += np.einsum("lij,j->li", cross.reshape(n, 9, 9), g)
        CA = np.matmul(cross, A, out=store.tmp[lo:hi].reshape(9 * n, 9))
        store.var[lo:hi] -= np.einsum("lij,lij->li", CA.reshape(n, 9, 9), cross.reshape(n, 9, 9))
        # C_i (I - A P) = C_i - (C_i A) P
        cross -= CA @ P
        P_new = P - P @ A @ P
        self._updated(0.5 * (P_new + P_new.T))

    def _updated(self, P_new: np.ndarray) -> None:
        """The newest state's covariance after an update; the lazy states brought up to date when due."""
        store = self._store
        hi = store.hi
        self._newest.P = P_new
        store.cross[hi - 1] = P_new
        store.var[hi - 1] = np.diagonal(P_new)
        self._counts.updates += 1
        if hi - store.split >= self.lazy_steps:
            self._boundary()
