"""Figures of the papers, regenerated from gfimu's own estimates.

Every function returns a :class:`matplotlib.figure.Figure` built without
pyplot (no global state); :func:`save_figure` writes it with the Agg canvas.
Matplotlib is imported lazily (``pip install gfimu[plot]``), so the core
library does not need it. Functions take arrays and :class:`~gfimu.motion.Motion`
objects only; computing the studies is done elsewhere (:mod:`gfimu.compare`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from .errors import InputError, MissingExtraError
from .motion import QUANTITIES, Motion
from .io.atomic import atomic_path

# field -> (symbol for titles, unit for axis labels)
LABELS: dict[str, tuple[str, str]] = {
    "accel_b_mps2": ("linear acceleration a", "m/s²"),
    "specific_force_b_mps2": ("specific force f", "m/s²"),
    "omega_dot_b_radps2": ("angular acceleration ω̇", "rad/s²"),
    "omega_b_radps": ("angular velocity ω", "rad/s"),
}
AXES = ("x", "y", "z")


def _figure(width_in: float, height_in: float):
    try:
        from matplotlib.figure import Figure
    except ImportError:
        raise MissingExtraError("drawing figures", "matplotlib", "plot") from None
    return Figure(figsize=(width_in, height_in), layout="constrained")


def save_figure(fig, path, dpi: int = 110) -> Path:
    """Write ``fig`` to ``path`` (format from the suffix) with the Agg canvas, atomically."""
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
    except ImportError:
        raise MissingExtraError("drawing figures", "matplotlib", "plot") from None


    path = Path(path)
    fmt = path.suffix.lstrip(".").lower() or "png"
    FigureCanvasAgg(fig)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=dpi, format=fmt)
    return path


def _interp_to(reference: Motion, estimate: Motion, name: str) -> np.ndarray:
    """Estimate values at the reference timestamps (exact when they match)."""
    values = getattr(estimate, name)
    if estimate.timestamps_ns.shape == reference.timestamps_ns.shape and np.array_equal(
        estimate.timestamps_ns, reference.timestamps_ns
    ):
        return values
    t_ref = (reference.timestamps_ns - reference.timestamps_ns[0]) * 1e-9
    t_est = (estimate.timestamps_ns - reference.timestamps_ns[0]) * 1e-9
    out = np.column_stack([np.interp(t_ref, t_est, values[:, k], left=np.nan, right=np.nan) for k in range(values.shape[1])])
    return out


def default_quantities(reference: Motion, estimates: Mapping[str, Motion]) -> list[str]:
    """Quantities shared by the reference and at least one estimate, in paper order (a, ω̇, ω)."""
    order = ["accel_b_mps2", "specific_force_b_mps2", "omega_dot_b_radps2", "omega_b_radps"]
    out = []
    for name in order:
        if getattr(reference, name) is None:
            continue
        if any(getattr(m, name) is not None for m in estimates.values()):
            out.append(name)
    # linear acceleration and specific force are the same panel row; keep a only when estimated
    if "accel_b_mps2" in out and "specific_force_b_mps2" in out:
        out.remove("specific_force_b_mps2")
    return out


ESTIMATE_STYLES = ("-", "--", "-.", ":")
"""Line styles of the estimates, in turn with the colours C0..C9, so that lines stay apart in grey too."""
REFERENCE_STYLE = dict(color="k", lw=2.4, alpha=0.35, solid_capstyle="butt")
"""The reference: a wide, pale black line underneath the estimates."""
BAND_ALPHA = 0.22
"""Opacity of the ±1σ bands."""


def estimate_style(index: int) -> dict:
    """Colour and line style of the ``index``-th estimate (ten colours, four line styles, both in turn)."""
    return dict(color=f"C{index % 10}", ls=ESTIMATE_STYLES[index % len(ESTIMATE_STYLES)])


def _interp_sigma(reference: Motion, estimate: Motion, name: str) -> np.ndarray | None:
    sigma = estimate.sigma.get(name)
    if sigma is None:
        return None
    return _interp_to(reference, estimate.replace(**{name: np.asarray(sigma, dtype=float)}), name)


def _layers(values: Mapping[str, np.ndarray], ref: np.ndarray, k: int, valid: np.ndarray | None) -> dict[str, int]:
    """zorder of each estimate's line in one panel: larger RMS error against ``ref`` lower; bands at zorder - 1."""
    rms = {}
    for label, v in values.items():
        err = v[:, k] - ref
        if valid is not None:
            err = err[valid]
        err = err[np.isfinite(err)]
        rms[label] = float(np.sqrt(np.mean(err**2))) if err.size else np.inf
    names = list(values)
    # bottom first: the largest error, and among equals the last named
    ranked = sorted(names, key=lambda n: (-rms[n], -names.index(n)))
    return {label: 3 + 2 * i for i, label in enumerate(ranked)}


