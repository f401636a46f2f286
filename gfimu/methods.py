"""The methods registry: every estimator by name, above the layers that define them.

The per-sample methods live in :mod:`gfimu.estimators` (one module per paper), the
smoothers in :mod:`gfimu.smoother`; this module names them all so that the CLI and the
comparison study ask one place, and nothing below imports upward.

Every estimator is a small object configured at construction (a dataclass of options with
documented defaults) that offers

- ``method``: its name here;
- ``applicable(array) -> str | None``: ``None`` when it can run on the array, else the reason;
- ``estimate(log, progress=False) -> Estimate``: a :class:`gfimu.estimate.Estimate`, the
  :class:`~gfimu.motion.Motion` (one row per sample of the log) and the
  :class:`~gfimu.estimate.Report` of the run (options, timings, warnings, and where they apply
  the model check, the noise chosen, iterations and cost). The estimator keeps nothing of a run.

Classes are imported on first use so that ``gfimu --help`` stays fast.
"""

from __future__ import annotations

import dataclasses
import importlib
from typing import Any

from .errors import InputError


METHODS: dict[str, str] = {
    "inversion": "gfimu.estimators.inversion:InversionEstimator",
    "integration": "gfimu.estimators.integration:IntegrationEstimator",
    "pure-integration": "gfimu.estimators.integration:PureIntegrationEstimator",
    "imm": "gfimu.estimators.imm:IMMEstimator",
    "ml": "gfimu.estimators.ml:MLEstimator",
    "gyro-aided": "gfimu.estimators.gyro_aided:GyroAidedEstimator",
    "free-flight": "gfimu.estimators.free_flight:FreeFlightEstimator",
    "smoother": "gfimu.smoother.batch.engine:BatchSmootherEstimator",
    "fixed-lag": "gfimu.smoother.stream.fixed_lag:FixedLagEstimator",
}
"""Method name -> ``module:class`` of its estimator."""


class UnknownMethodError(InputError, KeyError):
    """No method of that name (the message lists them)."""

    __str__ = InputError.__str__


def estimator_class(name: str):
    try:
        target = METHODS[name]
    except KeyError:
        raise UnknownMethodError(f"unknown method {name!r}; choose one of: {', '.join(METHODS)}") from None
    module, cls = target.split(":")
    return getattr(importlib.import_module(module), cls)


def option_field_list(name: str) -> list[dataclasses.Field]:
    """The options of method ``name`` (the fields set at construction)."""
    cls = estimator_class(name)
    if not dataclasses.is_dataclass(cls):
        return []
    return [f for f in dataclasses.fields(cls) if f.init]


def make_estimator(name: str, **options: Any):
    """Instantiate the estimator ``name`` with keyword options (checked by name).

    ``preset=NAME`` (method "smoother"): start from the named settings of
    :data:`gfimu.smoother.model.presets.PRESETS`; the other options given win over it.
    """
    cls = estimator_class(name)
    if "preset" in options:
        from .smoother.model.presets import expand_preset  # on first use: `gfimu --help` loads no numpy

        options = expand_preset(name, options)
    if dataclasses.is_dataclass(cls):
        known = {f.name for f in option_field_list(name)}
        unknown = sorted(set(options) - known)
        if unknown:
            raise InputError(f"method {name!r} has no option(s) {unknown}; options are: {sorted(known)}")
    return cls(**options)


def option_fields(name: str) -> dict[str, Any]:
    """Option name -> (type, default) of a method, for the CLI's help."""
    out = {}
    for f in option_field_list(name):
        default = f.default if f.default is not dataclasses.MISSING else (
            f.default_factory() if f.default_factory is not dataclasses.MISSING else None)
        out[f.name] = (f.type, default)
    return out

