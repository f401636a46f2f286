"""Accuracy comparison of the estimation methods on one log.

:func:`compare` runs every requested method on a log with truth (or a
reference), scores each estimate with :func:`gfimu.evaluation.evaluate`, puts
the Cramér–Rao bound and the smoother's own bound beside the errors, and
returns one :class:`ComparisonResult` table: RMSE per axis and of the norm for
linear acceleration (or specific force), angular acceleration and angular
velocity in the layout of Lin et al. 2011, Table 1; McGinnis, Perkins & King 2012's relative RMS error
(eq. 7); the share of samples with a wrong sign of ω; and each method's run
time. A method that is missing, not applicable or fails is a row with its
reason, never an exception.

No file I/O here except through :mod:`gfimu.io` when asked to keep the
estimates (``estimates_dir``).
"""

from __future__ import annotations

import csv
import io
import json
import math
import time
import traceback
from dataclasses import dataclass, field
from typing import Any, Iterable, Mapping, Sequence

import numpy as np

from .crb import crb_per_sample
from .errors import InputError
from .estimate import Estimate, Report
from .estimators.inversion import invert
from .evaluation import evaluate
from .io import write_motion_csv
from .log import Log
from .methods import METHODS, UnknownMethodError, make_estimator
from .motion import Motion
from .smoother.batch.bound import smoother_bound
from .smoother.model.problem import SmootherOptions
from .smoother.model.presets import expand_preset

# Quantities in table order: field -> (short key, label for headers, unit)
TABLE_QUANTITIES: dict[str, tuple[str, str, str]] = {
    "accel_b_mps2": ("a", "linear acceleration", "m/s²"),
    "specific_force_b_mps2": ("f", "specific force", "m/s²"),
    "omega_dot_b_radps2": ("dw", "angular acceleration", "rad/s²"),
    "omega_b_radps": ("w", "angular velocity", "rad/s"),
}
AXES = ("x", "y", "z")
BOUND_NAMES = {
    "crb": "CRB (accelerometers)",
    "crb_gyro": "CRB (with gyro)",
    "smoother_bound": "smoother bound",
}
STATUS_OK = "ok"
SYMBOLS = {"a": "a", "f": "f", "dw": "ω̇", "w": "ω"}


def metric_columns() -> list[str]:
    """All numeric columns of a comparison row, in table order."""
    cols = ["time_s", "samples_per_s", "n_evaluated"]
    for key, _, _ in TABLE_QUANTITIES.values():
        cols += [f"{key}_rmse_{a}" for a in AXES] + [f"{key}_rmse_norm"]
        cols += [f"{key}_rel_rms_{a}" for a in AXES]
    cols += ["w_flipped_share", "w_axis_sign_off_share", "w_off_5radps_share"]
    for key, _, _ in TABLE_QUANTITIES.values():
        cols += [f"{key}_rmse_norm_over_{b}" for b in BOUND_NAMES]
    return cols


COLUMNS = ["method", "kind", "status", "reason"] + metric_columns()


# --- metrics --------------------------------------------------------------------

def _evaluation_metrics(estimate: Motion, reference: Motion, valid: np.ndarray | None) -> dict[str, float]:
    """Table columns from :func:`gfimu.evaluation.evaluate`."""

    result = evaluate(estimate, reference, valid=valid, large_error_radps=5.0)
    return metrics_from_evaluation(result)


def metrics_from_evaluation(result) -> dict[str, float]:
    """Map an :class:`~gfimu.evaluation.EvaluationResult` to the comparison columns."""
    out: dict[str, float] = {"n_evaluated": float(result.n_compared)}
    for fname, (key, _, _) in TABLE_QUANTITIES.items():
        if fname not in result:
            continue
        m = result[fname]
        for k, a in enumerate(AXES):
            out[f"{key}_rmse_{a}"] = _num(m.rmse[k])
            if m.relative_rms is not None:
                out[f"{key}_rel_rms_{a}"] = _num(m.relative_rms[k])
        out[f"{key}_rmse_norm"] = _num(m.rmse_norm)
        if fname == "omega_b_radps":
            out["w_axis_sign_off_share"] = _num(m.signs.axis_sign_off_share)
            out["w_flipped_share"] = _num(m.signs.flipped_share)
            out["w_off_5radps_share"] = _num(m.signs.large_error_share)
    return out


