"""Diagnosis of a log before trusting it: what the readings say about themselves.

:func:`diagnose` runs the per-sample maximum-likelihood fit
(:class:`gfimu.estimators.ml.MLEstimator`) once and reads from it, and from the raw readings:

- **rigid-body consistency**: the model check of the batch smoother
  (:func:`gfimu.smoother.tuning.model_choice.check_model`), and its residual per sensor and per |ω| band
  (robust scale, 1.4826 × median absolute value, corrected for the 9 unknowns fitted per sample);
- **noise floor**: σ₀ of that check against the noise stated in ``array.toml``;
- **timing**: rate, jitter, gaps, repeated and backward timestamps (:func:`timing_of`);
- **units**: the still array's |f| (:mod:`gfimu.io.plausibility`) near 1 (readings in g) or
  near 9807 (mg); a gyroscope reading about 57.3 × the accelerometers' |ω| (deg/s);
- **positions**: the residual is the same for positions all scaled by one factor (readings
  ``S(c r)`` are fitted by ω̇ / c and ω / √c exactly), so a common scale mistake shows only in
  the sizes (an accelerometer more than 1 m from the origin: mm; all within 1 mm: divided once
  too often) and, with a gyroscope, in ``c = (|ω_gyro| / |ω_accelerometers|)²``;
- **time skew** of one sensor against the others (:func:`sensor_skews`);
- **calibration errors**: constant errors of each sensor's position and each axis' gain that the residual
  shows (:func:`gfimu.array_misfit.calibration_errors`): a misfit that is mostly theirs biases every
  estimate along the states, which no smoother's σ covers (docs/uncertainty.md);
- **stuck and clipped channels** (:func:`channel_faults`);
- **expected accuracy**: the per-sample Cramér-Rao bound (:mod:`gfimu.crb`) at the fitted ω, with
  the stated and the measured noise;
- **sign of ω**: whether the change of ω within 1 s windows is large enough, against the bound,
  for the integral of ω̇ to tell ω from -ω (:func:`sign_resolution`);
- **the smoother against the per-sample fit**: the default batch smoother on the accelerometers
  and its guard (:mod:`gfimu.smoother.guard`): the spans where it fits the readings worse than its
  model allows (:func:`smoother_guard`).

Every threshold below says where it comes from. Pure computation, no I/O.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from .array_misfit import CALIBRATION_MIN_Z, CALIBRATION_SHARE, CalibrationFit, calibration_errors
from .crb import crb_per_sample
from .errors import InputError
from .estimators.ml import MLEstimator
from .io.plausibility import MAX_POSITION_M, MIN_EXTENT_M, RATE_TOLERANCE, still_specific_force, suggested_factor
from .io.units import STANDARD_GRAVITY_MPS2
from .log import Log
from .readings import clipped_readings, dead_channels, describe_dead_channels, runs_of, screen_log, stuck_runs
from .rigid_body import quadratic_terms_jacobian
from .smoother.tuning.model_choice import NOISE_RATIO_LIMIT, check_model, rigid_body_residual

DEG_PER_RAD = 180.0 / np.pi
BANDS_RADPS = (0.0, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0, np.inf)
"""Edges of the |ω| bands [rad/s] of the residual table (octaves from 0.5 rad/s)."""
UNIT_TOLERANCE = 1.4
"""A measured scale within this factor of a unit's scale (g: 1/9.81, mg: 1000/9.81, deg/s: 57.3) names that
unit; the candidates differ by at least 1.8 (57.3 against 31.6, the gyro ratio of positions in mm)."""
CLIP_MIN_RUN = 3
"""A channel pinned at its extreme value for this many consecutive samples is clipped (a smooth peak stays within
one quantum for one or two samples at the rates of IMUs)."""
CLIP_MIN_MAGNITUDE_MPS2 = 1.5 * STANDARD_GRAVITY_MPS2
"""Without a stated range, only extremes beyond 1.5 g can be clipping: a still sensor reads at most 1 g and the
smallest common range is ±2 g."""
SKEW_FRACTION_OF_NOISE = 0.5
"""A sensor's time skew is reported when the residual it explains (skew × the projected rate of change of its
readings, RMS) exceeds half the stated noise std (it then adds a quarter of the noise variance)."""
SKEW_MIN_Z = 5.0
"""... and when the skew is 5 standard errors from zero."""
SIGN_WINDOW_S = 1.0
"""Length [s] of the windows over which the sign of ω is judged."""
SIGN_SNR = 6.0
"""The two signs predict changes of ω that differ by 2 Δω; a decision at the midpoint errs with probability
Φ(-SNR / 2): 0.13 % at 6."""
MAX_FIGURE_POINTS = 20000


@dataclass(frozen=True)
class Timing:
    """The timestamps of a log (:func:`timing_of`)."""

    samples: int
    duration_s: float
    rate_hz: float
    """From the median step."""
    jitter_s: float
    """Robust std of the steps (1.4826 × median absolute deviation from the median step), gaps left out."""
    jitter_max_s: float
    """Largest |step - median step| outside the gaps."""
    gaps: int
    """Steps over 1.5 × the median step."""
    largest_gap_s: float
    duplicates: int
    """Steps of zero."""
    backwards: int
    """Negative steps."""


@dataclass(frozen=True)
class SensorReport:
    name: str
    residual_mps2: float
    """Robust residual scale of the sensor's axes [m/s²] (corrected for the fitted unknowns)."""
    stated_noise_mps2: float
    ratio_to_others: float
    """Residual over the median residual of the other sensors."""
    skew_s: float
    """Time skew against the others [s]: the sensor reads at t + skew (NaN when not estimated)."""
    skew_std_s: float
    position_offset_mm: tuple = (float("nan"),) * 3
    """The constant error of the sensor's position the residual shows [mm, body frame]: the true position less
    array.toml's, the part the readings can tell (:func:`calibration_errors`; NaN when not estimated)."""
    position_offset_std_mm: tuple = (float("nan"),) * 3
    gain_error: tuple = ()
    """The constant gain error of each of its axes (the reading over the true value, less 1)."""
    gain_error_std: tuple = ()


@dataclass(frozen=True)
class BandReport:
    low_radps: float
    high_radps: float
    samples: int
    residual_mps2: float
    crb_omega_radps: float
    """Median per-sample bound on |ω| error [rad/s] (stated noise; measured noise where none stated)."""


