"""Checked command-line values: argparse types with ranges, and ``-O KEY=VALUE`` method options.

Every error names the option and what it expects, e.g.
``argument --window-s: must be a number > 0 [s], got '0'`` or
``-O window_s='abc': expected a number (option of method 'smoother', default 0.5)``.
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import math
from collections.abc import Callable

from ..errors import InputError

SHOWN_CHARS = 80
"""At most this many characters of a value are quoted in a message."""


def shown(value) -> str:
    """``repr(value)``, or its first :data:`SHOWN_CHARS` characters and the length when longer:
    ``'abc…' (129,000 characters)``."""
    text = repr(value)
    if len(text) <= SHOWN_CHARS:
        return text
    if isinstance(value, str):
        head = repr(value[:SHOWN_CHARS])
        return f"{head[:-1]}…{head[-1]} ({len(value):,} characters)"
    return f"{text[:SHOWN_CHARS]}… ({len(text):,} characters)"


class OptionError(InputError):
    """A method option (``-O KEY=VALUE``) is malformed or has a wrong value."""


def _number(text: str, unit: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number{f' [{unit}]' if unit else ''}, got {shown(text)}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected a finite number{f' [{unit}]' if unit else ''}, got {shown(text)}")
    return value


def number(low: float | None = None, high: float | None = None, unit: str = "", low_open: bool = False,
           high_open: bool = False) -> Callable[[str], float]:
    """An argparse type: a finite float in [low, high] (``low_open``/``high_open`` exclude the ends)."""

    def parse(text: str) -> float:
        value = _number(text, unit)
        bad = ((low is not None and (value < low or (low_open and value == low)))
               or (high is not None and (value > high or (high_open and value == high))))
        if bad:
            lo = "" if low is None else f"{'>' if low_open else '>='} {low:g}"
            hi = "" if high is None else f"{'<' if high_open else '<='} {high:g}"
            rng = " and ".join(x for x in (lo, hi) if x)
            raise argparse.ArgumentTypeError(f"must be a number {rng}{f' [{unit}]' if unit else ''}, got {shown(text)}")
        return value

    parse.__name__ = "number"
    return parse


def positive(unit: str = "") -> Callable[[str], float]:
    """A finite number > 0."""
    return number(0.0, unit=unit, low_open=True)


def non_negative(unit: str = "") -> Callable[[str], float]:
    """A finite number >= 0."""
    return number(0.0, unit=unit)


def integer(low: int | None = None, high: int | None = None) -> Callable[[str], int]:
    """An argparse type: an integer in [low, high]."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got {shown(text)}") from None
        if (low is not None and value < low) or (high is not None and value > high):
            bounds = ("" if low is None else f">= {low}", "" if high is None else f"<= {high}")
            rng = " and ".join(x for x in bounds if x)
            raise argparse.ArgumentTypeError(f"must be an integer {rng}, got {shown(text)}")
        return value

    parse.__name__ = "integer"
    return parse


# --- -O KEY=VALUE --------------------------------------------------------------------

def parse_value(text: str):
    """A value as a Python literal when it reads as one (``4``, ``0.5``, ``True``, ``(1, 2)``), ``nan`` and
    ``inf`` as floats, else the text."""
    try:
        return ast.literal_eval(text.strip())
    except (ValueError, SyntaxError, TypeError, MemoryError, RecursionError):
        pass
    try:
        return float(text)  # nan, inf
    except ValueError:
        return text


def parse_options(pairs: list[str] | None, flag: str = "-O") -> dict:
    """``KEY=VALUE`` pairs -> {key: value}; keys with ``-`` become ``_``."""
    out = {}
    for pair in pairs or []:
        key, sep, value = pair.partition("=")
        key = key.strip().replace("-", "_")
        if not sep or not key:
            raise OptionError(f"{flag} {shown(pair)}: expected KEY=VALUE")
        if not key.isidentifier():
            raise OptionError(f"{flag} {shown(pair)}: {shown(key)} is not an option name")
        out[key] = parse_value(value)
    return out


def parse_method_options(pairs: list[str] | None, methods: list[str] | None, flag: str = "-O") -> dict[str, dict]:
    """``METHOD.KEY=VALUE`` pairs -> {method: {key: value}}."""
    out: dict[str, dict] = {}
    for pair in pairs or []:
        head, sep, value = pair.partition("=")
        method, dot, key = head.partition(".")
        if not sep or not dot or not method.strip() or not key.strip():
            raise OptionError(f"{flag} {shown(pair)}: expected METHOD.KEY=VALUE")
        method = method.strip()
        if methods is not None and method not in methods:
            raise OptionError(f"{flag} {shown(pair)}: method {shown(method)} is not among --methods {','.join(methods)}")
        out.setdefault(method, {}).update(parse_options([f"{key}={value}"], flag))
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


OPTION_MAGNITUDE = (1e-100, 1e12)
"""The magnitudes a number given to a method option may have (besides 0): no option means anything
beyond (1e308 overflowed a window's sample count, 1e20 s a lag's, 1e-320 a noise's inverse)."""


def _unknown_option(method: str, fields: dict, key: str, value, flag: str, prefix: str) -> str:
    """The one-line error for ``key``, which ``method`` has not: an option of the other smoother's own group
    (:mod:`gfimu.smoother.model.option_groups`) is named as that; else the method's options are listed."""
    groups = {f.metadata.get("group") for f in fields.values()} - {None}
    if groups:
        from ..smoother.model.option_groups import GROUP_METHODS, GROUP_OF

        group = GROUP_OF.get(key)
        if group in GROUP_METHODS and group not in groups:
            kind, owner = GROUP_METHODS[group]
            return (f"{flag} {prefix}{key}={shown(value)}: {key} is a {kind} option (method {owner!r}, group "
                    f"[{group}]); method {method!r} does not take it")
    return (f"{flag} {prefix}{shown(key)[1:-1]}=...: method {method!r} has no option {shown(key)}; "
            f"its options are: {', '.join(sorted(fields))}")


