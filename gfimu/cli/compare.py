"""``gfimu compare LOG``: every applicable method scored against the log's truth or reference."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from . import CLIError, add_no_progress, info, show_progress
from .options import non_negative, parse_method_options


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "compare",
        help="run several methods on a log and tabulate their errors against truth or reference",
        description="Run every applicable method (or those given) on a log that has truth.csv or reference.csv "
        "and write one table: RMSE per axis and of the norm for linear acceleration, angular acceleration "
        "and angular velocity (Lin et al. 2011, Table 1), relative RMS error (McGinnis, Perkins & King 2012, eq. 7), share of wrong "
        "signs of ω, run time, and the Cramér–Rao / smoother bounds with the ratio RMSE / bound.",
    )
    p.add_argument("log", help="log directory (array.toml + imu.csv + truth.csv or reference.csv)")
    p.add_argument("--methods", default=None, help="comma-separated methods (default: all registered)")
    p.add_argument("--format", choices=["markdown", "csv", "json"], default="markdown", help="table format (default: markdown)")
    p.add_argument("--out", default=None,
                   help="file to write the table to (atomically; never over an input; default: standard output, -)")
    p.add_argument("--estimates-dir", default=None,
                   help="also write each method's estimate as DIR/<method>.csv (DIR is created when missing)")
    p.add_argument("--option", "-O", action="append", default=[], metavar="METHOD.KEY=VALUE",
                   help="option of one method, repeatable, e.g. -O imm.t2=4.0")
    p.add_argument("--preset", default=None, metavar="NAME",
                   help="named settings of the smoother (-O smoother.KEY=VALUE wins over it), e.g. hand-held-low-rate "
                        "(gfimu.smoother.model.presets)")
    p.add_argument("--no-bounds", action="store_true", help="leave out the Cramér–Rao and smoother bounds")
    p.add_argument("--gyro-noise", type=non_negative("rad/s"), default=None, metavar="RAD_PER_S",
                   help="gyro noise std for the 'CRB (with gyro)' row when the array has no gyroscope")
    p.add_argument("--calibration", default=None, help="calibration.toml to apply to the readings first")
    add_no_progress(p)
    p.add_argument("--progress", action="store_true",
                   help="no effect, kept for older command lines: the methods' progress bars now show by default "
                        "on a terminal (see --no-progress, --quiet; default: off)")
    p.set_defaults(func=run)


def run(args) -> int:
    from .. import io as gio
    from ..compare import compare
    from ..methods import METHODS, resolve_options

    methods = None
    if args.methods is not None:
        methods = [m.strip() for m in args.methods.split(",") if m.strip()]
        if not methods:
            raise CLIError("--methods: no method named; give a comma-separated list, or leave --methods out for all")
        unknown = [m for m in methods if m not in METHODS]
        if unknown:
            raise CLIError(f"unknown method(s) {unknown}; choose among: {', '.join(METHODS)}")
    from ..io.outputs import check_output, write_output

    inputs = [args.log, args.calibration]
    out = check_output(args.out, inputs, "--out", stdout=True)
    options = parse_method_options(args.option, methods)
    for method, opts in options.items():
        if method not in METHODS:
            raise CLIError(f"-O {method}.…: unknown method {method!r}; choose among: {', '.join(METHODS)}")
        options[method] = resolve_options(method, opts, prefix=f"{method}.").options
    if getattr(args, "preset", None) is not None:
        if methods is not None and "smoother" not in methods:
            raise CLIError(f"--preset sets the smoother's options, but smoother is not among --methods {','.join(methods)}")
        from ..smoother.model.presets import apply_preset

        apply_preset(args.preset)  # an unknown name stops here, before the log is read
        options.setdefault("smoother", {})["preset"] = args.preset
    if args.estimates_dir is not None:
        folder = Path(args.estimates_dir)
        if folder.exists() and not folder.is_dir():
            raise CLIError(f"--estimates-dir {folder}: exists and is not a folder")
        from ..io.outputs import same_file

        log_folder = Path(args.log) if Path(args.log).is_dir() else Path(args.log).parent
        if folder.is_dir() and (same_file(folder, log_folder)
                                or ((folder / "array.toml").is_file() and (folder / "imu.csv").is_file())):
            what = "the input log folder" if same_file(folder, log_folder) else "a log folder"
            raise CLIError(f"--estimates-dir {folder}: is {what}; the estimates are written into a folder of "
                           "their own, never into a log (give another folder)")
        if folder.is_dir():
            for name in methods or list(METHODS):
                check_output(folder / f"{name}.csv", inputs, "--estimates-dir")
    log = gio.read_log(args.log)
    from ..pipeline import screened

    log = screened(log)
    if args.calibration:
        from ..calibration import apply_calibration_file

        log = apply_calibration_file(log, args.calibration)
    result = compare(log, methods=methods, options=options, bounds=not args.no_bounds,
                     estimates_dir=args.estimates_dir, progress=show_progress(args),
                     gyro_noise_std_radps=args.gyro_noise)
    text = {"markdown": result.to_markdown, "csv": result.to_csv, "json": result.to_json}[args.format]()
    write_output(out, [text])
    method_rows = [r for r in result.rows if r["kind"] == "method"]
    n_ok = sum(1 for r in method_rows if r["status"] == "ok")
    if out is not None:
        info(args, f"compare: {n_ok} of {len(result.methods)} methods ran on {len(log)} samples -> {out}",
             file=sys.stdout)
    # a method that failed is an error; so is one asked for by name (--methods) that did not run
    failed = [r for r in method_rows if r["status"] == "failed" or (methods is not None and r["status"] != "ok")]
    if failed:
        for r in failed:
            print(f"gfimu compare: error: method {r['method']!r} {r['status']}: {r.get('reason', '')}",
                  file=sys.stderr)
        return 1
    if n_ok == 0:
        print("gfimu compare: error: no method could run on this log", file=sys.stderr)
        return 1
    return 0
