"""One option of an estimator, declared once: a dataclass field whose metadata holds its unit and help.

``gfimu estimate --method NAME --list-options`` prints each option's name, default, unit and help from
these fields (:func:`gfimu.cli.options.describe_options`)."""

from __future__ import annotations

import dataclasses


def option(default, unit: str = "", help: str = "") -> dataclasses.Field:
    """A dataclass field holding one option: its ``default``, its ``unit`` ('' for switches, counts, factors
    and choices) and a one-line ``help`` (white space collapsed), the last two in the field's metadata."""
    text = " ".join(help.split())
    if not text:
        raise TypeError("an option needs its help text")
    return dataclasses.field(default=default, metadata={"unit": unit, "help": text})
