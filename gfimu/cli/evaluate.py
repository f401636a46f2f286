"""``gfimu evaluate REFERENCE ESTIMATE.csv [--format markdown|csv|json] [--out FILE]``.

The reference comes first, as in evo: a truth or reference CSV, or a log folder
(its ``truth.csv`` is used, else its ``reference.csv``). The older order
``ESTIMATE.csv LOG`` (a log folder, truth.csv or reference.csv second) keeps working. Rows whose reference
has ``valid`` = 0 are left out (see :mod:`gfimu.io.tables`); options select the
moving samples, a time window, and shift the estimate in time (given or
estimated); ``--errors-out`` writes the per-sample ω errors.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import warnings
from pathlib import Path

from . import CLIError, info
from .options import non_negative


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "evaluate",
        help="errors of an estimate against truth or a reference (RMSE, relative RMS, sign errors)",
        description="Compare an estimate CSV with a truth or reference CSV (or a log folder's truth.csv, else "
                    "reference.csv): RMSE per axis and of the norm, median error norm, relative RMS error "
                    "(McGinnis, Perkins & King 2012, eq. 7) for every quantity both files have; for ω also the share of samples on the "
                    "wrong sign (ω_est · ω_ref < 0), of samples with a component of the other sign, and of errors "
                    "over 5 rad/s; when the estimate has σ columns (gfimu estimate --sigma), per axis the share of rows within "
                    "1σ and 2σ and the mean NEES. Rows marked invalid in the reference (valid = 0) are left out.",
    )
    p.add_argument("reference", help="truth or reference CSV, or a log folder (its truth.csv, else reference.csv)")
    p.add_argument("estimate", help="estimate CSV (as written by gfimu estimate)")
    p.add_argument("--format", choices=["markdown", "csv", "json"], default="markdown", help="output format")
    p.add_argument("--out", default=None,
                   help="write the table to this file (atomically; never over an input) instead of standard output (-)")
    p.add_argument("--against", choices=["auto", "truth", "reference"], default="auto",
                   help="with a log folder: compare with truth.csv or reference.csv (default: truth if present)")
    p.add_argument("--interpolate", action="store_true",
                   help="if the timestamps differ, interpolate the truth at the estimate's timestamps")
    p.add_argument("--sign-threshold", type=non_negative("rad/s"), default=0.1, metavar="RADPS",
                   help="count signs only where ‖ω‖ (wrong sign) or the ω component (axis sign off) is above this "
                        "magnitude [rad/s] (default 0.1)")
    p.add_argument("--moving-threshold-radps", type=non_negative("rad/s"), default=0.0, metavar="RADPS",
                   help="use only rows where the reference turns faster than this, |ω_ref| > RADPS "
                        "(default 0: every valid row)")
    p.add_argument("--t-start-s", type=float, default=None, metavar="S",
                   help="use only rows from this time on, in s from the reference's first row (default: the start)")
    p.add_argument("--t-end-s", type=float, default=None, metavar="S",
                   help="use only rows up to this time, in s from the reference's first row (default: the end)")
    offset = p.add_mutually_exclusive_group()
    offset.add_argument("--time-offset-s", type=float, default=0.0, metavar="S",
                        help="add this to the estimate's timestamps before comparing (default 0 s; "
                             "implies --interpolate when not 0)")
    offset.add_argument("--estimate-time-offset", action="store_true",
                        help="estimate that offset (cross-correlation of |ω| within ±0.5 s), report it and apply it")
    p.add_argument("--calibration", default=None, metavar="FILE",
                   help="calibration.toml the estimate was made with (gfimu estimate --calibration): its gyro bias "
                        "is removed from a reference's ω too, as gfimu estimate removes it from the gyro (default: "
                        "the reference as it is)")
    p.add_argument("--errors-out", default=None, metavar="FILE",
                   help="also write the per-sample ω errors (timestamp, error x, y, z, norm [rad/s], used 0/1) "
                        "as CSV (atomically; never over an input)")
    p.set_defaults(func=run)


def _truth_path(arg: str, against: str) -> Path:
    path = Path(arg)
    if not path.exists():
        raise CLIError(f"{path}: not found (expected a truth/reference CSV or a log folder)")
    if not path.is_dir():
        if against != "auto":
            raise CLIError("--against applies to a log folder only")
        return path
    names = {"auto": ["truth.csv", "reference.csv"], "truth": ["truth.csv"], "reference": ["reference.csv"]}[against]
    for name in names:
        if (path / name).is_file():
            return path / name
    raise CLIError(f"{path}: log folder has no {' or '.join(names)} to evaluate against")


def _warn_gyro_is_reference(truth_path: Path, truth) -> None:
    """A warning when the reference is the log's own gyroscope (convert mimu4444 --with-gyro): an estimate
    that reads the gyro then agrees with it by construction."""
    import numpy as np

    imu = truth_path.parent / "imu.csv"
    if truth_path.name != "reference.csv" or truth.omega_b_radps is None or not imu.is_file():
        return
    with imu.open(encoding="utf-8") as f:
        header = f.readline()
    if "w_x" not in header:
        return
    from .. import io as gio

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        gyro = gio.read_log(truth_path.parent, check=False).gyro_b_radps
    if gyro is None or gyro.shape != truth.omega_b_radps.shape:
        return
    same = np.all(np.isfinite(gyro), axis=1) & np.all(gyro == truth.omega_b_radps, axis=1)
    if np.mean(same) > 0.9:
        warnings.warn(f"{truth_path}: the reference is the log's own gyroscope (imu.csv's w_x, w_y, w_z); an "
                      "estimate made with the gyro agrees with it by construction, so this is no independent check "
                      "(to evaluate the accelerometers alone, estimate without the gyro: gfimu estimate -O use_gyro=False with "
                      "the smoothers or ml; or convert mimu4444 or rosbag without --with-gyro, which writes no gyroscope "
                      "channels)", UserWarning, stacklevel=2)


def _order(args) -> tuple[str, str]:
    """(reference, estimate) from the two positional arguments: reference first, as evo takes them;
    the older order ``ESTIMATE.csv LOG`` (a log folder, truth.csv or reference.csv second) keeps working."""
    def looks_like_reference(path: Path) -> bool:
        return path.is_dir() or path.name in ("truth.csv", "reference.csv")

    first, second = Path(args.reference), Path(args.estimate)
    if looks_like_reference(second) and not looks_like_reference(first):
        return args.estimate, args.reference
    return args.reference, args.estimate


def run(args) -> int:
    import numpy as np

    from .. import io as gio
    from ..evaluation import (EvaluationAlignmentWarning, TimestampMismatchError, error_table, estimate_time_offset_s,
                              evaluate, shifted)
    from ..io.outputs import check_outputs, write_output

    reference_arg, estimate_arg = _order(args)
    inputs = [reference_arg, estimate_arg, args.calibration]
    out, errors_out = check_outputs({"--out": args.out, "--errors-out": args.errors_out}, inputs, stdout="--out")
    truth_path = _truth_path(reference_arg, args.against)
    estimate = gio.read_motion_csv(estimate_arg, allow_nan=True)
    truth, valid = gio.read_motion_table(truth_path)
    _warn_gyro_is_reference(truth_path, truth)
    if args.calibration is not None:
        from ..calibration import read_calibration

        bias = read_calibration(args.calibration).gyro_bias_b_radps
        if bias is not None and truth.omega_b_radps is not None and truth_path.name != "truth.csv":
            truth = truth.replace(omega_b_radps=truth.omega_b_radps - bias)
    interpolate = args.interpolate
    offset_s = float(args.time_offset_s)
    if args.estimate_time_offset:
        offset_s = estimate_time_offset_s(estimate, truth, valid)
    if offset_s:
        estimate = shifted(estimate, offset_s)
        interpolate = True
    t = (truth.timestamps_ns - truth.timestamps_ns[0]) * 1e-9
    use = np.ones(len(truth), bool) if valid is None else np.array(valid, bool)
    if args.t_start_s is not None:
        use &= t >= args.t_start_s
    if args.t_end_s is not None:
        use &= t <= args.t_end_s
    if args.moving_threshold_radps > 0:
        if truth.omega_b_radps is None:
            raise CLIError(f"{truth_path}: --moving-threshold-radps needs ω (w_x, w_y, w_z) in the reference")
        use &= np.linalg.norm(truth.omega_b_radps, axis=1) > args.moving_threshold_radps
    if not np.any(use):
        raise CLIError("no reference row left to evaluate (check --t-start-s, --t-end-s, --moving-threshold-radps)")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", EvaluationAlignmentWarning)
        try:
            result = evaluate(estimate, truth, valid=use, sign_threshold_radps=args.sign_threshold,
                              align="interpolate" if interpolate else "exact")
        except TimestampMismatchError as exc:  # the command line's option, not the keyword
            raise CLIError(f"{estimate_arg} vs {truth_path}: {TimestampMismatchError(exc.detail, 'give --interpolate')}"
                           ) from None
        except ValueError as exc:  # the files the mismatch is between
            raise CLIError(f"{estimate_arg} vs {truth_path}: {exc}") from None
        if result.n_invalid and (valid is None or np.any(use != np.asarray(valid, bool))):
            # the rows the selection left out are not invalid reference: count those apart
            invalid = 0 if valid is None else evaluate(
                estimate, truth, valid=np.array(valid, bool), sign_threshold_radps=args.sign_threshold,
                align="interpolate" if interpolate else "exact").n_invalid
            result = dataclasses.replace(result, n_invalid=invalid, n_deselected=result.n_invalid - invalid)
    if args.format == "markdown":
        text = result.to_markdown(title=f"{estimate_arg} vs {truth_path}")
    elif args.format == "csv":
        text = result.to_csv()
    else:
        text = result.to_json()
    write_output(out, [text])
    report = sys.stderr if out is None else sys.stdout
    if offset_s:
        info(args, f"evaluate: estimate shifted by {offset_s * 1e3:+.3f} ms"
                   f"{' (estimated from |omega|)' if args.estimate_time_offset else ''}", file=report)
    if errors_out is not None:
        if estimate.omega_b_radps is None or truth.omega_b_radps is None:
            raise CLIError("--errors-out needs ω in both the estimate and the reference")
        table = error_table(estimate, truth, use)
        lines = ["#timestamp [ns],err_w_x [rad s^-1],err_w_y [rad s^-1],err_w_z [rad s^-1],err_w_norm [rad s^-1],used []\n"]
        lines += [f"{int(r[0])},{r[1]:.9g},{r[2]:.9g},{r[3]:.9g},{r[4]:.9g},{int(r[5])}\n" for r in table]
        write_output(errors_out, ["".join(lines)])
    if out is not None:
        info(args, f"evaluation of {estimate_arg} -> {args.out} ({result.summary()})", file=sys.stdout)
    return 0
