"""What a smoother run returns: the estimate and everything chosen or measured on the way."""

from __future__ import annotations

from dataclasses import dataclass, fields

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

    @property
    def sigma(self) -> dict:
        return self.motion.sigma


class SmootherEstimatorRuns:
    """What the batch and fixed-lag estimators share: their model options as plain
    :class:`gfimu.smoother.graph.SmootherOptions`, and :meth:`estimate` keeping the newest
    :class:`SmootherResult` (in the estimator's ``_runs`` list) behind :attr:`last_tuning`.
    A subclass is a :class:`SmootherOptions` dataclass that defines ``result(log, progress)``."""

    def options(self):
        from .graph import SmootherOptions

        return SmootherOptions(**{f.name: getattr(self, f.name) for f in fields(SmootherOptions)})

    def estimate(self, log, progress: bool = False) -> Motion:
        res = self.result(log, progress)
        self._runs[:] = [res]
        return res.motion

    @property
    def last_tuning(self) -> list:
        """The process noise chosen from the data in the newest :meth:`estimate`, per solve window
        (:class:`gfimu.smoother.tuning.Tuning`; empty when not tuned); :meth:`result` returns it too."""
        return list(self._runs[-1].tunings) if self._runs else []
