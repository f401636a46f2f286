"""What every method's ``estimate(log)`` returns: the motion and a report of how it was obtained.

:class:`Estimate` is a value: ``(motion, report)``, both frozen. The estimator that made it keeps
nothing of the run, so the caller reads what the method chose, measured or noticed from the
:class:`Report` alone, and one estimator may run on many logs (or in many processes) at once.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

from .motion import Motion


def _frozen_mapping(values: Mapping | None) -> Mapping:
    return MappingProxyType(dict(values or {}))


@dataclass(frozen=True)
class Report:
    """How an estimate was obtained.

    ``method`` and ``options``: the method's name and every option it ran with (defaults included).
    ``timings``: seconds per step, in the order run (``{"estimate": 0.8}`` for a per-sample method;
    the pipeline adds its own steps, :func:`gfimu.pipeline.estimate_log`). The rest applies to the
    methods that have it and is empty otherwise: ``model_check`` (the batch smoother's check of the
    readings against a rigid body, :class:`gfimu.smoother.tuning.model_choice.ModelCheck`), ``tunings`` (the noise
    chosen from the data, per solve window, :class:`gfimu.smoother.tuning.evidence.Tuning`), ``calibration``
    (calibration variables estimated, per solve window), ``iterations`` and ``cost`` (solver
    iterations and final cost, summed over the windows), ``windows`` (solve windows; 0 for a stream),
    ``guard`` (the smoothers' comparison with the per-sample estimate,
    :class:`gfimu.smoother.guard.GuardResult`: the spans where the smoother fits the readings worse),
    ``warnings``: plain-text notes on anything that went less well than planned, and ``per_sample``:
    the per-sample ML estimate of the whole log when the run made one (the batch smoother's model check
    of an inconsistent log, or of any log its guard will judge; the guard reuses it). The estimate's one-sigma
    uncertainties, when asked for, are the motion's (``Estimate.motion.sigma``)."""

    method: str
    options: Mapping[str, Any] = field(default_factory=dict)
    timings: Mapping[str, float] = field(default_factory=dict)
    warnings: tuple[str, ...] = ()
    model_check: Any = None
    tunings: tuple = ()
    calibration: tuple = ()
    iterations: int | None = None
    cost: float | None = None
    windows: int | None = None
    guard: Any = None
    per_sample: Motion | None = field(default=None, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "options", _frozen_mapping(self.options))
        object.__setattr__(self, "timings", _frozen_mapping({k: float(v) for k, v in dict(self.timings).items()}))
        object.__setattr__(self, "warnings", tuple(str(w) for w in self.warnings))
        object.__setattr__(self, "tunings", tuple(self.tunings))
        object.__setattr__(self, "calibration", tuple(self.calibration))

    @classmethod
    def of(cls, method: str, estimator: Any, **fields: Any) -> Report:
        """The report of ``estimator`` (a dataclass of options) run as ``method``; ``fields`` as above."""
        return cls(method, options_of(estimator), **fields)

    @property
    def seconds(self) -> float:
        """All the steps' time [s]."""
        return float(math.fsum(self.timings.values()))

    def with_timings(self, **steps: float) -> Report:
        """This report with more steps timed (a step given again replaces the earlier time)."""
        return dataclasses.replace(self, timings={**self.timings, **steps})

    def describe(self) -> list[str]:
        """One line per thing worth telling a user: the model check, the noise chosen, the solver's
        work, the warnings."""
        lines = []
        if self.model_check is not None and hasattr(self.model_check, "describe"):
            lines.append(self.model_check.describe())
        if self.iterations is not None and self.windows:
            lines.append(f"{self.iterations} solver iterations over {self.windows} solve window(s), final cost {self.cost:.6g}")
        return lines


@dataclass(frozen=True)
class Estimate:
    """One run of a method on a log: ``motion`` (one row per sample) and ``report`` (how)."""

    motion: Motion
    report: Report


def options_of(estimator: Any) -> dict[str, Any]:
    """The options of an estimator: its dataclass fields set at construction, by name."""
    if not dataclasses.is_dataclass(estimator):
        return {}
    return {f.name: getattr(estimator, f.name) for f in dataclasses.fields(estimator) if f.init}