@dataclass(frozen=True)
class ChannelFault:
    column: str
    kind: str
    """'stuck' (one value repeated while the others move) or 'clipped' (pinned at the range or at an extreme);
    'dead', 'constant' or 'placeholder' (:func:`gfimu.readings.dead_channels`: no measurement at all)."""
    samples: int
    first_row: int
    last_row: int
    value_mps2: float


@dataclass(frozen=True)
class Consistency:
    """How well the readings fit a rigid body (the per-sample ML fit's residual)."""

    model: dict
    """The smoother's model check (:meth:`gfimu.smoother.tuning.model_choice.ModelCheck.as_dict`)."""
    noise_floor_mps2: float
    stated_noise_mps2: float
    per_sensor: tuple[SensorReport, ...]
    bands: tuple[BandReport, ...]
    calibration_share: float = float("nan")
    """The share of the residual's power that constant position and gain errors explain (:func:`calibration_errors`)."""


@dataclass(frozen=True)
class UnitsAndSizes:
    """What the readings say of their units and of the array's sizes."""

    still_specific_force_mps2: float | None
    """Median |f| of the still stretches, as read [m/s²] (None: no still stretch)."""
    median_specific_force_mps2: float
    """Median |f| of the fitted specific force over the log, as read [m/s²] (the unit check without a still
    stretch: motion of a hand-held or vehicle-borne body changes it by well under the factor 1.4)."""
    accel_unit_suspect: str | None
    """'g', 'mg' or 'unknown scale' when the still |f| is far from 9.81 m/s²; else None."""
    accel_scale_to_mps2: float | None
    """Factor that brings the readings to m/s² when a unit is suspected."""
    gyro_ratio: float | None
    """Median |ω_gyro| / |ω_accelerometers| on well-resolved samples (None without a gyro)."""
    gyro_unit_suspect: str | None
    position_scale_suspect: float | None
    """Factor to apply to position_m when the sizes (or the gyro) say they are not in metres; else None."""
    array_extent_m: float
    array_max_distance_m: float


@dataclass(frozen=True)
class Channels:
    """Channels found at fault (stuck, clipped, dead) and the readings the screening replaced."""

    faults: tuple[ChannelFault, ...]
    screened_readings: int


@dataclass(frozen=True)
class ExpectedAccuracy:
    """The per-sample Cramér-Rao bound at the fitted ω, and how often ω and its sign are told."""

    crb_omega_radps: float
    """Median per-sample bound on |ω| error over the log, with the stated noise [rad/s]."""
    crb_omega_measured_radps: float
    """The same with the measured noise floor [rad/s]."""
    crb_omega_dot_radps2: float
    """Bound on |ω̇| error per sample with the measured noise floor [rad/s²]."""
    omega_p50_radps: float
    omega_p90_radps: float
    resolved_share: float
    """Share of samples whose |ω| exceeds 3 × its bound (magnitude of ω known)."""
    sign_window_share: float
    """Share of 1 s windows whose change of ω tells its sign (:func:`sign_resolution`)."""


class _Part:
    """A value of one of the diagnosis's parts, read by its flat name (the name it has in :meth:`Diagnosis.as_dict`)."""

    def __init__(self, part: str):
        self.part = part

    def __set_name__(self, owner, name: str) -> None:
        self.name = name

    def __get__(self, obj, owner=None):
        return self if obj is None else getattr(getattr(obj, self.part), self.name)


_PARTS = ("consistency", "units", "channels", "accuracy")


