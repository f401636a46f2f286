"""One option of an estimator, declared once: a dataclass field whose metadata holds its unit, help and check.

``gfimu estimate --method NAME --list-options`` prints each option's name, default, unit, help and the values it
accepts from these fields (:meth:`gfimu.methods.MethodOptions.describe`); ``-O NAME=VALUE`` is read by the option's
check (:meth:`Check.parse`), and the classes that hold options check every value with it when they are made
(:func:`check_declared`), so no list of option names repeats a rule.

The checks: :class:`Number` (a range, None where allowed), :class:`Switch` (true or false), :class:`Choice`
(the values of an :class:`enum.StrEnum`), :class:`Numbers` (a fixed count of numbers in a range) and
:class:`Satisfies` (any other rule, with the words that say what it accepts). A value given on a command line
that an option refuses is an :class:`OptionError`, its value quoted by :func:`shown`.
"""

from __future__ import annotations

import dataclasses
import enum
import math
import numbers

from .errors import InputError

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


class Rejected(ValueError):
    """A value an option's check does not accept; its text says what the check accepts."""


class Check:
    """What an option accepts: :meth:`describe` says it, :meth:`check` takes a Python value (returned as the
    option holds it) and :meth:`parse` one given on a command line (text for switches and choices, numbers
    and tuples as :func:`gfimu.cli.options.parse_value` reads them). Both raise :class:`Rejected`."""

    def describe(self, unit: str = "", given: bool = False) -> str:
        """What it accepts (``given``: on a command line), e.g. ``a number > 0 [s]``."""
        raise NotImplementedError

    def check(self, value, unit: str = ""):
        raise NotImplementedError

    def parse(self, value, unit: str = ""):
        return self.check(value, unit)


def _bounds(low, high, low_open: bool, high_open: bool) -> str:
    lo = "" if low is None else f"{'>' if low_open else '>='} {low:g}"
    hi = "" if high is None else f"{'<' if high_open else '<='} {high:g}"
    return " and ".join(x for x in (lo, hi) if x)


class Number(Check):
    """A finite number (an integer with ``integer``) in [low, high] (``low_open``/``high_open`` exclude the
    ends), or None with ``none``. ``least_given``: the smallest magnitude besides 0 a value given on the command
    line may have (a noise density below 1e-9 leaves the normal equations singular)."""

    def __init__(self, low: float | None = None, high: float | None = None, *, low_open: bool = False,
                 high_open: bool = False, none: bool = False, integer: bool = False,
                 least_given: float | None = None) -> None:
        self.low, self.high, self.low_open, self.high_open = low, high, low_open, high_open
        self.none, self.integer, self.least_given = none, integer, least_given

    def describe(self, unit: str = "", finite: bool = False, given: bool = False) -> str:
        """What it accepts; ``given``: on a command line (at least ``least_given``)."""
        if given and self.least_given is not None:
            return Number(self.least_given, self.high, high_open=self.high_open, none=self.none,
                          integer=self.integer).describe(unit, finite)
        rng = _bounds(self.low, self.high, self.low_open, self.high_open)
        noun = "integer" if self.integer else "number"
        text = (f"a finite {noun}" if finite else f"{'an' if self.integer else 'a'} {noun}") + (f" {rng}" if rng else "")
        text += f" [{unit}]" if unit else ""
        return text + (" or None" if self.none else "")

    def check(self, value, unit: str = ""):
        if value is None and self.none:
            return None
        kind = numbers.Integral if self.integer else numbers.Real
        if isinstance(value, bool) or not isinstance(value, kind):
            raise Rejected(self.describe(unit))
        if not math.isfinite(float(value)):
            raise Rejected(self.describe(unit, finite=True))
        v = float(value)
        if ((self.low is not None and (v < self.low or (self.low_open and v == self.low)))
                or (self.high is not None and (v > self.high or (self.high_open and v == self.high)))):
            raise Rejected(self.describe(unit))
        return int(value) if self.integer else value

    def parse(self, value, unit: str = ""):
        if isinstance(value, str) and self.none and value.strip().lower() in ("none", "null"):
            return None
        value = self.check(value, unit)
        if self.least_given is not None and value is not None and 0 < abs(float(value)) < self.least_given:
            raise Rejected(f"{self.describe(unit, given=True)} (a smaller noise density leaves the normal equations "
                           "singular)")
        return value


