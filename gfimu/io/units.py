"""Units of log columns and timestamps.

A header unit that differs from the specified one is converted when the
conversion is unambiguous and refused otherwise (never misread):

- acceleration ``[m s^-2]``; also ``[g]`` and ``[mg]`` with g = 9.80665 m/s²;
- angular rate ``[rad s^-1]``; also ``[deg s^-1]`` (``[dps]``), ``[rpm]``;
- angular acceleration ``[rad s^-2]``; also ``[deg s^-2]``;
- angle ``[rad]``; also ``[deg]``, ``[mrad]``;
- timestamps ``[ns]``; also ``[us]``, ``[ms]``, ``[s]``, converted exactly
  from the decimal text and rounded to the nearest nanosecond, a half to the
  even one, in every unit (:func:`timestamps_ns`; the one rule of every
  reader).

Equivalent spellings are accepted (``m/s^2``, ``m/s²``, ``rad/s``,
``deg/s``, ``°``, ``µs`` ...).
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from decimal import MAX_PREC, ROUND_HALF_EVEN, Context, Decimal, InvalidOperation

import numpy as np

from ..errors import InputError

STANDARD_GRAVITY_MPS2 = 9.80665

_DEG = math.pi / 180.0
# kind -> (canonical unit, {accepted canonical spelling: factor to the canonical unit})
UNITS: dict[str, tuple[str, dict[str, float]]] = {
    "acceleration": ("m s^-2", {"m s^-2": 1.0, "g": STANDARD_GRAVITY_MPS2, "mg": STANDARD_GRAVITY_MPS2 * 1e-3}),
    "angular_rate": ("rad s^-1", {"rad s^-1": 1.0, "deg s^-1": _DEG, "mrad s^-1": 1e-3, "rpm": 2.0 * math.pi / 60.0}),
    "angular_acceleration": ("rad s^-2", {"rad s^-2": 1.0, "deg s^-2": _DEG}),
    "angle": ("rad", {"rad": 1.0, "deg": _DEG, "mrad": 1e-3}),
    "dimensionless": ("", {"": 1.0}),
}
# timestamp unit -> nanoseconds per unit
TIME_UNITS_NS = {"ns": 1, "us": 1_000, "ms": 1_000_000, "s": 1_000_000_000}
KIND_OF_UNIT = {"m s^-2": "acceleration", "rad s^-1": "angular_rate", "rad s^-2": "angular_acceleration",
                 "rad": "angle", "": "dimensionless"}
_WORDS = {"degree": "deg", "degrees": "deg", "°": "deg", "radian": "rad", "radians": "rad", "sec": "s",
          "second": "s", "seconds": "s", "dps": "deg s^-1", "1": "", "-": "", "µs": "us", "μs": "us",
          "nanoseconds": "ns", "microseconds": "us", "milliseconds": "ms", "rev/min": "rpm"}


def canonical_unit(text: str) -> str:
    """Spelling-independent form of a unit: ``m/s²``, ``m s-2``, ``m*s^-2`` -> ``m s^-2``."""
    u = text.strip()
    for a, b in (("⁻¹", "^-1"), ("⁻²", "^-2"), ("²", "^2"), ("¹", "^1"), ("·", " "), ("*", " "), (".", " "),
                 ("°/", "deg/"), ("° ", "deg ")):
        u = u.replace(a, b)
    u = re.sub(r"\s+", " ", u).strip()
    u = _WORDS.get(u.lower(), u)
    m = re.fullmatch(r"([A-Za-z°µμ]+) ?/ ?s(?: ?\^? ?(\d))?(?: ?/ ?s)?", u)
    if m:
        power = int(m.group(2) or 1) + (1 if u.rstrip().endswith("/s") and u.count("/") == 2 else 0)
        return f"{_WORDS.get(m.group(1).lower(), m.group(1))} s^-{power}"
    m = re.fullmatch(r"([A-Za-z°µμ]+) ?s ?\^? ?-(\d)", u)
    if m:
        return f"{_WORDS.get(m.group(1).lower(), m.group(1))} s^-{m.group(2)}"
    return u


def unit_factor(unit: str, kind: str) -> float:
    """Factor converting a value in ``unit`` to the canonical unit of ``kind``; KeyError if not accepted."""
    return UNITS[kind][1][canonical_unit(unit)]


def unit_help(kind: str) -> str:
    canonical, accepted = UNITS[kind]
    others = [f"[{u}]" for u in accepted if u != canonical]
    return f"[{canonical}]" + (f" (or, converted: {', '.join(others)})" if others else "")


def header_name_and_unit(field: str) -> tuple[str, str | None]:
    """A column header split into its name and unit: ``a_x [m s^-2]`` and ``Acceleration x (m/s^2)`` give
    the name and the unit text; a header without a bracketed or parenthesised unit gives ``(name, None)``.
    A leading ``#`` (EuRoC's ``#timestamp [ns]``) and surrounding quotes are not part of the name."""
    text = field.strip().strip('"').strip()
    m = re.match(r"^(.*?)\s*(?:\[([^\[\]]*)\]|\(([^()]*)\))\s*$", text)
    name, unit = (m.group(1), m.group(2) if m.group(2) is not None else m.group(3)) if m and m.group(1).strip() else (text, None)
    return name.lstrip("#").strip(), None if unit is None else unit.strip()


