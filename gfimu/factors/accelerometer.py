"""Accelerometer equation (Ho & Lin 2009, eqs. 1-6).

An axis with unit direction s (in B) at lever arm r reads the specific force
of its point, ``y = sᵀ (f + ω̇ × r + ω × (ω × r))``; with self-calibration the
reading is ``(1 + k) y + b`` (scale-factor error k, bias b, both per axis).
The residual is ``predicted - measured`` [m/s²].
"""

from __future__ import annotations

import numpy as np

from .. import rigid_body
from ..array import Accelerometer
from . import custom_factor, vector_at


def sensor_geometry(accelerometer: Accelerometer) -> tuple[np.ndarray, np.ndarray]:
    """(directions_b (n, 3), positions_m (n, 3)) of one accelerometer's axes."""
    d = accelerometer.directions_b
    return d, np.tile(accelerometer.position_m, (d.shape[0], 1))


def array_geometry(array) -> list[tuple[np.ndarray, np.ndarray, slice]]:
    """(directions_b, positions_m, column slice) of every accelerometer of ``array`` (a
    :class:`gfimu.array.SensorArray`), in the order of its reading columns."""
    out = []
    col = 0
    for acc in array.accelerometers:
        d, p = sensor_geometry(acc)
        out.append((d, p, slice(col, col + d.shape[0])))
        col += d.shape[0]
    return out


def axis_rows(directions_b: np.ndarray, positions_m: np.ndarray) -> np.ndarray:
    """Rows of the structure matrix (n, 12) for the given axes (Ho & Lin 2009, eq. 6)."""
    return rigid_body.structure_matrix(directions_b, positions_m)


def rigid_body_readings(omega_b_radps: np.ndarray, omega_dot_b_radps2: np.ndarray, specific_force_b_mps2: np.ndarray,
                        rows: np.ndarray, directions_b: np.ndarray, positions_m: np.ndarray):
    """(N, n) readings ``S [f, ω̇, q(ω)]`` of axes with structure-matrix rows ``rows`` (n, 12),
    sensing directions s and positions r (n, 3) (Ho & Lin 2009, eq. 6), the centripetal part written
    ``sᵀ (ω × (ω × r)) = (sᵀω)(rᵀω) - (sᵀr)|ω|²``; and those products ``(sᵀω, rᵀω, sᵀr)`` for
    :func:`omega_jacobian`."""
    w = omega_b_radps
    ws, wr, sr = w @ directions_b.T, w @ positions_m.T, np.einsum("ai,ai->a", directions_b, positions_m)
    pred = (specific_force_b_mps2 @ rows[:, 0:3].T + omega_dot_b_radps2 @ rows[:, 3:6].T + ws * wr
            - sr * np.sum(w * w, axis=1, keepdims=True))
    return pred, (ws, wr, sr)


def omega_jacobian(omega_b_radps: np.ndarray, products, directions_b: np.ndarray, positions_m: np.ndarray) -> np.ndarray:
    """(N, n, 3) ∂reading/∂ω of :func:`rigid_body_readings`: ``(rᵀω) s + (sᵀω) r - 2 (sᵀr) ω``."""
    ws, wr, sr = products
    return (wr[:, :, None] * directions_b + ws[:, :, None] * positions_m
            - 2.0 * sr[:, None] * omega_b_radps[:, None, :])


