"""Torque-free rotation of a rigid body in closed form (McGinnis, Perkins & King 2012, Table 1).

Euler's equations without torque, ``I ω̇ + ω × I ω = 0`` (McGinnis, Perkins & King 2012, eq. 1),
keep the rotational kinetic energy ``2T = Σ I_i ω_i²`` and the squared angular
momentum ``H² = Σ I_i² ω_i²`` constant (eqs. 2-3). With the principal moments
relabelled ``I_a > I_b > I_c`` (major, intermediate, minor) the solution is a
set of Jacobi elliptic functions of ``τ = p t + τ0``:

* ``H² > 2T I_b`` (precession about the major axis):
  ``ω_a = σ_a A_a dn τ``, ``ω_b = σ_b A_b sn τ``, ``ω_c = σ_c A_c cn τ`` with
  ``A_a² = (H² − 2T I_c) / (I_a (I_a − I_c))``,
  ``A_b² = (2T I_a − H²) / (I_b (I_a − I_b))``,
  ``A_c² = (2T I_a − H²) / (I_c (I_a − I_c))``,
  ``p² = (I_a − I_b)(H² − 2T I_c) / (I_a I_b I_c)``,
  ``k² = (I_b − I_c)(2T I_a − H²) / ((I_a − I_b)(H² − 2T I_c))``.
* ``H² < 2T I_b`` (precession about the minor axis): the roles of the major
  and minor axes swap: ``ω_a = σ_a A_a cn τ``, ``ω_b = σ_b A_b sn τ``,
  ``ω_c = σ_c A_c dn τ`` with
  ``A_a² = (H² − 2T I_c) / (I_a (I_a − I_c))``,
  ``A_b² = (H² − 2T I_c) / (I_b (I_b − I_c))``,
  ``A_c² = (2T I_a − H²) / (I_c (I_a − I_c))``,
  ``p² = (I_b − I_c)(2T I_a − H²) / (I_a I_b I_c)``,
  ``k² = (I_a − I_b)(H² − 2T I_c) / ((I_b − I_c)(2T I_a − H²))``.

In both cases ``p² = z1 − z2`` or ``z3 − z2`` with McGinnis, Perkins & King 2012's eq. 4. Putting
the solution into Euler's equations (``sn' = cn dn``, ``cn' = −sn dn``,
``dn' = −k² sn cn``) fixes the signs: ``σ_a σ_b σ_c = −1`` when (a, b, c) is
a cyclic order of the body axes (x, y, z), +1 otherwise. The sign of the
axes following ``dn`` and ``cn`` are those of their initial values (so
``cn τ0 ≥ 0``) and the third follows. The phase ``τ0`` is the incomplete
elliptic integral ``F(φ0 | k²)`` of the Jacobi amplitude
``φ0 = atan2(sn τ0, cn τ0) ∈ [−π/2, π/2]`` given by the initial condition. ``H² = 2T I_b``
(the separatrix) is the limit ``k → 1`` (``sn = tanh``, ``cn = dn = sech``).

The paper's footnote 2 prints the small-oscillation frequencies with lost
signs; linearising Euler's equations about a steady spin ``Ω`` gives
``Ω √((I_a − I_b)(I_a − I_c) / (I_b I_c))`` about the major axis and
``Ω √((I_a − I_c)(I_b − I_c) / (I_a I_b))`` about the minor axis
(:func:`small_oscillation_frequency_radps`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import special

from ..errors import InputError

DELRIN_BLOCK_SIZE_M = (0.201, 0.147, 0.102)
DELRIN_BLOCK_MASS_KG = 4.36


def box_principal_inertia(size_m=DELRIN_BLOCK_SIZE_M, mass_kg: float = DELRIN_BLOCK_MASS_KG) -> np.ndarray:
    """Principal moments of a uniform box about axes along its edges, (3,).

    ``I_x = m (b² + c²) / 12`` etc. for edge lengths ``(a, b, c)`` along x, y, z.
    McGinnis, Perkins & King 2012's Delrin block (0.201 × 0.147 × 0.102 m, 4.36 kg) gives about
    (0.0116, 0.0185, 0.0225) kg m²: x is its minor axis, z its major axis.
    """
    a, b, c = (float(v) for v in size_m)
    if min(a, b, c) <= 0 or mass_kg <= 0:
        raise InputError(f"box size {size_m!r} and mass {mass_kg!r} must be positive")
    return mass_kg / 12.0 * np.array([b * b + c * c, a * a + c * c, a * a + b * b])


def energy_and_momentum(inertia_kgm2, omega_b_radps) -> tuple[np.ndarray, np.ndarray]:
    """``2T = Σ I_i ω_i²`` and ``H² = Σ I_i² ω_i²`` (McGinnis, Perkins & King 2012, eqs. 2-3), per row."""
    i = np.asarray(inertia_kgm2, dtype=float)
    w = np.asarray(omega_b_radps, dtype=float)
    return np.sum(i * w * w, axis=-1), np.sum(i * i * w * w, axis=-1)


def euler_rhs(inertia_kgm2, omega_b_radps) -> np.ndarray:
    """ω̇ from torque-free Euler's equations: ``ω̇ = −I⁻¹ (ω × I ω)``, (..., 3)."""
    i = np.asarray(inertia_kgm2, dtype=float)
    w = np.asarray(omega_b_radps, dtype=float)
    return -np.cross(w, i * w) / i


