"""Units of log columns and timestamps.

A header unit that differs from the specified one is converted when the
conversion is unambiguous and refused otherwise (never misread):

- acceleration ``[m s^-2]``; also ``[g]`` and ``[mg]`` with g = 9.80665 m/s²;
- angular rate ``[rad s^-1]``; also ``[deg s^-1]`` (``[dps]``), ``[rpm]``;
- angular acceleration ``[rad s^-2]``; also ``[deg s^-2]``;
- angle ``[rad]``; also ``[deg]``, ``[mrad]``;
- timestamps ``[ns]``; also ``[us]``, ``[ms]``, ``[s]``, converted exactly
  from the decimal text and rounded to the nearest nanosecond.

Equivalent spellings are accepted (``m/s^2``, ``m/s²``, ``rad/s``,
``deg/s``, ``°``, ``µs`` ...).
"""

from __future__ import annotations

import math
import re
from decimal import Decimal, InvalidOperation

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


def timestamp_ns(text: str, ns_per_unit: int) -> int:
    """Integer nanoseconds of a timestamp written as decimal text in a unit of ``ns_per_unit`` ns, converted
    exactly and rounded to the nearest nanosecond; ValueError if the text is not a finite number."""
    try:
        value = Decimal(text.strip()) * ns_per_unit
    except InvalidOperation:
        raise ValueError(f"timestamp {text.strip()!r} is not a number") from None
    if not value.is_finite():
        raise ValueError(f"timestamp {text.strip()!r} is not a finite number")
    return int(value.to_integral_value())
