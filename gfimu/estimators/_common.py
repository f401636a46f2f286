"""Helpers shared by the per-sample estimators (pure maths, no I/O)."""

from __future__ import annotations

import time
from typing import Sequence

import numpy as np

from ..errors import DataError, InputError
from ..estimate import Estimate, Report
from ..motion import Motion
from ..rigid_body import omega_from_quadratic_terms

# (i, j) -> index of ωiωj in q = [ωx²+ωy², ωx²+ωz², ωy²+ωz², ωxωy, ωxωz, ωyωz]
_CROSS_INDEX = {(0, 1): 3, (0, 2): 4, (1, 2): 5}


class PerSampleEstimator:
    """What the per-sample estimators share: :meth:`estimate` runs the subclass's :meth:`estimate_motion`
    and returns it with its :class:`~gfimu.estimate.Report` (the method's name, ``method``, its options
    and the time taken). A subclass is a dataclass of options that defines ``method`` (its name in
    :data:`gfimu.methods.METHODS`), ``applicable(array)`` and ``estimate_motion(log, progress)``."""

    method = ""

    def estimate(self, log, progress: bool = False) -> Estimate:
        """The method on ``log``: :class:`~gfimu.estimate.Estimate` ``(motion, report)``."""
        t0 = time.perf_counter()
        motion = self.estimate_motion(log, progress=progress)
        return Estimate(motion, Report.of(self.method, self, timings={"estimate": time.perf_counter() - t0}))

    def estimate_motion(self, log, progress: bool = False) -> Motion:
        raise NotImplementedError


def check_finite(values: np.ndarray, what: str, columns: Sequence[str] | None = None) -> None:
    """Raise :class:`~gfimu.errors.DataError` naming the first sample (and column) that is not finite."""
    bad = ~np.isfinite(values)
    if bad.any():
        row, col = np.argwhere(bad)[0] if values.ndim == 2 else (int(np.argmax(bad)), None)
        where = f" column {columns[col]!r}" if columns is not None and col is not None else ""
        raise DataError(f"{what}: non-finite value at sample {int(row)}{where}")


def checked_readings(estimator, log, method: str) -> np.ndarray:
    """``log.accel_mps2`` after the checks an estimator makes first: ``estimator.applicable(log.array)`` (InputError
    with its reason) and finite readings (DataError naming the first non-finite sample and column)."""
    reason = estimator.applicable(log.array)
    if reason:
        raise InputError(f"{log.source}: method {method!r} cannot run: {reason}")
    y = log.accel_mps2
    if not np.all(np.isfinite(y)):
        bad = np.argwhere(~np.isfinite(y))[0]
        raise DataError(f"{log.source}: non-finite accelerometer reading at sample {bad[0]}, column "
                        f"{log.array.accel_columns[bad[1]]}")
    return y


def weighted_least_squares(S: np.ndarray, std: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Estimator matrix ``A`` (x = A y) of the least squares ``y = S x`` and the covariance of x.

    Weighted by ``1/std²`` when every axis has a positive noise std (covariance
    ``(SᵀΣ⁻¹S)⁻¹``); unweighted otherwise, with the covariance propagated from
    ``std`` where it is finite and NaN where any std is unknown.
    """
    n = S.shape[1]
    weighted = bool(np.all(np.isfinite(std)) and np.all(std > 0))
    w = 1.0 / std**2 if weighted else np.ones(S.shape[0])
    normal = S.T @ (w[:, None] * S)
    A = np.linalg.solve(normal, S.T * w[None, :])
    if weighted:
        cov = np.linalg.inv(normal)
    else:
        cov = (A * std[None, :] ** 2) @ A.T if np.all(np.isfinite(std)) else np.full((n, n), np.nan)
    return A, 0.5 * (cov + cov.T)


def omega_from_quadratic_terms_signed(q: np.ndarray) -> np.ndarray:
    """ω from q up to one global sign, (N, 6) -> (N, 3).

    The magnitudes come from the three quadratic sums (Ho & Lin 2009 §IV:
    ``ωx² = (q1 + q2 - q3)/2`` …). The cross terms ``ωxωy, ωxωz, ωyωz`` fix the
    relative signs: the largest-magnitude component is taken positive and each
    other component gets the sign of its cross term with that one (the cross
    term with the largest component has the best signal-to-noise ratio). A zero
    cross term counts as positive. The true ω is either the result or its
    negative (Lin et al. 2011, eqs. 18-19: two candidates).
    """
    q = np.asarray(q, dtype=float).reshape(-1, 6)
    mag = omega_from_quadratic_terms(q)
    cross = np.zeros((q.shape[0], 3, 3))
    for (i, j), k in _CROSS_INDEX.items():
        cross[:, i, j] = q[:, k]
        cross[:, j, i] = q[:, k]
    ref = np.argmax(mag, axis=1)
    rows = np.arange(q.shape[0])
    sign = np.where(cross[rows, ref, :] < 0.0, -1.0, 1.0)
    sign[rows, ref] = 1.0
    return sign * mag


def continuity_signs(v: np.ndarray) -> np.ndarray:
    """Global signs s_j (N,) making ``s_j v_j`` continuous from sample to sample.

    ``s_0 = +1`` and ``s_j = s_{j-1} · sign(v_j · v_{j-1})`` (a zero dot product
    keeps the sign): each sample takes whichever of ``±v_j`` is nearer (L2) to
    the previous estimate. Vectorised as a cumulative product.
    """
    v = np.asarray(v, dtype=float)
    if len(v) == 0:
        return np.ones(0)
    dots = np.einsum("ij,ij->i", v[1:], v[:-1])
    flips = np.where(dots < 0.0, -1.0, 1.0)
    return np.concatenate([[1.0], np.cumprod(flips)])


def trapezoid_increments(omega_dot_b_radps2: np.ndarray, timestamps_ns: np.ndarray) -> np.ndarray:
    """``h/2 (ω̇_{j-1} + ω̇_j)`` for j = 1..N-1 (Ho & Lin 2009, eq. 10, Lin et al. 2011, eq. 8), (N-1, 3)."""
    dt = np.diff(np.asarray(timestamps_ns, dtype=np.int64)) * 1e-9
    w = np.asarray(omega_dot_b_radps2, dtype=float)
    return 0.5 * dt[:, None] * (w[1:] + w[:-1])


def resolve_initial_omega(initial_omega, q_first: np.ndarray, first_segment: bool) -> np.ndarray:
    """The starting ω of a segment from an ``initial_omega`` option.

    ``"zero"``: at rest; ``"quadratic"``: :func:`omega_from_quadratic_terms_signed`
    of the segment's first sample; a 3-sequence (rad/s): used for the first
    segment only, later segments (after gaps) start as ``"quadratic"``.
    """
    if isinstance(initial_omega, str):
        if initial_omega == "zero":
            return np.zeros(3)
        if initial_omega == "quadratic":
            return omega_from_quadratic_terms_signed(q_first)[0]
        raise InputError(f"initial_omega must be 'zero', 'quadratic' or three numbers (rad/s), got {initial_omega!r}")
    w0 = np.asarray(initial_omega, dtype=float).reshape(-1)
    if w0.shape != (3,) or not np.all(np.isfinite(w0)):
        raise InputError(f"initial_omega must be 'zero', 'quadratic' or three finite numbers (rad/s), got {initial_omega!r}")
    return w0 if first_segment else omega_from_quadratic_terms_signed(q_first)[0]


def validate_initial_omega(initial_omega) -> None:
    """Fail early (at construction) on a malformed ``initial_omega`` option."""
    resolve_initial_omega(initial_omega, np.zeros(6), True)