class Switch(Check):
    """True or False (on a command line also ``true``/``false``, ``yes``/``no``, ``on``/``off``, 1/0)."""

    TRUE = ("true", "yes", "on", "1")
    FALSE = ("false", "no", "off", "0")

    def describe(self, unit: str = "", given: bool = False) -> str:
        return "true or false"

    def check(self, value, unit: str = ""):
        if isinstance(value, bool) or type(value).__name__ == "bool_":  # numpy's too
            return bool(value)
        raise Rejected(self.describe())

    def parse(self, value, unit: str = ""):
        text = str(value).strip().lower() if isinstance(value, (str, int)) else None
        if isinstance(value, bool):
            return value
        if text in self.TRUE:
            return True
        if text in self.FALSE:
            return False
        raise Rejected(self.describe())


class Choice(Check):
    """One of the values of ``choices``, an :class:`enum.StrEnum` (the option holds the value's text)."""

    def __init__(self, choices: type[enum.StrEnum]) -> None:
        self.choices = choices

    @property
    def values(self) -> tuple[str, ...]:
        return tuple(member.value for member in self.choices)

    def describe(self, unit: str = "", given: bool = False) -> str:
        shown = [repr(v) for v in self.values]
        return " or ".join(shown) if len(shown) == 2 else f"one of {', '.join(shown)}"

    def check(self, value, unit: str = ""):
        if isinstance(value, str) and value in self.values:
            return str(self.choices(value).value)
        raise Rejected(self.describe())


class Numbers(Check):
    """``count`` finite numbers each in [low, high] (``low_open`` excludes low), held as a tuple of floats."""

    def __init__(self, count: int, low: float | None = None, high: float | None = None, *,
                 low_open: bool = False) -> None:
        self.count, self.low, self.high, self.low_open = count, low, high, low_open

    def describe(self, unit: str = "", given: bool = False) -> str:
        words = {3: "three"}.get(self.count, str(self.count))
        rng = _bounds(self.low, self.high, self.low_open, False)
        return f"{words} numbers" + (f" {rng}" if rng else "") + (f" [{unit}]" if unit else "") + " as 1,2,3"

    def check(self, value, unit: str = ""):
        try:
            items = tuple(value)
        except TypeError:
            raise Rejected(self.describe(unit)) from None
        one = Number(self.low, self.high, low_open=self.low_open)
        if len(items) != self.count:
            raise Rejected(self.describe(unit))
        try:
            return tuple(float(one.check(v)) for v in items)
        except Rejected:
            raise Rejected(self.describe(unit)) from None


class Satisfies(Check):
    """Any other rule: ``test(value)`` says whether the value is accepted, ``accepts`` says what is."""

    def __init__(self, test, accepts: str) -> None:
        self.test, self.accepts = test, accepts

    def describe(self, unit: str = "", given: bool = False) -> str:
        return self.accepts

    def check(self, value, unit: str = ""):
        if not self.test(value):
            raise Rejected(self.accepts)
        return value


def _inferred(default) -> Check | None:
    """The check of an option declared without one, from its default: a switch for True/False."""
    if isinstance(default, bool):
        return Switch()
    return None


def option(default, unit: str = "", help: str = "", check: Check | None = None) -> dataclasses.Field:
    """A dataclass field holding one option: its ``default``, its ``unit`` ('' for switches, counts, factors
    and choices), a one-line ``help`` (white space collapsed) and its ``check`` (a switch when the default is
    True or False), the last three in the field's metadata. The default must pass the check."""
    text = " ".join(help.split())
    if not text:
        raise TypeError("an option needs its help text")
    check = check if check is not None else _inferred(default)
    if check is not None:
        try:
            check.check(default, unit)
        except Rejected as exc:
            raise TypeError(f"the default {default!r} is not {exc}") from None
    return dataclasses.field(default=default, metadata={"unit": unit, "help": text, "check": check})


def check_declared(obj, owner: str) -> None:
    """Check every option of the dataclass ``obj`` that declares a check (:func:`option`), setting the value
    as the check returns it (a tuple for numbers given as a list); an :class:`~gfimu.errors.InputError`
    ``OWNER option NAME must be WHAT IT ACCEPTS, got VALUE`` for the first value it refuses."""
    for f in dataclasses.fields(obj):
        check = f.metadata.get("check")
        if check is None:
            continue
        value = getattr(obj, f.name)
        try:
            new = check.check(value, f.metadata.get("unit", ""))
        except Rejected as exc:
            raise InputError(f"{owner} option {f.name} must be {exc}, got {value!r}") from None
        if new is not value and not (type(new) is type(value) and new == value):
            object.__setattr__(obj, f.name, new)

