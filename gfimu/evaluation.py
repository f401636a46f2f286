"""Accuracy of an estimate against truth or a reference (pure computation, no I/O).

For every quantity both motions have, :func:`evaluate` reports, over the rows
kept (matching timestamps, valid, finite):

- ``rmse`` per axis: sqrt(mean_i e_ij²) with e = estimate − truth;
- ``rmse_norm``: RMS of the error vector's norm, sqrt(mean_i ‖e_i‖²);
- ``median_norm``: median of ‖e_i‖;
- ``relative_rms`` per axis, McGinnis, Perkins & King 2012, eq. (7):
  ε_j = sqrt(mean_i e_ij²) / sqrt(mean_i ‖t_i‖²), the component's RMS error
  normalised by the RMS magnitude of the true vector t (the paper's
  "theoretical root mean square angular velocity magnitude"); applied to
  every vector quantity, not to attitude;
- for ω only: ``flipped_share`` (the share of samples on the wrong sign: the whole
  vector points the other way), ``axis_sign_off_share``, ``axis_sign_off_share_axis``
  (a component's sign differs, which small components of a right vector also do) and
  ``large_error_share`` (:class:`SignShares`, ``QuantityMetrics.signs``);
- when the estimate carries one-sigma values (``gfimu estimate --sigma``), the calibration of that σ:
  ``coverage_1sigma`` / ``coverage_2sigma`` per axis, the share of rows with |e_j| < σ_j (resp. 2σ_j;
  0.683 and 0.954 for a Gaussian error of that σ), and ``mean_nees``, the mean over rows of
  Σ_j (e_j/σ_j)² (the number of axes, 3, when σ is right); over the rows whose σ is finite and positive
  (:class:`SigmaCoverage`, ``QuantityMetrics.sigma``).

Attitude (quaternions): the error is the rotation vector of
R_trueᵀ R_est, in B, in rad (its norm is the attitude error angle); a
``tilt`` row also gives the angle between the true and estimated vertical
seen from B (yaw-free, for orientation from gravity alone).

Rows left out: those where ``valid`` is False (pass
``~log.invalid_reference``), counted as ``n_invalid``; per quantity, rows
whose estimate or truth is not finite, counted as ``n_nonfinite``.
"""

from __future__ import annotations

import csv as _csv
import io
import json
import math
import warnings
from dataclasses import dataclass, replace

import numpy as np

from .errors import DataError, InputError
from .motion import QUANTITIES, Motion
from .rotations import quaternion_from_rotation_vector, quaternion_multiply, rotation_vector_from_quaternion

# quantity identifier (Motion field name; attitude and tilt errors in rad) -> (short label, unit, CSV prefix)
QUANTITY_INFO = {
    "omega_b_radps": ("omega", "rad s^-1", "w"),
    "omega_dot_b_radps2": ("omega_dot", "rad s^-2", "dw"),
    "accel_b_mps2": ("accel", "m s^-2", "a"),
    "specific_force_b_mps2": ("specific_force", "m s^-2", "f"),
    "attitude_rad": ("attitude", "rad", "q"),
    "tilt_rad": ("tilt", "rad", None),
}
_ALIASES = {alias: ident for ident, (label, _, prefix) in QUANTITY_INFO.items() for alias in (ident, label, prefix)
            if alias is not None}
_ALIASES["quaternion_wb"] = "attitude_rad"
AXES = ("x", "y", "z")


def row_keys(large_error_radps: float = 5.0) -> tuple[str, ...]:
    """Keys of :attr:`EvaluationResult.rows`, in table order."""
    return ("quantity", "unit", "n_samples", "n_nonfinite", "rmse_x", "rmse_y", "rmse_z", "rmse_norm", "median_norm",
            "relative_rms_x", "relative_rms_y", "relative_rms_z", "axis_sign_off_share", "axis_sign_off_share_x",
            "axis_sign_off_share_y", "axis_sign_off_share_z", "flipped_share", f"share_off_{large_error_radps:g}radps",
            "coverage_1sigma_x", "coverage_1sigma_y", "coverage_1sigma_z", "coverage_2sigma_x", "coverage_2sigma_y",
            "coverage_2sigma_z", "mean_nees", "n_sigma")


