"""``gfimu calibrate LOG --out calibration.toml``: static calibration from still periods."""

from __future__ import annotations

import argparse
import sys

from . import CLIError, add_no_progress, info, show_progress
from .options import non_negative, positive


def register(sub: argparse._SubParsersAction) -> None:
    from ..calibration import StillDetector

    d = StillDetector()
    p = sub.add_parser(
        "calibrate",
        help="fit accelerometer biases and gains from still periods",
        description="Find the still periods of a log (the array held still in several orientations) and fit, "
        "per accelerometer, a bias and a 3x3 gain-and-misalignment matrix against gravity; also the gyro bias "
        "when the log has a gyroscope or an angular-velocity reference. Prints the inter-sensor spread of the "
        "still means before and after.",
    )
    p.add_argument("log", help="log directory")
    p.add_argument("--out", required=True,
                   help="calibration.toml to write (atomically; never over an input), or - for standard output")
    p.add_argument("--window-s", type=positive("s"), default=d.window_s,
                   help=f"detector window [s] (default {d.window_s})")
    p.add_argument("--accel-std", type=positive("m/s^2"), default=d.accel_std_mps2,
                   help=f"max accelerometer std in the window [m/s^2] (default {d.accel_std_mps2})")
    p.add_argument("--gyro-std", type=positive("rad/s"), default=d.gyro_std_radps,
                   help=f"max gyro std in the window [rad/s] (default {d.gyro_std_radps})")
    p.add_argument("--min-duration-s", type=non_negative("s"), default=d.min_duration_s,
                   help=f"shortest still period [s] (default {d.min_duration_s})")
    p.add_argument("--until-s", type=positive("s"), default=None,
                   help="use only the first UNTIL_S seconds of the log [s] (default: all)")
    add_no_progress(p)
    p.set_defaults(func=run)


def run(args) -> int:
    from .. import io as gio
    from ..calibration import calibration_to_toml
    from ..io.outputs import check_output, write_output
    from ..progress import steps

    out = check_output(args.out, [args.log], "--out", stdout=True)
    with steps("calibrate", ["read the log", "find still periods and fit", "write"], show_progress(args)) as bar:
        bar.step("read the log")
        log = gio.read_log(args.log)
        if log.array.readings == "linear_acceleration":
            raise CLIError(f"{args.log}: its array.toml says readings = \"linear_acceleration\" (gravity removed by "
                           "the phone): a calibration fits the accelerometers against gravity, which these readings "
                           "no longer hold; calibrate from the specific force (convert the export with its gravity)")
        bar.step("find still periods and fit")
        cal = _fit(args, log)
        bar.step("write")
        write_output(out, [calibration_to_toml(cal)])
    i = cal.info
    report = sys.stdout if out is not None else sys.stderr  # standard output may hold the calibration itself
    info(args, f"{i['still_periods']} still periods ({i['still_samples']} samples); fit residual "
               f"{i['residual_rms_mps2']:.4f} m/s^2 RMS", file=report)
    info(args, f"inter-sensor spread of the still means: {i['spread_before_mps2']:.4f} -> "
               f"{i['spread_after_mps2']:.4f} m/s^2 (norm); {i['spread_per_axis_before_mps2']:.4f} -> "
               f"{i['spread_per_axis_after_mps2']:.4f} m/s^2 (per axis)", file=report)
    if cal.gyro_bias_b_radps is not None:
        info(args, "gyro bias (B): " + ", ".join(f"{v:+.4f}" for v in cal.gyro_bias_b_radps) + " rad/s", file=report)
    info(args, f"calibration written: {out if out is not None else 'standard output'}", file=report)
    return 0


def _fit(args, log):
    from ..calibration import StillDetector, find_still_periods, fit

    if args.until_s is not None:
        n = int((log.times_s <= args.until_s).sum())
        if n < 2:
            raise CLIError(f"--until-s {args.until_s:g}: keeps {n} sample(s) of {args.log}; at least 2 are needed")
        log = log.select(slice(0, n))
    det = StillDetector(window_s=args.window_s, accel_std_mps2=args.accel_std, gyro_std_radps=args.gyro_std,
                        min_duration_s=args.min_duration_s)
    periods = find_still_periods(log, det)
    if not periods:
        import numpy as np

        from ..readings import refuse_unreplaceable

        all_bad = log.replace(accel_mps2=np.where(np.isfinite(log.accel_mps2).any(axis=0), 0.0, np.nan)
                              * np.ones_like(log.accel_mps2))
        refuse_unreplaceable(all_bad)  # a column with no finite reading: named, not "no still period"
        raise CLIError(f"{args.log}: no still period found: the recording needs the array held still for at least "
                       f"{det.min_duration_s:g} s (plus {2 * det.trim_s:g} s trimmed) in each of several "
                       "orientations (at least 4, not all in one plane); with such periods, loosen the detector: "
                       f"--accel-std (now {det.accel_std_mps2:g} m/s^2), --gyro-std (now {det.gyro_std_radps:g} "
                       f"rad/s), --window-s (now {det.window_s:g} s), --min-duration-s (now {det.min_duration_s:g} s)")
    return fit(log, det, periods=periods)