def _num(value) -> float:
    if value is None or value == "":
        return math.nan
    return float(value)


# --- bounds ------------------------------------------------------------------

def bound_rms(variance: Mapping[str, np.ndarray], valid: np.ndarray | None = None) -> dict[str, float]:
    """RMS bound per axis and of the norm from per-sample variances.

    ``variance`` maps a Motion field name to (N, 3) variances along the truth;
    the bound on an RMSE is ``sqrt(mean(variance))`` per axis and
    ``sqrt(mean(trace))`` for the norm, over the valid samples.
    """
    out: dict[str, float] = {}
    for fname, var in variance.items():
        if fname not in TABLE_QUANTITIES or var is None:
            continue
        key = TABLE_QUANTITIES[fname][0]
        v = np.asarray(var, dtype=float)
        if valid is not None:
            v = v[np.asarray(valid, dtype=bool)]
        if v.size == 0:
            continue
        for k, a in enumerate(AXES):
            out[f"{key}_rmse_{a}"] = float(np.sqrt(np.mean(v[:, k])))
        out[f"{key}_rmse_norm"] = float(np.sqrt(np.mean(np.sum(v, axis=1))))
    return out


def compute_bounds(log: Log, truth: Motion, valid: np.ndarray | None, which: Iterable[str] = tuple(BOUND_NAMES),
                   gyro_noise_std_radps: float | None = None,
                   smoother_options: Mapping[str, Any] | None = None,
                   smoother_tunings: Sequence[Any] = ()) -> list[dict]:
    """Rows of the available bounds, each with a reason when it cannot be computed.

    ``smoother_tunings``: the process noise the smoother chose per solve window
    (the ``tunings`` of its :class:`~gfimu.estimate.Report`); the smoother's bound then uses the same graph."""
    rows = []
    for name in which:
        label = BOUND_NAMES[name]
        try:
            variance = _bound_variances(name, log, truth, gyro_noise_std_radps, smoother_options, smoother_tunings)
        except (ImportError, AttributeError) as exc:
            rows.append(_row(label, "bound", "unavailable", f"{type(exc).__name__}: {exc}"))
            continue
        except Exception as exc:  # noqa: BLE001 - a bound failing must not stop the table
            rows.append(_row(label, "bound", "failed", f"{type(exc).__name__}: {exc}"))
            continue
        if isinstance(variance, str):
            rows.append(_row(label, "bound", "not applicable", variance))
            continue
        row = _row(label, "bound", STATUS_OK, "")
        row.update(bound_rms(variance, valid))
        rows.append(row)
    return rows


def _bound_variances(name: str, log: Log, truth: Motion, gyro_noise_std_radps: float | None = None,
                     smoother_options: Mapping[str, Any] | None = None, smoother_tunings: Sequence[Any] = ()):
    """Per-field variances (N, 3) of one bound along the truth, or the reason it does not apply."""
    if truth.omega_b_radps is None:
        return "the truth has no angular velocity to evaluate the bound at"
    if name in ("crb", "crb_gyro"):

        if name == "crb_gyro":
            if gyro_noise_std_radps is None:
                if log.array.gyroscope is None or log.array.gyroscope.noise_std_radps is None:
                    return "the array has no gyroscope with a noise level (give gyro_noise_std_radps for a hypothetical one)"
                gyro_noise_std_radps = log.array.gyroscope.noise_std_radps
            result = crb_per_sample(log.array, truth.omega_b_radps, gyro_noise_std_radps=gyro_noise_std_radps)
        else:
            result = crb_per_sample(log.array, truth.omega_b_radps)
        diag = np.diagonal(result.covariance, axis1=1, axis2=2)
        return {
            "specific_force_b_mps2": diag[:, 0:3],
            "accel_b_mps2": diag[:, 0:3],  # a = f + g with g known: same bound
            "omega_dot_b_radps2": diag[:, 3:6],
            "omega_b_radps": diag[:, 6:9],
        }

    reason = make_estimator("smoother", **dict(smoother_options or {})).applicable(log.array)
    if reason:
        return f"the smoother cannot run on this array: {reason}"
    opt = SmootherOptions(**dict(smoother_options or {}))
    window_models = [t.apply(opt.model_groups) for t in smoother_tunings] or None
    sigma = smoother_bound(log, opt.model_groups, opt.batch, truth=truth, window_models=window_models).sigma
    variances = {k: v**2 for k, v in sigma.items()}
    if "specific_force_b_mps2" in variances:
        variances["accel_b_mps2"] = variances["specific_force_b_mps2"]
    return variances