def accelerometer_residual(
    omega_b_radps: np.ndarray,
    omega_dot_b_radps2: np.ndarray,
    specific_force_b_mps2: np.ndarray,
    readings_mps2: np.ndarray,
    directions_b: np.ndarray,
    positions_m: np.ndarray,
    bias_mps2: np.ndarray | None = None,
    scale: np.ndarray | None = None,
):
    """Residuals of N samples of one group of axes.

    Shapes: ω, ω̇, f (N, 3); readings (N, n); directions, positions (n, 3);
    bias, scale (n,) or None. Returns ``(residual (N, n), jacobians)`` with
    ``jacobians = {'w': (N, n, 3), 'd': (N, n, 3), 'f': (N, n, 3),
    'b': (N, n, n), 's': (N, n, n)}`` (``'b'``/``'s'`` only when given).
    """
    w = np.atleast_2d(np.asarray(omega_b_radps, dtype=float))
    dw = np.atleast_2d(np.asarray(omega_dot_b_radps2, dtype=float))
    f = np.atleast_2d(np.asarray(specific_force_b_mps2, dtype=float))
    y = np.atleast_2d(np.asarray(readings_mps2, dtype=float))
    rows = axis_rows(directions_b, positions_m)
    n = rows.shape[0]
    if y.shape[-1] != n:
        raise ValueError(f"accelerometer factor: readings have {y.shape[-1]} axes, geometry has {n}")
    s = np.asarray(directions_b, dtype=float).reshape(-1, 3)
    p = np.asarray(positions_m, dtype=float).reshape(-1, 3)
    pred, products = rigid_body_readings(w, dw, f, rows, s, p)
    n_samples = pred.shape[0]
    jw = omega_jacobian(w, products, s, p)
    jd = np.broadcast_to(rows[:, 3:6], (n_samples, n, 3))
    jf = np.broadcast_to(rows[:, 0:3], (n_samples, n, 3))
    jac = {}
    gain = np.ones(n) if scale is None else 1.0 + np.asarray(scale, dtype=float)
    residual = gain * pred - y
    jac["w"] = gain[:, None] * jw
    jac["d"] = gain[:, None] * jd
    jac["f"] = gain[:, None] * jf
    if bias_mps2 is not None:
        residual = residual + np.asarray(bias_mps2, dtype=float)
        jac["b"] = np.broadcast_to(np.eye(n), (n_samples, n, n))
    if scale is not None:
        jac["s"] = pred[:, :, None] * np.eye(n)
    return residual, jac


def accelerometer_prediction(omega_b_radps: np.ndarray, omega_dot_b_radps2: np.ndarray, specific_force_b_mps2: np.ndarray,
                             rows: np.ndarray) -> np.ndarray:
    """(N, n) rigid-body readings ``S [f, ω̇, q(ω)]`` of axes with structure-matrix rows ``rows`` (n, 12)
    (Ho & Lin 2009, eq. 6): the residual of :func:`accelerometer_residual` without its Jacobians."""
    return (specific_force_b_mps2 @ rows[:, 0:3].T + omega_dot_b_radps2 @ rows[:, 3:6].T
            + rigid_body.quadratic_terms(omega_b_radps) @ rows[:, 6:12].T)


def make_accelerometer_factor(
    key_omega: int,
    key_omega_dot: int,
    key_specific_force: int,
    readings_mps2,
    directions_b,
    positions_m,
    noise_model,
    key_bias: int | None = None,
    key_scale: int | None = None,
):
    """CustomFactor on (ω_k, ω̇_k, f_k[, b_i][, s_i]) for one sample of one sensor."""
    readings = np.asarray(readings_mps2, dtype=float).reshape(1, -1)
    directions = np.asarray(directions_b, dtype=float).reshape(-1, 3)
    positions = np.asarray(positions_m, dtype=float).reshape(-1, 3)
    keys = [key_omega, key_omega_dot, key_specific_force]
    if key_bias is not None:
        keys.append(key_bias)
    if key_scale is not None:
        keys.append(key_scale)

    def error(values):
        bias = vector_at(values, key_bias) if key_bias is not None else None
        scale = vector_at(values, key_scale) if key_scale is not None else None
        r, j = accelerometer_residual(
            vector_at(values, key_omega), vector_at(values, key_omega_dot), vector_at(values, key_specific_force),
            readings, directions, positions, bias, scale,
        )
        jac = [j["w"][0], j["d"][0], j["f"][0]]
        if key_bias is not None:
            jac.append(j["b"][0])
        if key_scale is not None:
            jac.append(j["s"][0])
        return r[0], jac

    return custom_factor(noise_model, keys, error)