@dataclass(frozen=True)
class Diagnosis:
    """What :func:`diagnose` found; :meth:`to_text` for people, :meth:`as_dict` for JSON.

    The log named (``source``, ``array_name``, ``sensors``, ``axes``), its ``timing``, four parts
    (``consistency``, ``units``, ``channels``, ``accuracy``), the ``warnings`` (``fix_first``: those that make
    every estimate wrong until fixed), the ``verdict`` and the smoother's ``guard``. A part's values read
    by their flat names too (``d.gyro_ratio`` is ``d.units.gyro_ratio``), as :meth:`as_dict` writes them."""

    source: str
    array_name: str
    sensors: int
    axes: int
    timing: Timing
    consistency: Consistency
    units: UnitsAndSizes
    channels: Channels
    accuracy: ExpectedAccuracy
    warnings: tuple[str, ...]
    fix_first: tuple[str, ...]
    """The warnings that make every estimate wrong until fixed (units, positions, timestamps)."""
    verdict: str
    guard: dict = field(default_factory=dict)
    """The default smoother's guard on the accelerometers (:meth:`gfimu.smoother.guard.GuardResult.as_dict`:
    ``spans`` with ``start_s``, ``end_s``, samples and excess; ``note`` when it did not run)."""
    figure_data: dict = field(default_factory=dict, repr=False, compare=False)

    model = _Part("consistency")
    noise_floor_mps2 = _Part("consistency")
    stated_noise_mps2 = _Part("consistency")
    per_sensor = _Part("consistency")
    bands = _Part("consistency")
    calibration_share = _Part("consistency")
    still_specific_force_mps2 = _Part("units")
    median_specific_force_mps2 = _Part("units")
    accel_unit_suspect = _Part("units")
    accel_scale_to_mps2 = _Part("units")
    gyro_ratio = _Part("units")
    gyro_unit_suspect = _Part("units")
    position_scale_suspect = _Part("units")
    array_extent_m = _Part("units")
    array_max_distance_m = _Part("units")
    faults = _Part("channels")
    screened_readings = _Part("channels")
    crb_omega_radps = _Part("accuracy")
    crb_omega_measured_radps = _Part("accuracy")
    crb_omega_dot_radps2 = _Part("accuracy")
    omega_p50_radps = _Part("accuracy")
    omega_p90_radps = _Part("accuracy")
    resolved_share = _Part("accuracy")
    sign_window_share = _Part("accuracy")

    def as_dict(self) -> dict:
        """One flat JSON object: the log, its timing, each part's values in turn, the warnings, the verdict,
        the guard (the figure's data left out)."""
        out = {}
        for name, value in asdict(self).items():
            if name in _PARTS:
                out.update(value)
            elif name != "figure_data":
                out[name] = value
        return _json_clean(out)

    def to_text(self) -> str:
        t = self.timing
        lines = [f"gfimu diagnose: {self.source}",
                 f"verdict: {self.verdict}", ""]
        if self.warnings:
            lines.append("warnings")
            lines += [f"  - {w}" for w in self.warnings]
            lines.append("")
        lines += ["timing",
                  f"  {t.samples} samples over {t.duration_s:.2f} s at {t.rate_hz:.4g} Hz; jitter {t.jitter_s * 1e3:.3g} ms "
                  f"(largest {t.jitter_max_s * 1e3:.3g} ms); {t.gaps} gap(s)"
                  + (f", largest {t.largest_gap_s:.4g} s" if t.gaps else "")
                  + f"; {t.duplicates} repeated, {t.backwards} backward timestamp(s)", ""]
        m = self.model
        level = (f"residual {m['noise_ratio']:.2f} x the stated noise" if m["noise_ratio"] is not None
                 else "no noise level stated (measured from the residual)")
        stated = (f"stated {self.stated_noise_mps2:.3g} m/s^2" if np.isfinite(self.stated_noise_mps2)
                  else "none stated")
        floored = (f"; below the readings' resolution, floored at {m['resolution_floor_mps2']:.3g} m/s^2"
                   if m.get("floored") else "")
        lines += ["rigid-body consistency (per-sample ML fit)",
                  f"  {level}, {100 * m['tail_share']:.2f} % beyond 4 sigma; "
                  + ("consistent with a rigid body" if m["consistent"] else "inconsistent: " + "; ".join(m["reasons"])),
                  f"  noise floor {self.noise_floor_mps2:.3g} m/s^2 ({stated}{floored})"
                  f" + {m['noise_slope_mps2_per_radps']:.3g} m/s^2 per rad/s",
                  "  sensor      residual [m/s^2]  x others  skew [ms]          position error [mm]"]
        for s in self.per_sensor:
            skew = "" if not np.isfinite(s.skew_s) else f"{s.skew_s * 1e3:+.3g} ± {s.skew_std_s * 1e3:.2g}"
            offset = ("" if not np.all(np.isfinite(s.position_offset_mm))
                      else ", ".join(f"{v:+.2f}" for v in s.position_offset_mm)
                      + f" ± {max(s.position_offset_std_mm):.2g}")
            lines.append(f"  {s.name:<10}  {s.residual_mps2:>16.3g}  {s.ratio_to_others:>8.2f}  {skew:<17}  {offset}")
        if np.isfinite(self.calibration_share):
            lines.append(f"  constant position and gain errors explain {100 * self.calibration_share:.1f} % of the "
                         "residual's power (a misfit mostly theirs is a calibration error)")
        lines.append("  |omega| band [rad/s]  samples  residual [m/s^2]  bound on |omega| error [rad/s]")
        for b in self.bands:
            high = "inf" if not np.isfinite(b.high_radps) else f"{b.high_radps:g}"
            lines.append(f"  {f'{b.low_radps:g}-{high}':<20} {b.samples:>8}  {b.residual_mps2:>16.3g}  {b.crb_omega_radps:.3g}")
        lines += ["", "units and sizes",
                  "  still |f|: " + (f"no still stretch found; median |f| {self.median_specific_force_mps2:.4g}"
                                     if self.still_specific_force_mps2 is None
                                     else f"{self.still_specific_force_mps2:.4g}") + " (read as m/s^2)"
                  + (f" -> readings likely in {self.accel_unit_suspect}" if self.accel_unit_suspect else ""),
                  f"  array extent {self.array_extent_m * 1e3:.4g} mm, farthest accelerometer {self.array_max_distance_m:.4g} m "
                  "from the origin" + (f" -> positions likely need x {self.position_scale_suspect:g}"
                                       if self.position_scale_suspect else "")]
        if self.gyro_ratio is not None:
            lines.append(f"  gyroscope |omega| / accelerometers' |omega|: {self.gyro_ratio:.3g}"
                         + (f" -> gyroscope likely in {self.gyro_unit_suspect}" if self.gyro_unit_suspect else ""))
        lines += ["", "channels",
                  f"  {self.screened_readings} reading(s) replaced by the screening (not finite, out of range, spikes, "
                  "clipped, stuck)"]
        if not self.faults:
            lines.append("  no stuck, clipped, dead or constant channel")
        for f in self.faults:
            lines.append(f"  {f.column}: {f.kind} at {f.value_mps2:.6g} m/s^2 for {f.samples} sample(s), rows "
                         f"{f.first_row}-{f.last_row}")
        lines += ["", "expected accuracy (per-sample Cramer-Rao bound at the fitted omega)",
                  f"  |omega| median {self.omega_p50_radps:.3g} rad/s, 90th percentile {self.omega_p90_radps:.3g} rad/s",
                  f"  bound on |omega| error, median: {self.crb_omega_radps:.3g} rad/s with the stated noise, "
                  f"{self.crb_omega_measured_radps:.3g} rad/s with the measured noise",
                  f"  bound on |omega_dot| error: {self.crb_omega_dot_radps2:.3g} rad/s^2 (measured noise)",
                  f"  |omega| above 3 x its bound on {100 * self.resolved_share:.1f} % of the samples; the sign of omega "
                  f"is told by the integral of omega_dot in {100 * self.sign_window_share:.1f} % of the "
                  f"{SIGN_WINDOW_S:g} s windows",
                  "  (q(omega) = q(-omega): a sample gives omega up to its sign; the sign comes from how omega changes, "
                  "which omega_dot measures; where omega barely changes, the sign is carried from other windows or lost)"]
        lines += ["", "smoother against the per-sample fit (default smoother on the accelerometers, its guard)"]
        g = self.guard or {}
        if g.get("note"):
            lines.append(f"  {g['note']}")
        else:
            spans = g.get("spans", [])
            lines.append(f"  {len(spans)} span(s) where the smoother fits the readings worse than its model allows, "
                         f"{g.get('seconds', 0.0):.2f} s in all; {g.get('usable_samples', 0)} of {g.get('samples', 0)} "
                         "samples judged (per-sample fit well determined, no outlier)")
            for sp in spans:
                lines.append(f"  {sp['start_s']:.2f}-{sp['end_s']:.2f} s  samples {sp['first_sample']}-"
                             f"{sp['last_sample']} ({sp['samples']})  excess {sp['excess_chi2_per_sample']:.3g} "
                             f"chi2 per sample (allowed 9 on average)  rms ratio {sp['rms_ratio']:.3g}")
        return "\n".join(lines) + "\n"


