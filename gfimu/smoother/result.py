"""What a smoother run returns: the estimate and everything chosen or measured on the way."""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass, field, fields

from ..estimate import Estimate, Report
from ..motion import Motion


@dataclass(frozen=True)
class SmootherResult:
    """What one run of the batch or fixed-lag smoother produced.

    ``motion`` carries the estimate and, when asked for, its per-sample one-sigma marginal
    uncertainties (``motion.sigma``, also :attr:`sigma`)."""

    motion: Motion
    tunings: tuple = ()
    """Per solve window: the process noise chosen from the data (:class:`gfimu.smoother.tuning.Tuning`)."""
    calibration: tuple = ()
    """Per solve window: calibration variable name -> estimate."""
    iterations: int = 0
    """Solver iterations, summed over the windows (and re-weighting passes)."""
    cost: float = float("nan")
    """Final cost (half the sum of squared whitened residuals), summed over the windows."""
    windows: int = 1
    """Solve windows of a batch run (0: a stream)."""
    warnings: tuple = ()
    """Plain-text notes on anything that went less well than planned (e.g. a window that did not converge)."""
    model_check: object | None = None
    """The batch smoother's check of the readings against a rigid body (:class:`gfimu.smoother.auto.ModelCheck`),
    None when it did not run."""
    timings: Mapping[str, float] = field(default_factory=dict)
    """Seconds per step of the run (empty: not timed by step)."""

    @property
    def sigma(self) -> dict:
        return self.motion.sigma

    def report(self, method: str, estimator, seconds: float) -> Report:
        """The :class:`~gfimu.estimate.Report` of this run of ``estimator`` as ``method``, which took
        ``seconds`` in all (the timings by step when the run has them)."""
        return Report.of(method, estimator, timings=dict(self.timings) or {"estimate": seconds},
                         warnings=self.warnings, model_check=self.model_check, tunings=self.tunings,
                         calibration=self.calibration, iterations=self.iterations, cost=self.cost,
                         windows=self.windows)


class SmootherEstimator:
    """What the batch and fixed-lag estimators share: their model options as plain
    :class:`gfimu.smoother.graph.SmootherOptions`, and :meth:`estimate` returning the motion with
    the :class:`~gfimu.estimate.Report` of the run (the estimator itself keeps nothing of it).
    A subclass is a :class:`SmootherOptions` dataclass that defines ``method`` (its name in
    :data:`gfimu.methods.METHODS`) and ``result(log, progress)`` (the :class:`SmootherResult`)."""

    method = ""

    def options(self):
        from .graph import SmootherOptions

        return SmootherOptions(**{f.name: getattr(self, f.name) for f in fields(SmootherOptions)})

    def estimate(self, log, progress: bool = False) -> Estimate:
        """The smoother on ``log``: :class:`~gfimu.estimate.Estimate` ``(motion, report)``; the report
        carries the noise chosen, the model check, the solver's iterations and cost, and its notes."""
        t0 = time.perf_counter()
        res = self.result(log, progress)
        return Estimate(res.motion, res.report(self.method, self, time.perf_counter() - t0))
