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

A command's options go one way, once: :func:`resolve_options` reads the method's class and declared
options, checks the names given, expands a preset (:mod:`gfimu.smoother.model.presets`) and reads each
value given by its declaration (:func:`_read_given`); the :class:`MethodOptions` it returns
makes the estimator and lists the options (``--list-options``).

Classes are imported on first use so that ``gfimu --help`` stays fast.
"""

from __future__ import annotations

import dataclasses
import importlib
import math
from typing import Any

from .errors import InputError
from .option import OptionError, Rejected, shown


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


def _option_fields(cls) -> tuple[dataclasses.Field, ...]:
    """The options of an estimator class: the fields set at construction (none when it is no dataclass)."""
    if not dataclasses.is_dataclass(cls):
        return ()
    return tuple(f for f in dataclasses.fields(cls) if f.init)


@dataclasses.dataclass(frozen=True)
class MethodOptions:
    """The options of one method, resolved once (:func:`resolve_options`): its estimator class, the options it
    declares (``fields``) and those it will be made with (``options``: given, each read by its declaration,
    over the preset's)."""

    method: str
    cls: type
    fields: tuple[dataclasses.Field, ...]
    options: dict[str, Any]

    def estimator(self):
        """The estimator made with these options (its own checks run here: before any log is read)."""
        return self.cls(**self.options)

    def describe(self) -> str:
        """Every option: name, default, unit, help and the values it accepts, one block each, from the option's
        declaration (:func:`gfimu.option.option`: the field's metadata); the smoothers' options under their group
        (model, batch_model, batch, stream, tuning, guard: :mod:`gfimu.smoother.model.option_groups`)."""
        if not self.fields:
            return f"method {self.method!r} has no options"
        lines = [f"options of method {self.method!r} (-O NAME=VALUE: a number as 0.5 or 1e-3, a switch as true or "
                 "false, a choice by its name, three numbers as 1,2,3 or [1,2,3], None where a value may be None):", ""]
        fields = [f for f in self.fields if not f.name.startswith("_")]
        sections = [("", fields)]
        if any("group" in f.metadata for f in fields):
            from .smoother.model.option_groups import GROUPS

            sections = [(group, [f for f in fields if f.metadata.get("group") == group]) for group in GROUPS]
            sections.append(("other", [f for f in fields if "group" not in f.metadata]))
        for group, members in sections:
            if not members:
                continue
            if group:
                lines.append(f"[{group}]")
            for f in members:
                unit = f.metadata.get("unit", "")
                lines.append(f"{f.name} = {_default(f)!r}" + (f" [{unit}]" if unit else ""))
                lines.append(f"    {f.metadata.get('help') or '(no description)'}")
                check = f.metadata.get("check")
                if check is not None:
                    lines.append(f"    accepts: {check.describe(unit, given=True)}")
            if group:
                lines.append("")
        return "\n".join(lines).rstrip("\n") + "\n"


def resolve_options(method: str, given: dict[str, Any] | None = None, *, preset: str | None = None, flag: str = "-O",
                    prefix: str = "") -> MethodOptions:
    """The options of ``method`` from those ``given`` on a command line (``-O KEY=VALUE``, read by
    :func:`gfimu.cli.options.parse_options`), in one pass: the class and its declared options read once, each
    name given checked against them and each value read by its declaration (:func:`_read_given`), then the
    preset (``preset``, or a ``preset`` among ``given``) expanded once (:mod:`gfimu.smoother.model.presets`:
    the options given win over the preset's).

    Every error is one line (:class:`~gfimu.option.OptionError` and the like) naming the option: an unknown
    name lists the method's options, or names the other smoother whose group (``[stream]``, ``[batch]``:
    :mod:`gfimu.smoother.model.option_groups`) holds it."""
    cls = estimator_class(method)
    fields = _option_fields(cls)
    given = dict(given or {})
    named = given.pop("preset", None)
    preset = named if preset is None else preset
    known = {f.name: f for f in fields}
    for key, value in given.items():
        if key not in known:
            raise OptionError(_unknown_option(method, known, key, value, flag, prefix))
    options = _read_given(method, cls, known, given, flag, prefix)
    if preset is not None:
        from .smoother.model.presets import expand_preset  # on first use: `gfimu --help` loads no numpy

        options = expand_preset(method, {**options, "preset": preset})
    return MethodOptions(method, cls, fields, options)


def _unknown_option(method: str, fields: dict, key: str, value, flag: str, prefix: str) -> str:
    """The one-line error for ``key``, which ``method`` has not: an option of the other smoother's own group
    (:mod:`gfimu.smoother.model.option_groups`) is named as that; else the method's options are listed."""
    groups = {f.metadata.get("group") for f in fields.values()} - {None}
    if groups:
        from .smoother.model.option_groups import GROUP_METHODS, GROUP_OF

        group = GROUP_OF.get(key)
        if group in GROUP_METHODS and group not in groups:
            kind, owner = GROUP_METHODS[group]
            return (f"{flag} {prefix}{key}={shown(value)}: {key} is a {kind} option (method {owner!r}, group "
                    f"[{group}]); method {method!r} does not take it")
    return (f"{flag} {prefix}{shown(key)[1:-1]}=...: method {method!r} has no option {shown(key)}; "
            f"its options are: {', '.join(sorted(fields))}")


def _default(f: dataclasses.Field):
    return f.default if f.default is not dataclasses.MISSING else (
        f.default_factory() if f.default_factory is not dataclasses.MISSING else None)


def make_estimator(name: str, **options: Any):
    """Instantiate the estimator ``name`` with keyword options (checked by name).

    ``preset=NAME`` (method "smoother"): start from the named settings of
    :data:`gfimu.smoother.model.presets.PRESETS`; the other options given win over it.
    """
    cls = estimator_class(name)
    if "preset" in options:
        from .smoother.model.presets import expand_preset  # on first use: `gfimu --help` loads no numpy

        options = expand_preset(name, options)
    known = {f.name for f in _option_fields(cls)}
    unknown = sorted(set(options) - known)
    if unknown and dataclasses.is_dataclass(cls):
        raise InputError(f"method {name!r} has no option(s) {unknown}; options are: {sorted(known)}")
    return cls(**options)


# --- the options given, each read by its field -------------------------------------

OPTION_MAGNITUDE = (1e-100, 1e12)
"""The magnitudes a number given to a method option may have (besides 0): no option means anything
beyond (1e308 overflowed a window's sample count, 1e20 s a lag's, 1e-320 a noise's inverse)."""


def _read_given(method: str, cls: type, fields: dict[str, dataclasses.Field], given: dict, flag: str,
                prefix: str) -> dict:
    """The options ``given`` to ``method`` (``-O KEY=VALUE``, as :func:`gfimu.cli.options.parse_value` reads the
    values), each read by its field of the dataclass ``cls`` (``fields``: name -> field; every name given is
    one, the caller checks the names). Returns a new dict, each value as its declaration reads it.

    An option declared with its check (:func:`gfimu.option.option`: a range, a switch taking ``true``/``false``, a
    choice) is read by that check (:meth:`gfimu.option.Check.parse`): the one-line :class:`OptionError` names the
    option and what it accepts. The others by their type and default: a number where a number is expected (an integer is a valid
    float), True or False for a switch, text for text, ``None`` where the default is ``None``; numbers
    (``1,2,3`` or ``[1,2,3]``, made a tuple) where the type is a tuple of numbers. Every number is 0 or of a
    magnitude in :data:`OPTION_MAGNITUDE`.
    """
    out = {}
    for key, value in given.items():
        f = fields[key]
        default = f.default if f.default is not dataclasses.MISSING else None
        shape = _sequence_shape(cls, key)
        if shape is not None and value is not None:
            value = _check_sequence(method, key, value, shape, flag, prefix)
        out[key] = value
        declared = f.metadata.get("check")
        if declared is not None:
            _check_magnitude(method, key, value, default, flag, prefix)
            try:
                out[key] = declared.parse(value, f.metadata.get("unit", ""))
            except Rejected as exc:
                raise OptionError(f"{flag} {prefix}{key}={shown(value)}: expected {exc} (option of method "
                                  f"{method!r}, default {default!r})") from None
            continue
        if shape is not None:
            continue
        kind = _kind_of(f.type, default)
        if kind is None or (value is None and (default is None or _takes_none(f.type))):
            continue
        ok = {"bool": isinstance(value, bool),
              "int": isinstance(value, int) and not isinstance(value, bool),
              "float": isinstance(value, (int, float)) and not isinstance(value, bool),
              "str": isinstance(value, str)}[kind]
        if ok and kind == "float" and not math.isfinite(float(value)):
            raise OptionError(f"{flag} {prefix}{key}={shown(value)}: expected a finite number (option of method "
                              f"{method!r})")
        if ok and kind == "float":
            _check_magnitude(method, key, value, default, flag, prefix)
        if not ok:
            expected = {"bool": "True or False", "int": "an integer", "float": "a number", "str": "text"}[kind]
            raise OptionError(f"{flag} {prefix}{key}={shown(value)}: expected {expected} (option of method "
                              f"{method!r}, default {default!r})")
    return out


def _kind_of(annotation, default) -> str | None:
    """'bool', 'int', 'float', 'str' or None (not checked) from a field's annotation and default."""
    if isinstance(default, bool):
        return "bool"
    if isinstance(default, int):
        return "int" if "float" not in str(annotation) else "float"
    if isinstance(default, float):
        return "float"
    if isinstance(default, str):
        return "str"
    text = str(annotation).replace(" ", "")
    for kind in ("bool", "float", "int", "str"):
        if text in (kind, f"{kind}|None", f"None|{kind}", f"Optional[{kind}]"):
            return kind
    return None


def _takes_none(annotation) -> bool:
    """Whether a field's annotation allows None (``float | None``, ``Optional[float]``: window_s=None)."""
    text = str(annotation).replace(" ", "")
    return "None" in text.split("|") or text.startswith("Optional[")


def _sequence_shape(cls, name: str) -> tuple[bool, int | None] | None:
    """For a field whose type takes a tuple (``tuple[float, float, float]``, ``Union[str, tuple]``):
    (text also allowed, the fixed length or None); None for any other field."""
    import typing

    try:
        hint = typing.get_type_hints(cls).get(name)
    except Exception:  # noqa: BLE001 - an annotation that does not resolve is simply not checked here
        return None
    options = typing.get_args(hint) if typing.get_origin(hint) is typing.Union else (hint,)
    text = str in options
    for option in options:
        if option is tuple or typing.get_origin(option) is tuple:
            args = typing.get_args(option)
            length = len(args) if args and Ellipsis not in args else None
            if not args or not all(a in (float, int) for a in args if a is not Ellipsis):
                return None  # a tuple of objects (factor groups): not given on a command line
            return text, length
    return None


def _check_sequence(method: str, key: str, value, shape, flag: str, prefix: str):
    """A tuple-valued option: ``1,2,3`` or ``[1,2,3]`` or ``(1,2,3)`` -> a tuple of finite numbers."""
    text_allowed, length = shape
    if isinstance(value, str) and text_allowed:
        return value
    numbers = f"{'three' if length == 3 else (length or 'some')} numbers"
    form = f"{numbers} as {key}=1,2,3 or {key}=[1,2,3]" if length == 3 else f"{numbers} as {key}=[a,b,...]"
    if isinstance(value, (list, tuple)) and all(
            isinstance(v, (int, float)) and not isinstance(v, bool) for v in value):
        if length is not None and len(value) != length:
            raise OptionError(f"{flag} {prefix}{key}={shown(value)}: expected {form}, got {len(value)} "
                              f"(option of method {method!r})")
        if not all(math.isfinite(float(v)) for v in value):
            raise OptionError(f"{flag} {prefix}{key}={shown(value)}: expected finite numbers (option of method "
                              f"{method!r})")
        return tuple(float(v) for v in value)
    alternatives = "text or " if text_allowed else ""
    raise OptionError(f"{flag} {prefix}{key}={shown(value)}: expected {alternatives}{form} (option of method "
                      f"{method!r})")


def _check_magnitude(method: str, key: str, value, default, flag: str, prefix: str) -> None:
    """A finite number given must be 0 or of a magnitude in :data:`OPTION_MAGNITUDE`."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        return
    if value != 0 and not OPTION_MAGNITUDE[0] <= abs(float(value)) <= OPTION_MAGNITUDE[1]:
        raise OptionError(f"{flag} {prefix}{key}={shown(value)}: expected 0 or a number of magnitude "
                          f"{OPTION_MAGNITUDE[0]:g} to {OPTION_MAGNITUDE[1]:g} (option of method {method!r}, "
                          f"default {default!r})")