class EvaluationAlignmentWarning(UserWarning):
    """The truth was interpolated at the estimate's timestamps."""


class TimestampMismatchError(InputError):
    """Estimate and truth timestamps differ and ``align='exact'``; ``detail`` says where."""

    def __init__(self, detail: str, hint: str = "pass align='interpolate'"):
        self.detail = detail
        super().__init__(f"estimate and truth timestamps do not match ({detail}); they must be equal, or {hint} to "
                         "interpolate the truth at the estimate's timestamps")


@dataclass(frozen=True)
class SignShares:
    """ω's signs against the truth's (:func:`evaluate`, ω only).

    ``axis_sign_off_share_axis[j]``: among samples with |ω_true_j| above the sign threshold, the share where
    the estimate's component j has the other sign or is zero (ω_est_j · ω_true_j ≤ 0). ``axis_sign_off_share``:
    among samples with at least one such component, the share with at least one wrong sign.
    ``flipped_share``: among samples with ‖ω_true‖ above the sign threshold, the share whose estimate points
    into the opposite half-space (ω_est · ω_true < 0): the whole vector has the wrong sign.
    ``large_error_share``: share of samples with ‖ω_est − ω_true‖ above the large-error limit (5 rad/s by
    default). NaN when no sample qualifies.
    """

    axis_sign_off_share: float
    axis_sign_off_share_axis: tuple[float, ...]
    large_error_share: float
    flipped_share: float


@dataclass(frozen=True)
class SigmaCoverage:
    """The calibration of an estimate's one-sigma values against its errors (:func:`sigma_metrics`), over the
    ``n_sigma`` rows whose σ is finite and positive on every axis (None for the others when there is none)."""

    n_sigma: int
    coverage_1sigma: tuple[float, ...] | None = None
    """Per axis, the share of rows with |error| < σ."""
    coverage_2sigma: tuple[float, ...] | None = None
    """Per axis, the share of rows with |error| < 2σ."""
    mean_nees: float | None = None
    """Mean over rows of Σ_j (error_j / σ_j)² (normalised estimation error squared, diagonal σ)."""


@dataclass(frozen=True)
class QuantityMetrics:
    """Errors of one quantity.

    ``quantity`` is the Motion field name (``omega_b_radps`` ...) or ``attitude_rad`` / ``tilt_rad``;
    ``label`` is its short name (``omega``). ``signs``: ω's signs (:class:`SignShares`; None for the other
    quantities); ``sigma``: the calibration of the estimate's σ (:class:`SigmaCoverage`; None without σ).
    """

    quantity: str
    label: str
    unit: str
    n: int
    n_nonfinite: int
    rmse: tuple[float, ...] | None
    rmse_norm: float
    median_norm: float
    relative_rms: tuple[float, ...] | None = None
    signs: SignShares | None = None
    sigma: SigmaCoverage | None = None

    def row(self, large_error_radps: float = 5.0) -> dict:
        keys = row_keys(large_error_radps)
        r = dict.fromkeys(keys)
        r.update(quantity=self.quantity, unit=self.unit, n_samples=self.n, n_nonfinite=self.n_nonfinite,
                 rmse_norm=self.rmse_norm, median_norm=self.median_norm)
        vectors = [("rmse", self.rmse), ("relative_rms", self.relative_rms)]
        if self.signs is not None:
            r.update(axis_sign_off_share=self.signs.axis_sign_off_share, flipped_share=self.signs.flipped_share)
            r[f"share_off_{large_error_radps:g}radps"] = self.signs.large_error_share
            vectors.append(("axis_sign_off_share", self.signs.axis_sign_off_share_axis))
        if self.sigma is not None:
            r.update(mean_nees=self.sigma.mean_nees, n_sigma=self.sigma.n_sigma)
            vectors += [("coverage_1sigma", self.sigma.coverage_1sigma), ("coverage_2sigma", self.sigma.coverage_2sigma)]
        for name, values in vectors:
            if values is not None:
                for a, v in zip(AXES, values):
                    r[f"{name}_{a}"] = v
        return r