# --- comparison ----------------------------------------------------------------

def _row(method: str, kind: str, status: str, reason: str) -> dict[str, Any]:
    row: dict[str, Any] = {c: math.nan for c in COLUMNS}
    row.update(method=method, kind=kind, status=status, reason=reason)
    return row


@dataclass(frozen=True)
class ComparisonResult:
    """One comparison table: a row per method and per bound (``rows``, dicts with :data:`COLUMNS`).

    ``estimates`` maps each method that ran to its estimate (not part of the
    table formats).
    """

    source: str
    against: str
    n_samples: int
    rows: tuple[dict, ...]
    estimates: Mapping[str, Motion] = field(default_factory=dict, repr=False, compare=False)

    def row(self, method: str) -> dict:
        for r in self.rows:
            if r["method"] == method:
                return r
        raise KeyError(f"no row {method!r} in the comparison; rows: {[r['method'] for r in self.rows]}")

    @property
    def methods(self) -> list[str]:
        return [r["method"] for r in self.rows if r["kind"] == "method"]

    # --- formats -----------------------------------------------------------
    def to_csv(self) -> str:
        buf = io.StringIO()
        writer = csv.DictWriter(buf, fieldnames=COLUMNS, lineterminator="\n")
        writer.writeheader()
        for r in self.rows:
            writer.writerow({c: _csv_value(r.get(c)) for c in COLUMNS})
        return buf.getvalue()

    def to_json(self) -> str:
        doc = {
            "source": self.source,
            "against": self.against,
            "n_samples": self.n_samples,
            "columns": COLUMNS,
            "rows": [{c: _json_value(r.get(c)) for c in COLUMNS} for r in self.rows],
        }
        return json.dumps(doc, indent=1, ensure_ascii=False)

    def to_markdown(self) -> str:
        return format_markdown(self)

    @classmethod
    def from_json(cls, text: str) -> "ComparisonResult":
        doc = json.loads(text)
        rows = tuple({c: (math.nan if r.get(c) is None and c not in ("method", "kind", "status", "reason") else r.get(c))
                      for c in COLUMNS} for r in doc["rows"])
        return cls(doc["source"], doc["against"], int(doc["n_samples"]), rows)

    @classmethod
    def from_csv(cls, text: str, source: str = "<csv>", against: str = "truth") -> "ComparisonResult":
        rows = []
        for r in csv.DictReader(io.StringIO(text)):
            rows.append({c: (r[c] if c in ("method", "kind", "status", "reason") else _num(r[c])) for c in COLUMNS})
        n = max((int(r["n_evaluated"]) for r in rows if np.isfinite(r["n_evaluated"])), default=0)
        return cls(source, against, n, tuple(rows))


def _csv_value(v):
    if isinstance(v, float):
        return "" if not math.isfinite(v) else repr(v)
    return v


def _json_value(v):
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


def reference_of(log: Log) -> tuple[Motion, str, np.ndarray | None]:
    """The motion to score against (truth first, else the reference), its name and valid mask."""
    if log.truth is not None:
        return log.truth, "truth", None
    if log.reference is not None:
        valid = None if log.invalid_reference is None else ~np.asarray(log.invalid_reference, dtype=bool)
        return log.reference, "reference", valid
    raise InputError(f"{log.source}: the log has neither truth.csv nor reference.csv to compare against")


def default_methods() -> list[str]:

    return list(METHODS)


