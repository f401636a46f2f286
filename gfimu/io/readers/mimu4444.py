"""The MIMU4444 board's raw ``data.bin`` (decoding in :mod:`gfimu.datasets.mimu4444`)."""

from __future__ import annotations

import argparse

from . import Conversion, Reader


def _add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--with-gyro", action="store_true",
                        help="also write the mean of the 8 gyros as the log's gyroscope channels w_x.. (default: off)")
    parser.add_argument("--reference-shift-ms", type=float, default=0.0,
                        help="re-sample the gyro reference at t + SHIFT [ms] (cubic spline) to align it with the "
                             "accelerometers; -1.5 is the shift measured on the MIMU4444 recordings (default 0: as recorded)")


def read(path, with_gyro: bool = False, reference_shift_ms: float = 0.0) -> Conversion:
    """The board's 8 accelerometers in the board frame; the mean gyro is the reference."""
    from ...datasets.mimu4444 import read_mimu4444, shift_reference

    log, report = read_mimu4444(path, with_gyro=with_gyro)
    lines = [f"{path}:", report.summary()]
    if reference_shift_ms:
        log = shift_reference(log, reference_shift_ms)
        lines.append(f"reference re-sampled at t {reference_shift_ms:+g} ms; "
                     f"invalid on {int(log.invalid_reference.sum())} sample(s)")
    return Conversion(log, tuple(lines))


READER = Reader(
    name="mimu4444",
    summary="MIMU4444 board data.bin: 8 accelerometers in the board frame, the mean of its 8 gyros as the "
            "angular-velocity reference (invalid where a gyro saturates)",
    read=read,
    add_arguments=_add_arguments,
    input_help="data.bin or the folder holding it",
)
