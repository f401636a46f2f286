"""The smoother's model chosen from the log itself (the batch smoother's default).

The smoother's Gaussian model is right for arrays whose readings follow the
rigid-body equation up to white noise of the stated level (simulations, well
built rigs). Real arrays often do not: their rigid-body residual exceeds the
datasheet noise several times, grows with the rotation rate and has heavy
tails (sample-time skew, filter differences, alignment and position errors;
see docs/rigid-body-residual.md). The marginal-likelihood tuner
(:mod:`gfimu.smoother.tuning.evidence`) then trusts a wrong noise model, chooses a far
too smooth motion model, and the smoother settles on the wrong sign branch of
ω at fast rotations.

:func:`check_model` asks the data which case holds, before any smoothing, from
the per-sample maximum-likelihood fit (:class:`gfimu.estimators.ml.MLEstimator`),
whose residual ``r_k = y_k - S x̂_k`` (Ho & Lin 2009, eq. 6) sees the readings'
disagreement with a rigid body, sample by sample:

- **noise ratio**: the robust scale (1.4826 × median absolute value) of ``r``,
  corrected for the 9 unknowns fitted per sample (``sqrt(n / (n - 9))`` for n
  axes), over the stated noise std;
- **tail share**: the share of residuals beyond 4 robust scales (a Gaussian puts
  6e-5 there);
- **noise slope**: the residual's growth with |ω|: ``E[r²] = σ₀² + (s |ω|)²``
  fitted to the median residual power in |ω| bins.

The log is *consistent* when the noise ratio is below
:data:`NOISE_RATIO_LIMIT` (where a noise is stated), the tail share below
:data:`TAIL_SHARE_LIMIT` and the residual's variance grows by less than the
variance itself from the 10th to the 90th percentile of |ω|
(:data:`SLOPE_VARIANCE_LIMIT`). These limits are statements about Gaussianity
(a factor two on the noise, a hundred times the Gaussian tail), not values fitted
to any recording.

Consistent logs keep the model that is optimal for them: the sign-resolving
initialisation and the process noise by marginal likelihood. Inconsistent logs
get the model the residual asks for (:func:`misfit_options`): the per-sample ML
initialisation with its sign chain, the accelerometer noise floor σ₀ and slope
s measured above, a Cauchy loss at 2 σ on every accelerometer axis and every
motion-model step (heavy tails, sudden jerks), and process densities by the
method of moments on the initial estimate (:func:`moment_densities`), per solve
window.
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace

import numpy as np

from ...log import Log
from ...rigid_body import quadratic_terms
from ..model.option_groups import ModelGroups, ModelOptions

CHECK_SAMPLES = 5000
"""The model check (:func:`gfimu.smoother.tuning.model_choice.check_model`) reads at most about this many samples,
evenly spread over the log or the stream's recent past (120,000 residuals of an 8-triad array)."""
NOISE_RATIO_LIMIT = 2.0
"""Largest robust residual scale over the stated noise std of a consistent log."""
TAIL_SHARE_LIMIT = 0.006
"""Largest share of residuals beyond 4 robust scales of a consistent log (100 × Gaussian)."""
SLOPE_VARIANCE_LIMIT = 1.0
"""Largest growth of the residual variance from the 10th to the 90th percentile of |ω|, over the
variance at the 10th, of a consistent log: ``s² (|ω|₉₀² - |ω|₁₀²) / (σ₀² + s² |ω|₁₀²)`` (for a
log that also rests, ``(s |ω|₉₀)² / σ₀²``)."""
ROBUST_THRESHOLD = 2.0
"""Cauchy loss threshold [robust σ] of the accelerometer axes and motion-model steps on an
inconsistent log (95 % efficiency region of the Cauchy loss is about 2.4 σ; 2 σ favours robustness)."""