def _clean(v):
    if v is None:
        return None
    if isinstance(v, (float, np.floating)):
        return None if not math.isfinite(v) else float(v)
    if isinstance(v, np.integer):
        return int(v)
    return v


def _csv_cell(v) -> str:
    v = _clean(v)
    if v is None:
        return ""
    return repr(v) if isinstance(v, float) else str(v)


def _fmt(v, digits: int = 4) -> str:
    if v is None:
        return "-"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, str):
        return v
    if not math.isfinite(v):
        return "nan"
    return f"{v:.{digits}g}"


def _pct(v) -> str:
    return "-" if v is None else ("nan" if not math.isfinite(v) else f"{100 * v:.3g} %")


@dataclass(frozen=True)
class EvaluationResult:
    """Metrics of every quantity both motions have (see the module docstring)."""

    metrics: tuple[QuantityMetrics, ...]
    n_rows: int
    n_compared: int
    n_invalid: int
    n_outside: int
    alignment: str
    sign_threshold_radps: float
    large_error_radps: float
    n_deselected: int = 0
    """Rows of a valid reference left out by a selection (time window, moving threshold); ``n_invalid``
    then counts only the rows whose reference is invalid."""

    def __getitem__(self, name: str) -> QuantityMetrics:
        """Metrics by Motion field name, short label (``omega``) or CSV prefix (``w``)."""
        ident = _ALIASES.get(name, name)
        for m in self.metrics:
            if m.quantity == ident:
                return m
        raise KeyError(f"no metrics for {name!r}; have {self.quantities}")

    def __contains__(self, name: str) -> bool:
        return any(m.quantity == _ALIASES.get(name, name) for m in self.metrics)

    @property
    def quantities(self) -> list[str]:
        """Short labels of the quantities evaluated, in table order."""
        return [m.label for m in self.metrics]

    @property
    def columns(self) -> tuple[str, ...]:
        """Row keys in table order (the CSV header)."""
        return row_keys(self.large_error_radps)

    @property
    def rows(self) -> list[dict]:
        """One dict per quantity with the keys of :func:`row_keys` (None where not applicable)."""
        return [m.row(self.large_error_radps) for m in self.metrics]

    def summary(self) -> str:
        parts = [f"{self.n_compared} of {self.n_rows} rows compared"]
        if self.n_invalid:
            parts.append(f"{self.n_invalid} left out as invalid reference")
        if self.n_deselected:
            parts.append(f"{self.n_deselected} left out by the selection")
        if self.n_outside:
            parts.append(f"{self.n_outside} outside the truth's time span")
        if self.alignment != "exact":
            parts.append("truth interpolated at the estimate's timestamps")
        nonfinite = [f"{m.label}: {m.n_nonfinite}" for m in self.metrics if m.n_nonfinite]
        if nonfinite:
            parts.append("rows with non-finite estimates left out (" + ", ".join(nonfinite) + ")")
        return "; ".join(parts)

    def to_markdown(self, title: str | None = None) -> str:
        head = ["quantity", "unit", "n", "RMSE x", "RMSE y", "RMSE z", "RMSE norm", "median norm",
                "rel. RMS x", "rel. RMS y", "rel. RMS z", "wrong sign", "axis sign off",
                f"> {self.large_error_radps:g} rad/s"]
        lines = []
        if title:
            lines += [f"### {title}", ""]
        lines += ["| " + " | ".join(head) + " |", "|" + "|".join(["---"] * 2 + ["---:"] * (len(head) - 2)) + "|"]
        for m in self.metrics:
            rmse = m.rmse or (None,) * 3
            rel = m.relative_rms or (None,) * 3
            signs = (None,) * 3 if m.signs is None else (m.signs.flipped_share, m.signs.axis_sign_off_share,
                                                         m.signs.large_error_share)
            cells = [m.label, m.unit, str(m.n), *map(_fmt, rmse), _fmt(m.rmse_norm), _fmt(m.median_norm),
                     *map(_pct, rel), *map(_pct, signs)]
            lines.append("| " + " | ".join(cells) + " |")
        calibrated = [m for m in self.metrics if m.sigma is not None and m.sigma.coverage_1sigma is not None]
        if calibrated:
            lines += ["", "| quantity | n with σ | < 1σ x | < 1σ y | < 1σ z | < 2σ x | < 2σ y | < 2σ z | mean NEES |",
                      "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
            for m in calibrated:
                c = m.sigma
                lines.append("| " + " | ".join([m.label, str(c.n_sigma), *map(_pct, c.coverage_1sigma),
                                                 *map(_pct, c.coverage_2sigma), _fmt(c.mean_nees)]) + " |")
            lines += ["", "σ calibration: the share of rows whose error is within the estimate's one-sigma value "
                          "(a Gaussian error of that σ: 68.3 %) and within 2σ (95.4 %) per axis; mean NEES "
                          f"Σ_j (e_j/σ_j)² over the axes ({len(AXES)} when σ is right)."]
        lines += ["", f"{self.summary()}. Relative RMS: McGinnis, Perkins & King 2012, eq. (7). Wrong sign: samples whose ω points the "
                      f"other way, ω_est · ω_true < 0 where ‖ω_true‖ > {self.sign_threshold_radps:g} rad/s; axis sign off: "
                      f"samples with some component of |ω| > {self.sign_threshold_radps:g} rad/s estimated with the other "
                      "sign (small components of a right ω count too)."]
        return "\n".join(lines) + "\n"

    def to_csv(self) -> str:
        buf = io.StringIO()
        w = _csv.writer(buf, lineterminator="\n")
        w.writerow(self.columns)
        for r in self.rows:
            w.writerow([_csv_cell(r[k]) for k in self.columns])
        return buf.getvalue()

    def to_json(self) -> str:
        doc = {
            "n_rows": self.n_rows, "n_compared": self.n_compared, "n_invalid": self.n_invalid,
            "n_deselected": self.n_deselected, "n_outside": self.n_outside, "alignment": self.alignment,
            "sign_threshold_radps": self.sign_threshold_radps, "large_error_radps": self.large_error_radps,
            "quantities": [{k: _clean(v) for k, v in r.items()} for r in self.rows],
        }
        return json.dumps(doc, indent=2, allow_nan=False) + "\n"


# --- maths ---------------------------------------------------------------------

def _conjugate(q: np.ndarray) -> np.ndarray:
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def attitude_error(q_est_wb: np.ndarray, q_true_wb: np.ndarray) -> np.ndarray:
    """Rotation vector (N, 3) of R_trueᵀ R_est, in B; its norm is the attitude error in rad."""
    return rotation_vector_from_quaternion(quaternion_multiply(_conjugate(q_true_wb), q_est_wb))


def tilt_error(q_est_wb: np.ndarray, q_true_wb: np.ndarray) -> np.ndarray:
    """Angle (N,) in rad between the true and estimated world vertical expressed in B."""
    def up_in_body(q):
        q = q / np.linalg.norm(q, axis=-1, keepdims=True)
        w, x, y, z = np.moveaxis(q, -1, 0)
        return np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=-1)

    u, v = up_in_body(q_true_wb), up_in_body(q_est_wb)
    return np.arctan2(np.linalg.norm(np.cross(u, v), axis=-1), np.sum(u * v, axis=-1))


