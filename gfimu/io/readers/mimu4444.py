"""The MIMU4444 board's raw ``data.bin``: decoding the packet stream, and the reader of ``gfimu convert mimu4444``.

The packet layer (search, fields, unwrapping, board frame, and the incremental
:class:`~gfimu.io.mimu4444_packets.StreamDecoder` of a live stream) is :mod:`gfimu.io.mimu4444_packets`.

The board (8 corner IMUs, each a triaxial accelerometer and gyroscope,
62.5 Hz) streams 106-byte big-endian packets::

    0       header 0xAA
    1-2     uint16 packet counter (wraps at 65536)
    3       uint8 payload length = 100
    4-7     uint32 timestamp, 64 MHz ticks (wraps about every 67 s)
    8-103   8 IMUs x int16 [ax ay az gx gy gz]
    104-105 uint16 checksum = sum of bytes 0-103 modulo 65536

The decoder works on bytes only (no file access except in
:func:`read_mimu4444`): candidate packets are found by header, length byte and
checksum, all vectorised; overlapping candidates are resolved in favour of
those chained to a neighbour exactly one packet away. Everything else is
counted as skipped bytes.

Gyro saturation: the gyros clip at int16 full scale (2000 deg/s = 34.9
rad/s): on exp_1..3 about 3 % of the samples hold some gyro axis at exactly
+32767 or -32768, while values between 32000 and 32766 occur only a few
times. A sample is marked when any gyro axis has ``|count| >= 32767``; the
reference (mean of the eight gyros) is not valid there. No neighbourhood is
marked by default (``SATURATION_MARGIN = 0``): on exp_1 the RMS disagreement
between the eight gyros on the samples next to a clipped one is 0.46 rad/s,
the same as on unclipped samples with |ω| > 25 rad/s (0.44 rad/s), so the
clipping does not leak into neighbouring samples. Accelerometer clipping
(±16 g) is counted in the report but not masked.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import Conversion, Reader
from ...array import mimu4444_array
from ...errors import InputError
from ...log import Log
from ...motion import Motion
from ..mimu4444_packets import (  # noqa: F401  (the packet layer, also importable from here)
    ACCEL_MPS2_PER_COUNT, COUNTER_DISORDER, COUNTER_MODULUS, DISORDER_MIN_PACKETS, GYRO_RADPS_PER_COUNT, HEADER, N_IMUS, NOMINAL_TICKS_PER_PACKET,
    PACKET_BYTES, PAYLOAD_BYTES, ROTATION_BOARD_UPSIDE_DOWN, SATURATION_COUNT, SATURATION_MARGIN, STREAM_DISORDER_PACKETS,
    TICK_HZ,
    TICK_MODULUS, UPSIDE_DOWN_IMUS, DecodedPackets, StreamDecoder, board_frame, decode_packets, find_packets,
    saturation_mask, ticks_to_ns, unwrap_counter, unwrap_ticks)


class MIMU4444FormatError(InputError):
    """The byte stream holds no decodable MIMU4444 packet."""


@dataclass(frozen=True)
class DecodeReport:
    """What the decoder found and what it left out."""

    n_bytes: int
    n_packets: int
    skipped_bytes: int
    skipped_regions: int
    bad_checksums: int
    duplicates_removed: int
    dropped_packets: int
    counter_gaps: int
    time_gaps: int
    saturated_samples: int
    invalid_reference_samples: int
    accel_clipped_samples: int
    duration_s: float
    gap_indices: tuple[int, ...] = field(default=())

    def summary(self) -> str:
        lines = [
            f"packets: {self.n_packets} decoded from {self.n_bytes} bytes ({self.duration_s:.1f} s)",
            f"skipped: {self.skipped_bytes} bytes in {self.skipped_regions} region(s); "
            f"{self.bad_checksums} candidate packet(s) with a bad checksum; {self.duplicates_removed} duplicate(s) removed",
            f"dropped: {self.dropped_packets} packet(s) in {self.counter_gaps} counter gap(s); {self.time_gaps} time gap(s)",
            f"gyro saturated: {self.saturated_samples} sample(s); reference marked invalid on "
            f"{self.invalid_reference_samples} sample(s) ({100 * self.invalid_reference_samples / max(self.n_packets, 1):.1f} %); "
            "these are left out of evaluation",
            f"accelerometer clipped (16 g): {self.accel_clipped_samples} sample(s)",
        ]
        return "\n".join(lines)


@dataclass(frozen=True)
class Recording:
    """A decoded recording in the board frame."""

    timestamps_ns: np.ndarray  # (N,)
    accel_b_mps2: np.ndarray  # (N, 8, 3)
    gyro_b_radps: np.ndarray  # (N, 8, 3)
    saturated: np.ndarray  # (N,) any gyro clipped
    invalid_reference: np.ndarray  # (N,) saturated +/- margin
    report: DecodeReport


def decode(data: bytes | np.ndarray, gap_factor: float = 1.5) -> Recording:
    """Decode a whole MIMU4444 byte stream (pure: bytes in, arrays out)."""
    b = np.frombuffer(data, dtype=np.uint8) if not isinstance(data, np.ndarray) else data.astype(np.uint8, copy=False)
    starts, n_bad, holes = find_packets(b)
    if starts.size == 0:
        raise MIMU4444FormatError(
            f"no MIMU4444 packet (header 0xAA, length 100, valid checksum) in {b.size} bytes"
        )
    pk = decode_packets(b, starts)
    # drop repeated or out-of-order packets (counter step 0 or >= half the range)
    keep = np.ones(starts.size, dtype=bool)
    cstep = np.diff(pk.counter.astype(np.int64)) % COUNTER_MODULUS
    if np.any((cstep == 0) | (cstep >= COUNTER_MODULUS // 2)):
        last = int(pk.counter[0])
        for i in range(1, starts.size):
            s = (int(pk.counter[i]) - last) % COUNTER_MODULUS
            if s == 0 or s >= COUNTER_MODULUS // 2:
                keep[i] = False
            else:
                last = int(pk.counter[i])
    n_dup = int(np.count_nonzero(~keep))
    pk = DecodedPackets(pk.starts[keep], pk.counter[keep], pk.ticks[keep], pk.raw[keep])
    counter = unwrap_counter(pk.counter)
    dc = np.diff(counter)
    ticks = unwrap_ticks(pk.ticks, dc)
    t_ns = ticks_to_ns(ticks)
    dt = np.diff(t_ns)
    if np.any(dt <= 0):
        k = int(np.argmax(dt <= 0)) + 1
        raise MIMU4444FormatError(f"timestamps not increasing at packet {k} (byte offset {int(pk.starts[k])})")
    nominal = float(np.median(dt)) if dt.size else 0.0
    gap_idx = tuple(int(i) + 1 for i in np.nonzero(dt > gap_factor * nominal)[0]) if dt.size else ()
    acc, gyr = board_frame(pk.raw)
    clipped, invalid = saturation_mask(pk.raw)
    report = DecodeReport(
        n_bytes=int(b.size),
        n_packets=int(starts.size) - n_dup,
        skipped_bytes=int(b.size - PACKET_BYTES * starts.size),
        skipped_regions=holes,
        bad_checksums=n_bad,
        duplicates_removed=n_dup,
        dropped_packets=int(np.sum(dc - 1)) if dc.size else 0,
        counter_gaps=int(np.count_nonzero(dc > 1)),
        time_gaps=len(gap_idx),
        saturated_samples=int(np.count_nonzero(clipped)),
        invalid_reference_samples=int(np.count_nonzero(invalid)),
        accel_clipped_samples=int(np.count_nonzero(np.any(np.abs(pk.raw[:, :, 0:3].astype(np.int32)) >= SATURATION_COUNT, axis=(1, 2)))),
        duration_s=float((t_ns[-1] - t_ns[0]) * 1e-9),
        gap_indices=gap_idx,
    )
    _check_counters(report)
    return Recording(t_ns, acc, gyr, clipped, invalid, report)


def _check_counters(report: DecodeReport) -> None:
    """A warning when the packet counter does not count: more than :data:`COUNTER_DISORDER` of the packets
    repeated, out of order or after a gap (random counters: the times made from them are not to be trusted)."""
    import warnings

    from ..errors import LogPlausibilityWarning

    packets = report.n_packets + report.duplicates_removed
    disorder = report.duplicates_removed + report.counter_gaps
    if packets >= DISORDER_MIN_PACKETS and disorder > COUNTER_DISORDER * packets:
        warnings.warn(f"the packet counter does not count: {report.duplicates_removed} of {packets} packets repeated or "
                      f"out of order and {report.counter_gaps} counter gap(s) ({report.dropped_packets} packets "
                      "missing by the counter); the times made from it are not to be trusted (a damaged or "
                      "another device's recording?)", LogPlausibilityWarning, stacklevel=2)


def to_log(rec: Recording, with_gyro: bool = False, source: str = "<memory>"):
    """A :class:`gfimu.log.Log` of the 8 accelerometers (board frame, nominal positions).

    ``reference`` holds the mean of the eight gyros (board frame) as angular
    velocity; ``invalid_reference`` marks the saturated samples. With
    ``with_gyro`` the same mean is also given as the log's gyroscope channel.
    """

    array = mimu4444_array(with_gyroscope=with_gyro)
    n = rec.timestamps_ns.size
    accel = rec.accel_b_mps2.reshape(n, 3 * N_IMUS)
    omega = rec.gyro_b_radps.mean(axis=1)
    reference = Motion(rec.timestamps_ns, omega_b_radps=omega)
    return Log(
        array,
        rec.timestamps_ns,
        accel,
        gyro_b_radps=omega.copy() if with_gyro else None,
        reference=reference,
        invalid_reference=rec.invalid_reference.copy(),
        source=source,
    )


REFERENCE_SHIFT_MS = -1.5
"""Measured shift between the channels: the accelerometers agree best with the
gyro mean taken 1.5 ms earlier (rigid-body residual minimal at -1.5 ms on
each of exp_1..3, 0.1 ms grid; tools/mimu4444_study.py --residual)."""


def shift_reference(log, shift_ms: float):
    """The log with its reference ω re-sampled at ``t + shift_ms`` (cubic spline per gap-free segment).

    Use ``REFERENCE_SHIFT_MS`` to align the gyro reference with the
    accelerometers. A sample whose shifted time falls in an interval with an
    invalid end is also marked invalid, and so are samples whose shifted time
    leaves their gap-free segment.
    """
    from scipy.interpolate import CubicSpline

    if log.reference is None or log.reference.omega_b_radps is None:
        raise InputError(f"{log.source}: no reference angular velocity to shift")
    if shift_ms == 0:
        return log
    w = log.reference.omega_b_radps
    invalid = np.zeros(len(log), bool) if log.invalid_reference is None else log.invalid_reference.copy()
    t = log.timestamps_ns
    out = np.empty_like(w)
    bad = invalid.copy()
    if shift_ms < 0:  # sample k is read between samples k-1 and k
        bad[1:] |= invalid[:-1]
    else:
        bad[:-1] |= invalid[1:]
    shift_ns = shift_ms * 1e6
    for seg in log.segments():
        ts = (t[seg] - t[seg][0]) * 1e-9
        if ts.size < 4:
            out[seg] = w[seg]
            bad[seg] = True
            continue
        target = ts + shift_ns * 1e-9
        out[seg] = CubicSpline(ts, w[seg])(np.clip(target, ts[0], ts[-1]))
        bad[seg] |= (target < ts[0]) | (target > ts[-1])
    return log.replace(reference=log.reference.replace(omega_b_radps=out), invalid_reference=bad)


def read_mimu4444(path: str | Path, with_gyro: bool = False):
    """Read ``data.bin`` and return ``(log, report)``."""
    path = Path(path)
    if path.is_dir():
        path = path / "data.bin"
    data = path.read_bytes()
    try:
        rec = decode(data)
    except MIMU4444FormatError as exc:
        raise MIMU4444FormatError(f"{path}: {exc}") from None
    return to_log(rec, with_gyro=with_gyro, source=str(path)), rec.report


# --- reader of `gfimu convert mimu4444` ---------------------------------------------

def _add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--with-gyro", action="store_true",
                        help="also write the mean of the 8 gyros as the log's gyroscope channels w_x.. (default: off)")
    parser.add_argument("--reference-shift-ms", type=float, default=0.0,
                        help="re-sample the gyro reference at t + SHIFT [ms] (cubic spline) to align it with the "
                             "accelerometers; -1.5 is the shift measured on the MIMU4444 recordings (default 0: as recorded)")


def read(path, with_gyro: bool = False, reference_shift_ms: float = 0.0) -> Conversion:
    """The board's 8 accelerometers in the board frame; the mean gyro is the reference."""
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