@dataclass(frozen=True)
class ModelCheck:
    """Rigid-body consistency of a log, and the model it leads to (:func:`check_model`)."""

    consistent: bool
    """Whether the readings follow the rigid-body model up to white noise (of the stated level, when
    one is stated)."""
    samples: int
    noise_ratio: float
    """Robust residual scale / stated noise std (NaN when no axis states a noise)."""
    tail_share: float
    """Share of residuals beyond 4 robust scales."""
    noise_floor_mps2: float
    """σ₀ of the fit ``E[r²] = σ₀² + (s |ω|)²`` [m/s²], at least :attr:`resolution_floor_mps2`."""
    noise_slope_mps2_per_radps: float
    """s of that fit [m/s² per rad/s] (0 when the residual does not grow with |ω|)."""
    omega_p90_radps: float
    """90th percentile of the per-sample |ω| [rad/s]."""
    stated_noise_mps2: float
    """Mean stated noise std of the axes that state one [m/s²] (0: stated as noise-free; NaN when none does)."""
    reasons: tuple[str, ...] = ()
    """Why the log is inconsistent (empty when consistent)."""
    resolution_floor_mps2: float = 0.0
    """The smallest noise std the readings can show [m/s²]: their quantisation step / √12, and at least
    :data:`RELATIVE_RESOLUTION` of their RMS; a measured floor below it is raised to it."""
    floored: bool = False
    """Whether the measured noise floor was below :attr:`resolution_floor_mps2` (and raised to it)."""
    constant: bool = False
    """Whether every reading is the same at every sample (nothing to estimate beyond one sample)."""

    @property
    def noise_stated(self) -> bool:
        """Whether any axis states a noise std."""
        return bool(np.isfinite(self.stated_noise_mps2))

    def describe(self) -> str:
        if self.constant:
            return "readings are constant: nothing to estimate beyond a single sample"
        head = ("readings consistent with a rigid body (Gaussian model, noise by marginal likelihood)" if self.consistent
                else "readings disagree with a rigid body beyond white noise (robust model): " + "; ".join(self.reasons))
        if self.noise_stated and self.stated_noise_mps2 == 0:
            level = (f"Noise stated as 0: residual {self.noise_ratio:.1f} x the readings' resolution, "
                     f"floor {self.noise_floor_mps2:.3g} m/s^2")
        elif self.noise_stated:
            level = (f"Residual {self.noise_ratio:.1f} x the stated {self.stated_noise_mps2:.3g} m/s^2, "
                     f"floor {self.noise_floor_mps2:.3g} m/s^2")
        else:
            level = f"No noise level stated: measured {self.noise_floor_mps2:.3g} m/s^2 from the log's own residual"
        if self.floored:
            level += f" (below the readings' resolution, floored at {self.resolution_floor_mps2:.3g} m/s^2)"
        return (f"{head}. {level}, {100 * self.tail_share:.2f} % beyond 4 sigma, "
                f"+ {self.noise_slope_mps2_per_radps:.3g} m/s^2 per rad/s")

    def as_dict(self) -> dict:
        def num(v):
            return float(v) if np.isfinite(v) else None

        return {"consistent": self.consistent, "samples": self.samples, "noise_ratio": num(self.noise_ratio),
                "tail_share": self.tail_share, "noise_floor_mps2": self.noise_floor_mps2,
                "noise_slope_mps2_per_radps": self.noise_slope_mps2_per_radps, "omega_p90_radps": self.omega_p90_radps,
                "stated_noise_mps2": num(self.stated_noise_mps2), "reasons": list(self.reasons),
                "resolution_floor_mps2": self.resolution_floor_mps2, "floored": self.floored,
                "constant": self.constant}


RELATIVE_RESOLUTION = 1e-7
"""The readings' resolution is at least this fraction of their RMS: double precision carries 1e-16,
but the smoothers' normal equations square the weights, and a weight of 1e-16 of the readings makes
them singular; 1e-7 keeps every answer of an exact log within 1e-6 of it."""