def _slerp(q0: np.ndarray, q1: np.ndarray, s: np.ndarray) -> np.ndarray:
    delta = rotation_vector_from_quaternion(quaternion_multiply(_conjugate(q0), q1))
    return quaternion_multiply(q0, quaternion_from_rotation_vector(delta * s[:, None]))


def _interpolate_truth(truth: Motion, t_ns: np.ndarray, valid: np.ndarray | None):
    """Truth at times ``t_ns`` inside its span: (Motion, kept mask over t_ns, valid at kept times)."""
    t_truth = truth.timestamps_ns
    inside = (t_ns >= t_truth[0]) & (t_ns <= t_truth[-1])
    tq = t_ns[inside]
    hi = np.clip(np.searchsorted(t_truth, tq, side="left"), 1, t_truth.size - 1)
    lo = hi - 1
    span = (t_truth[hi] - t_truth[lo]).astype(float)
    s = np.where(span > 0, (tq - t_truth[lo]) / np.where(span > 0, span, 1.0), 0.0)
    kw = {}
    for name in truth.available():
        v = getattr(truth, name)
        if name == "quaternion_wb":
            kw[name] = _slerp(v[lo], v[hi], s)
        else:
            kw[name] = v[lo] + s[:, None] * (v[hi] - v[lo])
    valid_at = None
    if valid is not None:
        valid_at = (valid[lo] | (s == 1.0)) & (valid[hi] | (s == 0.0))
    return Motion(tq, **kw), inside, valid_at