def plot_time_series(
    reference: Motion,
    estimates: Mapping[str, Motion],
    quantities: Sequence[str] | None = None,
    reference_label: str = "truth",
    errors: bool = True,
    title: str | None = None,
    valid: np.ndarray | None = None,
    bands: bool = True,
    time_origin_ns: int | None = None,
):
    """Estimates against the reference over time, one column per axis (Ho & Lin 2009; Lu, Tsai & Lin 2010; Lin et al. 2011, Figs. 4–5, 10–11).

    For each quantity one row of values and, with ``errors``, one row of errors
    (estimate − reference). The reference is a wide pale black line underneath; each
    estimate has its own colour and line style (:func:`estimate_style`); in each panel the
    estimates with the larger RMS error are drawn underneath, so that a noisy one does not
    bury the accurate ones (ties: the first named on top). Where an estimate has a one-sigma uncertainty (``Motion.sigma``, the
    ``sigma_`` columns of ``gfimu estimate --sigma``) and ``bands``, a translucent band
    of its colour shows ±1σ around it in the value rows and ±1σ around zero in the
    error rows (so an error inside its band is within one sigma). One legend for the
    figure, under the panels, names the reference, each estimate and each band.
    Samples where ``valid`` is False are greyed out of the error rows. Time is in seconds
    from ``time_origin_ns`` (default: the reference's first sample).
    """
    quantities = _checked_quantities(reference, estimates, quantities, reference_label)
    rows_per = 2 if errors else 1
    n_rows = rows_per * len(quantities)
    fig = _figure(13.0, 2.1 * n_rows + 1.0)
    axes = fig.subplots(n_rows, 3, sharex=True, squeeze=False)
    origin = reference.timestamps_ns[0] if time_origin_ns is None else int(time_origin_ns)
    t = (reference.timestamps_ns - origin) * 1e-9
    valid_mask = None if valid is None else np.asarray(valid, dtype=bool)
    handles: dict[str, object] = {}
    for qi, name in enumerate(quantities):
        ref = getattr(reference, name)
        values = {label: _interp_to(reference, m, name) for label, m in estimates.items() if getattr(m, name) is not None}
        sigmas = {label: _interp_sigma(reference, estimates[label], name) for label in values} if bands else {}
        for k in range(len(AXES)):
            layer = _layers(values, ref[:, k], k, valid_mask)
            _draw_values(axes[rows_per * qi, k], t, name, k, ref[:, k], estimates, values, sigmas, layer,
                         reference_label, handles)
            if errors:
                _draw_errors(axes[rows_per * qi + 1, k], t, name, k, ref[:, k], estimates, values, sigmas, layer,
                             valid_mask)
    for k in range(3):
        axes[-1, k].set_xlabel("time [s]")
    order = [reference_label] + [x for label in estimates for x in (label, f"{label} ±1σ") if x in handles]
    fig.legend([handles[x] for x in order], order, loc="outside lower center", fontsize=9,
               ncol=min(len(order), 7), frameon=False)
    fig.suptitle(title or f"Estimates against {reference_label}")
    return fig


def _checked_quantities(reference: Motion, estimates: Mapping[str, Motion], quantities: Sequence[str] | None,
                        reference_label: str) -> list[str]:
    """The quantities :func:`plot_time_series` draws (``quantities``, or :func:`default_quantities`), each one
    checked: known, held by the reference and by at least one estimate (an :class:`InputError` says which not)."""
    if not estimates:
        raise InputError("plot_time_series needs at least one estimate")
    quantities = list(quantities) if quantities is not None else default_quantities(reference, estimates)
    if not quantities:
        raise InputError("the reference and the estimates share no quantity to plot (ω, ω̇, a or f)")
    for name in quantities:
        if name not in LABELS:
            raise InputError(f"cannot plot quantity {name!r}; choose among {list(LABELS)}")
        if getattr(reference, name) is None:
            raise InputError(f"the {reference_label} has no {LABELS[name][0]}")
        if all(getattr(m, name) is None for m in estimates.values()):
            raise InputError(f"no estimate has {LABELS[name][0]} ({', '.join(estimates)})")
    return quantities


