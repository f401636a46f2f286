"""``gfimu batch LOG... --method M --out DIR [--scheduler ADDRESS]``: many logs on Dask distributed."""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from . import CLIError, add_no_progress, info, show_progress
from ..errors import MissingExtraError
from .options import integer


def register(sub: argparse._SubParsersAction) -> None:
    from ..methods import METHODS

    p = sub.add_parser(
        "batch", help="run one method on many logs, in parallel on Dask (this machine or a cluster)",
        description="Estimate every LOG with one method on Dask distributed and write DIR/<log folder name>/"
                    "estimate.csv (as gfimu estimate would; logs of the same folder name take the parts of their "
                    "paths that tell them apart, a__log and b__log) and DIR/summary.csv (log, status, samples, seconds, "
                    "ω RMSE where the log has a truth or reference, warnings, error message). A log that fails, or a LOG "
                    "that is not a log folder, is reported in the summary and the exit status is 1; the others go "
                    "on. Needs the distributed "
                    "extra (pip install 'gfimu[distributed]').")
    p.add_argument("logs", nargs="+", metavar="LOG", help="log folders (array.toml + imu.csv)")
    p.add_argument("--method", default="smoother", choices=list(METHODS), help="estimation method (default: smoother)")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (created; estimates are never written "
                                                                "over an input)")
    p.add_argument("--option", "-O", action="append", default=[], metavar="KEY=VALUE",
                   help="method option, repeatable (gfimu estimate --method M --list-options lists them)")
    p.add_argument("--preset", default=None, metavar="NAME", help="named smoother settings (method smoother)")
    p.add_argument("--calibration", default=None, metavar="FILE", help="calibration.toml applied to every log")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="Dask scheduler to use, e.g. tcp://10.0.0.5:8786 (default: a local cluster on this machine)")
    p.add_argument("--workers", type=integer(1, 256), default=2, metavar="N",
                   help="worker processes of the local cluster (default 2; ignored with --scheduler)")
    add_no_progress(p)
    p.set_defaults(func=run)


def run(args) -> int:
    try:
        import dask.distributed  # noqa: F401
    except ImportError:
        raise MissingExtraError("gfimu batch", "dask.distributed", "distributed") from None
    from ..batch import output_folders
    from ..io.atomic import output_lock
    from ..io.outputs import check_output, check_output_within
    from .options import method_options

    chosen = method_options(args.method, args.option, preset=getattr(args, "preset", None),
                            solver=getattr(args, "solver", None))
    chosen.estimator()  # the values checked here, before any log; each worker makes its own
    options = chosen.options
    out_dir = Path(args.out)
    if out_dir.exists() and not out_dir.is_dir():
        raise CLIError(f"--out {out_dir}: exists and is not a folder")
    inputs = list(args.logs) + ([args.calibration] if args.calibration else [])
    out_real = Path(os.path.realpath(out_dir))
    for log in args.logs:
        log_real = Path(os.path.realpath(log))
        if log_real.is_dir() and (out_real == log_real or log_real in out_real.parents):
            raise CLIError(f"--out {out_dir}: is {'the' if out_real == log_real else 'inside the'} input log folder "
                           f"{log}; the estimates and summary go to a folder of their own (give another folder)")
    folders = output_folders(args.logs, out_dir)  # unique names, or refused before any work
    for folder in folders:  # each estimate is checked again where it is written
        check_output_within(out_dir, Path(folder.name) / "estimate.csv", inputs, "--out")
    check_output_within(out_dir, "summary.csv", inputs, "--out")
    out_dir.mkdir(parents=True, exist_ok=True)
    summary = check_output(out_dir / "summary.csv", inputs, "--out")
    with output_lock(summary, "--out"):  # one batch at a time writes into this folder
        return _run(args, out_dir, summary, options)


def _run(args, out_dir: Path, summary: Path, options: dict) -> int:
    from ..batch import run_batch
    from ..io.outputs import write_output

    bar = _Bar(len(args.logs), enable=show_progress(args))
    failed = []

    def done(row):
        bar.update(1)
        if row["status"] != "ok":
            failed.append(row)

    try:
        result = run_batch(args.logs, out_dir, args.method, options, args.calibration, args.scheduler, args.workers,
                           on_done=done)
    except OSError as exc:
        text = str(exc)
        if not text.startswith("--scheduler "):
            text = f"Dask scheduler {args.scheduler or '(local cluster)'}: {text}"
        raise CLIError(text) from None
    finally:
        bar.close()
    write_output(summary, [result.summary_csv()])
    for row in result.failed:
        print(f"gfimu batch: {row['log']}: failed: {row['message']}", file=sys.stderr)
    ok = len(result.rows) - len(result.failed)
    info(args, f"batch: {ok} of {len(result.rows)} logs estimated with {args.method} on {result.scheduler} "
               f"-> {out_dir}", file=sys.stdout)
    return 1 if result.failed else 0


class _Bar:
    """A tqdm bar across the logs (nothing when disabled)."""

    def __init__(self, total: int, enable: bool):
        self._bar = None
        if enable:
            from tqdm import tqdm

            self._bar = tqdm(total=total, desc="batch", unit="log", leave=False)

    def update(self, n: int) -> None:
        if self._bar is not None:
            self._bar.update(n)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()
