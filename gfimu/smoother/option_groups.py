"""The smoothers' options in four groups: the model, the batch solver, the fixed-lag stream and
the noise tuning (read by ``gfimu estimate --list-options``; every option keeps its flat name for
``-O name=value``)."""

from __future__ import annotations

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
        "reweight_iterations", "initialisation", "ml_sign_chain", "auto_model", "solver",
    ),
    "fixed-lag": (
        "lag_s", "relinearize_threshold", "relinearize_skip", "marginalise_every_s", "warmup_s", "gap_factor",
        "fast_measurement", "tune_window_s", "engine",
    ),
    "tuning": (
        "tune_process_noise", "tune_span_s", "tune_axis_frequencies", "tune_motion_model", "tune_accel_noise",
    ),
}
"""Group -> option names."""

GROUP_OF = {name: group for group, names in GROUPS.items() for name in names}
"""Option name -> its group."""
