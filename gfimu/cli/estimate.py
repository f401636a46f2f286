"""``gfimu estimate LOG --method NAME --out FILE.csv``."""

from __future__ import annotations

import argparse
import sys
import warnings

from . import CLIError, add_no_progress, info, show_progress
from .options import method_options, positive


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
                        "fast hand-held motion at 50–100 Hz on real sensors (gfimu.smoother.model.presets)")
    p.add_argument("--solver", choices=["numpy", "gtsam"], default=None,
                   help="batch smoother solver (method smoother; default: numpy, the vectorised banded "
                        "Levenberg-Marquardt, linear in the length; gtsam: the same problem as a GTSAM graph, "
                        "eliminated in time order: the same answer 10-100 times slower (Python factor callbacks), a cross-check)")
    p.add_argument("--lag-s", type=positive("s"), default=None,
                   help="fixed-lag smoother lag [s] (default: the method's, see -O lag_s)")
    p.add_argument("--sigma", action="store_true", help="also write one-sigma uncertainties where the method gives them")
    p.add_argument("--calibration", default=None, help="calibration.toml to apply to the readings first")
    p.add_argument("--orientation", choices=["none", "inclinometer", "gyro", "estimate"], default="none",
                   help="add gravity-free acceleration and orientation: from the inclinometer (Lu, Tsai & Lin 2010) or "
                        "by propagating the gyro or the estimated ω (Li et al. 2021); default: none")
    p.add_argument("--tum", default=None, metavar="FILE",
                   help="also write the estimated orientation as a TUM trajectory (timestamp [s], tx ty tz [m] "
                        "= 0, qx qy qz qw of the body→world rotation), as evo reads it (`evo_traj tum FILE`; "
                        "compare with `evo_ape tum REF FILE --align_origin -r angle_deg`: --align fails on the "
                        "zero positions); needs --orientation inclinometer|gyro|estimate (default: none written)")
    add_no_progress(p)
    p.set_defaults(func=run)


def run(args) -> int:
    """Options -> estimator -> outputs checked -> the estimate of the log (gfimu.pipeline) -> written -> report."""
    progress = show_progress(args)
    chosen = method_options(args.method, args.option, preset=args.preset, solver=args.solver, lag_s=args.lag_s,
                            sigma=args.sigma)
    if args.list_options:
        sys.stdout.write(chosen.describe())
        return 0
    if args.log is None or args.out is None:
        raise CLIError("a LOG folder and --out (a file, or - for standard output) are needed "
                       "(--list-options alone lists the method's options)")
    import numpy as np

    from .. import io as gio
    from ..io import trajectory
    from ..io.outputs import check_outputs, write_output
    from ..pipeline import estimate_log

    estimator = chosen.estimator()  # option values checked before any log is read
    if args.tum is not None and args.orientation == "none" and not (chosen.options.get("estimate_attitude")
                                                                     or chosen.options.get("use_inclinometer")):
        raise CLIError("--tum writes the estimated orientation, but none is estimated: add --orientation "
                       "inclinometer, gyro or estimate")
    out, tum = check_outputs({"--out": args.out, "--tum": args.tum}, [args.log, args.calibration], stdout="--out")
    run_ = estimate_log(args.log, estimator, calibration=args.calibration, progress=progress,
                        orientation=args.orientation, truth=False)  # MethodNotApplicable: an InputError, exit 2
    tum_chunks = None
    if tum is not None:
        if run_.motion.quaternion_wb is None:
            raise CLIError(f"--tum {args.tum}: method {args.method!r} gave no orientation to write")
        tum_chunks = trajectory.tum_chunks(run_.motion)  # checked before anything is written
    write_output(out, gio.motion_csv_chunks(run_.motion))
    if tum_chunks is not None:
        write_output(tum, tum_chunks)
    report = run_.report
    for note in report.warnings:  # what went less well than planned, e.g. a solve window that did not converge
        warnings.warn(f"{args.method}: {note}", stacklevel=1)
    for line in report.describe():  # what the method learnt about the readings and the model it chose
        info(args, f"{args.method}: {line}")
    steps = ", ".join(f"{name} {seconds:.2f}" for name, seconds in report.timings.items())
    info(args, f"{args.method}: {run_.samples} samples in {report.seconds:.2f} s ({steps}) -> "
               f"{out if out is not None else 'standard output'}", file=sys.stderr if out is None else sys.stdout)
    if tum is not None:
        info(args, f"orientation: {int(np.sum(np.all(np.isfinite(run_.motion.quaternion_wb), axis=1)))} poses "
                   f"-> {tum} (TUM: timestamp tx ty tz qx qy qz qw)", file=sys.stderr if out is None else sys.stdout)
    return 0
