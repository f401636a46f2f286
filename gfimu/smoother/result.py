"""What a smoother run returns: the estimate and everything chosen or measured on the way."""

from __future__ import annotations

from dataclasses import dataclass

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