def resolution_floor(accel_mps2: np.ndarray) -> float:
    """The smallest noise std [m/s²] readings ``accel_mps2`` (N, axes) can show: the median over the
    axes of their quantisation step (the smallest gap between two of an axis' distinct values) / √12,
    the std of rounding to that step, and at least :data:`RELATIVE_RESOLUTION` of the readings' RMS."""
    a = np.asarray(accel_mps2, dtype=float)
    a = a[np.all(np.isfinite(a), axis=1)]
    if not a.size:
        return 0.0
    steps = []
    for col in a.T:
        u = np.unique(col)
        if u.size >= 2:
            steps.append(float(np.min(np.diff(u))))
    quantum = float(np.median(steps)) / np.sqrt(12.0) if steps else 0.0
    return max(quantum, RELATIVE_RESOLUTION * float(np.sqrt(np.mean(a * a))))


def rigid_body_residual(log: Log, omega_b_radps: np.ndarray, omega_dot_b_radps2: np.ndarray,
                        specific_force_b_mps2: np.ndarray) -> np.ndarray:
    """(N, n_axes) readings minus the rigid-body prediction ``S [f, ω̇, q(ω)]`` (Ho & Lin 2009, eq. 6) [m/s²]."""
    S = log.array.structure_matrix()
    x = np.hstack([specific_force_b_mps2, omega_dot_b_radps2, quadratic_terms(omega_b_radps)])
    return log.accel_mps2 - x @ S.T


def noise_vs_rate(residual_mps2: np.ndarray, omega_b_radps: np.ndarray, dof_factor: float,
                  bins: int = 20) -> tuple[float, float]:
    """(σ₀, s) of ``E[r²] = σ₀² + (s |ω|)²``, fitted to the per-sample mean residual power in |ω|
    quantile bins: σ₀ through the slowest bin, s by least squares on the power above it; each bin's power is its median, scaled to a
    mean by the median of a χ²_ν/ν law, ν = n_axes - 9 (robust against the heavy tails). The
    per-sample estimate's own |ω| error flattens the fit when the noise is large against the motion
    (0.14 measured for 0.2 m/s² per rad/s on a 5 cm cube turning at 2 rad/s)."""
    n_axes = residual_mps2.shape[1]
    power = np.mean(residual_mps2**2, axis=1) * dof_factor
    wn = np.linalg.norm(omega_b_radps, axis=1)
    edges = np.unique(np.quantile(wn, np.linspace(0.0, 1.0, bins + 1)))
    if edges.size < 3:
        return float(np.sqrt(np.mean(power))), 0.0
    idx = np.clip(np.searchsorted(edges, wn, side="right") - 1, 0, edges.size - 2)
    # the residual of a 9-unknown fit has ν = n_axes - 9 degrees of freedom; median of χ²_ν / ν:
    # (1 - 2/(9ν))³ (Wilson-Hilferty)
    nu = max(n_axes - 9, 1)
    median_to_mean = 1.0 / max(1.0 - 2.0 / (9.0 * nu), 0.1) ** 3
    w2, p = [], []
    for b in range(edges.size - 1):
        sel = idx == b
        if np.count_nonzero(sel) >= 10:
            w2.append(np.mean(wn[sel] ** 2))
            p.append(np.median(power[sel]) * median_to_mean)
    w2, p = np.asarray(w2), np.asarray(p)
    if w2.size < 2:
        return float(np.sqrt(np.mean(power))), 0.0
    # the floor from the slowest bin, the slope by least squares on the excess power above it
    # (unweighted: the fast bins, where the noise matters to ω, lead the fit)
    a = float(p[0])
    excess = p - a
    b = float(np.sum(excess * (w2 - w2[0])) / max(float(np.sum((w2 - w2[0]) ** 2)), 1e-300))
    a = max(a - b * w2[0], 0.0)
    if b <= 0:
        return float(np.sqrt(max(np.median(p), 0.0))), 0.0
    return float(np.sqrt(a)), float(np.sqrt(b))


