"""Trajectories in the TUM format, as read by evo (``evo_traj tum FILE``) and the TUM RGB-D tools.

One line per sample, fields separated by one space, no trailing space::

    # timestamp tx ty tz qx qy qz qw
    1.500000000 0 0 0 0.0871557427476582 0 0 0.9961946980917455

- ``timestamp``: seconds, written exactly from the integer nanoseconds of the
  estimate (nine decimals, no rounding);
- ``tx ty tz``: position of the body origin in the world frame W [m]; gfimu does
  not estimate position, so these are ``0`` unless positions are given;
- ``qx qy qz qw``: the unit quaternion of the body→world rotation R_WB (it turns a
  vector in B into W), vector part first and scalar last, the order of TUM and
  evo and of scipy's ``Rotation.from_quat``. It is the estimate's ``q_w, q_x,
  q_y, q_z`` (``quaternion_wb``) reordered, with the same sign.

Rows whose quaternion is not finite (an attitude that could not be computed) are
left out: evo reads every row as a pose.
"""

from __future__ import annotations

import os
from collections.abc import Iterator

import numpy as np

from ..errors import DataError, InputError
from ..motion import Motion
from .atomic import atomic_write

TUM_HEADER = "# timestamp tx ty tz qx qy qz qw"

_ROWS_PER_BLOCK = 16384


def seconds_text(timestamps_ns: np.ndarray) -> list[str]:
    """Integer nanoseconds as exact decimal seconds with nine decimals (``-0.000000001`` for -1 ns)."""
    out = []
    for ns in np.asarray(timestamps_ns, dtype=np.int64).tolist():
        sign = "-" if ns < 0 else ""
        whole, frac = divmod(abs(ns), 1_000_000_000)
        out.append(f"{sign}{whole}.{frac:09d}")
    return out


def tum_rows(motion: Motion, position_w_m: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(kept row mask, table (N, 7) of tx ty tz qx qy qz qw) of a Motion with attitude.

    An :class:`~gfimu.errors.InputError` when the motion has no attitude (``quaternion_wb``).
    """
    q = motion.quaternion_wb
    if q is None:
        raise InputError("the estimate has no orientation (quaternion q_w..q_z) to write as a TUM trajectory")
    n = len(motion)
    if position_w_m is None:
        position = np.zeros((n, 3))
    else:
        position = np.asarray(position_w_m, dtype=float)
        if position.shape != (n, 3):
            raise ValueError(f"position_w_m has shape {position.shape}, expected {(n, 3)}")
    keep = np.all(np.isfinite(q), axis=1) & np.all(np.isfinite(position), axis=1)
    table = np.column_stack([position, q[:, 1:4], q[:, 0]])
    return keep, table


def tum_chunks(motion: Motion, position_w_m: np.ndarray | None = None) -> Iterator[str]:
    """Text chunks of a TUM trajectory file (see the module); checks run before the first chunk."""
    keep, table = tum_rows(motion, position_w_m)
    stamps = motion.timestamps_ns[keep]
    table = table[keep]
    if not stamps.size:
        raise DataError("the estimate's orientation is not finite at any sample; no TUM trajectory to write")

    def fmt(v: float) -> str:
        return "0" if v == 0 else repr(v)

    def chunks() -> Iterator[str]:
        yield TUM_HEADER + "\n"
        for start in range(0, stamps.size, _ROWS_PER_BLOCK):
            stop = start + _ROWS_PER_BLOCK
            times = seconds_text(stamps[start:stop])
            yield "".join(f"{t} {' '.join(map(fmt, row))}\n" for t, row in zip(times, table[start:stop].tolist()))

    return chunks()


def write_tum(motion: Motion, path: str | os.PathLike, position_w_m: np.ndarray | None = None) -> int:
    """Write the attitude of ``motion`` as a TUM trajectory, atomically; returns the number of rows written."""
    keep, _ = tum_rows(motion, position_w_m)
    atomic_write(path, tum_chunks(motion, position_w_m))
    return int(keep.sum())