def time_unit_ns(unit: str) -> int:
    """Nanoseconds per unit of a timestamp unit (``ns``, ``us``/``µs``, ``ms``, ``s`` in any accepted spelling);
    KeyError if not one of them."""
    return TIME_UNITS_NS[canonical_unit(unit)]


_EXACT = Context(prec=MAX_PREC, rounding=ROUND_HALF_EVEN)  # a product of decimals, not rounded
_INT64 = (-(2**63), 2**63)


class TimestampError(InputError):
    """A timestamp token that is no time; ``index`` is its place among the tokens given."""

    def __init__(self, message: str, index: int):
        super().__init__(message)
        self.index = index


def timestamp_ns(text: str, ns_per_unit: int) -> int:
    """Integer nanoseconds of a timestamp written as decimal text in a unit of ``ns_per_unit`` ns.

    The text is converted exactly and rounded to the nearest nanosecond, a half to the even one
    (``1.5`` and ``2.5`` [ns] give 2, ``0.0000000015`` [s] gives 2), whatever the caller's decimal
    context; an InputError, naming the token, if it is not a finite number or is outside 64-bit nanoseconds.
    """
    tok = text.strip()
    try:
        value = Decimal(tok)
    except InvalidOperation:
        raise InputError(f"timestamp {tok!r} is not a number") from None
    if not value.is_finite():
        raise InputError(f"timestamp {tok!r} is not a finite number")
    if value and value.adjusted() > 30:  # far beyond 2^63 ns in any unit; not expanded to an integer
        raise InputError(f"timestamp {tok!r} is out of range for 64-bit nanoseconds")
    ns = _EXACT.multiply(value, ns_per_unit).to_integral_value(rounding=ROUND_HALF_EVEN)
    if not _INT64[0] <= ns < _INT64[1]:
        raise InputError(f"timestamp {tok!r} is out of range for 64-bit nanoseconds")
    return int(ns)


def timestamps_ns(tokens: Sequence[str], ns_per_unit: int) -> np.ndarray:
    """int64 nanoseconds of timestamp tokens in a unit of ``ns_per_unit`` ns, by the rule of
    :func:`timestamp_ns` (integer [ns] tokens read at once); TimestampError at the first bad token."""
    if ns_per_unit == 1:
        try:
            return np.array(tokens).astype(np.int64).reshape(len(tokens))
        except (ValueError, OverflowError):
            pass
    out = np.empty(len(tokens), dtype=np.int64)
    for k, tok in enumerate(tokens):
        try:
            out[k] = timestamp_ns(tok, ns_per_unit)
        except ValueError as exc:
            raise TimestampError(str(exc), k) from None
    return out


def same_nanosecond(earlier: str, later: str) -> bool:
    """Whether two timestamp tokens are distinct, increasing decimal times (the second after the first) that
    round to one nanosecond: a unit too coarse for them (seconds written under ``[ns]``), not a step back."""
    a, b = earlier.strip(), later.strip()
    if a == b:
        return False
    try:
        return Decimal(b) > Decimal(a)
    except InvalidOperation:
        return False
