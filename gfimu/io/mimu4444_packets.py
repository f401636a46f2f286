"""The MIMU4444 board's packet stream: finding, checking and decoding its 106-byte packets.

The packet layout and the decoding of ``data.bin`` are described in :mod:`gfimu.io.readers.mimu4444`
(the reader of ``gfimu convert mimu4444``, which decodes a whole file); this module holds what the
file reader and a live byte stream (:class:`StreamDecoder`, used by :mod:`gfimu.io.sources`) share:
the packet search, the field decoding, the counter and tick unwrapping, and the board frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

PACKET_BYTES = 106
HEADER = 0xAA
PAYLOAD_BYTES = 100
N_IMUS = 8
TICK_HZ = 64_000_000
NOMINAL_TICKS_PER_PACKET = 1_024_000  # 16 ms at 62.5 Hz
COUNTER_MODULUS = 1 << 16
TICK_MODULUS = 1 << 32
GRAVITY_MPS2 = 9.80665
ACCEL_MPS2_PER_COUNT = GRAVITY_MPS2 / 2048.0
GYRO_RADPS_PER_COUNT = np.deg2rad(1.0 / 16.4)
SATURATION_COUNT = 32767  # |count| at or above this is clipped (int16 full scale)
SATURATION_MARGIN = 0  # samples also marked either side of a clipped one (see module docstring)
UPSIDE_DOWN_IMUS = (1, 3, 5, 7)  # 0-based: IMUs 2, 4, 6, 8
ROTATION_BOARD_UPSIDE_DOWN = np.array([[0.0, -1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])


@dataclass(frozen=True)
class DecodedPackets:
    """Decoded raw fields, one row per kept packet."""

    starts: np.ndarray  # byte offset of each packet
    counter: np.ndarray  # uint16 as read
    ticks: np.ndarray  # uint32 as read
    raw: np.ndarray  # (N, 8, 6) int16 counts [ax ay az gx gy gz]


def _be_u16(b: np.ndarray, idx: np.ndarray) -> np.ndarray:
    return (b[idx].astype(np.int64) << 8) | b[idx + 1].astype(np.int64)


def find_packets(data: bytes | np.ndarray) -> tuple[np.ndarray, int, int]:
    """Start offsets of valid packets in ``data``.

    Returns ``(starts, bad_checksums, skipped_regions)``: sorted
    non-overlapping offsets of candidates with header, length byte and
    checksum all right; the number of header+length candidates outside the
    kept packets whose checksum failed; the number of byte runs left out.
    """
    b = np.frombuffer(data, dtype=np.uint8) if not isinstance(data, np.ndarray) else data.astype(np.uint8, copy=False)
    n = b.size
    if n < PACKET_BYTES:
        return np.zeros(0, dtype=np.int64), 0, int(n > 0)
    last = n - PACKET_BYTES
    cand = np.nonzero(b[: last + 1] == HEADER)[0]
    cand = cand[b[cand + 3] == PAYLOAD_BYTES]
    csum = np.concatenate([[0], np.cumsum(b, dtype=np.int64)])
    body_sum = (csum[cand + PACKET_BYTES - 2] - csum[cand]) % COUNTER_MODULUS
    ok = body_sum == _be_u16(b, cand + PACKET_BYTES - 2)
    good = cand[ok]
    # resolve overlaps: chained candidates (another one exactly one packet
    # before or after) first, then isolated ones that do not overlap them
    chained = np.isin(good + PACKET_BYTES, good) | np.isin(good - PACKET_BYTES, good)
    kept = _greedy_non_overlapping(good[chained])
    for s in good[~chained]:
        k = np.searchsorted(kept, s)
        if (k == 0 or kept[k - 1] + PACKET_BYTES <= s) and (k == kept.size or s + PACKET_BYTES <= kept[k]):
            kept = np.insert(kept, k, s)
    # candidates with a bad checksum that are not inside a kept packet
    bad = cand[~ok]
    k = np.searchsorted(kept, bad, side="right") - 1
    inside = (k >= 0) & (bad < kept[np.maximum(k, 0)] + PACKET_BYTES) if kept.size else np.zeros(bad.size, bool)
    n_bad = int(np.count_nonzero(~inside))
    # runs of bytes not covered by kept packets
    if kept.size:
        holes = int(kept[0] > 0) + int(np.count_nonzero(np.diff(kept) > PACKET_BYTES)) + int(kept[-1] + PACKET_BYTES < n)
    else:
        holes = int(n > 0)
    return kept.astype(np.int64), n_bad, holes


def _greedy_non_overlapping(starts: np.ndarray) -> np.ndarray:
    """Earliest-first selection of non-overlapping packets (fast path when none overlap)."""
    if starts.size < 2 or np.all(np.diff(starts) >= PACKET_BYTES):
        return starts.copy()
    out = [int(starts[0])]
    for s in starts[1:]:
        if s >= out[-1] + PACKET_BYTES:
            out.append(int(s))
    return np.asarray(out, dtype=np.int64)


def decode_packets(data: bytes | np.ndarray, starts: np.ndarray) -> DecodedPackets:
    """Counter, timestamp ticks and the (N, 8, 6) int16 counts at ``starts``."""
    b = np.frombuffer(data, dtype=np.uint8) if not isinstance(data, np.ndarray) else data.astype(np.uint8, copy=False)
    starts = np.asarray(starts, dtype=np.int64)
    rows = b[starts[:, None] + np.arange(PACKET_BYTES)]
    counter = rows[:, 1:3].copy().view(">u2").reshape(-1).astype(np.uint16)
    ticks = rows[:, 4:8].copy().view(">u4").reshape(-1).astype(np.uint32)
    raw = rows[:, 8:104].copy().view(">i2").reshape(-1, N_IMUS, 6).astype(np.int16)
    return DecodedPackets(starts, counter, ticks, raw)


def unwrap_counter(counter: np.ndarray) -> np.ndarray:
    """Unwrapped int64 packet counter (16-bit wrap), starting at its first value."""
    c = np.asarray(counter, dtype=np.int64)
    if c.size == 0:
        return c
    step = np.diff(c) % COUNTER_MODULUS
    return np.concatenate([[c[0]], c[0] + np.cumsum(step)])


def unwrap_ticks(ticks: np.ndarray, counter_steps: np.ndarray | None = None) -> np.ndarray:
    """Unwrapped int64 64 MHz ticks (32-bit wrap).

    Each step is taken modulo 2**32; when ``counter_steps`` (unwrapped
    counter differences) is given, whole wraps are added so that a step is
    closest to ``counter_step x 1,024,000`` ticks — this keeps time right
    across a gap of dropped packets longer than one wrap (67 s).
    """
    t = np.asarray(ticks, dtype=np.int64)
    if t.size == 0:
        return t
    step = np.diff(t) % TICK_MODULUS
    if counter_steps is not None:
        expected = np.asarray(counter_steps, dtype=np.int64) * NOMINAL_TICKS_PER_PACKET
        step = step + np.round((expected - step) / TICK_MODULUS).astype(np.int64) * TICK_MODULUS
    return np.concatenate([[t[0]], t[0] + np.cumsum(step)])


def ticks_to_ns(ticks: np.ndarray) -> np.ndarray:
    """64 MHz ticks to integer nanoseconds (exact: 1 tick = 15.625 ns, rounded down)."""
    return (np.asarray(ticks, dtype=np.int64) * 125) // 8


def saturation_mask(raw: np.ndarray, threshold: int = SATURATION_COUNT, margin: int = SATURATION_MARGIN) -> tuple[np.ndarray, np.ndarray]:
    """(clipped, invalid): rows where any gyro count reaches ``threshold``, and those dilated by ``margin``."""
    clipped = np.any(np.abs(raw[:, :, 3:6].astype(np.int32)) >= threshold, axis=(1, 2))
    invalid = clipped.copy()
    for k in range(1, margin + 1):
        invalid[k:] |= clipped[:-k]
        invalid[:-k] |= clipped[k:]
    return clipped, invalid


def board_frame(raw: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Counts (N, 8, 6) to board-frame accelerations (N, 8, 3) m/s² and rates (N, 8, 3) rad/s."""
    acc = raw[:, :, 0:3].astype(float) * ACCEL_MPS2_PER_COUNT
    gyr = raw[:, :, 3:6].astype(float) * GYRO_RADPS_PER_COUNT
    rot = np.tile(np.eye(3), (N_IMUS, 1, 1))
    rot[list(UPSIDE_DOWN_IMUS)] = ROTATION_BOARD_UPSIDE_DOWN
    acc = np.einsum("kij,nkj->nki", rot, acc)
    gyr = np.einsum("kij,nkj->nki", rot, gyr)
    return acc, gyr


