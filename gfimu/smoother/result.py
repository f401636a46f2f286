"""What a smoother run returns: the estimate and everything chosen or measured on the way."""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Mapping
from dataclasses import dataclass, field, fields

from ..errors import InputError
from ..estimate import Estimate, Report
from ..motion import Motion
from .model.option_groups import assemble


@dataclass(frozen=True)
class SmootherResult:
    """What one run of the batch or fixed-lag smoother produced.

    ``motion`` carries the estimate and, when asked for, its per-sample one-sigma marginal
    uncertainties (``motion.sigma``, also :attr:`sigma`)."""

    motion: Motion
    tunings: tuple = ()
    """Per solve window: the process noise chosen from the data (:class:`gfimu.smoother.tuning.evidence.Tuning`)."""
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
    """The batch smoother's check of the readings against a rigid body (:class:`gfimu.smoother.tuning.model_choice.ModelCheck`),
    None when it did not run."""
    timings: Mapping[str, float] = field(default_factory=dict)
    """Seconds per step of the run (empty: not timed by step)."""
    per_sample: Motion | None = None
    """The per-sample ML estimate of the whole log when the run made one (the batch smoother's model
    check of an inconsistent log); the guard (:mod:`gfimu.smoother.guard`) reuses it."""

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


@dataclass(frozen=True)
@assemble("guard")
class SmootherEstimator:
    """What the batch and fixed-lag estimators share: their options as plain
    :class:`gfimu.smoother.model.problem.SmootherOptions` (:meth:`options`), the ``guard`` option, and :meth:`estimate`
    returning the motion with the :class:`~gfimu.estimate.Report` of the run (the estimator itself keeps nothing
    of it). A subclass is a dataclass of option groups (:mod:`gfimu.smoother.model.option_groups`) that defines
    ``method`` (its name in :data:`gfimu.methods.METHODS`) and ``result(log, progress)`` (the
    :class:`SmootherResult`)."""

    method = ""

    def __post_init__(self) -> None:
        from .guard import GUARD_MODES

        if self.guard not in GUARD_MODES:
            raise InputError(f"smoother option guard must be one of {', '.join(map(repr, GUARD_MODES))}, "
                             f"got {self.guard!r}")
        parent = super()
        if hasattr(parent, "__post_init__"):
            parent.__post_init__()

    def options(self):
        from .model.problem import SmootherOptions

        own = {f.name for f in fields(self)}
        return SmootherOptions(**{f.name: getattr(self, f.name) for f in fields(SmootherOptions) if f.name in own})

    def estimate(self, log, progress: bool = False) -> Estimate:
        """The smoother on ``log``: :class:`~gfimu.estimate.Estimate` ``(motion, report)``; the report
        carries the noise chosen, the model check, the solver's iterations and cost, its notes, and what
        the guard found (:mod:`gfimu.smoother.guard`, unless ``guard='off'``)."""
        t0 = time.perf_counter()
        res = self.result(log, progress)
        seconds = time.perf_counter() - t0
        report = res.report(self.method, self, seconds)
        if self.guard == "off":
            return Estimate(res.motion, report)
        t1 = time.perf_counter()
        motion, outcome = guarded(log, res, self.guard, self.options())
        note = outcome.message()
        report = dataclasses.replace(report.with_timings(guard=time.perf_counter() - t1), guard=outcome,
                                     warnings=report.warnings + ((note,) if note else ()))
        return Estimate(motion, report)


def guarded(log, res: SmootherResult, mode: str, options):
    """(motion, :class:`gfimu.smoother.guard.GuardResult`) of the smoother's result ``res`` on ``log`` with
    the guard in ``mode`` ('replace' or 'warn'). The guard does not judge a smoother that used more than
    the accelerometers the per-sample fit sees (a gyroscope, an inclinometer, self-calibration): the result
    says why."""
    from ..estimators.ml import MLEstimator
    from .tuning.model_choice import check_model
    from .guard import GuardResult, check, replaced

    why = None
    if options.use_gyro and log.array.gyroscope is not None and getattr(log, "gyro_b_radps", None) is not None:
        why = "the smoother uses the gyroscope, which the per-sample fit does not"
    elif (options.estimate_attitude and options.use_inclinometer and log.array.inclinometer is not None
          and getattr(log, "tilt_rad", None) is not None):
        why = "the smoother uses the inclinometer, which the per-sample fit does not"
    elif options.self_calibrate_bias or options.self_calibrate_scale:
        why = "the smoother calibrates the readings, which the per-sample fit does not"
    elif res.model_check is not None and getattr(res.model_check, "constant", False):
        why = "the readings are constant"
    elif len(log) < 2:
        why = "fewer than 2 samples"
    else:
        why = MLEstimator().applicable(log.array)
    if why:
        return res.motion, GuardResult(mode, samples=len(log), note=f"not checked: {why}")
    per_sample = res.per_sample if res.per_sample is not None else MLEstimator().estimate_motion(log)
    model = res.model_check if res.model_check is not None and res.windows > 0 else check_model(log, per_sample)
    outcome = check(log, res.motion, per_sample, model, mode)
    return (replaced(res.motion, per_sample, outcome) if mode == "replace" else res.motion), outcome