def small_oscillation_frequency_radps(inertia_kgm2, spin_axis: int, spin_radps: float) -> float:
    """Angular frequency of the off-axis components for a spin near a stable axis.

    Linearised Euler equations about ``ω = Ω e_s`` (McGinnis, Perkins & King 2012, footnote 2, with
    the signs re-derived): ``ω_n = Ω √((I_s − I_j)(I_s − I_k) / (I_j I_k))``,
    real when ``I_s`` is the largest or the smallest moment. Raises for the
    intermediate axis, whose motion is unstable (no oscillation).
    """
    i = np.asarray(inertia_kgm2, dtype=float)
    j, k = [n for n in range(3) if n != spin_axis]
    prod = (i[spin_axis] - i[j]) * (i[spin_axis] - i[k])
    if prod <= 0:
        raise InputError(f"axis {spin_axis} is the intermediate axis of inertia {i.tolist()}: the spin is unstable")
    return float(abs(spin_radps) * np.sqrt(prod / (i[j] * i[k])))


@dataclass(frozen=True)
class TorqueFreeMotion:
    """Closed-form ω(t) of a torque-free rigid body (McGinnis, Perkins & King 2012, Table 1).

    Build with :meth:`from_initial`; call :meth:`omega` and :meth:`omega_dot`
    with times in seconds (relative to the initial condition).
    """

    inertia_kgm2: np.ndarray
    order: np.ndarray  # body axes of (major, intermediate, minor)
    case: str  # "major" (H² ≥ 2T I_b) or "minor"
    amplitude_radps: np.ndarray  # (A_a, A_b, A_c)
    sign: np.ndarray  # (σ_a, σ_b, σ_c)
    p_radps: float
    m: float  # parameter k²
    tau0: float
    two_t: float
    h2: float
    steady_radps: np.ndarray | None = None  # ω when it is a principal direction (no motion)

    @classmethod
    def from_initial(cls, inertia_kgm2, omega0_b_radps) -> "TorqueFreeMotion":
        """Constants, case, signs and phase from ω(0) (McGinnis, Perkins & King 2012, Table 1 and eq. 4)."""
        inertia = np.asarray(inertia_kgm2, dtype=float).reshape(-1)
        w0 = np.asarray(omega0_b_radps, dtype=float).reshape(-1)
        if inertia.shape != (3,) or np.any(inertia <= 0) or not np.all(np.isfinite(inertia)):
            raise InputError(f"principal inertia must be 3 positive numbers, got {inertia_kgm2!r}")
        if w0.shape != (3,) or not np.all(np.isfinite(w0)):
            raise InputError(f"initial angular velocity must be 3 finite numbers, got {omega0_b_radps!r}")
        order = np.argsort(-inertia, kind="stable")
        ia, ib, ic = inertia[order]
        if (ia - ib) <= 1e-9 * ia or (ib - ic) <= 1e-9 * ia:
            raise InputError(
                f"principal inertia {inertia.tolist()}: the elliptic closed form needs three distinct moments"
            )
        # Euler's equations are cyclic in (1, 2, 3): an odd relabelling flips the
        # sign of their right-hand sides, hence of σ_a σ_b σ_c.
        parity = 1.0 if tuple(order) in ((0, 1, 2), (1, 2, 0), (2, 0, 1)) else -1.0
        wa, wb, wc = w0[order]
        two_t = ia * wa**2 + ib * wb**2 + ic * wc**2
        h2 = ia**2 * wa**2 + ib**2 * wb**2 + ic**2 * wc**2
        if np.linalg.norm(np.cross(w0, inertia * w0)) <= 1e-14 * max(h2, 1e-300):
            # spin about a principal axis (or rest): a relative equilibrium, including the
            # unstable one about the intermediate axis, where Table 1's phase is infinite
            return cls(inertia, order, "major", np.zeros(3), np.ones(3), 0.0, 0.0, 0.0, float(two_t), float(h2),
                       w0.copy())
        # Differences written as sums of non-negative terms (no cancellation).
        h2_minus_c = ia * (ia - ic) * wa**2 + ib * (ib - ic) * wb**2  # H² − 2T I_c ≥ 0
        a_minus_h2 = ib * (ia - ib) * wb**2 + ic * (ia - ic) * wc**2  # 2T I_a − H² ≥ 0
        h2_minus_b = ia * (ia - ib) * wa**2 - ic * (ib - ic) * wc**2  # H² − 2T I_b
        if h2_minus_b >= 0:
            case = "major"
            amp = np.sqrt([h2_minus_c / (ia * (ia - ic)), a_minus_h2 / (ib * (ia - ib)), a_minus_h2 / (ic * (ia - ic))])
            p = np.sqrt((ia - ib) * h2_minus_c / (ia * ib * ic))
            m = (ib - ic) * a_minus_h2 / ((ia - ib) * h2_minus_c)
            s_dn = 1.0 if wa >= 0 else -1.0
            s_cn = 1.0 if wc >= 0 else -1.0
            sign = np.array([s_dn, -parity * s_dn * s_cn, s_cn])
            sn0 = sign[1] * wb / amp[1] if amp[1] > 0 else 0.0
            cn0 = sign[2] * wc / amp[2] if amp[2] > 0 else 1.0
        else:
            case = "minor"
            amp = np.sqrt([h2_minus_c / (ia * (ia - ic)), h2_minus_c / (ib * (ib - ic)), a_minus_h2 / (ic * (ia - ic))])
            p = np.sqrt((ib - ic) * a_minus_h2 / (ia * ib * ic))
            m = (ia - ib) * h2_minus_c / ((ib - ic) * a_minus_h2)
            s_dn = 1.0 if wc >= 0 else -1.0
            s_cn = 1.0 if wa >= 0 else -1.0
            sign = np.array([s_cn, -parity * s_dn * s_cn, s_dn])
            sn0 = sign[1] * wb / amp[1] if amp[1] > 0 else 0.0
            cn0 = sign[0] * wa / amp[0] if amp[0] > 0 else 1.0
        m = float(min(max(m, 0.0), 1.0))
        phi0 = float(np.arctan2(np.clip(sn0, -1, 1), np.clip(cn0, -1, 1)))
        tau0 = float(special.ellipkinc(phi0, m))
        return cls(inertia, order, case, amp, sign, float(p), m, tau0, float(two_t), float(h2))

    def _elliptic(self, times_s):
        tau = self.p_radps * np.asarray(times_s, dtype=float) + self.tau0
        sn, cn, dn, _ = special.ellipj(tau, self.m)
        return sn, cn, dn

    def omega(self, times_s) -> np.ndarray:
        """ω in B at the given times, (N, 3)."""
        if self.steady_radps is not None:
            return np.broadcast_to(self.steady_radps, np.shape(times_s) + (3,)).copy()
        sn, cn, dn = self._elliptic(times_s)
        cols = (dn, sn, cn) if self.case == "major" else (cn, sn, dn)
        out = np.empty(np.shape(sn) + (3,))
        for n, col in enumerate(cols):
            out[..., self.order[n]] = self.sign[n] * self.amplitude_radps[n] * col
        return out

    def omega_dot(self, times_s) -> np.ndarray:
        """ω̇ in B, the exact time derivative of :meth:`omega`, (N, 3)."""
        if self.steady_radps is not None:
            return np.zeros(np.shape(times_s) + (3,))
        sn, cn, dn = self._elliptic(times_s)
        d_sn, d_cn, d_dn = cn * dn, -sn * dn, -self.m * sn * cn
        cols = (d_dn, d_sn, d_cn) if self.case == "major" else (d_cn, d_sn, d_dn)
        out = np.empty(np.shape(sn) + (3,))
        for n, col in enumerate(cols):
            out[..., self.order[n]] = self.sign[n] * self.amplitude_radps[n] * self.p_radps * col
        return out

    @property
    def period_s(self) -> float:
        """Period of ω(t): ``4 K(k²) / p`` (infinite on the separatrix)."""
        if self.p_radps == 0 or self.m >= 1.0:
            return float("inf")
        return float(4.0 * special.ellipk(self.m) / self.p_radps)
