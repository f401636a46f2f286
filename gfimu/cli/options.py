"""Checked command-line values: argparse types with ranges, and ``-O KEY=VALUE`` method options.

Every error names the option and what it expects, e.g.
``argument --window-s: must be a number > 0 [s], got '0'`` or
``-O window_s='abc': expected a number (option of method 'smoother', default 0.5)``.
"""

from __future__ import annotations

import argparse
import ast
import math
from collections.abc import Callable
from typing import TYPE_CHECKING

from ..option import OptionError, shown

if TYPE_CHECKING:
    from ..methods import MethodOptions


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


def method_options(method: str, pairs: list[str] | None = None, preset: str | None = None,
                   solver: str | None = None, lag_s: float | None = None, sigma: bool = False,
                   flag: str = "-O") -> MethodOptions:
    """The options of ``method`` from the ``-O KEY=VALUE`` ``pairs`` and the command's own flags (``--preset``,
    ``--solver``, ``--lag-s``, ``--sigma``), resolved once (:func:`gfimu.methods.resolve_options`: names and
    values checked, the preset expanded) before any log is read."""
    from ..methods import resolve_options

    options = parse_options(pairs, flag)
    if preset is not None and method != "smoother":
        raise OptionError(f"--preset applies to --method smoother only, not {method!r}")
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
    return resolve_options(method, options, preset=preset, flag=flag)
