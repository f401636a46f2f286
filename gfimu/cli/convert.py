"""``gfimu convert FORMAT INPUT --out LOG``: raw recordings to a standard log directory."""

from __future__ import annotations

import argparse

from . import CLIError

FORMATS = ("mimu4444",)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "convert",
        help="convert a raw recording into a log directory",
        description="Convert a raw recording into a log directory (array.toml, imu.csv, reference.csv). "
        "mimu4444: the 8 accelerometers of the MIMU4444 board in the board frame; the mean of its 8 gyros "
        "is the angular-velocity reference (marked invalid where a gyro saturates).",
    )
    p.add_argument("format", choices=FORMATS, help="input format")
    p.add_argument("input", help="raw recording (mimu4444: data.bin or the folder holding it)")
    p.add_argument("--out", required=True, help="log directory to write")
    p.add_argument("--with-gyro", action="store_true", help="also write the mean gyro as the log's gyroscope channels (w_x..)")
    p.add_argument("--calibration", default=None, help="calibration.toml to apply to the readings before writing")
    p.add_argument("--reference-shift-ms", type=float, default=0.0,
                   help="re-sample the gyro reference at t + SHIFT (cubic spline) to align it with the accelerometers; "
                        "-1.5 is the shift measured on the MIMU4444 recordings (default 0: as recorded)")
    p.set_defaults(func=run)


def run(args) -> int:
    from .. import logio
    from ..datasets.mimu4444 import read_mimu4444, shift_reference

    if args.format != "mimu4444":  # pragma: no cover - argparse restricts the choices
        raise CLIError(f"unknown format {args.format!r}")
    log, report = read_mimu4444(args.input, with_gyro=args.with_gyro)
    print(f"{args.input}:")
    print(report.summary())
    if args.calibration:
        from ..calibration import apply_calibration, read_calibration

        log = apply_calibration(log, read_calibration(args.calibration))
        print(f"calibration applied: {args.calibration}")
    if args.reference_shift_ms:
        log = shift_reference(log, args.reference_shift_ms)
        print(f"reference re-sampled at t {args.reference_shift_ms:+g} ms; invalid on {int(log.invalid_reference.sum())} sample(s)")
    logio.write_log(log, args.out)
    print(f"log written: {args.out} ({len(log)} samples, {log.rate_hz:.2f} Hz)")
    return 0
