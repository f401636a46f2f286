"""``gfimu estimate LOG --method NAME --out FILE.csv``."""

from __future__ import annotations

import argparse
import sys

from . import CLIError
from .options import check_method_options, parse_options, positive


def register(sub: argparse._SubParsersAction) -> None:
    from ..methods import METHODS

    p = sub.add_parser("estimate", help="estimate ω, ω̇ and acceleration from a log",
                       description="Run one estimation method on a log directory and write an estimate CSV.")
    p.add_argument("log", nargs="?", default=None, help="log directory (array.toml + imu.csv)")
    p.add_argument("--method", default="smoother", choices=list(METHODS), help="estimation method (default: smoother)")
    p.add_argument("--list-options", action="store_true",
                   help="print every -O option of --method with its unit, default and meaning, and exit")
    p.add_argument("--out", required=False, default=None,
                   help="estimate CSV to write (atomically; never over an input), or - for standard output")
    p.add_argument("--option", "-O", action="append", default=[], metavar="KEY=VALUE",
                   help="method option, repeatable (see the method's documentation)")
    p.add_argument("--preset", default=None, metavar="NAME",
                   help="named smoother settings (method smoother; -O options win over it), e.g. hand-held-low-rate: "
                        "fast hand-held motion at 50–100 Hz on real sensors (gfimu.smoother.presets)")
    p.add_argument("--solver", choices=["numpy", "gtsam"], default=None,
                   help="batch smoother solver (method smoother; default: numpy, the vectorised banded "
                        "Levenberg-Marquardt, linear in the length; gtsam: the same problem as a GTSAM graph, "
                        "eliminated in time order, about ten times slower, a cross-check)")
    p.add_argument("--lag-s", type=positive("s"), default=None,
                   help="fixed-lag smoother lag [s] (default: the method's, see -O lag_s)")
    p.add_argument("--sigma", action="store_true", help="also write one-sigma uncertainties where the method gives them")
    p.add_argument("--calibration", default=None, help="calibration.toml to apply to the readings first")
    p.add_argument("--orientation", choices=["none", "inclinometer", "gyro", "estimate"], default="none",
                   help="add gravity-free acceleration and orientation: from the inclinometer (paper 001) or "
                        "by propagating the gyro or the estimated ω (paper 003)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def run(args) -> int:
    if args.list_options:
        from .options import describe_options

        sys.stdout.write(describe_options(args.method))
        return 0
    if args.log is None or args.out is None:
        raise CLIError("a LOG folder and --out (a file, or - for standard output) are needed "
                       "(--list-options alone lists the method's options)")
    from .. import io as gio
    from ..io.outputs import check_output, write_output
    from ..pipeline import MethodNotApplicable, estimate_log

    out = check_output(args.out, [args.log, args.calibration], "--out", stdout=True)
    options = method_options(args)
    try:
        run_ = estimate_log(args.log, args.method, options, args.calibration, progress=not args.no_progress,
                            orientation=args.orientation)
    except MethodNotApplicable as exc:
        raise CLIError(str(exc)) from None
    write_output(out, gio.motion_csv_chunks(run_.motion))
    if run_.model_check is not None:  # what the smoother learnt about the readings and the model it chose
        print(f"{args.method}: {run_.model_check.describe()}", file=sys.stderr)
    print(f"{args.method}: {run_.samples} samples in {run_.seconds:.2f} s -> "
          f"{out if out is not None else 'standard output'}", file=sys.stderr if out is None else sys.stdout)
    return 0


def method_options(args) -> dict:
    """The method's options from ``-O``, ``--preset``, ``--lag-s`` and ``--sigma``, checked."""
    options = parse_options(args.option)
    if getattr(args, "preset", None) is not None:  # checked before the log is read
        if args.method != "smoother":
            raise CLIError(f"--preset applies to --method smoother only, not {args.method!r}")
        from ..smoother.presets import apply_preset

        apply_preset(args.preset)
        options["preset"] = args.preset
    if getattr(args, "solver", None) is not None:
        if args.method != "smoother":
            raise CLIError(f"--solver applies to --method smoother only, not {args.method!r}")
        options["solver"] = args.solver
    if getattr(args, "lag_s", None) is not None:
        if args.method != "fixed-lag":
            raise CLIError("--lag-s applies to --method fixed-lag only")
        options["lag_s"] = args.lag_s
    if getattr(args, "sigma", False):
        options["compute_sigma"] = True
    check_method_options(args.method, options)
    from ..methods import make_estimator

    make_estimator(args.method, **options)  # option values checked before any log is read
    return options
