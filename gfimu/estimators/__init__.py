"""Per-sample estimators of the papers: a shared base (:mod:`._common`) and one module per method.

The registry of every method by name, smoothers included, is :mod:`gfimu.methods` (above this
layer). ``METHODS``, ``make_estimator``, ``estimator_class``, ``option_fields`` and
``UnknownMethodError`` are still reachable from here, resolved from :mod:`gfimu.methods` on
first use (no import of the layers above at import time).
"""

from __future__ import annotations

import importlib

_REGISTRY_NAMES = ("METHODS", "UnknownMethodError", "estimator_class", "make_estimator", "option_fields")


def __getattr__(name: str):
    if name in _REGISTRY_NAMES:
        return getattr(importlib.import_module("gfimu.methods"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
