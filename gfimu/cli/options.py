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


class OptionError(ValueError):
    """A method option (``-O KEY=VALUE``) is malformed or has a wrong value."""


def _number(text: str, unit: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number{f' [{unit}]' if unit else ''}, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected a finite number{f' [{unit}]' if unit else ''}, got {text!r}")
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
            raise argparse.ArgumentTypeError(f"must be a number {rng}{f' [{unit}]' if unit else ''}, got {text!r}")
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
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
        if (low is not None and value < low) or (high is not None and value > high):
            bounds = ("" if low is None else f">= {low}", "" if high is None else f"<= {high}")
            rng = " and ".join(x for x in bounds if x)
            raise argparse.ArgumentTypeError(f"must be an integer {rng}, got {text!r}")
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
            raise OptionError(f"{flag} {pair!r}: expected KEY=VALUE")
        if not key.isidentifier():
            raise OptionError(f"{flag} {pair!r}: {key!r} is not an option name")
        out[key] = parse_value(value)
    return out


def parse_method_options(pairs: list[str] | None, methods: list[str] | None, flag: str = "-O") -> dict[str, dict]:
    """``METHOD.KEY=VALUE`` pairs -> {method: {key: value}}."""
    out: dict[str, dict] = {}
    for pair in pairs or []:
        head, sep, value = pair.partition("=")
        method, dot, key = head.partition(".")
        if not sep or not dot or not method.strip() or not key.strip():
            raise OptionError(f"{flag} {pair!r}: expected METHOD.KEY=VALUE")
        method = method.strip()
        if methods is not None and method not in methods:
            raise OptionError(f"{flag} {pair!r}: method {method!r} is not among --methods {','.join(methods)}")
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


def check_method_options(method: str, options: dict, flag: str = "-O", prefix: str = "") -> dict:
    """Check the type of each option of ``method`` against its documented default; returns the options.

    A number where a number is expected (an integer is a valid float), True or
    False for a switch, text for text, ``None`` where the default is
    ``None``; an unknown name lists the known ones. Ranges are checked by the
    method itself (its errors name the option too).
    """
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
            known = ", ".join(sorted(fields))
            raise OptionError(f"{flag} {prefix}{key}=...: method {method!r} has no option {key!r}; "
                              f"its options are: {known}")
        default = f.default if f.default is not dataclasses.MISSING else None
        kind = _kind_of(f.type, default)
        if kind is None or (value is None and default is None):
            continue
        ok = {"bool": isinstance(value, bool),
              "int": isinstance(value, int) and not isinstance(value, bool),
              "float": isinstance(value, (int, float)) and not isinstance(value, bool),
              "str": isinstance(value, str)}[kind]
        if ok and kind == "float" and not math.isfinite(float(value)):
            raise OptionError(f"{flag} {prefix}{key}={value!r}: expected a finite number (option of method {method!r})")
        if not ok:
            expected = {"bool": "True or False", "int": "an integer", "float": "a number", "str": "text"}[kind]
            raise OptionError(f"{flag} {prefix}{key}={value!r}: expected {expected} (option of method {method!r}, "
                              f"default {default!r})")
    return options
