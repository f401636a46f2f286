"""``gfimu live --array ARRAY.toml --source SRC --out DEST``: estimates from a live stream of readings.

Only the arguments are read here: the source is :func:`gfimu.io.sources.open_source`, the session
:func:`gfimu.live.run`, the sink :class:`gfimu.live.EstimateSink` (see ``docs/live.md``). The summary
goes to standard error however the session ends (but when standard output's reader went away: one line,
exit 1). Exit status: 0 at the end of the stream, 130 after SIGINT, 143 after SIGTERM, 1 when the stream
broke (a connection reset) or the output failed, 2 for a header, an argument or an option that cannot be
used (``-O guard`` other than off, a rate beyond any IMU's) and for an output another session is writing.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import sys
from pathlib import Path

from . import EXIT_FAILURE, EXIT_USAGE, CLIError
from .options import positive


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "live", help="estimate ω live from readings on standard input, UDP, TCP or a serial port (fixed-lag smoother)",
        description="Run the fixed-lag smoother on a live stream and write estimate rows as each sample leaves the "
                    "lag window (same columns as gfimu estimate). Late or repeated samples are dropped and counted; "
                    "time going back by more than 1 s restarts the window (a clock reset); a bad row is reported "
                    "and skipped; if the input outruns the smoother the oldest queued samples are dropped.")
    p.add_argument("--array", required=True, metavar="ARRAY.toml", help="the array (as in a log folder)")
    p.add_argument("--source", required=True, metavar="SRC",
                   help="'-' (imu.csv rows on standard input, header first), udp://HOST:PORT (one data row per "
                        "datagram), tcp://HOST:PORT or serial:///dev/ttyUSB0?baud=N (MIMU4444 packets)")
    p.add_argument("--out", required=True, metavar="DEST", help="estimate CSV to write, or - for standard output")
    p.add_argument("--lag-s", type=positive("s"), default=None,
                   help="lag of the smoother [s] (default: -O lag_s, else 0.2)")
    p.add_argument("--rate-hz", type=positive("Hz"), default=None,
                   help="nominal sample rate [Hz] (default: rate_hz of array.toml, else the median period of the "
                        "first 64 samples received)")
    p.add_argument("--option", "-O", action="append", default=[], metavar="KEY=VALUE",
                   help="fixed-lag option (gfimu estimate --method fixed-lag --list-options)")
    p.add_argument("--queue", type=int, default=None, metavar="N",
                   help="samples held while the smoother is busy before the oldest are dropped (default: 10 s "
                        "of samples at the stream's rate, at least 5000: gfimu.live.QUEUE_S, QUEUE_MIN)")
    p.add_argument("--status-s", type=positive("s"), default=5.0, help="status line every this many s (default 5)")
    p.add_argument("--quiet", "-q", action="store_true", default=argparse.SUPPRESS,
                   help="no status lines; the summary at the end stays (default: off)")
    p.set_defaults(func=run)


def run(args) -> int:
    """Options -> array -> output checked -> (locked) source opened -> the session (gfimu.live) -> its summary."""
    from .. import io as gio
    from ..io.array_toml import check_noise_weights
    from ..io.atomic import output_lock, resource_error
    from ..io.outputs import check_output
    from ..io.plausibility import MAX_RATE_HZ
    from ..io.sources import SourceError, open_source
    from ..live import OUTPUT_CLOSED, EstimateSink, run as run_live
    from .options import method_options

    chosen = method_options("fixed-lag", args.option, lag_s=args.lag_s)
    _refuse_unapplied(chosen.options)
    estimator = chosen.estimator()  # the options checked before anything is opened
    array, declared_rate_hz = gio.load_array_toml(args.array)
    check_noise_weights(array, str(args.array))
    rate_hz = args.rate_hz or declared_rate_hz
    if rate_hz is not None and rate_hz > MAX_RATE_HZ:  # it would size the smoother's window at millions of samples
        what = "--rate-hz" if args.rate_hz else f"{args.array}: rate_hz"
        raise CLIError(f"{what} {rate_hz:g}: beyond any IMU's rate ({MAX_RATE_HZ:g} Hz at most)")
    out_path = check_output(args.out, [args.array], "--out", stdout=True)
    reason = estimator.applicable(array)
    if reason:
        raise CLIError(f"{args.array}: {reason}")
    if args.queue is not None and args.queue < 1:
        raise CLIError(f"--queue {args.queue}: must be at least 1")
    with contextlib.ExitStack() as held:
        if out_path is not None:  # one writer at a time: a second session on this file is refused, before any work
            held.enter_context(output_lock(out_path, "--out"))
        try:
            source = open_source(args.source, array)
        except SourceError as exc:
            raise CLIError(str(exc)) from None
        if args.rate_hz and declared_rate_hz and abs(args.rate_hz - declared_rate_hz) > 1e-6 * declared_rate_hz:
            _report(f"--rate-hz {args.rate_hz:g} replaces rate_hz = {declared_rate_hz:g} of {args.array}")
        with contextlib.ExitStack() as output:
            out = sys.stdout if out_path is None else output.enter_context(
                open(Path(out_path), "w", encoding="utf-8", newline=""))
            try:
                result = run_live(source, estimator, EstimateSink(out, sigma=estimator.compute_sigma), rate_hz=rate_hz,
                                  queue_size=args.queue, report=_report,
                                  status_s=None if getattr(args, "quiet", False) else args.status_s)
            except BrokenPipeError:  # standard output closed by its reader before the session began (its header)
                os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # nothing more to flush into it
                _report(f"error: --out {args.out}: the output was closed by its reader (a broken pipe) before the "
                        "first row; nothing was estimated")
                return EXIT_FAILURE
            except OSError as exc:
                if out_path is not None or exc.errno is None:
                    raise
                raise resource_error(exc, "standard output (--out -)") from None  # a full disk, named as the output
        if result.ended == OUTPUT_CLOSED:  # standard output closed by its reader: nothing more to flush into it
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
            _report(f"error: --out {args.out}: {result.failure}")
        elif result.failure:
            _report(f"error: {result.failure}")
        _report(result.summary())
    if result.signal_exit is not None:
        return result.signal_exit
    if result.ended == "input refused":
        return EXIT_USAGE
    return EXIT_FAILURE if result.failure else 0


def _report(message: str) -> None:
    """A line of the session on standard error (none when standard error is gone)."""
    try:
        print(f"gfimu live: {message}", file=sys.stderr, flush=True)
    except (OSError, ValueError):
        pass


UNAPPLIED = {"guard": "off"}
"""Options of the fixed-lag method that ``gfimu live`` cannot apply, with the one value it runs with."""


def _refuse_unapplied(options: dict) -> None:
    """Refuse (exit 2) an option live accepts by name but cannot apply, rather than ignore it."""
    value = options.get("guard")
    if value is not None and str(value) != UNAPPLIED["guard"]:
        raise CLIError(f"-O guard={value}: the guard compares the smoothed answer with the per-sample estimate "
                       "over spans of the whole log, after the fact; gfimu live writes each estimate as it leaves "
                       "the lag window and cannot apply it (give -O guard=off, or run gfimu estimate --method "
                       "fixed-lag on the recorded log)")

