"""The smoothers' options in five groups: the model, the batch solver, the fixed-lag stream,
the noise tuning and the guard against the per-sample estimate (read by ``gfimu estimate --list-options``; every option keeps its flat name for
``-O name=value`` and the presets). :func:`nested` gives a flat options object as nested frozen
dataclasses, one per group (``nested(options).model.motion_model``), and :func:`flatten` turns them
back into the flat options."""

from __future__ import annotations

import dataclasses
from functools import lru_cache

GROUPS: dict[str, tuple[str, ...]] = {
    "model": (
        "motion_model", "omega_dot_random_walk_radps2_per_sqrt_s", "omega_ddot_random_walk_radps3_per_sqrt_s",
        "specific_force_random_walk_mps2_per_sqrt_s", "default_accel_noise_std_mps2", "measurement", "use_gyro",
        "use_inclinometer", "estimate_attitude", "accel_random_walk_mps2_per_sqrt_s",
        "attitude_random_walk_rad_per_sqrt_s", "initial_yaw_std_rad", "self_calibrate_bias", "bias_prior_std_mps2",
        "gyro_bias_prior_std_radps", "self_calibrate_scale", "scale_prior_std", "free_flight", "torque_noise_std_nm",
        "free_fall_std_mps2", "initial_omega_std_radps", "initial_omega_dot_std_radps2",
        "initial_specific_force_std_mps2", "accel_noise_slope_mps2_per_radps", "process_axis_factors",
        "process_axis_frequencies_hz", "robust_loss", "accel_robust_threshold", "process_robust_threshold",
        "factor_groups",
    ),
    "batch": (
        "window_s", "overlap_s", "max_iterations", "relative_tolerance", "compute_sigma", "init_window_s",
        "reweight_iterations", "initialisation", "ml_sign_chain", "branch_restarts", "solver",
        "workers",
    ),
    "fixed-lag": (
        "lag_s", "relinearize_threshold", "relinearize_skip", "marginalise_every_s", "warmup_s", "gap_factor",
        "fast_measurement", "tune_window_s", "engine",
    ),
    "tuning": (
        "auto_model", "tune_process_noise", "tune_span_s", "tune_axis_frequencies", "tune_motion_model",
        "tune_accel_noise", "retune_every_s", "model_window_s",
    ),
    "guard": ("guard",),
}
"""Group -> option names."""

GROUP_OF = {name: group for group, names in GROUPS.items() for name in names}
"""Option name -> its group."""


ATTRIBUTE = {"model": "model", "batch": "batch", "fixed-lag": "fixed_lag", "tuning": "tuning", "guard": "guard",
             "other": "other"}
"""Group -> attribute of :func:`nested`'s result (``other``: options in no group, e.g. an estimator's own)."""


@lru_cache(maxsize=None)
def _classes(cls: type) -> tuple[type, dict[str, tuple[str, ...]]]:
    """The nested dataclass of the flat options class ``cls`` and group -> its option names (in the order of
    :data:`GROUPS`, as ``--list-options`` lists them)."""
    names = [f.name for f in dataclasses.fields(cls) if f.init]
    members = {group: tuple(n for n in GROUPS[group] if n in names) for group in GROUPS}
    members["other"] = tuple(n for n in names if n not in GROUP_OF)
    parts = []
    for group, own in members.items():
        part = dataclasses.make_dataclass(f"{cls.__name__}_{ATTRIBUTE[group]}", [(n, object) for n in own], frozen=True)
        parts.append((ATTRIBUTE[group], part))
    return dataclasses.make_dataclass(f"{cls.__name__}_groups", parts, frozen=True), members


def nested(options):
    """``options`` (a flat options dataclass: :class:`gfimu.smoother.graph.SmootherOptions`, an estimator)
    as nested frozen dataclasses: ``.model``, ``.batch``, ``.fixed_lag``, ``.tuning``, ``.guard``, ``.other``, each
    holding the options of that group the object has."""
    outer, members = _classes(type(options))
    parts = {f.name: f.type for f in dataclasses.fields(outer)}
    return outer(**{ATTRIBUTE[group]: parts[ATTRIBUTE[group]](**{n: getattr(options, n) for n in own})
                    for group, own in members.items()})


def flatten(cls: type, grouped, **changes):
    """The flat options of class ``cls`` from :func:`nested`'s ``grouped`` (with ``changes`` by flat name)."""
    _, members = _classes(cls)
    values = {n: getattr(getattr(grouped, ATTRIBUTE[group]), n) for group, own in members.items() for n in own}
    unknown = set(changes) - set(values)
    if unknown:
        raise TypeError(f"{cls.__name__} has no option {', '.join(sorted(unknown))}")
    return cls(**{**values, **changes})
