"""Gyro-aided inversion (Lu, Tsai & Lin 2010, eq. 8): x = S⁻¹ (a_m − W ω_m).

With a gyroscope the quadratic part of the rigid-body model is known from
the measured ω, ``W q(ω_m)``, and moves to the left-hand side; the six
unknowns [f, ω̇] follow from the six (or more) accelerometer axes by
(weighted) least squares. Any array whose first six structure-matrix
columns have full rank qualifies: six axes suffice (Lu, Tsai & Lin 2010's three
2-axis accelerometers).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..option import option
from ..array import ArrayModelError, SensorArray
from ..errors import DataError, InputError
from ..log import Log
from ..motion import Motion
from ..rigid_body import quadratic_terms, quadratic_terms_jacobian, structure_matrix
from ._common import PerSampleEstimator, check_finite, weighted_least_squares
from .inversion import check_log_for_inversion


def paper001_layout(lever_arm: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Sensing directions and positions (6, 3) of Lu, Tsai & Lin 2010's best layout, sensor order a1..a6.

    Derived in :func:`paper001_gain_matrix`: a1 (x) and a2 (y) at
    ``L(-1, -1, -1)``, a3 (z) and a4 (x) at ``L(-1, 1, 1)``, a5 (y) and a6 (z)
    at ``L(1, -1, 1)``, with L = ``lever_arm``.
    """
    e = np.eye(3)
    directions = np.array([e[0], e[1], e[2], e[0], e[1], e[2]])
    corners = np.array([[-1, -1, -1], [-1, -1, -1], [-1, 1, 1], [-1, 1, 1], [1, -1, 1], [1, -1, 1]], dtype=float)
    return directions, lever_arm * corners


def paper001_gain_matrix(m: float = 0.5, n: float = 0.25) -> tuple[np.ndarray, np.ndarray]:
    """The matrices of Lu, Tsai & Lin 2010, eq. 9: ``[f; ω̇] = G a_m − P q(ω_m)``; returns (G, P).

    G is printed in full (m = 0.5, n = 0.25)::

        G = [[ m, 0, 0,  m, 0, 0],      rows f_x, f_y, f_z,
             [ 0, m, 0,  0, m, 0],           ω̇x, ω̇y, ω̇z;
             [ 0, 0, m,  0, 0, m],      columns a1..a6, a1 and a4
             [ n, n, n, -n,-n,-n],      sensing along x, a2 and a5
             [-n,-n, n,  n, n,-n],      along y, a3 and a6 along z
             [ n,-n, n, -n, n,-n]]

    The printed text leaves out the sensor positions (only in Fig. 1), the
    lever-arm length, and the operator between G a_m and the gyro term (the
    PDF extraction shows "="). They follow from G itself:

    1. G = S₆⁻¹, so ``S₆ = G⁻¹``. With m = 1/2 and n = 1/4, G⁻¹ has entries 0
       and ±1 and exactly the pattern of eq. 6a (row of an x-sensor:
       ``[1, 0, 0, 0, r_z, -r_y]``, y-sensor ``[0, 1, 0, -r_z, 0, r_x]``,
       z-sensor ``[0, 0, 1, r_y, -r_x, 0]``). Reading the lever-arm components
       off G⁻¹: a1 at (·, -1, -1), a2 at (-1, ·, -1), a3 at (-1, 1, ·),
       a4 at (·, 1, 1), a5 at (1, ·, 1), a6 at (1, -1, ·), where "·" is the
       component along the sensing direction, which S₆ cannot see.
    2. Three 2-axis chips means three positions shared by pairs of sensors.
       Two pairings fit the known components: {a1 a2, a3 a4, a5 a6} at
       (-1,-1,-1), (-1,1,1), (1,-1,1), or {a1 a6, a2 a3, a4 a5} at (1,-1,-1),
       (-1,1,-1), (1,1,1): three alternate corners of a cube in both cases.
    3. The gyro term decides: with ``W`` of eq. 6b (identical to the
       centripetal rows of :func:`gfimu.rigid_body.structure_matrix`), the
       first pairing gives ``G W`` equal to the printed second matrix of
       eq. 9 entry by entry, and the second gives the negative of its first
       three rows. So the layout is the first pairing and the printed
       relation is ``x = G a_m − (G W) q(ω_m)``, i.e. eq. 8 with "−".
    4. Scale: the pair averages fix m = 1/2 for any size; scaling every
       position by L divides the ω̇ rows by L, so n = 1/(4L). The printed
       n = 0.25 means L = 1 in the paper's length unit (as Ho & Lin 2009 chooses
       its unit to make the cube's half edge 1).

    For general (m, n) this returns G with those entries and ``P = G W`` for
    the layout with L = 1/(4n); m must be 1/2 (no layout of this kind gives
    another value).
    """
    if not np.isclose(m, 0.5):
        raise InputError(f"Lu, Tsai & Lin 2010, eq. 9: m is the average of two opposite sensors and must be 0.5, got {m!r}")
    if not (np.isfinite(n) and n > 0):
        raise InputError(f"Lu, Tsai & Lin 2010, eq. 9: n = 1/(4 × lever arm) must be positive, got {n!r}")
    G = np.array(
        [
            [m, 0, 0, m, 0, 0],
            [0, m, 0, 0, m, 0],
            [0, 0, m, 0, 0, m],
            [n, n, n, -n, -n, -n],
            [-n, -n, n, n, n, -n],
            [n, -n, n, -n, n, -n],
        ],
        dtype=float,
    )
    directions, positions = paper001_layout(1.0 / (4.0 * n))
    W = structure_matrix(directions, positions)[:, 6:]
    return G, G @ W


