"""``gfimu convert FORMAT INPUT --out LOG``: a recording to a standard log directory.

The formats are those of :mod:`gfimu.io.readers`, each with its own options.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from . import CLIError, add_no_progress, info, show_progress


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
        fp.add_argument("--extrinsics", default=None, metavar="KALIBR.yaml",
                        help="Kalibr IMU-chain YAML (imu0, imu1, ... each with T_i_b, a 4x4 body-to-IMU transform, "
                             "as rows or an OpenCV !!opencv-matrix; OpenVINS's %%YAML:1.0 files too): replaces every "
                             "accelerometer's position [m] and rotation (default: none, the recording's own "
                             "geometry)")
        add_no_progress(fp)
        before = {a.dest for a in fp._actions}
        reader.add_arguments(fp)
        fp.set_defaults(func=run, reader_options=[a.dest for a in fp._actions if a.dest not in before])


def run(args) -> int:
    from .. import io as gio
    from ..io.outputs import prepare_log_folder
    from ..io.readers import read_recording
    from ..io.time_grid import nominal_rate_hz

    options = {dest: getattr(args, dest) for dest in args.reader_options}
    if not Path(args.input).exists():
        raise CLIError(f"{args.input}: no such file or folder")
    option_files = [v for v in options.values() if isinstance(v, str) and Path(v).is_file()]
    prepare_log_folder(args.out, [args.input, args.calibration, args.extrinsics, *option_files], force=args.force)
    from ..progress import steps

    names = (["read the recording"] + (["apply the extrinsics"] if args.extrinsics else [])
             + (["apply the calibration"] if args.calibration else []) + ["write the log"])
    with steps(f"convert {args.format}", names, show_progress(args)) as bar:
        bar.step("read the recording")
        conversion = read_recording(args.format, args.input, **options)
        log = conversion.log
        report = list(conversion.report)
        extrinsics_report: list[str] = []
        if args.extrinsics:
            from ..io.kalibr import apply_kalibr, read_kalibr

            bar.step("apply the extrinsics")
            array, extrinsics_report = apply_kalibr(log.array, read_kalibr(args.extrinsics), args.extrinsics)
            log = log.replace(array=array)
            report, replaced = _without_geometry_lines(report, options.get("array"))
            # --array (or the map's own places) and --extrinsics: the extrinsics win for position and rotation
            extrinsics_report = [f"positions and rotations from {args.extrinsics} replace those of {source}"
                                 for source in replaced] + extrinsics_report
        elif conversion.unplaced:
            raise CLIError(f"{args.input}: accelerometer(s) {', '.join(conversion.unplaced)} have no position or "
                           "rotation; give them in the map (position_m, rotation_body_sensor), with --array, or "
                           "with --extrinsics")
        if args.calibration:
            from ..calibration import apply_calibration_file

            bar.step("apply the calibration")
            log = apply_calibration_file(log, args.calibration)
        if len(log) < 2:  # one sample tells no rate, and no estimator reads it
            from ..errors import DataError

            raise DataError(f"{args.input}: {len(log)} sample(s) read; a log needs at least 2 (its rate is measured "
                            "from their timestamps)")
        bar.step("write the log")
        # the rate measured: 1e9 / the median step of the log's timestamps [Hz] (io/time_grid.py)
        gio.write_log(log, args.out, rate_hz=nominal_rate_hz(log.timestamps_ns), what="--out")
    for line in [*report, *extrinsics_report]:
        info(args, line, file=sys.stdout)
    if args.calibration:
        info(args, f"calibration applied: {args.calibration}", file=sys.stdout)
    info(args, f"log written: {args.out} ({len(log)} samples, {log.rate_hz:.2f} Hz)", file=sys.stdout)
    return 0


def _without_geometry_lines(report: list[str], array: str | None) -> tuple[list[str], list[str]]:
    """The report without its lines naming a file the geometry came from; and those files (``array`` first)."""
    sources = [array] if array else []
    kept = []
    for line in report:
        name = line[len("geometry: "):] if line.startswith("geometry: ") else None
        if name is not None and (name in sources or Path(name).is_file()):
            if name not in sources:
                sources.append(name)
            continue
        kept.append(line)
    return kept, sources
