"""The fixed-lag smoother's ``gtsam`` engine: gtsam's ``IncrementalFixedLagSmoother`` (iSAM2)
behind the same window interface as the numpy engine (:class:`gfimu.smoother.stream.window_filter.WindowFilter`),
so that :class:`gfimu.smoother.stream.fixed_lag.FixedLagSmoother` streams through either without asking
which: :meth:`begin` (the first state of a segment), :meth:`advance` (the next state), :meth:`commit`
(solve what was added), :meth:`mean`, :meth:`sigma`, :meth:`drop_oldest`, :attr:`n_keys`,
:attr:`n_slots`, :meth:`set_model`, :meth:`move_branch`. A failed update raises
:class:`gfimu.smoother.stream.window_filter.FilterFailure`, as the numpy engine does.

The factors are those of :class:`gfimu.smoother.stream.array_model.ArrayModel`; keys carry the start
time of their marginalisation block (``stamp``), so gtsam marginalises one block of states at a
time rather than re-eliminating the window at every update.
"""

from __future__ import annotations

import numpy as np

from . import array_model as model
from .window_filter import FilterFailure
from .array_model import gtsam
from ..model.layout import OMEGA, OMEGA_DOT, SPECIFIC_FORCE


class GtsamWindow:
    """iSAM2's fixed-lag smoother over the window of one segment."""

    replays = False
    """Whether the stream may solve the window again from its raw samples: not here (each new state's start
    value comes from the states before it, which iSAM2 gives only after a commit; the stream's own model
    runs on the numpy engine)."""

    def __init__(self, array_model, smoother_lag_s: float, stamp, relinearize_threshold: float,
                 relinearize_skip: int, factorization: str = "QR") -> None:
        self.model = array_model
        self._stamp = stamp
        params = gtsam.ISAM2Params()
        # Only ω enters the factors nonlinearly (through q(ω)); the Jacobians of
        # ω̇ and f are constant, so relinearising them would only cost time.
        thresholds = gtsam.ISAM2ThresholdMap()
        thresholds.insert(("w", np.full(3, relinearize_threshold)))
        thresholds.insert(("d", np.full(3, 1e300)))
        thresholds.insert(("f", np.full(3, 1e300)))
        params.setRelinearizeThreshold(thresholds)
        params.relinearizeSkip = relinearize_skip
        # QR rather than Cholesky: the densities chosen from the data can be tiny about some axes
        # (1e-4 of the others on a turntable), and gtsam's Cholesky then reports an indeterminate
        # system; QR works on the square-root information and costs the same here.
        params.setFactorization(factorization)
        params.findUnusedFactorSlots = True  # reuse the slots of marginalised factors: bounded memory
        self._smoother = gtsam.IncrementalFixedLagSmoother(smoother_lag_s, params)
        self._pending()

    def _pending(self) -> None:
        self._graph = gtsam.NonlinearFactorGraph()
        self._values = gtsam.Values()
        self._stamps: dict = {}

    def _add(self, k: int, t_ns: int, y, gyro, extra, x) -> None:
        self.model.add_measurement(self._graph, k, y, gyro, extra)
        model.insert_state(self._values, k, x[OMEGA], x[OMEGA_DOT], x[SPECIFIC_FORCE])
        t = self._stamp(t_ns)
        for key in model.keys(k):
            self._stamps[key] = t

    def begin(self, k: int, t_ns: int, y, gyro=None, start=None, extra=None) -> None:
        """The first state of a segment: the weak priors and its readings, started from ``start``."""
        self.model.add_priors(self._graph, k)
        self._add(k, t_ns, y, gyro, extra, np.asarray(start, dtype=float))

    def advance(self, k: int, step, t_ns: int, y, gyro=None, extra=None, start=None, prev=None) -> None:
        """State ``k``, one ``step`` (:meth:`ArrayModel.step`) after the newest: the step groups' rows and
        its readings, started from ``start`` or from ``prev`` (the newest state's ω, ω̇, f) one step on."""
        if start is None:
            start = self.model.predict_step(step, np.concatenate(prev), y)
        self.model.add_process(self._graph, k - 1, k, step)
        self._add(k, t_ns, y, gyro, extra, np.asarray(start, dtype=float))

    def commit(self) -> None:
        """Solve with what was added since the last commit."""
        graph, values, stamps = self._graph, self._values, self._stamps
        self._pending()
        try:
            self._smoother.update(graph, values, stamps)
        except RuntimeError as err:
            raise FilterFailure(str(err).strip()) from err

    def mean(self, k: int) -> np.ndarray:
        calc = self._smoother.calculateEstimateVector
        try:
            return np.concatenate([calc(key).reshape(3) for key in model.keys(k)])
        except RuntimeError as err:  # gtsam's IndeterminantLinearSystem and the like
            raise FilterFailure(f"could not solve the state: {str(err).strip()}") from err

    def sigma(self, k: int) -> np.ndarray:
        try:
            return np.concatenate([np.sqrt(np.clip(np.diag(self._smoother.marginalCovariance(key)), 0, None))
                                   for key in model.keys(k)])
        except RuntimeError as err:
            raise FilterFailure(f"could not compute the uncertainty: {str(err).strip()}") from err

    def drop_oldest(self) -> None:
        """Nothing to do: gtsam marginalises by the keys' timestamps."""

    def set_model(self, array_model) -> None:
        self.model = array_model

    def move_branch(self, k_first: int, kind: int, k_stop: int | None = None) -> None:
        raise NotImplementedError("the gtsam engine keeps its states' branch (the stream's model runs on the numpy engine)")

    def settle(self, readings) -> int:
        """Nothing: the gtsam engine keeps its states' branch (the numpy engine decides it again)."""
        return 0

    @property
    def n_keys(self) -> int:
        return len(self._smoother.timestamps())

    @property
    def n_slots(self) -> int:
        return int(self._smoother.getFactors().size())