def gyro_aided_matrices(array: SensorArray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(A (6, n_axes), W (n_axes, 6), covariance (6, 6) of [f, ω̇] from accelerometer noise).

    ``[f, ω̇] = A (a − W q(ω))`` with A the weighted least-squares solver of
    the first six columns of S (weights 1/σ² when every axis has a positive
    noise level, else equal; covariance NaN when a level is missing).
    Raises ArrayModelError when those columns lack full rank.
    """
    if array.n_axes < 6:
        raise ArrayModelError(
            f"array {array.name!r} has {array.n_axes} accelerometer axes; gyro-aided inversion needs at least 6"
        )
    S = array.structure_matrix()
    S6, W = S[:, :6], S[:, 6:]
    sv = np.linalg.svd(S6, compute_uv=False)
    if sv[-1] <= 1e-9 * sv[0]:
        raise ArrayModelError(
            f"array {array.name!r}: the [f, ω̇] columns of the structure matrix have rank "
            f"{int(np.sum(sv > 1e-9 * sv[0]))} of 6 (sensing directions and lever arms do not span f and ω̇)"
        )
    A, cov = weighted_least_squares(S6, array.noise_std_per_axis_mps2)
    return A, W, cov


def gyro_aided_solve(array: SensorArray, accel_mps2: np.ndarray, gyro_b_radps: np.ndarray) -> np.ndarray:
    """Lu, Tsai & Lin 2010, eq. 8 for every sample: (N, n_axes), (N, 3) -> [f, ω̇] (N, 6)."""
    a = np.atleast_2d(np.asarray(accel_mps2, dtype=float))
    g = np.atleast_2d(np.asarray(gyro_b_radps, dtype=float))
    if a.shape[1] != array.n_axes or g.shape != (a.shape[0], 3):
        raise InputError(f"gyro-aided inversion: readings {a.shape} and gyro {g.shape} do not match the array "
                         f"({array.n_axes} axes)")
    check_finite(a, "accel_mps2", array.accel_columns)
    check_finite(g, "gyro_b_radps", ["w_x", "w_y", "w_z"])
    A, W, _ = gyro_aided_matrices(array)
    return (a - quadratic_terms(g) @ W.T) @ A.T


@dataclass
class GyroAidedEstimator(PerSampleEstimator):
    """Accelerometers plus gyroscope (Lu, Tsai & Lin 2010, eq. 8).

    f and ω̇ by least squares from ``a_m − W q(ω_m)``; ω is the gyroscope
    reading itself (no blending: the gyro measures ω directly, and the
    accelerometers carry only its squares). Options: ``gfimu estimate --method gyro-aided --list-options``.
    """

    method = "gyro-aided"

    compute_sigma: bool = option(False, help=(
        "one-sigma of f and ω̇, from the accelerometer noise and the gyro noise propagated through W q(ω_m) "
        "(first order, per sample), and of ω (the gyro's noise level), when the array gives them"))

    def applicable(self, array: SensorArray) -> str | None:
        if array.gyroscope is None:
            return f"array {array.name!r} has no gyroscope (method 'gyro-aided' needs one)"
        reason = array.geometry_reason() if array.n_axes >= 6 else None  # fewer axes: the count says why
        if reason:
            return reason
        try:
            gyro_aided_matrices(array)
        except ArrayModelError as exc:
            return str(exc)
        return None

    def estimate_motion(self, log: Log, progress: bool = False) -> Motion:
        check_log_for_inversion(log)
        reason = self.applicable(log.array)
        if reason:
            raise ArrayModelError(reason)
        if log.gyro_b_radps is None:
            raise InputError(f"{log.source}: method 'gyro-aided' needs gyroscope columns w_x, w_y, w_z")
        bad = ~np.isfinite(log.gyro_b_radps)
        if bad.any():
            row, col = (int(v) for v in np.argwhere(bad)[0])
            where = f"{log.source}/imu.csv:{row + 2}" if log.source else f"sample {row}"
            raise DataError(f"{where}: gyroscope column {('w_x', 'w_y', 'w_z')[col]!r} is not finite ({int(bad.sum())} "
                            "reading(s) NaN, infinite or beyond ±1e4 rad/s); method 'gyro-aided' needs every "
                            "gyroscope reading")
        x = gyro_aided_solve(log.array, log.accel_mps2, log.gyro_b_radps)
        sigma = self._sigma(log) if self.compute_sigma else {}
        return Motion(log.timestamps_ns, omega_b_radps=log.gyro_b_radps.copy(), omega_dot_b_radps2=x[:, 3:6],
                      specific_force_b_mps2=x[:, 0:3], sigma=sigma)

    @staticmethod
    def _sigma(log: Log) -> dict[str, np.ndarray]:
        A, W, cov = gyro_aided_matrices(log.array)
        sg = log.array.gyroscope.noise_std_radps
        if not np.all(np.isfinite(cov)) or sg is None:
            return {}
        J = np.einsum("ij,jk,nkl->nil", A, W, quadratic_terms_jacobian(log.gyro_b_radps))  # (N, 6, 3)
        var = np.diag(cov)[None, :] + sg**2 * np.einsum("nil,nil->ni", J, J)
        sd = np.sqrt(var)
        return {"specific_force_b_mps2": sd[:, 0:3], "omega_dot_b_radps2": sd[:, 3:6],
                "omega_b_radps": np.full((len(log), 3), float(sg))}