def run_method(name: str, log: Log, options: Mapping[str, Any] | None = None, progress: bool = False):
    """Run one method: ``(status, reason, estimate | None, seconds)``, the estimate a
    :class:`~gfimu.estimate.Estimate` (motion and report); never raises for the method's own failures."""

    try:
        est = make_estimator(name, **dict(options or {}))
    except UnknownMethodError as exc:
        return "unknown", str(exc.args[0]), None, math.nan
    except ImportError as exc:
        return "unavailable", f"not installed in this version ({exc})", None, math.nan
    except (TypeError, ValueError) as exc:
        return "failed", f"bad options: {exc}", None, math.nan
    except Exception as exc:  # noqa: BLE001 - a broken registry entry must not stop the table
        return "unavailable", f"cannot load: {type(exc).__name__}: {exc}", None, math.nan
    try:
        reason = est.applicable(log.array)
    except Exception as exc:  # noqa: BLE001
        return "failed", f"applicable() raised {type(exc).__name__}: {exc}", None, math.nan
    if reason:
        return "not applicable", str(reason), None, math.nan
    t0 = time.perf_counter()
    try:
        estimate = est.estimate(log, progress=progress)
    except Exception as exc:  # noqa: BLE001 - one method failing must not stop the table
        where = traceback.extract_tb(exc.__traceback__)[-1]
        return "failed", f"{type(exc).__name__}: {exc} (at {where.filename.split('/')[-1]}:{where.lineno})", None, math.nan
    seconds = time.perf_counter() - t0
    if not isinstance(estimate, Estimate):
        return "failed", f"estimate returned a {type(estimate).__name__}, not an Estimate (motion, report)", None, seconds
    if len(estimate.motion) != len(log):
        return "failed", f"estimate returned {len(estimate.motion)} rows for a log of {len(log)} samples", None, seconds
    return STATUS_OK, "", estimate, seconds


def compare(
    log: Log,
    methods: Sequence[str] | None = None,
    options: Mapping[str, Mapping[str, Any]] | None = None,
    bounds: bool | Sequence[str] = True,
    estimates_dir=None,
    progress: bool = False,
    gyro_noise_std_radps: float | None = None,
) -> ComparisonResult:
    """Run ``methods`` (default: all registered) on ``log`` and score them against its truth or reference.

    ``options`` maps a method name to its keyword options. ``bounds`` selects
    the bound rows (True: all of :data:`BOUND_NAMES`; False: none).
    ``estimates_dir``: also write each estimate as ``<method>.csv`` there.
    ``gyro_noise_std_radps``: gyro noise for the "CRB (with gyro)" row when
    the array has no gyroscope (a hypothetical gyro, to show what one would add).
    """
    reference, against, valid = reference_of(log)
    if len(reference) != len(log):
        raise InputError(f"{log.source}: the {against} has {len(reference)} rows for {len(log)} samples")
    methods = list(methods) if methods is not None else default_methods()
    if not methods:
        raise InputError("no method to compare")
    options = dict(options or {})
    if "preset" in options.get("smoother", {}):  # the preset's settings, for the smoother and its bound

        options["smoother"] = expand_preset("smoother", options["smoother"])
    unknown_opts = sorted(set(options) - set(methods))
    if unknown_opts:
        raise InputError(f"options given for methods not compared: {unknown_opts}")
    rows: list[dict] = []
    estimates: dict[str, Motion] = {}
    which = list(BOUND_NAMES) if bounds is True else ([] if bounds is False else list(bounds))
    unknown_bounds = [name for name in which if name not in BOUND_NAMES]
    if unknown_bounds:
        raise InputError(f"unknown bound(s) {unknown_bounds}; bounds are: {', '.join(BOUND_NAMES)}")
    reports: dict[str, Report] = {}
    for name in methods:
        status, reason, estimate, seconds = run_method(name, log, options.get(name), progress=progress)
        row = _row(name, "method", status, reason)
        row["time_s"] = seconds
        if estimate is not None:
            motion = estimate.motion
            estimates[name] = motion
            reports[name] = estimate.report
            row["samples_per_s"] = len(log) / seconds if seconds > 0 else math.inf
            try:
                row.update(_evaluation_metrics(motion, reference, valid))
            except Exception as exc:  # noqa: BLE001
                row["status"] = "failed"
                row["reason"] = f"evaluation failed: {type(exc).__name__}: {exc}"
        rows.append(row)
    if which:
        if against != "truth":
            for name in which:
                rows.append(_row(BOUND_NAMES[name], "bound", "not applicable", "bounds are evaluated along a simulated truth"))
        else:
            smoother_options = {k: v for k, v in dict(options.get("smoother", {})).items() if k != "compute_sigma"}
            tunings = list(reports["smoother"].tunings) if "smoother" in reports else []
            bound_rows = compute_bounds(log, reference, valid, which, gyro_noise_std_radps, smoother_options, tunings)
            rows.extend(bound_rows)
            _add_ratios(rows, bound_rows, which)
    if estimates_dir is not None:
        from pathlib import Path


        out = Path(estimates_dir)
        out.mkdir(parents=True, exist_ok=True)
        for name, motion in estimates.items():
            write_motion_csv(motion, out / f"{name}.csv")
    return ComparisonResult(log.source, against, len(log), tuple(rows), estimates)


