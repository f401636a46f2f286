"""``gfimu evaluate ESTIMATE.csv TRUTH.csv|LOG [--format markdown|csv|json] [--out FILE]``.

The second argument is a truth or reference CSV, or a log folder: its
``truth.csv`` is used, else its ``reference.csv``. Rows whose reference has
``valid`` = 0 are left out (see :mod:`gfimu.io.tables`).
"""

from __future__ import annotations

import argparse
import warnings
from pathlib import Path

from . import CLIError
from .options import non_negative


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "evaluate",
        help="errors of an estimate against truth or a reference (RMSE, relative RMS, sign errors)",
        description="Compare an estimate CSV with a truth or reference CSV (or a log folder's truth.csv, else "
                    "reference.csv): RMSE per axis and of the norm, median error norm, relative RMS error "
                    "(paper 004 eq. 7) for every quantity both files have; for ω also the share of wrong signs "
                    "and of errors over 5 rad/s. Rows marked invalid in the reference (valid = 0) are left out.",
    )
    p.add_argument("estimate", help="estimate CSV (as written by gfimu estimate)")
    p.add_argument("truth", help="truth or reference CSV, or a log folder")
    p.add_argument("--format", choices=["markdown", "csv", "json"], default="markdown", help="output format")
    p.add_argument("--out", default=None,
                   help="write the table to this file (atomically; never over an input) instead of standard output (-)")
    p.add_argument("--against", choices=["auto", "truth", "reference"], default="auto",
                   help="with a log folder: compare with truth.csv or reference.csv (default: truth if present)")
    p.add_argument("--interpolate", action="store_true",
                   help="if the timestamps differ, interpolate the truth at the estimate's timestamps")
    p.add_argument("--sign-threshold", type=non_negative("rad/s"), default=0.1, metavar="RADPS",
                   help="count wrong signs only for ω components above this magnitude (default 0.1 rad/s)")
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


def run(args) -> int:
    from .. import io as gio
    from ..evaluation import EvaluationAlignmentWarning, evaluate
    from ..io.outputs import check_output, write_output

    out = check_output(args.out, [args.estimate, args.truth], "--out", stdout=True)
    truth_path = _truth_path(args.truth, args.against)
    estimate = gio.read_motion_csv(args.estimate, allow_nan=True)
    truth, valid = gio.read_motion_table(truth_path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", EvaluationAlignmentWarning)
        result = evaluate(estimate, truth, valid=valid, sign_threshold_radps=args.sign_threshold,
                          align="interpolate" if args.interpolate else "exact")
    if args.format == "markdown":
        text = result.to_markdown(title=f"{args.estimate} vs {truth_path}")
    elif args.format == "csv":
        text = result.to_csv()
    else:
        text = result.to_json()
    write_output(out, [text])
    if out is not None:
        print(f"evaluation of {args.estimate} -> {args.out} ({result.summary()})")
    return 0
