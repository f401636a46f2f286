"""Sign of a steady rotation from the gravity it turns in the body frame.

The accelerometer equation is even in ω (``q(ω) = q(-ω)``), so when ω̇
carries no information (a rotation at constant rate) the sign of ω is
unobservable from the lever-arm terms alone. Gravity breaks the tie: with
``g_B = Rᵀ g`` and ``Ṙ = R [ω]×``, ``ġ_B = -ω × g_B``, and the specific force
``f = a_B - g_B`` of a body whose world acceleration changes slowly obeys

    ḟ ≈ -ω × f.

:func:`gravity_sign_score` measures which sign of ω the rotation of f
supports; :func:`steady_rotation` tells whether ω̇ decides the sign on its own.
"""

from __future__ import annotations

import numpy as np

STANDARD_GRAVITY_MPS2 = 9.80665


def gravity_sign_score(omega_b_radps: np.ndarray, specific_force_b_mps2: np.ndarray, dt_s: np.ndarray,
                       min_omega_radps: float = 0.5, max_dynamic_mps2: float = 3.0) -> tuple[float, int]:
    """Least-squares coefficient s of ``ḟ = s (ω × f)`` and the samples it used.

    s ≈ -1 when ω has the right sign, +1 when it has the wrong one. Only
    samples with |ω| above ``min_omega_radps`` and ‖f‖ within
    ``max_dynamic_mps2`` of g (gravity dominates f) are used. ``dt_s`` is the
    (N-1,) step; ḟ by central differences. Returns (nan, 0) with no usable sample.
    """
    w = np.asarray(omega_b_radps, dtype=float)
    f = np.asarray(specific_force_b_mps2, dtype=float)
    if len(w) < 3:
        return float("nan"), 0
    dt = np.asarray(dt_s, dtype=float)
    fdot = (f[2:] - f[:-2]) / (dt[1:] + dt[:-1])[:, None]
    pred = np.cross(w[1:-1], f[1:-1])
    use = (np.linalg.norm(w[1:-1], axis=1) > min_omega_radps) & (
        np.abs(np.linalg.norm(f[1:-1], axis=1) - STANDARD_GRAVITY_MPS2) < max_dynamic_mps2)
    if not np.any(use):
        return float("nan"), 0
    den = float(np.sum(pred[use] ** 2))
    if den <= 0:
        return float("nan"), 0
    return float(np.sum(fdot[use] * pred[use]) / den), int(np.count_nonzero(use))


def steady_rotation(omega_b_radps: np.ndarray, omega_dot_sigma_radps: float, window: int) -> bool:
    """True when no window of ``window`` samples holds a ω change that decides ω's sign.

    Over a window ``ω(t) = ω₀ + W(t)``; the sign of ω₀ shows through the cross
    term ``J_q(W) ω₀`` of the quadratic terms. A window decides when the change
    ``‖W‖`` across it exceeds five times ``omega_dot_sigma_radps`` (the noise of
    integrated ω̇ over a window) while ω is away from zero.
    """
    w = np.asarray(omega_b_radps, dtype=float)
    n = len(w)
    for start in range(0, max(n - 1, 1), max(window, 2)):
        seg = w[start:start + window]
        if len(seg) < 2:
            break
        change = float(np.max(np.linalg.norm(seg - seg[0], axis=1)))
        # the information on the sign scales with ‖J_q(W) ω₀‖ ~ 2 ‖W‖ ‖ω₀‖
        if change > 5.0 * omega_dot_sigma_radps and np.linalg.norm(seg[0]) > 0.5:
            return False
    return True


__all__ = ["gravity_sign_score", "steady_rotation"]