def _vector_metrics(ident: str, err: np.ndarray, truth: np.ndarray, n_nonfinite: int, relative: bool = True,
                    signs: SignShares | None = None, sigma: SigmaCoverage | None = None) -> QuantityMetrics:
    label, unit, _ = QUANTITY_INFO[ident]
    n = err.shape[0]
    if n == 0:
        nan3 = (math.nan,) * err.shape[1]
        return QuantityMetrics(ident, label, unit, 0, n_nonfinite, nan3, math.nan, math.nan,
                               nan3 if relative else None, signs, sigma)
    norm = np.linalg.norm(err, axis=1)
    rmse = np.sqrt(np.mean(err**2, axis=0))
    rel = None
    if relative:
        denom = math.sqrt(float(np.mean(np.sum(truth**2, axis=1))))
        rel = tuple(float(v) for v in (rmse / denom if denom > 0 else np.full(rmse.shape, math.nan)))
    return QuantityMetrics(ident, label, unit, n, n_nonfinite, tuple(float(v) for v in rmse),
                           float(np.sqrt(np.mean(norm**2))), float(np.median(norm)), rel, signs, sigma)


def _sign_metrics(est: np.ndarray, true: np.ndarray, threshold: float, large: float) -> SignShares:
    eligible = np.abs(true) > threshold
    wrong = eligible & (est * true <= 0)
    with np.errstate(invalid="ignore", divide="ignore"):
        per_axis = wrong.sum(axis=0) / eligible.sum(axis=0)
        any_eligible = eligible.any(axis=1)
        share = wrong.any(axis=1).sum() / any_eligible.sum() if any_eligible.any() else math.nan
    norm = np.linalg.norm(est - true, axis=1)
    big = np.linalg.norm(true, axis=1) > threshold
    flipped = np.sum(est * true, axis=1) < 0
    return SignShares(float(share), tuple(float(v) for v in per_axis),
                      float(np.mean(norm > large)) if norm.size else math.nan,
                      float(np.mean(flipped[big])) if np.any(big) else math.nan)


def sigma_metrics(err: np.ndarray, sigma: np.ndarray) -> SigmaCoverage:
    """The calibration of one-sigma values ``sigma`` (N, k) against the errors ``err`` (N, k), over the rows
    whose σ is finite and positive on every axis (:class:`SigmaCoverage`): ``coverage_1sigma``,
    ``coverage_2sigma`` (per axis, the share with |e| < σ, < 2σ), ``mean_nees`` (mean of Σ_j (e_j/σ_j)²) and
    ``n_sigma`` (those rows)."""
    with np.errstate(invalid="ignore"):
        ok = np.all(np.isfinite(sigma) & (sigma > 0), axis=1) & np.all(np.isfinite(err), axis=1)
    n = int(np.count_nonzero(ok))
    if n == 0:
        return SigmaCoverage(0)
    z = np.abs(err[ok]) / sigma[ok]
    return SigmaCoverage(n, tuple(float(v) for v in np.mean(z < 1.0, axis=0)),
                         tuple(float(v) for v in np.mean(z < 2.0, axis=0)), float(np.mean(np.sum(z * z, axis=1))))


