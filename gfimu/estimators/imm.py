"""Context-based interacting multiple models for ω (Lin et al. 2011 §3.2, §4.1).

Three models estimate ω from one inverted sample (Ho & Lin 2009, eq. 7):

- zero model: ω = 0;
- integration model: ``ω_int,j = ω_{j-1} + h/2 (ω̇_{j-1} + ω̇_j)`` (eq. 8, from
  the previous *estimate*);
- quadratic model: magnitudes from the quadratic sums, signs by the L2
  choice against ω_int (eqs. 9-11, see :mod:`gfimu.estimators.integration`).

Contexts: each quadratic sum ``a = ωx²+ωy², b = ωx²+ωz², c = ωy²+ωz²`` lies
below T1 (zero), between T1 and T2 (integration) or above T2 (quadratic).
Of the 27 combinations, Lin et al. 2011 treats four cases (eqs. 12-15; the
printed equations are lost, they are rebuilt here from the text):

1. a, b, c ≥ T2: ω = ω_qua.
2. one sum in [T1, T2), the other two ≥ T2: the axis *not* in that sum
   (z for a, y for b, x for c) is far from zero and comes from the
   quadratic model; the two axes in the sum come from the integration model.
3. one sum < T1, the other two ≥ T2: the two axes in that sum are zero, the
   third comes from the quadratic model (its magnitude from the usual
   formula, e.g. ``ωz² = (b + c - a)/2``).
4. a, b, c < T1: ω = 0.

The other 19 combinations, and any sample with a negative sum (beyond
floating-point rounding), fall back to ω = ω_int.

Soft switching (eqs. 16-17, Fig. 6): each sum has a membership in the three
models, linear across a band of half-width ``h1 Δ`` around T1 and ``h2 Δ``
around T2 (``Δ = T2 - T1``), so that near T1 the estimate blends zero and
ω_int and near T2 blends ω_int and ω_qua. The memberships of a, b and c are
multiplied and the rules above mixed with those weights, which reduces
exactly to the hard cases when h1 = h2 = 0. Per axis the result is
``ω_k = α_k ω_int,k + β_k sign(ω_int,k) |ω_k|`` with α, β depending on a, b, c
only, so they are computed vectorised and only the scalar recursion loops.

T2 (Lin et al. 2011 §4.1): unless given, it comes from the trend line of the best
T2 against the level of motion ``a + b + c`` averaged over the log:
``T2 = t2_intercept + t2_slope · mean(a + b + c)``, fixed for the whole log.
The paper's fitted coefficients are only in its Fig. 8 (not legible in the
text); it reports the best T2 in the range 3-9 (rad/s)² and a small
positive slope. The defaults here are chosen accordingly (see the class).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from ..option import option
from ..array import SensorArray
from ..errors import DataError, InputError
from ..log import Log
from ..motion import Motion
from ..progress import progress as progress_bar
from ..rigid_body import omega_from_quadratic_terms
from ._common import PerSampleEstimator, resolve_initial_omega, trapezoid_increments, validate_initial_omega
from .integration import InitialOmega, sign_tracking_loop
from .inversion import check_log_for_inversion, invert, sigma_from_inversion

ZERO, INTEGRATION, QUADRATIC = 0, 1, 2
# axes contained in each quadratic sum a, b, c, and the axis each leaves out
SUM_AXES = ((0, 1), (0, 2), (1, 2))
OTHER_AXIS = (2, 1, 0)


def case_rule(labels: tuple[int, int, int]) -> tuple[tuple[int, int, int], int]:
    """Hard rule of Lin et al. 2011 §3.2: model per axis and case number (0 = fall-back).

    ``labels`` are the contexts (ZERO, INTEGRATION, QUADRATIC) of a, b, c.
    """
    la = list(labels)
    if all(lb == QUADRATIC for lb in la):
        return (QUADRATIC,) * 3, 1
    if all(lb == ZERO for lb in la):
        return (ZERO,) * 3, 4
    if la.count(QUADRATIC) == 2:
        k = next(i for i, lb in enumerate(la) if lb != QUADRATIC)
        models = [0, 0, 0]
        for ax in SUM_AXES[k]:
            models[ax] = la[k]
        models[OTHER_AXIS[k]] = QUADRATIC
        return tuple(models), (2 if la[k] == INTEGRATION else 3)
    return (INTEGRATION,) * 3, 0


# 27 label combinations, their per-axis models and case numbers
_COMBOS = list(itertools.product((ZERO, INTEGRATION, QUADRATIC), repeat=3))
_RULES = np.array([case_rule(c)[0] for c in _COMBOS])  # (27, 3)


def context_memberships(s: np.ndarray, t1: float, t2: float, h1: float, h2: float) -> np.ndarray:
    """Membership of quadratic sums in (zero, integration, quadratic), (...,) -> (..., 3).

    Linear ramps of half-width ``h1 Δ`` around T1 and ``h2 Δ`` around T2
    (``Δ = T2 - T1``, Lin et al. 2011, eqs. 16-17); hard thresholds when h = 0
    (a sum equal to a threshold belongs to the upper model).
    """
    s = np.asarray(s, dtype=float)
    delta = t2 - t1

    def ramp(threshold, half_width):
        if half_width <= 0:
            return (s >= threshold).astype(float)
        return np.clip((s - (threshold - half_width)) / (2.0 * half_width), 0.0, 1.0)

    above_t1 = ramp(t1, h1 * delta)
    p_quad = ramp(t2, h2 * delta)
    p_zero = 1.0 - above_t1
    p_int = np.clip(above_t1 - p_quad, 0.0, 1.0)
    total = p_zero + p_int + p_quad
    return np.stack([p_zero, p_int, p_quad], axis=-1) / total[..., None]


def imm_weights(q: np.ndarray, t1: float, t2: float, h1: float, h2: float) -> tuple[np.ndarray, np.ndarray]:
    """Per-axis weights α (integration) and β (quadratic) of the IMM mixture, (N, 6) -> 2 × (N, 3).

    The zero model takes the remaining weight ``1 - α - β``. Samples with a
    negative quadratic sum use the integration model only (α = 1, β = 0).
    """
    q = np.asarray(q, dtype=float).reshape(-1, 6)
    p = context_memberships(q[:, :3], t1, t2, h1, h2)  # (N, 3 sums, 3 models)
    combos = np.array(_COMBOS)  # (27, 3)
    w = p[:, 0, combos[:, 0]] * p[:, 1, combos[:, 1]] * p[:, 2, combos[:, 2]]  # (N, 27)
    alpha = w @ (_RULES == INTEGRATION).astype(float)
    beta = w @ (_RULES == QUADRATIC).astype(float)
    negative = negative_sums(q)
    alpha[negative] = 1.0
    beta[negative] = 0.0
    return alpha, beta


def negative_sums(q: np.ndarray) -> np.ndarray:
    """Samples (N,) with a quadratic sum below zero beyond rounding (``-1e-9 (1 + max|q|)``)."""
    q = np.asarray(q, dtype=float).reshape(-1, 6)
    return np.any(q[:, :3] < -1e-9 * (1.0 + np.abs(q).max(axis=1, keepdims=True)), axis=1)


def imm_case(q: np.ndarray, t1: float, t2: float) -> np.ndarray:
    """Hard-switching case number per sample (1-4; 0 = fall-back to integration), (N, 6) -> (N,)."""
    q = np.asarray(q, dtype=float).reshape(-1, 6)
    s = q[:, :3]
    labels = np.where(s < t1, ZERO, np.where(s < t2, INTEGRATION, QUADRATIC))
    lookup = {c: case_rule(c)[1] for c in _COMBOS}
    cases = np.array([lookup[tuple(row)] for row in labels.tolist()], dtype=int)
    cases[negative_sums(q)] = 0
    return cases


def t2_from_trend(q: np.ndarray, intercept: float, slope: float) -> float:
    """T2 from the Lin et al. 2011 §4.1 trend line: ``intercept + slope · mean(a + b + c)``."""
    level = float(np.mean(np.clip(np.asarray(q)[:, :3], 0.0, None).sum(axis=1))) if len(q) else 0.0
    return intercept + slope * level


@dataclass
class IMMEstimator(PerSampleEstimator):
    """Context-based IMM of Lin et al. 2011 §3.2 (zero / integration / quadratic models).

    Options (Lin et al. 2011 values where it gives them): ``gfimu estimate --method imm --list-options``.
    """

    method = "imm"

    t1: float = option(0.1, "(rad/s)²", "zero-model threshold T1 on each quadratic sum (§4.1: \"T1 is set around 0.1\")")
    t2: float | None = option(None, "(rad/s)²", (
        "quadratic-model threshold T2; None takes it from the trend line t2_intercept + t2_slope · mean(a + b + c)"))
    t2_intercept: float = option(3.0, "(rad/s)²", (
        "intercept of the trend line of T2 (§4.1, Fig. 8): T2 = 3 at rest, within the paper's good range of 3-9 "
        "for levels of motion up to 300 (rad/s)²"))
    t2_slope: float = option(0.02, help="slope of the trend line of T2 on mean(a + b + c) (§4.1, Fig. 8)")
    h1: float = option(0.02, help=(
        "soft-switching half-width around T1, as a fraction of T2 - T1 (eq. 16; \"around 2 %\")"))
    h2: float = option(0.02, help=(
        "soft-switching half-width around T2, as a fraction of T2 - T1 (eq. 17; \"around 2 %\")"))
    initial_omega: InitialOmega = option("zero", help=(
        "prediction for the first sample of each gap-free segment: 'zero', 'quadratic' or three numbers in rad/s "
        "(as method 'pure-integration')"))
    compute_sigma: bool = option(False, help="one-sigma of f and ω̇ from the inversion (ω has none)")

    def __post_init__(self) -> None:
        for name in ("t1", "h1", "h2", "t2_intercept", "t2_slope"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise InputError(f"imm option {name} must be a finite number >= 0, got {v!r}")
        if self.t2 is not None and not (np.isfinite(self.t2) and self.t2 > self.t1):
            raise InputError(f"imm option t2 must exceed t1 = {self.t1}, got {self.t2!r}")
        if self.h1 + self.h2 > 1.0:
            raise InputError(f"imm options h1 + h2 must not exceed 1 (bands would overlap), got {self.h1 + self.h2}")
        validate_initial_omega(self.initial_omega)

    def applicable(self, array: SensorArray) -> str | None:
        return array.inversion_reason()

    def thresholds(self, q: np.ndarray) -> tuple[float, float]:
        """(T1, T2) used for a log whose inverted quadratic terms are q."""
        t2 = self.t2 if self.t2 is not None else t2_from_trend(q, self.t2_intercept, self.t2_slope)
        if not t2 > self.t1:
            raise DataError(f"imm: T2 = {t2:g} from the trend line does not exceed T1 = {self.t1:g}")
        return self.t1, t2

    def estimate_motion(self, log: Log, progress: bool = False) -> Motion:
        check_log_for_inversion(log)
        x, cov = invert(log.array, log.accel_mps2)
        q = x[:, 6:]
        t1, t2 = self.thresholds(q)
        alpha, beta = imm_weights(q, t1, t2, self.h1, self.h2)
        mag = omega_from_quadratic_terms(q)
        omega = np.empty((len(log), 3))
        segs = log.segments()
        for k, seg in enumerate(progress_bar(segs, total=len(segs), desc="imm", enable=progress)):
            w0 = resolve_initial_omega(self.initial_omega, q[seg][:1], k == 0)
            inc = trapezoid_increments(x[seg, 3:6], log.timestamps_ns[seg])
            for axis in range(3):
                omega[seg, axis] = sign_tracking_loop(
                    mag[seg, axis].tolist(), inc[:, axis].tolist(), float(w0[axis]),
                    alpha[seg, axis].tolist(), beta[seg, axis].tolist(),
                )
        return Motion(log.timestamps_ns, omega_b_radps=omega, omega_dot_b_radps2=x[:, 3:6],
                      specific_force_b_mps2=x[:, 0:3],
                      sigma=sigma_from_inversion(cov, len(log)) if self.compute_sigma else {})
