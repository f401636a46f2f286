"""What the batch and fixed-lag estimators share: their options, the guard, and ``estimate()``.

A smoother run returns what every method returns, an :class:`~gfimu.estimate.Estimate`: the motion
and the :class:`~gfimu.estimate.Report` of everything chosen or measured on the way (noise tuned per
window, calibration, solver iterations and cost, the model check, the per-sample estimate it made).
:meth:`SmootherEstimator.estimate` is the entry: it runs the engine and then the guard."""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, fields

from ..estimate import Estimate
from .model.option_groups import (GROUP_CLASSES, AttitudeOptions, GuardOptions, ModelGroups, ModelOptions,
                            SelfCalibrationOptions, assemble, groups_of)


@dataclass(frozen=True)
@assemble("guard")
class SmootherEstimator:
    """What the batch and fixed-lag estimators share: the option groups of their model together
    (:attr:`model_groups`), the ``guard`` option, and :meth:`estimate`
    returning the motion with the :class:`~gfimu.estimate.Report` of the run (the estimator itself keeps nothing
    of it). A subclass is a dataclass of option groups (:mod:`gfimu.smoother.model.option_groups`) that defines
    ``method`` (its name in :data:`gfimu.methods.METHODS`) and ``result(log, progress)``: the engine's run,
    an :class:`~gfimu.estimate.Estimate` before the guard (callers use :meth:`estimate`)."""

    method = ""

    @property
    def model_groups(self) -> ModelGroups:
        """The option groups of the estimator's model (:class:`~gfimu.smoother.model.option_groups.ModelGroups`), what
        its smoother is made of; a group it does not carry at its defaults (the fixed-lag estimator: the batch
        model, attitude and self-calibration)."""
        own = groups_of(self)
        return ModelGroups(*(getattr(self, name) if name in own else GROUP_CLASSES[name]() for name in ModelGroups._fields))

    def estimate(self, log, progress: bool = False) -> Estimate:
        """The smoother on ``log``: :class:`~gfimu.estimate.Estimate` ``(motion, report)``; the report
        carries the noise chosen, the model check, the solver's iterations and cost, its notes, and what
        the guard found (:mod:`gfimu.smoother.guard`, unless ``guard='off'``)."""
        t0 = time.perf_counter()
        ahead = self._per_sample_ahead(log) if self.guard != "off" else None
        try:
            run = self.result(log, progress)
        except BaseException:
            if ahead is not None:
                ahead.close()
            raise
        seconds = time.perf_counter() - t0
        report = run.report if run.report.timings else run.report.with_timings(estimate=seconds)
        if self.guard == "off":
            return Estimate(run.motion, report)
        t1 = time.perf_counter()
        if ahead is not None:
            per_sample = _taken(ahead)
            if run.report.per_sample is None and per_sample is not None:
                run = Estimate(run.motion, dataclasses.replace(run.report, per_sample=per_sample))
                report = dataclasses.replace(report, per_sample=per_sample)
        # the fixed-lag smoother carries no attitude, inclinometer nor calibration
        motion, outcome = guarded(log, run, GuardOptions(self.guard), self.model, getattr(self, "attitude", None),
                                  getattr(self, "self_calibration", None))
        note = outcome.message()
        notes = (note,) if note else ()
        if self.model_groups.solve.compute_sigma:
            notes += self._calibration_note(log, report)
        report = dataclasses.replace(report.with_timings(guard=time.perf_counter() - t1), guard=outcome,
                                     warnings=report.warnings + notes)
        return Estimate(motion, report)

    @staticmethod
    def _calibration_note(log, report) -> tuple[str, ...]:
        """σ's warning where the readings' misfit is mostly a calibration error, a bias σ does not include
        (:func:`gfimu.array_misfit.misfit_warning`, on the per-sample estimate the report carries: the run's, or
        the one made beside it for the guard; only where the model check found the readings beyond white noise)."""
        check = report.model_check
        if report.per_sample is None or check is None or getattr(check, "consistent", True):
            return ()
        from ..array_misfit import misfit_warning

        note = misfit_warning(log, report.per_sample)
        return (note,) if note else ()

    def _per_sample_ahead(self, log):
        """The per-sample estimate the guard compares the run with, begun beside the run where the engine makes
        none of its own (a process of its own, :class:`~gfimu.smoother.stream.choice_worker.ChoiceProcess`,
        whose answer :func:`_taken` reads), or None: here, none (the batch engine makes it to start from)."""
        return None


def _taken(process):
    """The answer of a :meth:`SmootherEstimator._per_sample_ahead` process, or None where it failed (the guard
    then computes it, and raises there what computing it raises); the process ended."""
    try:
        return process.result()
    except Exception:  # noqa: BLE001 - computed again by the guard, where its error belongs
        return None
    finally:
        process.close()


def guarded(log, run: Estimate, guard: GuardOptions, model: ModelOptions, attitude: AttitudeOptions | None = None,
            self_calibration: SelfCalibrationOptions | None = None):
    """(motion, :class:`gfimu.smoother.guard.GuardResult`) of the smoother's run ``run`` on ``log`` with
    the guard's options ``guard`` (its mode 'replace' or 'warn'). The smoother's ``model``, ``attitude`` and
    ``self_calibration`` (None: a smoother without them, the fixed-lag smoother) say what it used beyond the
    accelerometers (:func:`unguarded`): the guard does not judge a smoother that used more than the
    accelerometers the per-sample fit sees (a gyroscope, an inclinometer, self-calibration, factor groups):
    the result says why."""
    from ..estimators.ml import MLEstimator
    from .tuning.model_choice import check_model
    from .guard import GuardResult, check, replaced

    mode = guard.guard
    report = run.report
    why = unguarded(log, model, attitude, self_calibration, report.model_check)
    if why:
        return run.motion, GuardResult(mode, samples=len(log), note=f"not checked: {why}")
    per_sample = report.per_sample if report.per_sample is not None else MLEstimator().estimate_motion(log)
    model_check = (report.model_check if report.model_check is not None and report.windows
                   else check_model(log, per_sample))
    outcome = check(log, run.motion, per_sample, model_check, mode)
    if mode != "replace":
        return run.motion, outcome
    return replaced(run.motion, per_sample, outcome, model_check, log.array), outcome


def unguarded(log, model: ModelOptions, attitude: AttitudeOptions | None = None,
              self_calibration: SelfCalibrationOptions | None = None, model_check=None) -> str | None:
    """Why the guard does not judge a smoother of ``model``, ``attitude`` and ``self_calibration`` (None: the
    smoother has none, as the fixed-lag smoother) on ``log`` (its model check ``model_check``, when made), or
    None when it does (and then needs the per-sample estimate of the whole log)."""
    from ..estimators.ml import MLEstimator

    if model.use_gyro and log.array.gyroscope is not None and getattr(log, "gyro_b_radps", None) is not None:
        return "the smoother uses the gyroscope, which the per-sample fit does not"
    if (attitude is not None and attitude.estimate_attitude and attitude.use_inclinometer
            and log.array.inclinometer is not None and getattr(log, "tilt_rad", None) is not None):
        return "the smoother uses the inclinometer, which the per-sample fit does not"
    if self_calibration is not None and self_calibration.calibrates:
        return "the smoother calibrates the readings, which the per-sample fit does not"
    if model.factor_groups:
        return "the smoother uses factor groups (more than the readings), which the per-sample fit does not"
    if model_check is not None and getattr(model_check, "constant", False):
        return "the readings are constant"
    if len(log) < 2:
        return "fewer than 2 samples"
    return MLEstimator().applicable(log.array)
