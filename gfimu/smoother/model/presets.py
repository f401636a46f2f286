"""Named settings of the batch smoother (method "smoother") for recurring situations.

A preset is a one-line description and a dict of
:class:`gfimu.smoother.model.problem.SmootherOptions` (and ``BatchSmootherEstimator``)
overrides. Options given explicitly win over the preset::

    make_estimator("smoother", preset="hand-held-low-rate")
    make_estimator("smoother", preset="hand-held-low-rate", reweight_iterations=3)
    gfimu estimate LOG --method smoother --preset hand-held-low-rate --out est.csv

Presets are named starting points, never required: the default smoother checks each
log's rigid-body residual and chooses a robust model for real sensors by itself
(:mod:`gfimu.smoother.tuning.model_choice`), which matches this preset on the MIMU4444 recordings.

``hand-held-low-rate`` holds the settings chosen on the first real MIMU4444
recording (``tools/mimu4444_study.py``): the per-sample maximum-likelihood
initialisation with its sign chain, fixed process noise for hand motion at
62.5 Hz (angular jerk density 3000 rad/s²/√s, specific-force density 300 m/s²/√s),
accelerometer noise growing by 0.03 m/s² per rad/s (the rigid-body residual of
real sensors grows with the rotation rate) and a Cauchy loss at 2 σ on every
accelerometer axis and every motion-model step, re-weighted over 5 solves.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from ...errors import InputError

PRESETS: dict[str, tuple[str, dict[str, Any]]] = {
    "hand-held-low-rate": (
        "fast hand-held motion at 50–100 Hz on real sensors whose rigid-body residual exceeds their noise",
        {
            "initialisation": "ml",
            "ml_sign_chain": True,
            "tune_process_noise": False,
            "omega_dot_random_walk_radps2_per_sqrt_s": 3000.0,
            "specific_force_random_walk_mps2_per_sqrt_s": 300.0,
            "accel_noise_slope_mps2_per_radps": 0.03,
            "robust_loss": "cauchy",
            "accel_robust_threshold": 2.0,
            "process_robust_threshold": 2.0,
            "reweight_iterations": 5,
        },
    ),
}
"""Preset name -> (one-line description, smoother option overrides)."""

PRESET_METHODS = ("smoother",)
"""Methods whose options the presets set."""


def describe_presets() -> str:
    """``name (description)`` of every preset, for messages and help texts."""
    return "; ".join(f"{name} ({desc})" for name, (desc, _) in PRESETS.items())


def apply_preset(name: str, options: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The preset's options updated with ``options`` (explicit options win).

    Raises an :class:`~gfimu.errors.InputError` naming the known presets when ``name`` is not one of them.
    """
    if not isinstance(name, str) or name not in PRESETS:
        raise InputError(f"unknown smoother preset {name!r}; presets: {describe_presets()}")
    return {**PRESETS[name][1], **dict(options or {})}


def expand_preset(method: str, options: Mapping[str, Any] | None) -> dict[str, Any]:
    """``options`` of ``method`` with a ``preset`` entry replaced by the preset's settings.

    Options without ``preset`` come back unchanged (as a new dict); a preset for a
    method other than those in :data:`PRESET_METHODS` is an :class:`~gfimu.errors.InputError`.
    """
    out = dict(options or {})
    if "preset" not in out:
        return out
    name = out.pop("preset")
    if method not in PRESET_METHODS:
        raise InputError(f"presets apply to the method(s) {', '.join(PRESET_METHODS)}, not {method!r} "
                         f"(preset {name!r} given)")
    return apply_preset(name, out)
