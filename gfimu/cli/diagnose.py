"""``gfimu diagnose LOG [--calibration cal.toml] [--figure out.png] [--format text|json] [--out FILE]``."""

from __future__ import annotations

import argparse
import json
import warnings

from . import add_no_progress, show_progress


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "diagnose",
        help="check a log before trusting it: rigid-body residual, noise, timing, units, positions, "
             "stuck or clipped channels, expected ω accuracy",
        description="Read a log and report what its readings say about themselves: the rigid-body consistency "
                    "residual per sensor and per |ω| band (per-sample ML fit, the smoother's model check), the "
                    "noise floor against the stated noise, timing (rate, jitter, gaps), likely unit and position "
                    "mistakes, time skew of a sensor, stuck and clipped channels, the Cramér-Rao bound on ω for "
                    "this array and this motion and whether the sign of ω can be told; then a one-line verdict. "
                    "Exit status 0 whatever is found (the verdict says it); 2 when the log cannot be read.",
    )
    p.add_argument("log", help="log directory (array.toml + imu.csv)")
    p.add_argument("--calibration", default=None,
                   help="calibration.toml to apply to the readings first (default: none, the readings as logged)")
    p.add_argument("--format", choices=["text", "json"], default="text", help="report format (default: text)")
    p.add_argument("--out", default=None,
                   help="write the report to this file (atomically; never over an input) instead of standard output "
                        "(default: -, standard output)")
    p.add_argument("--figure", default=None, metavar="FILE",
                   help="also draw a figure (.png, .svg or .pdf; needs matplotlib): |ω| and its bound, the residual "
                        "over time and per sensor, the time steps (default: none)")
    add_no_progress(p)
    p.set_defaults(func=run)


def run(args) -> int:
    from .. import io as gio
    from ..diagnose import diagnose, diagnosis_figure
    from ..io.outputs import check_outputs, write_output

    out, figure = check_outputs({"--out": args.out, "--figure": args.figure}, [args.log, args.calibration],
                                stdout="--out")
    calibration = None
    if args.calibration:
        from ..calibration import read_calibration

        calibration = read_calibration(args.calibration)
    with warnings.catch_warnings():  # the report states the gaps and the implausible values itself
        warnings.simplefilter("ignore", gio.LogGapWarning)
        log = gio.read_log(args.log, check=False)
    from ..calibration import CalibrationFileError

    try:
        result = diagnose(log, progress=show_progress(args), calibration=calibration)
    except CalibrationFileError as exc:  # the calibration does not fit this log's array: name its file
        raise CalibrationFileError(f"{args.calibration}: {exc}") from None
    if figure is not None:
        from ..plots import save_figure

        save_figure(diagnosis_figure(result), figure)
    text = (json.dumps(result.as_dict(), indent=2) + "\n") if args.format == "json" else result.to_text()
    write_output(out, [text])
    return 0