def check_method_options(method: str, options: dict, flag: str = "-O", prefix: str = "") -> dict:
    """Check each option of ``method``; returns the options, each as its declaration reads it.

    An option declared with its check (:func:`gfimu.option.option`: a range, a switch taking ``true``/``false``,
    a choice) is read by that check (:meth:`gfimu.option.Check.parse`): the one-line error names the option
    and what it accepts. The others by their type and default: a number where a number is expected (an
    integer is a valid float), True or False for a switch, text for text, ``None`` where the default is
    ``None``; numbers (``1,2,3`` or ``[1,2,3]``, made a tuple in ``options``) where the type is a tuple of
    numbers. Every number is 0 or of a magnitude in :data:`OPTION_MAGNITUDE`; an unknown name lists the
    known ones.
    """
    from ..option import Rejected

    from ..methods import estimator_class

    cls = estimator_class(method)
    if not dataclasses.is_dataclass(cls):
        return options
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    for key, value in options.items():
        if key == "preset":
            continue
        f = fields.get(key)
        if f is None:
            raise OptionError(_unknown_option(method, fields, key, value, flag, prefix))
        default = f.default if f.default is not dataclasses.MISSING else None
        shape = _sequence_shape(cls, key)
        if shape is not None and value is not None:
            value = options[key] = _check_sequence(method, key, value, shape, flag, prefix)
        declared = f.metadata.get("check")
        if declared is not None:
            _check_magnitude(method, key, value, default, flag, prefix)
            try:
                options[key] = declared.parse(value, f.metadata.get("unit", ""))
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
    return options


def _check_magnitude(method: str, key: str, value, default, flag: str, prefix: str) -> None:
    """A finite number given must be 0 or of a magnitude in :data:`OPTION_MAGNITUDE`."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        return
    if value != 0 and not OPTION_MAGNITUDE[0] <= abs(float(value)) <= OPTION_MAGNITUDE[1]:
        raise OptionError(f"{flag} {prefix}{key}={shown(value)}: expected 0 or a number of magnitude "
                          f"{OPTION_MAGNITUDE[0]:g} to {OPTION_MAGNITUDE[1]:g} (option of method {method!r}, "
                          f"default {default!r})")


def method_options(method: str, pairs: list[str] | None, preset: str | None = None, solver: str | None = None,
                   lag_s: float | None = None, sigma: bool = False, flag: str = "-O") -> dict:
    """The options of ``method`` from the ``-O KEY=VALUE`` ``pairs`` and the command's own flags (``--preset``,
    ``--solver``, ``--lag-s``, ``--sigma``), their names and types checked (:func:`check_method_options`;
    their values when the estimator is made, :func:`gfimu.methods.make_estimator`)."""
    options = parse_options(pairs, flag)
    if preset is not None:  # checked before the log is read
        if method != "smoother":
            raise OptionError(f"--preset applies to --method smoother only, not {method!r}")
        from ..smoother.model.presets import apply_preset

        apply_preset(preset)
        options["preset"] = preset
    if solver is not None:
        if method != "smoother":
            raise OptionError(f"--solver applies to --method smoother only, not {method!r}")
        options["solver"] = solver
    if lag_s is not None:
        if method != "fixed-lag":
            raise OptionError("--lag-s applies to --method fixed-lag only")
        if "lag_s" in options and options["lag_s"] != lag_s:
            raise OptionError(f"--lag-s {lag_s:g} and {flag} lag_s={options['lag_s']!r} disagree; give the lag once")
        options["lag_s"] = lag_s
    if sigma:
        options["compute_sigma"] = True
    return check_method_options(method, options, flag)


def describe_options(method: str) -> str:
    """Every ``-O`` option of ``method``: name, default, unit, help and the values it accepts, one block each,
    from the option's declaration (:func:`gfimu.option.option`: the field's metadata); the smoothers' options
    under their group (model, batch_model, batch, stream, tuning, guard:
    :mod:`gfimu.smoother.model.option_groups`)."""
    from ..methods import estimator_class

    cls = estimator_class(method)
    if not dataclasses.is_dataclass(cls):
        return f"method {method!r} has no options"
    lines = [f"options of method {method!r} (-O NAME=VALUE: a number as 0.5 or 1e-3, a switch as true or false, "
             "a choice by its name, three numbers as 1,2,3 or [1,2,3], None where a value may be None):", ""]
    fields = [f for f in dataclasses.fields(cls) if f.init and not f.name.startswith("_")]
    sections = [("", fields)]
    if any("group" in f.metadata for f in fields):
        from ..smoother.model.option_groups import GROUPS

        sections = [(group, [f for f in fields if f.metadata.get("group") == group]) for group in GROUPS]
        sections.append(("other", [f for f in fields if "group" not in f.metadata]))
    for group, members in sections:
        if not members:
            continue
        if group:
            lines.append(f"[{group}]")
        for f in members:
            default = f.default if f.default is not dataclasses.MISSING else (
                f.default_factory() if f.default_factory is not dataclasses.MISSING else None)
            unit = f.metadata.get("unit", "")
            lines.append(f"{f.name} = {default!r}" + (f" [{unit}]" if unit else ""))
            lines.append(f"    {f.metadata.get('help') or '(no description)'}")
            check = f.metadata.get("check")
            if check is not None:
                lines.append(f"    accepts: {check.describe(unit, given=True)}")
        if group:
            lines.append("")
    return "\n".join(lines).rstrip("\n") + "\n"