def _draw_values(ax, t: np.ndarray, name: str, k: int, ref_k: np.ndarray, estimates: Mapping[str, Motion],
                 values: Mapping[str, np.ndarray], sigmas: Mapping, layer: dict[str, int], reference_label: str,
                 handles: dict) -> None:
    """One value panel of :func:`plot_time_series`: axis ``k`` of quantity ``name``, the reference underneath,
    each estimate at its layer with its ±1σ band just under it; the legend's handles gathered in ``handles``."""
    symbol, unit = LABELS[name]
    (line,) = ax.plot(t, ref_k, label=reference_label, zorder=2, **REFERENCE_STYLE)
    handles.setdefault(reference_label, line)
    for mi, label in enumerate(estimates):
        if label not in values:
            continue
        style = estimate_style(mi)
        top = layer[label]  # each band just under its line
        v = values[label][:, k]
        s = sigmas.get(label)
        if s is not None:
            band = ax.fill_between(t, v - s[:, k], v + s[:, k], color=style["color"], alpha=BAND_ALPHA,
                                   lw=0, zorder=top - 1, label=f"{label} ±1σ")
            handles.setdefault(f"{label} ±1σ", band)
        (line,) = ax.plot(t, v, lw=1.0, label=label, zorder=top, **style)
        handles.setdefault(label, line)
    ax.set_title(f"{symbol} — {AXES[k]}", fontsize=9)
    ax.set_ylabel(f"{QUANTITIES[name][0]}_{AXES[k]} [{unit}]")
    ax.grid(alpha=0.3)


def _draw_errors(eax, t: np.ndarray, name: str, k: int, ref_k: np.ndarray, estimates: Mapping[str, Motion],
                 values: Mapping[str, np.ndarray], sigmas: Mapping, layer: dict[str, int],
                 valid_mask: np.ndarray | None) -> None:
    """One error panel of :func:`plot_time_series`: each estimate's error on axis ``k`` of ``name`` (NaN where
    not ``valid_mask``) at its layer, and its ±1σ band around zero drawn over the error lines."""
    from matplotlib.colors import to_rgba

    unit = LABELS[name][1]
    for mi, label in enumerate(estimates):
        if label not in values:
            continue
        style = estimate_style(mi)
        top = layer[label]
        err = values[label][:, k] - ref_k
        s = sigmas.get(label)
        if valid_mask is not None:
            err = np.where(valid_mask, err, np.nan)
        if s is not None:  # over the error lines, so that its edges stay visible on noise
            sk = s[:, k] if valid_mask is None else np.where(valid_mask, s[:, k], np.nan)
            edge = 0.6 * np.array(to_rgba(style["color"]))  # darker than the line, dashed
            edge[3] = 1.0
            eax.fill_between(t, -sk, sk, facecolor=to_rgba(style["color"], 0.5 * BAND_ALPHA),
                             edgecolor=tuple(edge), lw=1.1, ls=(0, (4, 2)), zorder=50 + top,
                             label=f"{label} ±1σ")
        eax.plot(t, err, lw=0.9, label=label, zorder=top, **style)
    eax.axhline(0.0, color="k", lw=0.6)
    eax.set_ylabel(f"error [{unit}]")
    eax.grid(alpha=0.3)


def plot_condition_number(sizes: np.ndarray, condition: Mapping[str, np.ndarray], unit: str = "m", marks=None):
    """Condition number of the structure matrix against layout size (Ho & Lin 2009, §III).

    ``condition`` maps a layout label to condition numbers at ``sizes``;
    ``marks`` is an optional list of (size, value, text) points from the paper.
    """
    fig = _figure(6.5, 4.5)
    ax = fig.add_subplot(1, 1, 1)
    for label, values in condition.items():
        ax.loglog(sizes, values, lw=1.5, label=label)
    for size, value, text in marks or []:
        ax.plot([size], [value], "ko", ms=5)
        ax.annotate(text, (size, value), textcoords="offset points", xytext=(6, 6), fontsize=8)
    ax.set_xlabel(f"half edge of the layout [{unit}]")
    ax.set_ylabel("condition number of S (2-norm)")
    ax.set_title("Structure-matrix conditioning against layout size")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    return fig


