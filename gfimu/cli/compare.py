"""``gfimu compare LOG``: every applicable method scored against the log's truth or reference."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from . import CLIError


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "compare",
        help="run several methods on a log and tabulate their errors against truth or reference",
        description="Run every applicable method (or those given) on a log that has truth.csv or reference.csv "
        "and write one table: RMSE per axis and of the norm for linear acceleration, angular acceleration "
        "and angular velocity (paper 002, Table 1), relative RMS error (paper 004, eq. 7), share of wrong "
        "signs of ω, run time, and the Cramér–Rao / smoother bounds with the ratio RMSE / bound.",
    )
    p.add_argument("log", help="log directory (array.toml + imu.csv + truth.csv or reference.csv)")
    p.add_argument("--methods", default=None, help="comma-separated methods (default: all registered)")
    p.add_argument("--format", choices=["markdown", "csv", "json"], default="markdown", help="table format (default: markdown)")
    p.add_argument("--out", default=None, help="file to write the table to (default: standard output)")
    p.add_argument("--estimates-dir", default=None, help="also write each method's estimate as DIR/<method>.csv")
    p.add_argument("--option", "-O", action="append", default=[], metavar="METHOD.KEY=VALUE",
                   help="option of one method, repeatable, e.g. -O imm.t2=4.0")
    p.add_argument("--preset", default=None, metavar="NAME",
                   help="named settings of the smoother (-O smoother.KEY=VALUE wins over it), e.g. hand-held-low-rate "
                        "(gfimu.smoother.presets)")
    p.add_argument("--no-bounds", action="store_true", help="leave out the Cramér–Rao and smoother bounds")
    p.add_argument("--gyro-noise", type=float, default=None, metavar="RAD_PER_S",
                   help="gyro noise std for the 'CRB (with gyro)' row when the array has no gyroscope")
    p.add_argument("--calibration", default=None, help="calibration.toml to apply to the readings first")
    p.add_argument("--progress", action="store_true", help="show progress bars of the methods")
    p.set_defaults(func=run)


def parse_method_options(pairs: list[str], methods: list[str] | None) -> dict[str, dict]:
    """``METHOD.KEY=VALUE`` pairs -> {method: {key: value}}."""
    from .estimate import parse_options

    out: dict[str, dict] = {}
    for pair in pairs:
        head, sep, value = pair.partition("=")
        method, dot, key = head.partition(".")
        if not sep or not dot or not method or not key:
            raise CLIError(f"--option expects METHOD.KEY=VALUE, got {pair!r}")
        if methods is not None and method not in methods:
            raise CLIError(f"--option {pair!r}: method {method!r} is not among --methods {','.join(methods)}")
        out.setdefault(method, {}).update(parse_options([f"{key}={value}"]))
    return out


def run(args) -> int:
    from .. import io as gio
    from ..compare import compare
    from ..estimators import METHODS

    methods = None
    if args.methods:
        methods = [m.strip() for m in args.methods.split(",") if m.strip()]
        unknown = [m for m in methods if m not in METHODS]
        if unknown:
            raise CLIError(f"unknown method(s) {unknown}; choose among: {', '.join(METHODS)}")
    options = parse_method_options(args.option, methods)
    if getattr(args, "preset", None) is not None:
        if methods is not None and "smoother" not in methods:
            raise CLIError(f"--preset sets the smoother's options, but smoother is not among --methods {','.join(methods)}")
        from ..smoother.presets import apply_preset

        apply_preset(args.preset)  # an unknown name stops here, before the log is read
        options.setdefault("smoother", {})["preset"] = args.preset
    log = gio.read_log(args.log)
    if args.calibration:
        from ..calibration import apply_calibration, read_calibration

        log = apply_calibration(log, read_calibration(args.calibration))
    result = compare(log, methods=methods, options=options, bounds=not args.no_bounds,
                     estimates_dir=args.estimates_dir, progress=args.progress,
                     gyro_noise_std_radps=args.gyro_noise)
    text = {"markdown": result.to_markdown, "csv": result.to_csv, "json": result.to_json}[args.format]()
    if args.out:
        out = Path(args.out)
        gio.atomic_write_text(out, text)
        n_ok = sum(1 for r in result.rows if r["kind"] == "method" and r["status"] == "ok")
        print(f"compare: {n_ok} of {len(result.methods)} methods ran on {len(log)} samples -> {out}")
    else:
        sys.stdout.write(text)
    return 0