def _json_clean(v):
    if isinstance(v, dict):
        return {k: _json_clean(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_json_clean(x) for x in v]
    if isinstance(v, (np.floating, float)):
        return float(v) if np.isfinite(v) else None
    if isinstance(v, np.integer):
        return int(v)
    if isinstance(v, np.bool_):
        return bool(v)
    return v


# --- timing ------------------------------------------------------------------

def timing_of(timestamps_ns) -> Timing:
    """:class:`Timing` of raw timestamps [ns] (repeated and backward steps counted, not refused)."""
    t = np.asarray(timestamps_ns, dtype=np.int64).reshape(-1)
    if t.size < 2:
        return Timing(int(t.size), 0.0, float("nan"), float("nan"), float("nan"), 0, 0.0, 0, 0)
    dt = np.diff(t).astype(float) * 1e-9
    positive = dt[dt > 0]
    step = float(np.median(positive)) if positive.size else float("nan")
    gaps = dt > 1.5 * step
    regular = positive[positive <= 1.5 * step]
    dev = np.abs(regular - step)
    return Timing(int(t.size), float((t.max() - t.min()) * 1e-9), 1.0 / step if step > 0 else float("nan"),
                  float(1.4826 * np.median(dev)) if dev.size else float("nan"), float(dev.max()) if dev.size else 0.0,
                  int(gaps.sum()), float(dt[gaps].max()) if gaps.any() else 0.0, int(np.sum(dt == 0)),
                  int(np.sum(dt < 0)))


# --- channels ----------------------------------------------------------------

def channel_faults(accel_mps2: np.ndarray, columns, rate_hz: float,
                   range_mps2=None) -> tuple[list[ChannelFault], np.ndarray]:
    """(stuck and clipped channels, (N, n_axes) mask of their readings) of readings (N, n_axes).

    *Clipped*: within :data:`gfimu.readings.CLIP_TOLERANCE` of ±``range_mps2`` (per axis, where stated) or,
    without a range, held at the channel's largest or smallest value for :data:`CLIP_MIN_RUN` samples in a row
    beyond :data:`CLIP_MIN_MAGNITUDE_MPS2`. *Stuck*: :func:`gfimu.readings.stuck_runs` (the screening's rule)."""
    y = np.asarray(accel_mps2, dtype=float)
    n, m = y.shape
    out: list[ChannelFault] = []
    rng = np.full(m, np.nan) if range_mps2 is None else np.broadcast_to(np.asarray(range_mps2, float), (m,))
    pinned = clipped_readings(y, rng)
    for c in range(m):
        col = y[:, c]
        if np.isfinite(rng[c]) or not np.isfinite(col).any():
            continue
        for v in (np.nanmax(col), np.nanmin(col)):
            at = col == v
            if abs(v) >= CLIP_MIN_MAGNITUDE_MPS2 and any(b - a >= CLIP_MIN_RUN for a, b in runs_of(at)):
                pinned[:, c] |= at
    mask = pinned.copy()
    for c in np.nonzero(pinned.any(axis=0))[0]:
        rows = np.nonzero(pinned[:, c])[0]
        out.append(ChannelFault(columns[c], "clipped", int(rows.size), int(rows[0]), int(rows[-1]), float(y[rows[0], c])))
    stuck: dict[int, list[tuple[int, int]]] = {}
    for c, a, b in stuck_runs(y, rate_hz, exclude=pinned):
        stuck.setdefault(c, []).append((a, b))
        mask[a:b, c] = True
    for c, spans in sorted(stuck.items()):
        out.append(ChannelFault(columns[c], "stuck", int(sum(b - a for a, b in spans)), spans[0][0], spans[-1][1] - 1,
                                float(y[spans[0][0], c])))
    return out, mask


# --- per-sensor residual and skew -------------------------------------------

def _robust_scale(x: np.ndarray, axis=0) -> np.ndarray:
    return 1.4826 * np.median(np.abs(x), axis=axis)


def _tangent_projector_apply(D_w: np.ndarray, v_w: np.ndarray) -> np.ndarray:
    """v - Q Qᵀ v per sample, Q an orthonormal basis of the columns of D_w (N, n, k)."""
    q, _ = np.linalg.qr(D_w)
    return v_w - np.einsum("nik,nk->ni", q, np.einsum("nik,ni->nk", q, v_w))


def _smooth_derivative(y: np.ndarray, times_s: np.ndarray) -> np.ndarray:
    """d y / dt of each column by a local quadratic fit over about 0.05 s (at least 5 samples)."""
    from scipy.signal import savgol_filter

    h = float(np.median(np.diff(times_s)))
    width = max(5, int(round(0.05 / h)) | 1)
    if y.shape[0] <= width:
        return np.gradient(y, times_s, axis=0)
    return savgol_filter(y, width, 2, deriv=1, delta=h, axis=0)


def sensor_skews(log: Log, motion, sigma_axes: np.ndarray, residual: np.ndarray,
                 use: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(skew [s], standard error [s], RMS of the projected regressor [m/s² per s]) of each accelerometer against
    the others (skew × the last is the RMS residual the skew explains on the sensor's axes).

    A sensor reading at t + δ reads ``y_i(t) + δ ẏ_i(t)``; the per-sample fit absorbs what of that lies in the
    tangent space of the model, ``D = [S_f, S_ω̇, S_q ∂q/∂ω]`` at the fitted ω, so its whitened residual is
    ``δ P⊥ W ẏ_i`` plus noise. δ is the least-squares slope of the residual on that regressor (ẏ_i by a smooth
    derivative of the readings). A skew common to all sensors is a shift of the whole log, not seen (its
    regressor lies in the tangent space). ``use`` (N,) selects the samples (default: all finite ones)."""
    array = log.array
    S = array.structure_matrix()
    w = 1.0 / sigma_axes
    ok = np.all(np.isfinite(residual), axis=1) & np.all(np.isfinite(motion.omega_b_radps), axis=1)
    if use is not None:
        ok &= use
    D = np.concatenate([np.broadcast_to(S[:, :6], (int(ok.sum()),) + S[:, :6].shape),
                        np.einsum("aj,njk->nak", S[:, 6:], quadratic_terms_jacobian(motion.omega_b_radps[ok]))], axis=2)
    D_w = D * w[None, :, None]
    ydot = _smooth_derivative(log.accel_mps2, log.times_s)[ok]
    r_w = residual[ok] * w[None, :]
    owner = array.axis_owner
    skew = np.full(len(array.accelerometers), np.nan)
    err = np.full(len(array.accelerometers), np.nan)
    size = np.full(len(array.accelerometers), np.nan)
    for i in range(len(array.accelerometers)):
        v = np.where((owner == i)[None, :], ydot * w[None, :], 0.0)
        g = _tangent_projector_apply(D_w, v)
        gg = float(np.sum(g**2))
        if gg <= 0:
            continue
        d = float(np.sum(g * r_w) / gg)
        rest = r_w - d * g
        skew[i] = d
        err[i] = float(np.median(_robust_scale(rest, axis=0))) / np.sqrt(gg)
        size[i] = np.sqrt(gg / (g.shape[0] * np.count_nonzero(owner == i))) * float(np.mean(sigma_axes[owner == i]))
    return skew, err, size


# --- sign --------------------------------------------------------------------

def sign_resolution(omega_b_radps: np.ndarray, sigma_omega: np.ndarray, sigma_omega_dot: np.ndarray,
                    times_s: np.ndarray, window_s: float = SIGN_WINDOW_S) -> np.ndarray:
    """(windows,) SNR of the sign of ω in windows of ``window_s``.

    ω and -ω give the same centripetal readings; ω̇ is measured with its sign. Over a window in which ω (one axis)
    changes by Δ, the hypotheses ω and -ω predict changes +Δ and -Δ, against the integral of ω̇ whose noise is
    ``σ_ω̇ √(h T)``, and the per-sample ω at both ends (``σ_ω √2``): SNR = 2 |Δ| / √(2 σ_ω² + σ_ω̇² h T), best axis."""
    h = float(np.median(np.diff(times_s))) if times_s.size > 1 else 1.0
    width = max(2, int(round(window_s / h)))
    out = []
    for s in range(0, len(times_s) - width + 1, width):
        sl = slice(s, s + width)
        w = omega_b_radps[sl]
        so = sigma_omega[sl]
        sd = sigma_omega_dot[sl]
        if not np.all(np.isfinite(w)):
            out.append(0.0)
            continue
        delta = np.percentile(w, 95, axis=0) - np.percentile(w, 5, axis=0)
        so_med = np.median(np.where(np.isfinite(so), so, np.inf), axis=0)
        noise = np.sqrt(2 * so_med**2 + np.median(sd, axis=0) ** 2 * h * window_s)
        with np.errstate(divide="ignore", invalid="ignore"):
            snr = np.where(np.isfinite(noise) & (noise > 0), 2 * delta / noise, 0.0)
        out.append(float(np.max(snr)))
    return np.asarray(out)


# --- the diagnosis -----------------------------------------------------------

def _unit_suspect(g0: float | None, still: bool = True) -> tuple[str | None, float | None]:
    """(unit, factor to m/s²) the readings are likely in, from |f| of a still stretch (``still``) or the median
    |f| of a moving log (there a larger |f| is a wrong scale only beyond
    :data:`~gfimu.io.plausibility.MOVING_HIGH` × gravity); (None, None) when |f| is near gravity."""
    from .io.plausibility import MOVING_HIGH

    if g0 is None or not g0 > 0 or not np.isfinite(g0):
        return None, None
    ratio = STANDARD_GRAVITY_MPS2 / g0
    if 1 / 2 <= ratio <= 2 or (not still and 1 / MOVING_HIGH < ratio < 1 / 2):
        return None, None
    for name, scale in (("g", STANDARD_GRAVITY_MPS2), ("mg", STANDARD_GRAVITY_MPS2 / 1000)):
        if scale / UNIT_TOLERANCE <= ratio <= scale * UNIT_TOLERANCE:
            return name, scale
    return "unknown scale", ratio


def diagnose(log: Log, progress: bool = False, calibration=None, smoother_options: dict | None = None) -> Diagnosis:
    """:class:`Diagnosis` of ``log`` (raw readings; ``calibration`` a :class:`gfimu.calibration.Calibration` to
    apply first; ``smoother_options``: options of the batch smoother whose guard is reported, default none)."""
    from . import noise as noise_policy

    if calibration is not None:
        from .calibration import apply_calibration

        log = apply_calibration(log, calibration)
    array = log.array
    timing = timing_of(log.timestamps_ns)
    faults, fault_mask = channel_faults(log.accel_mps2, array.accel_columns, timing.rate_hz, array.range_per_axis_mps2)
    clean, screening = screen_log(log)
    sigma_axes = noise_policy.accel_noise_std(array)
    fit = _Fit.of(log, clean, progress)
    sensors, skew_size, calibration = _sensor_reports(clean, fit, sigma_axes, ~fault_mask.any(axis=1))
    bound = _Bound.of(clean, fit, sigma_axes)
    units = _units_and_sizes(log, fit, bound)
    dead = dead_channels(log.accel_mps2, array.accel_columns)
    fix = _fix_first(units, dead, len(array.accel_columns), timing)
    warn = _warnings(fit, faults, sensors, skew_size, sigma_axes, timing, screening)
    if not fit.check.consistent:  # (a misfit within the noise is nobody's calibration error)
        warn += _calibration_warning(clean, calibration)
    faults += [ChannelFault(d.column, d.kind, d.samples, d.first_row, len(log) - 1, d.value_mps2) for d in dead]
    guard = smoother_guard(clean, smoother_options)
    if guard.get("spans"):
        warn.append(f"the smoother {guard['message']}")
    all_warnings = tuple(fix + warn)
    figure = {"times_s": clean.times_s, "omega_norm_radps": bound.wn, "bound_radps": bound.so_norm * max(bound.factor, 1.0),
              "residual_norm_mps2": np.sqrt(np.mean(fit.residual**2, axis=1)), "dt_s": np.diff(log.timestamps_ns) * 1e-9,
              "sign_snr": bound.sign_snr}
    consistency = Consistency(fit.check.as_dict(), float(fit.check.noise_floor_mps2), float(fit.check.stated_noise_mps2),
                              tuple(sensors), tuple(_band_reports(fit, bound)), float(calibration.share))
    return Diagnosis(log.source, array.name, len(array.accelerometers), array.n_axes, timing, consistency, units,
                     Channels(tuple(faults), int(screening.count)), bound.accuracy(), all_warnings, tuple(fix),
                     _verdict(fix, warn, all_warnings, bound), guard=_json_clean(guard), figure_data=figure)


@dataclass(frozen=True)
class _Fit:
    """The per-sample ML fit of the screened readings the diagnosis reads: its motion, the rigid-body residual
    (N, axes), the model check, the residual's robust scale per axis and the factor ``dof`` that corrects a
    scale for the 9 unknowns fitted per sample."""

    motion: object
    residual: np.ndarray
    check: object
    ok: np.ndarray
    """Samples whose residual is finite."""
    dof: float
    scale_axis: np.ndarray

    @classmethod
    def of(cls, log: Log, clean: Log, progress: bool) -> _Fit:
        """The fit of ``clean`` (the screened ``log``, which names the log in the error when ML cannot run)."""
        estimator = MLEstimator()
        reason = estimator.applicable(log.array)
        if reason:
            raise InputError(f"{log.source}: cannot diagnose the readings: {reason}")
        motion = estimator.estimate_motion(clean, progress=progress)
        residual = rigid_body_residual(clean, motion.omega_b_radps, motion.omega_dot_b_radps2,
                                       motion.specific_force_b_mps2)
        check = check_model(clean, motion, residual)
        n_axes = log.array.n_axes
        dof = np.sqrt(n_axes / max(n_axes - 9, 1))
        ok = np.all(np.isfinite(residual), axis=1)
        return cls(motion, residual, check, ok, dof, _robust_scale(residual[ok], axis=0) * dof)


def _sensor_reports(clean: Log, fit: _Fit, sigma_axes: np.ndarray, use: np.ndarray) -> tuple[list, np.ndarray,
                                                                                           CalibrationFit]:
    """(a :class:`SensorReport` per accelerometer: residual, stated noise, ratio to the others, time skew,
    position and gain errors; the size of each sensor's projected rate of change, which a skew multiplies; the
    calibration fit) from the samples ``use``."""
    array = clean.array
    owner = array.axis_owner
    stated = array.noise_std_per_axis_mps2
    per_sensor_scale = np.array([np.sqrt(np.mean(fit.scale_axis[owner == i] ** 2))
                                 for i in range(len(array.accelerometers))])
    skew, skew_err, skew_size = sensor_skews(clean, fit.motion, sigma_axes, fit.residual, use=use)
    calibration = calibration_errors(clean, fit.motion, sigma_axes, fit.residual, use=use)
    sensors = []
    for i, acc in enumerate(array.accelerometers):
        others = np.delete(per_sensor_scale, i)
        ref = float(np.median(others)) if others.size else float("nan")
        st = stated[owner == i]
        mine = owner == i
        sensors.append(SensorReport(acc.name, float(per_sensor_scale[i]),
                                    float(np.nanmean(st)) if np.any(np.isfinite(st)) else float("nan"),
                                    float(per_sensor_scale[i] / ref) if ref > 0 else float("nan"),
                                    float(skew[i]), float(skew_err[i]),
                                    tuple(float(v) for v in calibration.position_m[i] * 1e3),
                                    tuple(float(v) for v in calibration.position_std_m[i] * 1e3),
                                    tuple(float(v) for v in calibration.gain[mine]),
                                    tuple(float(v) for v in calibration.gain_std[mine])))
    return sensors, skew_size, calibration


def _calibration_warning(clean: Log, fit: CalibrationFit) -> list[str]:
    """The warning that the readings' misfit is mostly a calibration error (:data:`CALIBRATION_SHARE`), naming
    the sensors whose position error is significant (:data:`CALIBRATION_MIN_Z`, the largest three) and the
    largest significant gain error; none otherwise."""
    if not fit.share >= CALIBRATION_SHARE:
        return []
    array = clean.array
    with np.errstate(divide="ignore", invalid="ignore"):
        z_pos = np.max(np.abs(fit.position_m / fit.position_std_m), axis=1)
        z_gain = np.abs(fit.gain / fit.gain_std)
    size = np.linalg.norm(fit.position_m, axis=1)
    named = [i for i in np.argsort(-size) if z_pos[i] >= CALIBRATION_MIN_Z][:3]
    parts = []
    if named:
        listed = "; ".join(f"{array.accelerometers[i].name} " + ", ".join(f"{v * 1e3:+.2f}" for v in fit.position_m[i])
                           + " mm" for i in named)
        parts.append(f"sensor positions off array.toml's by up to {size[named[0]] * 1e3:.2g} mm ({listed}; a shift "
                     "common to every sensor does not show)")
    significant = np.nonzero(z_gain >= CALIBRATION_MIN_Z)[0]
    if significant.size:
        a = int(significant[np.argmax(np.abs(fit.gain[significant]))])
        parts.append(f"axis gains off by up to {100 * fit.gain[a]:+.2g} % ({array.accel_columns[a]})")
    if not parts:
        return []
    return [f"the readings' misfit is {100 * fit.share:.0f} % that of constant calibration errors: "
            + "; ".join(parts) + ". Re-measure the positions, calibrate the gains (gfimu calibrate); the smoothers' "
            "sigma does not cover such an error (docs/uncertainty.md)"]


@dataclass(frozen=True)
class _Bound:
    """The per-sample Cramér-Rao bound at the fitted ω: with the stated noise (``so``, ``sd``: σ of ω and ω̇,
    (N, 3)), and ``factor`` the measured noise floor over the stated noise; ``wn`` |ω| fitted, ``resolved``
    the samples whose |ω| exceeds 3 × its bound, ``sign_snr`` per window (:func:`sign_resolution`)."""

    so: np.ndarray
    sd: np.ndarray
    so_norm: np.ndarray
    factor: float
    wn: np.ndarray
    resolved: np.ndarray
    sign_snr: np.ndarray

    @classmethod
    def of(cls, clean: Log, fit: _Fit, sigma_axes: np.ndarray) -> _Bound:
        """The bound at ``fit``'s ω: stated noise (the measured floor where none is stated) and measured floor."""
        floor = fit.check.noise_floor_mps2 if fit.check.noise_floor_mps2 > 0 else float(np.nanmean(sigma_axes))
        omega = np.where(np.isfinite(fit.motion.omega_b_radps), fit.motion.omega_b_radps, 0.0)
        bound_stated = crb_per_sample(clean.array, omega, noise_std_mps2=sigma_axes)
        factor = floor / float(np.mean(sigma_axes))
        so = bound_stated.sigma_omega
        sd = bound_stated.sigma_omega_dot
        so_norm = np.sqrt(np.sum(so**2, axis=1))
        wn = np.linalg.norm(omega, axis=1)
        resolved = wn > 3 * so_norm * max(factor, 1.0)
        sign_snr = sign_resolution(omega, so * max(factor, 1.0), sd * max(factor, 1.0), clean.times_s)
        return cls(so, sd, so_norm, factor, wn, resolved, sign_snr)

    @property
    def crb_stated(self) -> float:
        """Median bound on |ω| error with the stated noise [rad/s]."""
        return float(np.median(self.so_norm))

    def accuracy(self) -> ExpectedAccuracy:
        """The :class:`ExpectedAccuracy` part of the diagnosis."""
        share_sign = float(np.mean(self.sign_snr >= SIGN_SNR)) if self.sign_snr.size else 0.0
        crb_stated = self.crb_stated
        return ExpectedAccuracy(crb_stated, crb_stated * self.factor,
                                float(np.median(np.sqrt(np.sum(self.sd**2, axis=1)))) * self.factor,
                                float(np.median(self.wn)), float(np.quantile(self.wn, 0.9)),
                                float(np.mean(self.resolved)), share_sign)


def _band_reports(fit: _Fit, bound: _Bound) -> list[BandReport]:
    """The residual and the median bound on |ω| error in each |ω| band of :data:`BANDS_RADPS` holding samples."""
    bands = []
    for lo, hi in zip(BANDS_RADPS[:-1], BANDS_RADPS[1:]):
        sel = fit.ok & (bound.wn >= lo) & (bound.wn < hi)
        if not sel.any():
            continue
        bands.append(BandReport(float(lo), float(hi), int(sel.sum()),
                                float(np.sqrt(np.mean((_robust_scale(fit.residual[sel], axis=0) * fit.dof) ** 2))),
                                float(np.median(bound.so_norm[sel]))))
    return bands


def _units_and_sizes(log: Log, fit: _Fit, bound: _Bound) -> UnitsAndSizes:
    """What the readings say of their unit (still |f|, or the median fitted |f|), of the gyroscope's unit
    (its |ω| against the fitted one on resolved samples) and of the positions' unit (sizes, or the gyro)."""
    array = log.array
    g0 = still_specific_force(log)
    f_median = float(np.nanmedian(np.linalg.norm(fit.motion.specific_force_b_mps2, axis=1)))
    unit, unit_scale = (_unit_suspect(g0 if g0 is not None else f_median, still=g0 is not None)
                        if array.readings == "specific_force"
                        else (None, None))  # linear acceleration: no gravity to measure the scale by
    gyro_ratio = gyro_unit = None
    if log.gyro_b_radps is not None:
        valid = np.all(np.isfinite(log.gyro_b_radps), axis=1) & bound.resolved
        if log.invalid_reference is not None:
            valid &= ~np.asarray(log.invalid_reference, bool)
        if np.count_nonzero(valid) >= 10:
            gyro_ratio = float(np.median(np.linalg.norm(log.gyro_b_radps[valid], axis=1) / bound.wn[valid]))
            if DEG_PER_RAD / UNIT_TOLERANCE <= gyro_ratio <= DEG_PER_RAD * UNIT_TOLERANCE:
                gyro_unit = "deg/s"
    pos = np.array([a.position_m for a in array.accelerometers])
    extent = float(np.max(np.linalg.norm(pos[:, None] - pos[None], axis=2))) if len(pos) > 1 else 0.0
    far = float(np.max(np.linalg.norm(pos, axis=1)))
    pos_scale = None
    if far > MAX_POSITION_M:
        pos_scale = next((f for f in (1e-3, 1e-2) if far * f <= MAX_POSITION_M), 1e-3)
    elif 0 < extent < MIN_EXTENT_M:
        pos_scale = 1e3
    elif gyro_ratio is not None and gyro_unit is None:
        # positions written c times too large give ω / √c: the gyro reads √c times the accelerometers' ω
        c = gyro_ratio**2
        for candidate in (1e3, 1e2):
            if candidate / UNIT_TOLERANCE**2 <= c <= candidate * UNIT_TOLERANCE**2:
                pos_scale = 1.0 / candidate
    return UnitsAndSizes(g0, f_median, unit, unit_scale, gyro_ratio, gyro_unit, pos_scale, extent, far)


def _fix_first(units: UnitsAndSizes, dead: list, n_columns: int, timing: Timing) -> list[str]:
    """The warnings that make every estimate wrong until fixed: units, positions, ``dead`` channels (of
    ``n_columns``), timestamps."""
    u = units
    fix = []
    if u.accel_unit_suspect:
        g0, f_median = u.still_specific_force_mps2, u.median_specific_force_mps2
        what = f"still |f| = {g0:.4g}" if g0 is not None else f"median |f| = {f_median:.4g} (no still stretch)"
        fix.append(f"{what} read as m/s^2, not {STANDARD_GRAVITY_MPS2:g}: readings likely in {u.accel_unit_suspect} "
                   f"(multiply by {u.accel_scale_to_mps2:.6g}; write the column units as [{u.accel_unit_suspect}])"
                   if u.accel_unit_suspect != "unknown scale"
                   else f"{what} read as m/s^2: {suggested_factor(1.0 / u.accel_scale_to_mps2)}; check the unit and "
                        "scale of the readings")
    if u.position_scale_suspect is not None:
        far, extent = u.array_max_distance_m, u.array_extent_m
        why = (f"farthest accelerometer {far:.4g} m from the origin" if far > MAX_POSITION_M else
               f"accelerometers within {extent * 1e3:.3g} mm of each other" if extent < MIN_EXTENT_M else
               f"gyroscope reads {u.gyro_ratio:.3g} x the accelerometers' |omega|")
        fix.append(f"position_m likely not in metres ({why}): multiply the positions by {u.position_scale_suspect:g}")
    if u.gyro_unit_suspect:
        fix.append(f"gyroscope reads {u.gyro_ratio:.3g} x the accelerometers' |omega|: likely in deg/s (write [deg s^-1])")
    fix += describe_dead_channels(dead, n_columns)
    if timing.backwards or timing.duplicates:
        fix.append(f"{timing.backwards} backward and {timing.duplicates} repeated timestamp(s)")
    return fix


def _warnings(fit: _Fit, faults: list, sensors: list, skew_size: np.ndarray, sigma_axes: np.ndarray,
              timing: Timing, screening) -> list[str]:
    """The other warnings, in order: stuck or clipped channels, time skews, a sensor whose residual stands out,
    readings no rigid body explains, gaps, timestamp jitter, readings the screening replaced."""
    warn = []
    for f in faults:
        warn.append(f"{f.column} {f.kind} at {f.value_mps2:.6g} m/s^2 for {f.samples} sample(s) (rows {f.first_row}-"
                    f"{f.last_row})")
    for i, s in enumerate(sensors):
        if not np.isfinite(s.skew_s):
            continue
        explained = abs(s.skew_s) * skew_size[i]
        if abs(s.skew_s) > SKEW_MIN_Z * s.skew_std_s and explained > SKEW_FRACTION_OF_NOISE * np.mean(sigma_axes):
            warn.append(f"{s.name} reads {s.skew_s * 1e3:+.3g} ms ({s.skew_s * timing.rate_hz:+.2f} samples) off the "
                        "others (time skew)")
    for s in sensors:
        if s.ratio_to_others > NOISE_RATIO_LIMIT and not any(w.startswith(s.name + " ") for w in warn):
            warn.append(f"{s.name}: residual {s.ratio_to_others:.1f} x the other sensors' (faulty, misplaced or "
                        "misaligned sensor)")
    if not fit.check.consistent:
        warn.append("readings disagree with a rigid body beyond white noise: " + "; ".join(fit.check.reasons))
    if timing.gaps:
        warn.append(f"{timing.gaps} gap(s) in time, largest {timing.largest_gap_s:.4g} s (estimators restart there)")
    if np.isfinite(timing.jitter_s) and timing.rate_hz > 0 and timing.jitter_s * timing.rate_hz > RATE_TOLERANCE:
        warn.append(f"timestamp jitter {timing.jitter_s * 1e3:.3g} ms, {100 * timing.jitter_s * timing.rate_hz:.1f} % "
                    "of the step")
    if screening.count:
        warn.append(f"{screening.count} reading(s) replaced by the screening")
    return warn


def _verdict(fix: list, warn: list, all_warnings: tuple, bound: _Bound) -> str:
    """The one-line verdict: FIX FIRST, USE WITH CARE or CLEAN (with the median bound on ω)."""
    if fix:
        return f"FIX FIRST: {fix[0]}" + (f" (and {len(all_warnings) - 1} more warning(s))" if len(all_warnings) > 1 else "")
    if warn:
        return f"USE WITH CARE: {len(warn)} warning(s), first: {warn[0]}"
    return f"CLEAN: no fault found; omega to about {bound.crb_stated * bound.factor:.3g} rad/s per sample (median bound)"


def smoother_guard(log: Log, options: dict | None = None) -> dict:
    """The batch smoother (default options, or ``options``) on ``log``'s accelerometers (``use_gyro=False``: the
    guard compares with the per-sample fit of the accelerometers alone) and what its guard found, in 'warn'
    mode (:meth:`gfimu.smoother.guard.GuardResult.as_dict`, with the spans in a few words as ``message``);
    ``note`` says why when the smoother cannot run on the log."""
    from .errors import GfimuError
    from .smoother.batch.engine import BatchSmootherEstimator

    estimator = BatchSmootherEstimator(**{**(options or {}), "use_gyro": False, "guard": "warn"})
    reason = estimator.applicable(log.array)
    if reason:
        return {"mode": "warn", "spans": [], "note": f"smoother not run: {reason}"}
    try:
        result = estimator.estimate(log).report.guard
    except GfimuError as e:
        return {"mode": "warn", "spans": [], "note": f"smoother not run: {e}"}
    out = result.as_dict()
    out["message"] = result.summary() or ""
    return out


def diagnosis_figure(d: Diagnosis):
    """A matplotlib Figure (Agg, imported here) of a diagnosis: residual and bound over time, per sensor, steps."""
    from .plots import _figure

    fig = _figure(9.0, 8.0)
    axes = fig.subplots(4, 1)
    data = d.figure_data
    t = data["times_s"]
    step = max(1, len(t) // MAX_FIGURE_POINTS)
    ax = axes[0]
    w = data["omega_norm_radps"][::step]
    top = 3.0 * max(float(np.max(w)) if w.size else 1.0, 1e-3)
    ax.plot(t[::step], np.clip(w, top * 1e-5, None), lw=0.6, label="|omega| (ML fit)")
    ax.plot(t[::step], np.clip(data["bound_radps"][::step], top * 1e-5, top), lw=0.6,
            label="bound on |omega| error (clipped to the plot)")
    ax.set_yscale("log")
    ax.set_ylim(top * 1e-5, top)
    ax.set_ylabel("rad/s")
    ax.legend(loc="upper right", fontsize=8)
    verdict = d.verdict if len(d.verdict) <= 110 else d.verdict[:107] + "..."
    ax.set_title(f"{d.source}\n{verdict}", fontsize=8)
    ax = axes[1]
    ax.plot(t[::step], data["residual_norm_mps2"][::step], lw=0.5)
    ax.axhline(d.stated_noise_mps2, color="k", ls="--", lw=0.8, label="stated noise")
    ax.set_ylabel("RMS residual [m/s^2]")
    ax.set_xlabel("time [s]")
    ax.legend(loc="upper right", fontsize=8)
    ax = axes[2]
    names = [s.name for s in d.per_sensor]
    ax.bar(names, [s.residual_mps2 for s in d.per_sensor])
    ax.axhline(d.stated_noise_mps2, color="k", ls="--", lw=0.8)
    ax.set_ylabel("residual per sensor [m/s^2]")
    ax = axes[3]
    dt = data["dt_s"]
    ax.plot(np.arange(dt.size)[::step], dt[::step] * 1e3, lw=0.5)
    ax.set_ylabel("step [ms]")
    ax.set_xlabel("sample")
    return fig