def plot_t2_rmse(t2_values: np.ndarray, rmse_radps: Mapping[str, np.ndarray], tolerance: float = 0.2):
    """RMSE of ω against the IMM threshold T2 (Lin et al. 2011, Fig. 7).

    ``rmse_radps`` maps a trial label to the summed per-axis RMSE at each T2;
    the band shows where the RMSE stays within ``tolerance`` of its minimum.
    """
    fig = _figure(6.5, 4.5)
    ax = fig.add_subplot(1, 1, 1)
    t2 = np.asarray(t2_values, dtype=float)
    for label, values in rmse_radps.items():
        values = np.asarray(values, dtype=float)
        (line,) = ax.plot(t2, values, "o-", ms=3, lw=1.2, label=label)
        if np.any(np.isfinite(values)):
            best = int(np.nanargmin(values))
            ax.plot([t2[best]], [values[best]], "*", ms=11, color=line.get_color())
            ax.axhline(values[best] * (1 + tolerance), color=line.get_color(), lw=0.6, ls=":")
    ax.set_xlabel("T2 threshold [rad²/s²]")
    ax.set_ylabel("RMSE of ω, sum of x, y, z [rad/s]")
    ax.set_title("IMM: RMSE of ω against T2 (★ = T2 min, dotted = +%d %%)" % round(100 * tolerance))
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return fig


def plot_t2_trend(motion_level: np.ndarray, t2_min: np.ndarray, t2_band: np.ndarray | None = None):
    """Best T2 against the motion level a + b + c with its linear trend line (Lin et al. 2011, Fig. 8).

    ``t2_band`` (n, 2) gives, per trial, the T2 range whose RMSE is within the tolerance.
    """
    x = np.asarray(motion_level, dtype=float)
    y = np.asarray(t2_min, dtype=float)
    fig = _figure(6.5, 4.5)
    ax = fig.add_subplot(1, 1, 1)
    if t2_band is not None:
        band = np.asarray(t2_band, dtype=float)
        ax.vlines(x, band[:, 0], band[:, 1], color="0.6", lw=3, alpha=0.6, label="T2 within +20 % of best RMSE")
    ax.plot(x, y, "o", color="C0", label="T2 min")
    if x.size >= 2 and np.ptp(x) > 0:
        slope, intercept = np.polyfit(x, y, 1)
        xs = np.linspace(x.min(), x.max(), 50)
        ax.plot(xs, slope * xs + intercept, "C0-", lw=1.2, label=f"trend: T2 = {slope:.3g}(a+b+c) + {intercept:.3g}")
    ax.set_xlabel("motion level a + b + c (mean quadratic sums) [rad²/s²]")
    ax.set_ylabel("T2 min [rad²/s²]")
    ax.set_title("IMM: best T2 against amplitude of motion")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return fig