def check_model(log: Log, ml_motion, residual: np.ndarray | None = None) -> ModelCheck:
    """:class:`ModelCheck` of ``log`` from its per-sample ML estimate ``ml_motion`` (a Motion); ``residual``:
    its :func:`rigid_body_residual` when already computed.

    Where no axis states a noise std, the check is of Gaussianity alone (tails, growth with |ω|) and
    the noise level is the one measured; axes without a stated std are left out of the ratio."""
    r = residual if residual is not None else rigid_body_residual(
        log, ml_motion.omega_b_radps, ml_motion.omega_dot_b_radps2, ml_motion.specific_force_b_mps2)
    ok = np.all(np.isfinite(r), axis=1)
    r, omega = r[ok], ml_motion.omega_b_radps[ok]
    n_axes = r.shape[1]
    dof_factor = n_axes / max(n_axes - 9, 1)
    stated = np.asarray(log.array.noise_std_per_axis_mps2, dtype=float)
    stated = np.where(np.isfinite(stated) & (stated >= 0), stated, np.nan)  # 0: stated as noise-free
    stated_mean = float(np.nanmean(stated)) if np.any(np.isfinite(stated)) else float("nan")
    accel = log.accel_mps2[ok]
    resolution = resolution_floor(accel)
    constant = bool(len(accel) >= 2 and np.all(np.ptp(accel, axis=0) == 0))
    scale = 1.4826 * np.median(np.abs(r), axis=0) * np.sqrt(dof_factor)  # per axis
    scale = np.maximum(scale, resolution)
    # a std stated as 0 promises no more than the readings' resolution
    ratio = float(np.nanmedian(scale / np.maximum(stated, resolution))) if np.isfinite(stated_mean) else float("nan")
    tail = float(np.mean(np.abs(r) > 4.0 * scale[None, :] / np.sqrt(dof_factor))) if r.size else 0.0
    floor, slope = noise_vs_rate(r, omega, dof_factor)
    floored = floor < resolution
    floor = max(floor, resolution)
    w90 = float(np.quantile(np.linalg.norm(omega, axis=1), 0.9)) if len(omega) else 0.0
    reasons = []
    if np.isfinite(ratio) and not ratio < NOISE_RATIO_LIMIT:
        reasons.append(f"residual {ratio:.1f} x the stated noise")
    if tail > TAIL_SHARE_LIMIT:
        reasons.append(f"{100 * tail:.2f} % of residuals beyond 4 sigma")
    w10 = float(np.quantile(np.linalg.norm(omega, axis=1), 0.1)) if len(omega) else 0.0
    # the residual grows with |ω| when its power at the 90th percentile of |ω| exceeds its power at the
    # 10th by more than SLOPE_VARIANCE_LIMIT times the latter (a log turning at one rate cannot tell)
    low_power = floor**2 + (slope * w10) ** 2
    if slope > 0 and slope**2 * (w90**2 - w10**2) > SLOPE_VARIANCE_LIMIT * low_power:
        reasons.append(f"residual grows with |omega| ({slope:.3g} m/s^2 per rad/s)")
    return ModelCheck(not reasons, int(len(r)), ratio, tail, floor, slope, w90, stated_mean, tuple(reasons),
                      resolution, bool(floored), constant)


def measured_noise_options(model: ModelOptions, check: ModelCheck) -> ModelOptions:
    """The ``model`` for a consistent log: where no axis states a noise std above 0 (none stated, or
    stated as 0), the measured floor is the accelerometer noise (:func:`gfimu.noise.accel_noise_std`
    then fills every axis with it)."""
    user_set = model.default_accel_noise_std_mps2 != ModelOptions.default_accel_noise_std_mps2
    if check.stated_noise_mps2 > 0 or user_set or not check.noise_floor_mps2 > 0:
        return model
    return replace(model, default_accel_noise_std_mps2=float(check.noise_floor_mps2))


def misfit_options(given: ModelGroups, check: ModelCheck) -> ModelGroups:
    """The option groups of the smoother's model for a log that disagrees with the rigid-body model (see
    module docstring), from those ``given``: its model, solve, batch model and tuning changed."""
    model = given.model
    floor = check.noise_floor_mps2 if check.noise_floor_mps2 > 0 else model.default_accel_noise_std_mps2
    return given._replace(
        model=replace(model, motion_model="jerk", default_accel_noise_std_mps2=floor),
        solve=replace(given.solve, initialisation="ml", ml_sign_chain=True),
        batch_model=replace(given.batch_model, accel_noise_slope_mps2_per_radps=check.noise_slope_mps2_per_radps,
                            robust_loss="cauchy", accel_robust_threshold=ROBUST_THRESHOLD,
                            process_robust_threshold=ROBUST_THRESHOLD),
        tuning=replace(given.tuning, tune_process_noise=False, tune_motion_model=False))