def evaluate(estimate: Motion, truth: Motion, valid: np.ndarray | None = None, sign_threshold_radps: float = 0.1,
             large_error_radps: float = 5.0, align: str = "exact") -> EvaluationResult:
    """Errors of ``estimate`` against ``truth`` (or a reference) for every quantity both have.

    ``valid`` (len(truth),) bool marks truth rows to use (e.g.
    ``~log.invalid_reference``). Timestamps must match exactly unless
    ``align="interpolate"``: then the truth is interpolated (linearly; slerp
    for attitude) at the estimate's timestamps, with a warning, and estimate
    rows outside the truth's time span are left out (``n_outside``).
    """
    if align not in ("exact", "interpolate"):
        raise InputError(f"align must be 'exact' or 'interpolate', got {align!r}")
    if not (sign_threshold_radps >= 0 and large_error_radps > 0):
        raise InputError("sign_threshold_radps must be >= 0 and large_error_radps > 0")
    if valid is not None:
        valid = np.asarray(valid)
        if valid.shape != (len(truth),) or valid.dtype != bool:
            raise InputError(f"valid must be a boolean array of shape ({len(truth)},) (one per truth row), "
                             f"got {valid.dtype} {valid.shape}")
    common = [n for n in QUANTITIES if getattr(estimate, n) is not None and getattr(truth, n) is not None]
    if not common:
        raise InputError(f"no quantity in common: the estimate has {estimate.available()}, "
                         f"the truth has {truth.available()}")
    n_rows = len(estimate)
    n_outside = 0
    same = len(estimate) == len(truth) and np.array_equal(estimate.timestamps_ns, truth.timestamps_ns)
    if same:
        alignment = "exact"
    elif align == "exact":
        if len(estimate) != len(truth):
            detail = f"the estimate has {len(estimate)} rows, the truth {len(truth)}"
        else:
            k = int(np.flatnonzero(estimate.timestamps_ns != truth.timestamps_ns)[0])
            detail = (f"row {k} differs: estimate {estimate.timestamps_ns[k]} ns, truth {truth.timestamps_ns[k]} ns")
        raise TimestampMismatchError(detail)
    else:
        if len(truth) < 2:
            raise DataError("cannot interpolate a truth with fewer than 2 rows")
        warnings.warn(f"interpolating the truth ({len(truth)} rows) at the estimate's {len(estimate)} timestamps",
                      EvaluationAlignmentWarning, stacklevel=2)
        truth, inside, valid = _interpolate_truth(truth, estimate.timestamps_ns, valid)
        n_outside = int(np.sum(~inside))
        estimate = estimate.select(inside)
        alignment = "interpolated"
    keep = np.ones(len(truth), bool) if valid is None else valid
    n_invalid = int(np.sum(~keep))

    metrics = []
    for name in common:
        est = getattr(estimate, name)
        tru = getattr(truth, name)
        finite = keep & np.all(np.isfinite(est), axis=1) & np.all(np.isfinite(tru), axis=1)
        n_nonfinite = int(np.sum(keep & ~finite))
        est, tru = est[finite], tru[finite]
        if name == "quaternion_wb":
            metrics.append(_vector_metrics("attitude_rad", attitude_error(est, tru), tru, n_nonfinite, relative=False))
            m = _vector_metrics("tilt_rad", tilt_error(est, tru)[:, None], tru, n_nonfinite, relative=False)
            metrics.append(QuantityMetrics(m.quantity, m.label, m.unit, m.n, n_nonfinite, None, m.rmse_norm,
                                           m.median_norm))
            continue
        signs = _sign_metrics(est, tru, sign_threshold_radps, large_error_radps) if name == "omega_b_radps" else None
        sigma = estimate.sigma.get(name)
        coverage = None if sigma is None else sigma_metrics(est - tru, np.asarray(sigma, dtype=float)[finite])
        metrics.append(_vector_metrics(name, est - tru, tru, n_nonfinite, signs=signs, sigma=coverage))
    return EvaluationResult(tuple(metrics), n_rows, int(np.sum(keep)), n_invalid, n_outside, alignment,
                            float(sign_threshold_radps), float(large_error_radps))


