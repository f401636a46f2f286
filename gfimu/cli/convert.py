"""``gfimu convert FORMAT INPUT --out LOG``: a recording to a standard log directory.

The formats are those of :mod:`gfimu.io.readers`, each with its own options.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from . import CLIError


def register(sub: argparse._SubParsersAction) -> None:
    from ..io.readers import get_reader, reader_names

    p = sub.add_parser(
        "convert",
        help="convert a recording into a log directory",
        description="Convert a recording into a log directory (array.toml, imu.csv, and reference.csv where the "
        "recording has a reference). Formats: " + ", ".join(reader_names()) + "; `gfimu convert FORMAT --help` "
        "lists a format's options.",
    )
    formats = p.add_subparsers(dest="format", metavar="FORMAT", required=True)
    for name in reader_names():
        reader = get_reader(name)
        fp = formats.add_parser(name, help=reader.summary, description=reader.summary)
        fp.add_argument("input", help=reader.input_help)
        fp.add_argument("--out", required=True,
                        help="log folder to write (created when missing; an existing non-empty folder needs --force)")
        fp.add_argument("--force", action="store_true",
                        help="write into a non-empty --out folder: its array.toml, imu.csv, truth.csv and "
                             "reference.csv are replaced or removed, other files are kept")
        fp.add_argument("--calibration", default=None, help="calibration.toml to apply to the readings before writing")
        before = {a.dest for a in fp._actions}
        reader.add_arguments(fp)
        fp.set_defaults(func=run, reader_options=[a.dest for a in fp._actions if a.dest not in before],
                        reader_inputs=list(reader.input_options))


def run(args) -> int:
    from .. import io as gio
    from ..io.outputs import prepare_log_folder
    from ..io.readers import read_recording

    options = {dest: getattr(args, dest) for dest in args.reader_options}
    if not Path(args.input).exists():
        raise CLIError(f"{args.input}: no such file or folder")
    prepare_log_folder(args.out, [args.input, args.calibration] + [getattr(args, d) for d in args.reader_inputs],
                       force=args.force)
    conversion = read_recording(args.format, args.input, **options)
    log = conversion.log
    for line in conversion.report:
        print(line)
    if args.calibration:
        from ..calibration import apply_calibration, read_calibration

        log = apply_calibration(log, read_calibration(args.calibration))
        print(f"calibration applied: {args.calibration}")
    gio.write_log(log, args.out)
    print(f"log written: {args.out} ({len(log)} samples, {log.rate_hz:.2f} Hz)")
    return 0