def user_set(given: ModelGroups, chosen: ModelGroups) -> tuple[dict, ...]:
    """Per group of ``given``, the options set away from their defaults (``tune_process_noise`` aside) that
    ``chosen`` changes: name -> the value given. A choice of the model keeps them (:func:`with_user_set`)."""
    return tuple({f.name: getattr(mine, f.name) for f in fields(mine)
                  if f.name != "tune_process_noise" and getattr(mine, f.name) != f.default
                  and getattr(theirs, f.name) != getattr(mine, f.name)}
                 for mine, theirs in zip(given, chosen))


def with_user_set(chosen: ModelGroups, kept: tuple[dict, ...]) -> ModelGroups:
    """``chosen`` with the options ``kept`` (:func:`user_set`) back at the values given."""
    return ModelGroups(*(replace(part, **changes) if changes else part for part, changes in zip(chosen, kept)))


def chosen_options(given: ModelGroups, check: ModelCheck, log: Log, ml_motion) -> ModelGroups:
    """The option groups of the model for ``log`` after its :func:`check_model`, from those ``given``: a
    consistent log keeps them (with the measured noise floor where none is stated, :func:`measured_noise_options`);
    an inconsistent one gets the robust model (:func:`misfit_options`) with, when ``given.tuning`` tunes the
    process noise, the densities of the motion of its per-sample ML estimate ``ml_motion``
    (:func:`motion_densities`), and the options the user set kept (:func:`user_set`)."""
    if check.consistent:
        return given._replace(model=measured_noise_options(given.model, check))
    chosen = misfit_options(given, check)
    kept = user_set(given, chosen)
    if given.tuning.tune_process_noise:  # the process noise of the log's motion (else the fixed densities)
        x = np.hstack([ml_motion.omega_b_radps, ml_motion.omega_dot_b_radps2, ml_motion.specific_force_b_mps2])
        chosen = chosen._replace(model=with_densities(chosen.model, *motion_densities(x, log.dt_s, *estimate_noise_variances(
            log.array, check, ml_motion.omega_b_radps))))
    return with_user_set(chosen, kept)