def evaluate_log(estimate: Motion, log, **options) -> EvaluationResult:
    """Evaluate against a log's truth, else its reference (leaving out ``log.invalid_reference`` rows)."""
    if log.truth is not None:
        return evaluate(estimate, log.truth, **options)
    if log.reference is None:
        raise InputError(f"{log.source}: the log has neither truth nor reference to evaluate against")
    valid = None if log.invalid_reference is None else ~np.asarray(log.invalid_reference, dtype=bool)
    return evaluate(estimate, log.reference, valid=valid, **options)


def estimate_time_offset_s(estimate: Motion, reference: Motion, valid: np.ndarray | None = None,
                           max_offset_s: float = 0.5) -> float:
    """Offset [s] to add to the estimate's timestamps that best lines it up with the reference: the
    lag minimising the mean squared difference of |ω| (sign-free, so a sign error does not pull it)
    over the rows both cover, on the reference's time grid within ±``max_offset_s``, refined to a
    fraction of a sample by a parabola through the minimum."""
    if estimate.omega_b_radps is None or reference.omega_b_radps is None:
        raise InputError("a time offset is estimated from ω: both need omega columns")
    t_ref = reference.timestamps_ns * 1e-9
    t_est = estimate.timestamps_ns * 1e-9
    if len(t_ref) < 4 or len(t_est) < 4:
        raise DataError("too few rows to estimate a time offset")
    dt = float(np.median(np.diff(t_ref)))
    ref = np.linalg.norm(reference.omega_b_radps, axis=1)
    est_t = t_est
    est_v = np.linalg.norm(estimate.omega_b_radps, axis=1)
    ok = np.ones(len(ref), bool) if valid is None else np.asarray(valid, bool)
    ok &= np.isfinite(ref)
    finite = np.isfinite(est_v)
    lags = np.arange(-int(round(max_offset_s / dt)), int(round(max_offset_s / dt)) + 1)
    score = np.full(len(lags), np.inf)
    for j, k in enumerate(lags):
        # the estimate shifted by k dt, sampled at the reference's times
        shifted_est = np.interp(t_ref, est_t[finite] + k * dt, est_v[finite], left=np.nan, right=np.nan)
        both = ok & np.isfinite(shifted_est)
        if np.count_nonzero(both) > 3:
            score[j] = float(np.mean((shifted_est[both] - ref[both]) ** 2))
    i = int(np.argmin(score))
    frac = 0.0
    if 0 < i < len(lags) - 1 and np.all(np.isfinite(score[i - 1:i + 2])):
        y0, y1, y2 = score[i - 1], score[i], score[i + 1]
        denom = y0 - 2 * y1 + y2
        frac = 0.5 * (y0 - y2) / denom if denom > 0 else 0.0
    return float((lags[i] + frac) * dt)


def shifted(motion: Motion, offset_s: float) -> Motion:
    """``motion`` with ``offset_s`` added to its timestamps."""
    return replace(motion, timestamps_ns=motion.timestamps_ns + int(round(offset_s * 1e9)))


def error_table(estimate: Motion, reference: Motion, used: np.ndarray) -> np.ndarray:
    """(N, 6) per-sample ω errors on the reference's rows: timestamp [ns], error x, y, z, norm
    [rad/s], 1 where the row is used by the metrics (else 0); NaN where the estimate has no value."""
    t = reference.timestamps_ns
    est = np.column_stack([np.interp(t, estimate.timestamps_ns, estimate.omega_b_radps[:, i],
                                     left=np.nan, right=np.nan) for i in range(3)])
    err = est - reference.omega_b_radps
    return np.column_stack([t.astype(float), err, np.linalg.norm(err, axis=1), used.astype(float)])
