"""Options of a dataclass described generically: name, group, type, default, unit and help.

Read from the dataclass itself: a field's ``metadata`` (``unit``, ``help``, ``group``) when given,
else the unit its name carries (``window_s`` [s], ``omega_dot_random_walk_radps2_per_sqrt_s``
[rad/s²/√s], ...) and the docstring written under the field. ``gfimu estimate --list-options``
prints them.
"""

from __future__ import annotations

import ast
import dataclasses
import inspect
import textwrap
from dataclasses import dataclass

UNIT_SUFFIXES = (
    ("_radps2_per_sqrt_s", "rad/s²/√s"),
    ("_radps3_per_sqrt_s", "rad/s³/√s"),
    ("_mps2_per_sqrt_s", "m/s²/√s"),
    ("_rad_per_sqrt_s", "rad/√s"),
    ("_mps2_per_radps", "(m/s²)/(rad/s)"),
    ("_radps2", "rad/s²"),
    ("_radps", "rad/s"),
    ("_mps2", "m/s²"),
    ("_nm", "N·m"),
    ("_hz", "Hz"),
    ("_rad", "rad"),
    ("_s", "s"),
    ("_m", "m"),
)
"""Name suffix -> unit, longest first (the project's naming rule: names carry their units)."""


def unit_of(name: str) -> str:
    """The unit a name carries ('' when it carries none)."""
    for suffix, unit in UNIT_SUFFIXES:
        if name.endswith(suffix):
            return unit
    return ""


def field_docstrings(cls) -> dict[str, str]:
    """Field name -> the string literal written under it, over ``cls`` and its bases."""
    out: dict[str, str] = {}
    for klass in reversed(inspect.getmro(cls)):
        if klass is object:
            continue
        try:
            source = textwrap.dedent(inspect.getsource(klass))
        except (OSError, TypeError):
            continue
        body = ast.parse(source).body[0].body
        for node, after in zip(body, body[1:] + [None]):
            if (isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name) and isinstance(after, ast.Expr)
                    and isinstance(after.value, ast.Constant) and isinstance(after.value.value, str)):
                out[node.target.id] = " ".join(after.value.value.split())
    return out


@dataclass(frozen=True)
class OptionInfo:
    name: str
    group: str
    type: str
    default: object
    unit: str
    help: str


def describe(cls, groups: dict[str, str] | None = None, default_group: str = "") -> list[OptionInfo]:
    """The options (init fields) of dataclass ``cls``; ``groups`` maps a name to its group when the
    field's metadata gives none."""
    docs = field_docstrings(cls)
    out = []
    for f in dataclasses.fields(cls):
        if not f.init:
            continue
        default = f.default if f.default is not dataclasses.MISSING else (
            f.default_factory() if f.default_factory is not dataclasses.MISSING else None)
        meta = f.metadata or {}
        group = meta.get("group") or (groups or {}).get(f.name, default_group)
        type_name = f.type if isinstance(f.type, str) else getattr(f.type, "__name__", str(f.type))
        out.append(OptionInfo(f.name, group, type_name, default, meta.get("unit", unit_of(f.name)),
                              meta.get("help") or docs.get(f.name, "")))
    return out


def format_options(infos: list[OptionInfo], width: int = 100) -> str:
    """Text listing grouped by ``group`` (in order of first appearance): name [unit] = default, help."""
    order: list[str] = []
    for info in infos:
        if info.group not in order:
            order.append(info.group)
    lines = []
    for group in order:
        if group:
            lines.append(f"{group}:")
        for info in (i for i in infos if i.group == group):
            unit = f" [{info.unit}]" if info.unit else ""
            lines.append(f"  {info.name}{unit} = {info.default!r}  ({info.type})")
            if info.help:
                lines.extend("      " + line for line in textwrap.wrap(info.help, width - 6))
    return "\n".join(lines) + "\n"