def _add_ratios(rows: list[dict], bound_rows: list[dict], which: Sequence[str]) -> None:
    by_label = {r["method"]: r for r in bound_rows}
    for name in which:
        b = by_label.get(BOUND_NAMES[name])
        if b is None or b["status"] != STATUS_OK:
            continue
        for r in rows:
            if r["kind"] != "method" or r["status"] != STATUS_OK:
                continue
            for key, _, _ in TABLE_QUANTITIES.values():
                num, den = r[f"{key}_rmse_norm"], b[f"{key}_rmse_norm"]
                if np.isfinite(num) and np.isfinite(den) and den > 0:
                    r[f"{key}_rmse_norm_over_{name}"] = num / den


# --- markdown ----------------------------------------------------------------------

def _fmt(v, digits: int = 4, scale: float = 1.0) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "–"
    v = float(v) * scale
    if v == 0:
        return "0"
    if abs(v) >= 1e5 or abs(v) < 1e-3:
        return f"{v:.{digits - 1}e}"
    return f"{v:.{digits}g}"


def _present(rows, columns) -> bool:
    return any(np.isfinite(r.get(c, math.nan)) for r in rows for c in columns)


def format_markdown(result: ComparisonResult) -> str:
    """Markdown tables: RMSE (Lin et al. 2011, Table 1 layout), relative errors and signs, bounds, and methods not run."""
    ok = [r for r in result.rows if r["status"] == STATUS_OK]
    ran = [r for r in ok if r["kind"] == "method"]
    quantities = [(k, label, unit) for k, label, unit in TABLE_QUANTITIES.values()
                  if _present(ran or ok, [f"{k}_rmse_norm"])]
    lines = [f"## Comparison on {result.source} against {result.against} ({result.n_samples} samples)", ""]
    if not ok:
        lines.append("No method produced an estimate.")
    else:
        lines.append("RMSE per axis and of the error norm (layout of Lin et al. 2011, Table 1); bounds are √(mean variance) along the truth.")
        if any(r["kind"] == "bound" and r["method"].startswith("CRB") for r in ok):
            lines.append("The per-sample CRB uses one sample's readings only; without a gyro its bound on ω grows "
                         "without limit as ω → 0 (∂q/∂ω = 0), so slow stretches dominate its mean.")
        lines.append("")
        head = ["method"] + [f"{SYMBOLS[key]}{a} [{unit}]" if a != "‖·‖" else f"‖{SYMBOLS[key]}‖ [{unit}]"
                             for key, _, unit in quantities for a in (*AXES, "‖·‖")] + ["time [s]"]
        lines.append("| " + " | ".join(head) + " |")
        lines.append("|" + "---|" * len(head))
        for r in ok:
            cells = [r["method"]]
            for key, _, _ in quantities:
                cells += [_fmt(r[f"{key}_rmse_{a}"]) for a in AXES] + [_fmt(r[f"{key}_rmse_norm"])]
            cells.append(_fmt(r["time_s"], 3) if r["kind"] == "method" else "")
            lines.append("| " + " | ".join(cells) + " |")
        methods_ok = [r for r in ok if r["kind"] == "method"]
        rel_q = [(k, unit) for k, _, unit in quantities if _present(methods_ok, [f"{k}_rel_rms_{a}" for a in AXES])]
        if methods_ok and (rel_q or _present(methods_ok, ["w_axis_sign_off_share"])):
            lines += ["", "Relative RMS error per axis (McGinnis, Perkins & King 2012, eq. 7) in %, and shares of samples where ω has the wrong sign (ω_est · ω_true < 0), a component with the other sign, or is > 5 rad/s off.", ""]
            head = ["method"] + [f"{SYMBOLS[k]}{a} rel. [%]" for k, _ in rel_q for a in AXES] + ["ω wrong sign [%]", "ω axis sign off [%]", "ω > 5 rad/s off [%]"]
            lines.append("| " + " | ".join(head) + " |")
            lines.append("|" + "---|" * len(head))
            for r in methods_ok:
                cells = [r["method"]] + [_fmt(r[f"{k}_rel_rms_{a}"], 3, 100) for k, _ in rel_q for a in AXES]
                cells += [_fmt(r["w_flipped_share"], 3, 100), _fmt(r["w_axis_sign_off_share"], 3, 100),
                          _fmt(r["w_off_5radps_share"], 3, 100)]
                lines.append("| " + " | ".join(cells) + " |")
        ratio_cols = [(k, b) for k, _, _ in quantities for b in BOUND_NAMES
                      if _present(methods_ok, [f"{k}_rmse_norm_over_{b}"])]
        if ratio_cols:
            lines += ["", "RMSE of the norm divided by the bound (1 = efficient).", ""]
            head = ["method"] + [f"‖{SYMBOLS[k]}‖ / {BOUND_NAMES[b]}" for k, b in ratio_cols]
            lines.append("| " + " | ".join(head) + " |")
            lines.append("|" + "---|" * len(head))
            for r in methods_ok:
                lines.append("| " + " | ".join([r["method"]] + [_fmt(r[f"{k}_rmse_norm_over_{b}"], 3) for k, b in ratio_cols]) + " |")
    not_run = [r for r in result.rows if r["status"] != STATUS_OK]
    if not_run:
        lines += ["", "Not in the table:", ""]
        for r in not_run:
            lines.append(f"- **{r['method']}** ({r['status']}): {r['reason']}")
    return "\n".join(lines) + "\n"


