"""``gfimu plot LOG ESTIMATE.csv ... --out fig.png``: figures of estimates against truth or reference."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from . import CLIError, add_no_progress, info, show_progress
from ..errors import MissingExtraError
from .options import non_negative

PREFIXES = {"a": "accel_b_mps2", "f": "specific_force_b_mps2", "dw": "omega_dot_b_radps2", "w": "omega_b_radps"}


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "plot",
        help="plot estimates against the log's truth or reference (needs the 'plot' extra)",
        description="Figures (PNG, SVG or PDF by the --out suffix). 'time': ω, ω̇ and linear acceleration of each "
        "estimate against truth/reference over time with error panels (Ho & Lin 2009; Lu, Tsai & Lin 2010; Lin et al. 2011). 'polhode': the "
        "estimated ω path on the kinetic-energy and momentum ellipsoids (McGinnis, Perkins & King 2012; the array needs [body]). "
        "'condition': condition number of the log's array scaled over layout sizes (Ho & Lin 2009, §III).",
    )
    p.add_argument("log", help="log directory (array.toml + imu.csv, truth.csv or reference.csv)")
    p.add_argument("estimates", nargs="*",
                   help="estimate CSV files (gfimu estimate --out ...), each in its own colour and line style, named "
                        "by its file name in the legend; sigma_ columns (gfimu estimate --sigma) are drawn as ±1σ bands")
    p.add_argument("--out", required=True,
                   help="figure file to write (atomically; never over an input); .png, .svg or .pdf")
    p.add_argument("--kind", choices=["time", "polhode", "condition"], default="time", help="figure (default: time)")
    p.add_argument("--quantities", default=None, help="comma-separated among w, dw, a, f (default: all available)")
    p.add_argument("--start-s", type=non_negative("s"), default=None,
                   help="first second to show, from the log start [s] (default: the start)")
    p.add_argument("--end-s", type=non_negative("s"), default=None, help="last second to show [s] (default: the end)")
    p.add_argument("--no-errors", action="store_true", help="time plot without the error panels (default: with)")
    p.add_argument("--no-bands", action="store_true",
                   help="leave out the ±1σ bands (default: drawn where an estimate has sigma_ columns)")
    add_no_progress(p)
    p.set_defaults(func=run)


def estimate_labels(paths: list[str]) -> list[str]:
    """Legend names of the estimate files: the file name without .csv, with as many parent folders as it
    takes to tell files of the same name apart (``a/smoother``, ``b/smoother``)."""
    parts = [Path(p).with_suffix("").parts if Path(p).suffix.lower() == ".csv" else Path(p).parts for p in paths]
    depth = 1
    while True:
        labels = ["/".join(x[-depth:]) for x in parts]
        if len(set(labels)) == len(labels) or depth >= max(len(x) for x in parts):
            break
        depth += 1
    seen: dict[str, int] = {}
    out = []
    for label in labels:  # the same file named twice
        seen[label] = seen.get(label, 0) + 1
        out.append(label if seen[label] == 1 else f"{label} ({seen[label]})")
    return out


def _window(log, start_s, end_s) -> slice:
    t = log.times_s
    i0 = 0 if start_s is None else int(np.searchsorted(t, start_s, side="left"))
    i1 = len(t) if end_s is None else int(np.searchsorted(t, end_s, side="right"))
    if i1 - i0 < 2:
        raise CLIError(f"the window [{start_s}, {end_s}] s holds fewer than 2 samples of the log ({t[-1]:.3f} s long)")
    return slice(i0, i1)


def run(args) -> int:
    from ..progress import steps

    with steps("plot", ["read the log and estimates", "draw", "write the figure"], show_progress(args)) as bar:
        message = _run(args, bar)
    info(args, message, file=sys.stdout)
    return 0


def _run(args, bar) -> str:
    """Draw and write the figure; returns the status line."""
    from .. import io as gio, plots
    from ..compare import condition_vs_scale

    from ..io.outputs import check_output

    out = check_output(args.out, [args.log, *args.estimates], "--out")
    try:
        from matplotlib.backend_bases import FigureCanvasBase
    except ImportError:
        raise MissingExtraError("gfimu plot", "matplotlib", "plot") from None

    formats = FigureCanvasBase.get_supported_filetypes()
    if out.suffix.lower().lstrip(".") not in formats:
        raise CLIError(f"--out {args.out}: the figure format comes from the suffix; use one of "
                       f"{', '.join('.' + f for f in sorted(formats))}")
    if args.start_s is not None and args.end_s is not None and args.end_s <= args.start_s:
        raise CLIError(f"--end-s {args.end_s:g} must be after --start-s {args.start_s:g}")
    bar.step("read the log and estimates")
    log = gio.read_log(args.log)
    if args.kind == "condition":
        positions = np.array([a.position_m for a in log.array.accelerometers])
        size = float(np.max(np.abs(positions)))
        sizes = np.logspace(np.log10(size) - 2, np.log10(size) + 2, 41)
        bar.step("draw")
        fig = plots.plot_condition_number(sizes, {log.array.name: condition_vs_scale(log.array, sizes)},
                                          marks=[(size, log.array.condition_number(), "this array")])
        bar.step("write the figure")
        plots.save_figure(fig, args.out)
        return f"plot: condition number over {sizes[0]:.3g}-{sizes[-1]:.3g} m -> {args.out}"
    if not args.estimates:
        raise CLIError(f"--kind {args.kind} needs at least one estimate CSV")
    window = _window(log, args.start_s, args.end_s)
    estimates = {}
    for label, path in zip(estimate_labels(args.estimates), args.estimates):
        motion = gio.read_motion_csv(path, allow_nan=True)
        if len(motion) != len(log):
            raise CLIError(f"{path}: {len(motion)} rows, but the log {args.log} has {len(log)} samples")
        estimates[label] = motion.select(window)
    bar.step("draw")
    if args.kind == "polhode":
        if log.array.body is None:
            raise CLIError(f"{args.log}: array.toml has no [body] principal_inertia_kgm2, needed for the polhode")
        paths = {}
        reference = log.truth if log.truth is not None else log.reference
        if reference is not None and reference.omega_b_radps is not None:
            paths["truth" if log.truth is not None else "reference"] = reference.select(window).omega_b_radps
        for name, m in estimates.items():
            if m.omega_b_radps is None:
                raise CLIError(f"estimate {name!r} has no angular velocity")
            paths[name] = m.omega_b_radps
        fig = plots.plot_polhode(paths, log.array.body.principal_inertia_kgm2)
    else:
        if log.truth is not None:
            reference, label, valid = log.truth, "truth", None
        elif log.reference is not None:
            reference, label = log.reference, "reference"
            valid = None if log.invalid_reference is None else ~log.invalid_reference[window]
        else:
            raise CLIError(f"{args.log}: no truth.csv or reference.csv to plot against")
        quantities = None
        if args.quantities:
            try:
                quantities = [PREFIXES[q.strip()] for q in args.quantities.split(",") if q.strip()]
            except KeyError as exc:
                raise CLIError(f"--quantities: unknown {exc.args[0]!r}; choose among {', '.join(PREFIXES)}") from None
        fig = plots.plot_time_series(reference.select(window), estimates, quantities=quantities,
                                     reference_label=label, errors=not args.no_errors, valid=valid,
                                     bands=not args.no_bands, time_origin_ns=int(log.timestamps_ns[0]),
                                     title=f"{Path(args.log).name}: estimates against {label}")
    bar.step("write the figure")
    plots.save_figure(fig, args.out)
    return f"plot: {len(estimates)} estimate(s), {window.stop - window.start} samples -> {args.out}"