def _ellipsoid(semi_axes, n: int = 28):
    u = np.linspace(0, 2 * np.pi, n)
    v = np.linspace(0, np.pi, n // 2)
    return (
        semi_axes[0] * np.outer(np.cos(u), np.sin(v)),
        semi_axes[1] * np.outer(np.sin(u), np.sin(v)),
        semi_axes[2] * np.outer(np.ones_like(u), np.cos(v)),
    )


def polhode_constants(omega_b_radps: np.ndarray, principal_inertia_kgm2) -> tuple[float, float]:
    """Twice the kinetic energy 2T and H² (McGinnis, Perkins & King 2012, eqs. 2–3) at the first sample of ω."""
    inertia = np.asarray(principal_inertia_kgm2, dtype=float)
    w0 = np.asarray(omega_b_radps, dtype=float)[0]
    return float(np.sum(inertia * w0**2)), float(np.sum((inertia * w0) ** 2))


def plot_polhode(
    omega_b_radps: Mapping[str, np.ndarray],
    principal_inertia_kgm2,
    constants_from: str | None = None,
):
    """Polhode: kinetic-energy and momentum ellipsoids with ω paths (McGinnis, Perkins & King 2012, Fig. 5, eqs. 5–6).

    The ellipsoids use 2T and H² from the first sample of the path
    ``constants_from`` (default: the first one given). Left: 3-D view; right:
    the three principal-plane projections of the paths.
    """
    if not omega_b_radps:
        raise InputError("plot_polhode needs at least one angular-velocity path")
    inertia = np.asarray(principal_inertia_kgm2, dtype=float)
    key = constants_from or next(iter(omega_b_radps))
    two_t, h2 = polhode_constants(omega_b_radps[key], inertia)
    fig = _figure(12.0, 5.2)
    ax3 = fig.add_subplot(1, 2, 1, projection="3d")
    ax3.plot_wireframe(*_ellipsoid(np.sqrt(two_t / inertia)), color="0.35", lw=0.3, alpha=0.5)
    ax3.plot_wireframe(*_ellipsoid(np.sqrt(h2) / inertia), color="C1", lw=0.3, alpha=0.35)
    # the first path (usually the truth) thick and solid underneath, the others thin and dashed on top
    styles = [dict(color="k", lw=3.0, alpha=0.45)] + [dict(color=f"C{k}", lw=1.1, ls="--") for k in range(9)]
    for i, (label, w) in enumerate(omega_b_radps.items()):
        w = np.asarray(w, dtype=float)
        ax3.plot(w[:, 0], w[:, 1], w[:, 2], label=label, **styles[i % 10])
    lim = max(np.max(np.sqrt(two_t / inertia)), np.max(np.sqrt(h2) / inertia))
    for setter in (ax3.set_xlim, ax3.set_ylim, ax3.set_zlim):
        setter(-lim, lim)
    ax3.set_box_aspect((1, 1, 1))
    ax3.set_xlabel("ω₁ [rad/s]")
    ax3.set_ylabel("ω₂ [rad/s]")
    ax3.set_zlabel("ω₃ [rad/s]")
    ax3.set_title("energy (grey) and momentum (orange) ellipsoids")
    ax3.legend(fontsize=8, loc="upper left")
    sub = fig.add_gridspec(1, 2)[0, 1].subgridspec(3, 1)
    # the polhode projected on the three planes of principal axes, against the exact intersection
    for row, (i, j) in enumerate(((0, 1), (0, 2), (1, 2))):
        ax = fig.add_subplot(sub[row, 0])
        for k, (label, w) in enumerate(omega_b_radps.items()):
            w = np.asarray(w, dtype=float)
            ax.plot(w[:, i], w[:, j], label=label, **styles[k % 10])
        ax.set_xlabel(f"ω{i + 1} [rad/s]", fontsize=8)
        ax.set_ylabel(f"ω{j + 1} [rad/s]", fontsize=8)
        ax.set_aspect("equal", adjustable="datalim")
        ax.grid(alpha=0.3)
    fig.suptitle(f"Polhode (McGinnis, Perkins & King 2012): 2T = {two_t:.4g} J, H² = {h2:.4g} (kg m²/s)²")
    return fig


def plot_step_size(step_s: np.ndarray, errors: Mapping[str, np.ndarray], ylabel: str, title: str | None = None):
    """Error against integration step size (Li et al. 2021, Fig. 5), one line per propagation."""
    fig = _figure(6.5, 4.5)
    ax = fig.add_subplot(1, 1, 1)
    h = np.asarray(step_s, dtype=float) * 1e3
    for label, values in errors.items():
        ax.plot(h, np.asarray(values, dtype=float), "o-", ms=4, lw=1.2, label=label)
    ax.set_xlabel("step size [ms]")
    ax.set_ylabel(ylabel)
    ax.set_title(title or "Error against step size")
    ax.set_yscale("log")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    return fig


def plot_bench(lengths: np.ndarray, throughput: Mapping[str, np.ndarray]):
    """Throughput (samples/s) against log length, one line per method."""
    fig = _figure(6.5, 4.5)
    ax = fig.add_subplot(1, 1, 1)
    for label, values in throughput.items():
        ax.loglog(lengths, values, "o-", ms=4, label=label)
    ax.set_xlabel("log length [samples]")
    ax.set_ylabel("throughput [samples/s]")
    ax.set_title("Estimator throughput")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    return fig