# --- studies -----------------------------------------------------------------------

def condition_vs_scale(array, half_edges: np.ndarray, reference_half_edge: float | None = None) -> np.ndarray:
    """Condition number of the structure matrix with the layout scaled (Ho & Lin 2009, §III).

    Positions are scaled by ``half_edge / reference_half_edge``, where the
    reference is the array's largest absolute coordinate by default.
    """
    from dataclasses import replace as dc_replace

    positions = np.array([a.position_m for a in array.accelerometers])
    ref = float(reference_half_edge or np.max(np.abs(positions)))
    if ref <= 0:
        raise InputError(f"array {array.name!r}: all accelerometers at the origin; cannot scale the layout")
    out = []
    for h in np.asarray(half_edges, dtype=float):
        scaled = array.with_accelerometers([dc_replace(a, position_m=a.position_m * (h / ref)) for a in array.accelerometers])
        out.append(scaled.condition_number())
    return np.array(out)


def omega_rmse_sum(estimate: Motion, reference: Motion, valid: np.ndarray | None = None) -> float:
    """Sum over x, y, z of the RMSE of ω (the quantity of Lin et al. 2011, Fig. 7)."""
    err = estimate.omega_b_radps - reference.omega_b_radps
    if valid is not None:
        err = err[np.asarray(valid, dtype=bool)]
    return float(np.sum(np.sqrt(np.mean(err**2, axis=0))))


def t2_sweep(log: Log, t2_values: Sequence[float], imm_options: Mapping[str, Any] | None = None) -> np.ndarray:
    """Summed RMSE of ω of the ``imm`` method at each T2 (Lin et al. 2011, §4.1, Fig. 7)."""

    reference, _, valid = reference_of(log)
    out = []
    for t2 in t2_values:
        est = make_estimator("imm", **{**dict(imm_options or {}), "t2": float(t2)})
        out.append(omega_rmse_sum(est.estimate(log).motion, reference, valid))
    return np.array(out)


def t2_band(t2_values: Sequence[float], rmse: np.ndarray, tolerance: float = 0.2) -> tuple[float, float, float]:
    """T2 min and the range of T2 whose RMSE stays within ``tolerance`` of the best (Lin et al. 2011, Fig. 8)."""
    t2 = np.asarray(t2_values, dtype=float)
    rmse = np.asarray(rmse, dtype=float)
    best = int(np.nanargmin(rmse))
    ok = rmse <= rmse[best] * (1 + tolerance)
    lo, hi = best, best
    while lo > 0 and ok[lo - 1]:
        lo -= 1
    while hi < t2.size - 1 and ok[hi + 1]:
        hi += 1
    return float(t2[best]), float(t2[lo]), float(t2[hi])


def motion_level(log: Log) -> float:
    """Mean of a + b + c, the three quadratic sums (Lin et al. 2011, Fig. 8), from the per-sample inversion.

    As in the paper this uses only the accelerometers (S⁻¹ times the readings,
    eq. 7), so it needs an invertible array.
    """

    x, _ = invert(log.array, log.accel_mps2)
    return float(np.mean(np.sum(x[:, 6:9], axis=1)))