COUNTER_DISORDER = 0.1
"""Share of packets out of order or after a counter gap beyond which the counters are said not to count."""

DISORDER_MIN_PACKETS = 10
"""Fewest packets of a file on which its counter is judged."""

STREAM_DISORDER_PACKETS = 100
"""Fewest packets of a stream on which its counter is judged (about 1.6 s at 62.5 Hz): a few lost
packets at the start of a link are not yet a counter that does not count."""


class StreamDecoder:
    """Incremental decoding of a MIMU4444 byte stream (serial port, TCP): bytes in, board-frame
    samples out, with the packet search, counter and tick unwrapping of :func:`decode` (a packet
    split between two chunks is kept for the next; a repeated or out-of-order packet is dropped
    and counted in ``duplicates``). ``feed(chunk)`` returns ``[(timestamp_ns, accel_row (24,))]``,
    accelerometer axes ordered as the 8-IMU array's columns (m/s², board frame)."""

    def __init__(self) -> None:
        self._buffer = b""
        self._counter: int | None = None  # last unwrapped counter
        self._raw_counter = 0
        self._ticks: int | None = None  # last unwrapped ticks
        self._raw_ticks = 0
        self.duplicates = 0
        self.skipped_bytes = 0
        self.packets = 0
        """Packets decoded, repeated and out-of-order ones included."""
        self.counter_gaps = 0
        """Steps of the counter by more than one (packets lost, or a counter that does not count)."""
        self._disorder_said = False

    def disorder(self) -> str | None:
        """Once, when the counter is seen not to count (the rule of the file reader: more than
        :data:`COUNTER_DISORDER` of the packets repeated, out of order or after a gap, judged from
        :data:`STREAM_DISORDER_PACKETS` packets on): the warning's words; None otherwise and after it was said."""
        if self._disorder_said or self.packets < STREAM_DISORDER_PACKETS:
            return None
        disorder = self.duplicates + self.counter_gaps
        if disorder <= COUNTER_DISORDER * self.packets:
            return None
        self._disorder_said = True
        return (f"the packet counter does not count: {self.duplicates} of the first {self.packets} packets repeated "
                f"or out of order and {self.counter_gaps} counter gap(s); the times made from it are not to be "
                "trusted (a damaged link or another device?)")

    def feed(self, chunk: bytes) -> list[tuple[int, np.ndarray]]:
        data = self._buffer + bytes(chunk)
        starts, _, _ = find_packets(data)
        out = []
        consumed = 0
        if starts.size:
            pk = decode_packets(data, starts)
            acc, _ = board_frame(pk.raw)
            for i in range(starts.size):
                c, t = int(pk.counter[i]), int(pk.ticks[i])
                self.packets += 1
                if self._counter is None:
                    self._counter, self._ticks = c, t
                else:
                    step = (c - self._raw_counter) % COUNTER_MODULUS
                    if step == 0 or step >= COUNTER_MODULUS // 2:
                        self.duplicates += 1
                        continue
                    self.counter_gaps += step > 1
                    dt = (t - self._raw_ticks) % TICK_MODULUS
                    dt += int(round((step * NOMINAL_TICKS_PER_PACKET - dt) / TICK_MODULUS)) * TICK_MODULUS
                    self._counter += step
                    self._ticks += dt
                self._raw_counter, self._raw_ticks = c, t
                out.append((int(ticks_to_ns(np.array([self._ticks]))[0]), acc[i].reshape(-1)))
            consumed = int(starts[-1]) + PACKET_BYTES
            self.skipped_bytes += int(starts[0])
        else:
            consumed = max(len(data) - (PACKET_BYTES - 1), 0)  # keep what could start a packet
            self.skipped_bytes += consumed
        self._buffer = data[consumed:]
        return out