def estimate_noise_variances(array, check: ModelCheck, omega_b_radps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(N, 3) variances of the per-sample ω̇ and f estimates by the linear rigid-body model with all
    12 unknowns (Ho & Lin 2009, eq. 6), ``diag((SᵀS)⁻¹) σ_k²`` with the measured noise
    ``σ_k² = σ₀² + (s |ω_k|)²``: what the per-sample estimate's own noise puts into its steps."""
    S = array.structure_matrix()
    c = np.diag(np.linalg.pinv(S.T @ S))
    wn = np.linalg.norm(omega_b_radps, axis=1)
    var = check.noise_floor_mps2**2 + (check.noise_slope_mps2_per_radps * wn) ** 2
    return var[:, None] * c[None, 3:6], var[:, None] * c[None, 0:3]


DENSITY_FLOOR = 1e-9
"""Smallest process density [per √s] :func:`with_densities` sets (exactly constant readings measure 0)."""
MOTION_STEP_SIGMAS = 3.0
"""A stretch of the per-sample estimate is motion when the RMS of its steps (over the axes and
:data:`MOTION_PERIOD_S`) exceeds this many times what the estimate's own noise gives."""
MOTION_PERIOD_S = 0.5
"""Length of the stretches [s] over which motion is told from rest."""


def motion_densities(states: np.ndarray, dt_s: np.ndarray, noise_var_jerk: np.ndarray,
                     noise_var_force: np.ndarray, with_motion: bool = False):
    """Per-axis jerk density [rad/s²/√s] and specific-force density [m/s²/√s] of the motion, from the
    steps of the per-sample estimate ``states`` [ω, ω̇, f]: a random walk of density q has steps of
    std ``q √h``; the estimate's own noise (variances ``noise_var_*``, independent per sample) gives
    steps of std ``√(v_k + v_{k+1})``. Steps beyond :data:`MOTION_STEP_SIGMAS` of that are motion;
    q is the robust scale (1.4826 × median absolute value) of the motion's steps / √h, the scale
    of the Cauchy core that the robust motion-model loss expects (its heavy tail, the sudden jerks,
    goes through the loss). A log that rests part of the time keeps the density of its motion;
    a log without motion gets the density of the noise. ``with_motion``: also say whether motion was
    found (jerk, force, found)."""
    h = np.asarray(dt_s, dtype=float)
    out = []
    found = False
    for sl, v in ((slice(3, 6), noise_var_jerk), (slice(6, 9), noise_var_force)):
        steps = np.diff(states[:, sl], axis=0) / np.sqrt(h)[:, None]
        rest = np.sqrt((v[:-1] + v[1:]) / h[:, None])
        z2 = np.mean((steps / np.maximum(rest, 1e-300)) ** 2, axis=1)
        # (at most the stretch: a longer kernel would make the "same" convolution longer than the steps)
        width = min(max(int(round(MOTION_PERIOD_S / max(float(np.median(h)), 1e-12))), 1), len(z2))
        local = np.convolve(z2, np.ones(width) / width, mode="same")
        moving = local > MOTION_STEP_SIGMAS**2
        floor = np.median(rest, axis=0)
        if np.count_nonzero(moving) >= max(10, 0.01 * len(z2)):
            q = 1.4826 * np.median(np.abs(steps[moving]), axis=0)
            found = found or sl.start == 3
        else:
            q = floor
        out.append(np.maximum(q, floor))
    return (out[0], out[1], found) if with_motion else (out[0], out[1])


def with_densities(model: ModelOptions, jerk: np.ndarray, force: np.ndarray) -> ModelOptions:
    """The ``model`` with per-axis jerk densities (their RMS and per-axis factors) and the RMS of the
    per-axis specific-force densities."""
    jerk = np.maximum(np.asarray(jerk, dtype=float), DENSITY_FLOOR)  # readings without any noise or motion
    force = np.maximum(np.asarray(force, dtype=float), DENSITY_FLOOR)
    q = float(np.sqrt(np.mean(jerk**2)))
    return replace(model, omega_dot_random_walk_radps2_per_sqrt_s=q,
                   process_axis_factors=tuple(float(v) for v in jerk / q),
                   specific_force_random_walk_mps2_per_sqrt_s=float(np.sqrt(np.mean(np.asarray(force) ** 2))))


def local_density_factors(states: np.ndarray, dt_s: np.ndarray, noise_var_jerk: np.ndarray,
                          density: float, period_s: float = MOTION_PERIOD_S) -> np.ndarray:
    """(N-1,) factors on the jerk density per step: the local density of the motion over the
    motion density ``density`` [rad/s²/√s], at most 1. The local density is the step power of the
    per-sample ω̇ in ``states`` above what its own noise gives (variances ``noise_var_jerk``),
    averaged over ``period_s``; where the body rests it falls to the level that noise can resolve,
    so that short, slow turns from rest keep the sign the integral of ω̇ gives them instead of
    following the per-sample estimate, which cannot tell the sign of a slow ω (its centripetal
    signal is below the noise)."""
    h = np.asarray(dt_s, dtype=float)
    width = min(max(int(round(period_s / max(float(np.median(h)), 1e-12))), 1), max(h.size, 1))  # a log shorter than the period: its length
    kernel = np.ones(width) / width
    steps = np.sum(np.diff(states[:, 3:6], axis=0) ** 2, axis=1) / h
    noise = np.sum(noise_var_jerk[:-1] + noise_var_jerk[1:], axis=1) / h
    local_noise = np.convolve(noise, kernel, mode="same")
    excess = np.maximum(np.convolve(steps, kernel, mode="same") - local_noise, local_noise)
    return np.clip(np.sqrt(excess / (3.0 * density**2)), 0.0, 1.0)
