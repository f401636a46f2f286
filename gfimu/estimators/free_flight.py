"""Angular velocity in free flight from one triaxial accelerometer (McGinnis, Perkins & King 2012).

A torque-free body in free fall (McGinnis, Perkins & King 2012, eqs. 8-11): the centre of mass
falls with g, so the specific force at the origin of B (the centre of mass,
axes along the principal axes) is zero and an accelerometer at r reads

    a_s = ω̇ × r + ω × (ω × r),   ω̇ = -I⁻¹ (ω × I ω)       (eqs. 11-12)

a function of ω alone (eq. 13; written here with the array's structure
matrix, y = S_ω̇ ω̇(ω) + S_q q(ω), so any sensor rotation and any number of
sensors on the body are handled). Two constants hold along the motion:
2T = Σ I_i ω_i² and H² = Σ I_i² ω_i² (eqs. 2-3).

1. Start (McGinnis, Perkins & King 2012: the five unknowns [ω(0), 2T, H²] from the first
   readings). Eq. 13 alone at the first sample has several roots besides
   ±ω; they are found by multi-start least squares, and the root from which
   Euler's equations (integrated by RK4) best predict the first
   ``init_samples`` readings is kept.
   2T and H² are then fitted jointly with ω at those ``init_samples``
   samples (scipy ``least_squares``, trust-region reflective).
2. Every sample: the least-squares solution of eq. 13 with eqs. 2-3, with
   McGinnis, Perkins & King 2012's eq. 14 weighting (acceleration residual over the mean |a_s|,
   constants relative), by ``scipy.optimize.least_squares(method="trf")``
   from the previous sample's ω.

All equations are even in ω, so ω is found up to its sign; ``omega_sign``
picks the branch: "positive" / "negative" make the mean component on the
spin axis positive / negative. The spin axis is the major or the minor axis,
the one whose component never changes sign in torque-free motion (the major
axis when H²/2T > I_intermediate): of the two, the one whose estimated
component keeps its sign best along the track;
"auto" keeps the sign for which the whole track best obeys Euler's
equations forward in time (-ω(t) solves them only backwards in time).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import sparse
from scipy.optimize import least_squares

from .. import rigid_body
from ..option import option
from ..array import SensorArray
from ..errors import DataError, InputError
from ..log import Log
from ..motion import Motion
from ..progress import progress as progress_bar
from ..rotations import skew
from ._common import PerSampleEstimator, checked_readings

OMEGA_SIGNS = ("positive", "negative", "auto")


def euler_omega_dot(inertia_kgm2: np.ndarray, omega_b_radps: np.ndarray) -> np.ndarray:
    """Torque-free Euler equations (McGinnis, Perkins & King 2012, eq. 1): ``ω̇ = -I⁻¹ (ω × I ω)``, (..., 3)."""
    i = np.asarray(inertia_kgm2, dtype=float)
    w = np.asarray(omega_b_radps, dtype=float)
    return -np.cross(w, i * w) / i


def euler_omega_dot_jacobian(inertia_kgm2: np.ndarray, omega_b_radps: np.ndarray) -> np.ndarray:
    """∂ω̇/∂ω of :func:`euler_omega_dot`, (3, 3) for one ω."""
    i = np.asarray(inertia_kgm2, dtype=float)
    w = np.asarray(omega_b_radps, dtype=float)
    # d(ω × Iω) = dω × Iω + ω × I dω = -[Iω]× dω + [ω]× I dω
    d_cross = -skew(i * w) + skew(w) * i[None, :]
    return -d_cross / i[:, None]


def _propagate(inertia_kgm2: np.ndarray, omega0_b_radps: np.ndarray, times_s: np.ndarray) -> np.ndarray:
    """ω at ``times_s`` (from 0, increasing) by RK4 on Euler's equations, steps ≤ 0.2 ms."""
    out = np.empty((len(times_s), 3))
    w = np.asarray(omega0_b_radps, dtype=float)
    t_now = 0.0
    for j, t_next in enumerate(times_s):
        span = t_next - t_now
        m = max(int(np.ceil(span / 2e-4)), 1) if span > 0 else 0
        for _ in range(m):
            h = span / m
            k1 = euler_omega_dot(inertia_kgm2, w)
            k2 = euler_omega_dot(inertia_kgm2, w + 0.5 * h * k1)
            k3 = euler_omega_dot(inertia_kgm2, w + 0.5 * h * k2)
            k4 = euler_omega_dot(inertia_kgm2, w + h * k3)
            w = w + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        t_now = t_next
        out[j] = w
    return out


class _FreeFlightModel:
    """Readings of the array as a function of ω alone (McGinnis, Perkins & King 2012, eq. 13)."""

    def __init__(self, array: SensorArray):
        S = array.structure_matrix()
        self.S_dw = S[:, 3:6]
        self.S_q = S[:, 6:]
        self.inertia = np.asarray(array.body.principal_inertia_kgm2, dtype=float)
        self.lever_m = float(np.max(np.linalg.norm(array.axis_positions_m, axis=1)))

    def readings(self, w: np.ndarray) -> np.ndarray:
        """(..., n_axes) readings for ω (..., 3)."""
        return euler_omega_dot(self.inertia, w) @ self.S_dw.T + rigid_body.quadratic_terms(w) @ self.S_q.T

    def readings_one(self, w: np.ndarray) -> np.ndarray:
        """:meth:`readings` for a single ω (3,), without the broadcasting overhead."""
        x, y, z = w
        i1, i2, i3 = self.inertia
        dw = np.array([(i2 - i3) * y * z / i1, (i3 - i1) * z * x / i2, (i1 - i2) * x * y / i3])
        q = np.array([x * x + y * y, x * x + z * z, y * y + z * z, x * y, x * z, y * z])
        return self.S_dw @ dw + self.S_q @ q

    def jacobian(self, w: np.ndarray) -> np.ndarray:
        """(n_axes, 3) ∂y/∂ω at one ω."""
        x, y, z = w
        i1, i2, i3 = self.inertia
        a, b, c = (i2 - i3) / i1, (i3 - i1) / i2, (i1 - i2) / i3
        d_dw = np.array([[0.0, a * z, a * y], [b * z, 0.0, b * x], [c * y, c * x, 0.0]])
        return self.S_dw @ d_dw + self.S_q @ rigid_body.quadratic_terms_jacobian(w)

    def constants(self, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """2T and H² (McGinnis, Perkins & King 2012, eqs. 2-3), per row of ω."""
        i = self.inertia
        return np.sum(i * w * w, axis=-1), np.sum(i * i * w * w, axis=-1)

    def spin_axis(self, two_t: float, h2: float) -> int:
        """Axis whose ω component never changes sign: major if H²/2T > I_intermediate, else minor."""
        order = np.argsort(self.inertia)
        return int(order[2]) if h2 / two_t > self.inertia[order[1]] else int(order[0])

    def spin_axis_of_track(self, omega: np.ndarray, two_t: float, h2: float) -> int:
        """Of the major and minor axes, the one whose component keeps its sign best along ``omega``.

        Near the separatrix (spin about the intermediate axis) noisy constants
        can put H²/2T on the wrong side of I_intermediate, so the track itself
        decides: the ratio |mean ω_i| / mean |ω_i| is 1 for a component that
        never changes sign. The constants decide when the two ratios tie.
        """
        order = np.argsort(self.inertia)
        ratios = {}
        for axis in (int(order[2]), int(order[0])):
            mag = np.mean(np.abs(omega[:, axis]))
            ratios[axis] = abs(np.mean(omega[:, axis])) / mag if mag > 0 else 0.0
        a, b = ratios
        if abs(ratios[a] - ratios[b]) <= 1e-3:
            return self.spin_axis(two_t, h2)
        return a if ratios[a] > ratios[b] else b


@dataclass
class FreeFlightEstimator(PerSampleEstimator):
    """ω of a torque-free body in free fall from its accelerometer(s) (McGinnis, Perkins & King 2012, eqs. 11-14).

    Options: ``gfimu estimate --method free-flight --list-options``. The whole log is taken as one free-flight phase (cut the throw and the
    catch first). Returns ω and ω̇ (from Euler's equations); the specific
    force at the centre of mass is zero by assumption and is not reported.
    """

    method = "free-flight"

    omega_sign: str = option("positive", help=(
        "branch of the ±ω ambiguity: 'positive' or 'negative' on the spin axis, or 'auto' (module docstring)"))
    init_samples: int = option(50, help="readings used to find ω(0), 2T and H²")
    starts: int = option(24, help="multi-start points for the roots of eq. 13 at sample 0")
    compute_sigma: bool = option(False, help=(
        "one-sigma of ω from the Fisher information of eq. 13 alone (accelerometer noise from the array), "
        "ignoring the information added by the constants; ω̇'s follows to first order"))

    def __post_init__(self) -> None:
        if self.omega_sign not in OMEGA_SIGNS:
            raise InputError(f"omega_sign must be one of {OMEGA_SIGNS}, got {self.omega_sign!r}")
        if int(self.init_samples) < 1:
            raise InputError(f"init_samples must be >= 1, got {self.init_samples}")
        if int(self.starts) < 1:
            raise InputError(f"starts must be >= 1, got {self.starts}")

    def applicable(self, array: SensorArray) -> str | None:
        if array.body is None:
            return f"array {array.name!r} has no [body] principal_inertia_kgm2 (needed by free-flight)"
        if not any(len(a.axes) == 3 for a in array.accelerometers):
            return f"array {array.name!r} has no triaxial accelerometer (free-flight needs one)"
        if np.max(np.linalg.norm(array.axis_positions_m, axis=1)) <= 0:
            return f"array {array.name!r}: an accelerometer at the centre of mass senses no rotation"
        i = np.sort(array.body.principal_inertia_kgm2)
        if i[1] - i[0] <= 1e-9 * i[2] or i[2] - i[1] <= 1e-9 * i[2]:
            return f"array {array.name!r}: principal moments {list(i)} are not distinct (axisymmetric body)"
        return None

    # ------------------------------------------------------------------
    def estimate_motion(self, log: Log, progress: bool = False) -> Motion:
        array = log.array
        y = checked_readings(self, log, "free-flight")
        n = len(log)
        if n < 2:
            raise DataError(f"{log.source}: free-flight needs at least 2 samples, got {n}")
        model = _FreeFlightModel(array)
        t = log.times_s
        k = min(int(self.init_samples), n)
        if not np.any(y[:k]):
            raise DataError(f"{log.source}: the first {k} readings are all zero; free-flight needs a spinning body")
        w_init, two_t, h2 = self._initial(model, y[:k], t[:k])
        if not (np.isfinite(two_t) and np.isfinite(h2) and two_t > 0 and h2 > 0):
            raise DataError(f"{log.source}: the first {k} readings show no rotation (2T = {two_t:.3g}); "
                            "free-flight needs a spinning body")

        accel_scale = float(np.mean(np.linalg.norm(y, axis=1)))  # eq. 14: mean |a_s| over the N samples
        omega = np.empty((n, 3))
        w = w_init
        for i in progress_bar(range(n), total=n, desc="free-flight", enable=progress):
            w = self._solve_sample(model, y[i], w, two_t, h2, accel_scale)
            omega[i] = w
        # the track is continuous, so one global sign remains to choose
        if self.omega_sign == "auto":
            dw = euler_omega_dot(model.inertia, omega)
            inc = 0.5 * np.diff(t)[:, None] * (dw[1:] + dw[:-1])
            flip = np.sum(np.diff(omega, axis=0) * inc) < 0
        else:
            axis = model.spin_axis_of_track(omega, two_t, h2)
            want = 1.0 if self.omega_sign == "positive" else -1.0
            flip = np.sign(np.sum(omega[:, axis])) != want
        if flip:
            omega = -omega
        omega_dot = euler_omega_dot(model.inertia, omega)
        sigma = {}
        if self.compute_sigma:
            sigma = self._sigma(array, model, omega)
        return Motion(log.timestamps_ns, omega_b_radps=omega, omega_dot_b_radps2=omega_dot, sigma=sigma)

    # ------------------------------------------------------------------
    def _roots(self, model: _FreeFlightModel, y0: np.ndarray) -> list[np.ndarray]:
        """Distinct (up to sign) local least-squares solutions of eq. 13 at one sample, best first."""
        scale = np.sqrt(max(np.linalg.norm(y0), 1e-12) / model.lever_m)
        m = max(int(self.starts) // 2, 1)
        kk = np.arange(m) + 0.5
        z = kk / m
        phi = np.pi * (1 + 5**0.5) * kk
        dirs = np.column_stack([np.sqrt(1 - z**2) * np.cos(phi), np.sqrt(1 - z**2) * np.sin(phi), z])
        starts = np.vstack([0.8 * scale * dirs, 2.0 * scale * dirs])
        found: list[tuple[float, np.ndarray]] = []
        for st in starts:
            r = least_squares(lambda w: model.readings_one(w) - y0, st, jac=model.jacobian, method="trf",
                              xtol=1e-12, ftol=1e-12, gtol=1e-12)
            w = r.x * (1.0 if r.x[np.argmax(np.abs(r.x))] >= 0 else -1.0)
            if not any(np.linalg.norm(w - v) <= 1e-6 * (1 + np.linalg.norm(v)) for _, v in found):
                found.append((float(np.sum(r.fun**2)), w))
        # every local solution is kept (with noise none is exact when there are more than
        # three axes); the Euler-equation prediction of the next readings ranks them
        return [w for _, w in sorted(found, key=lambda cw: cw[0])]

    def _initial(self, model: _FreeFlightModel, y: np.ndarray, t: np.ndarray):
        """ω(0), 2T and H² from the first readings (see module docstring)."""
        k = len(y)
        accel_scale = float(np.mean(np.linalg.norm(y, axis=1)))
        best = None
        for root in self._roots(model, y[0]):
            # rank the roots by how well Euler's equations from them predict the next readings
            # (either sign: -ω(t) solves Euler's equations only backwards in time)
            score = min(np.sum((model.readings(_propagate(model.inertia, s * root, t - t[0])) - y) ** 2) for s in (1.0, -1.0))
            if best is None or score < best[0]:
                best = (score, root)
        root = best[1]
        two_t, h2 = model.constants(root)
        if not (two_t > 0 and h2 > 0):
            return root, float(two_t), float(h2)  # no rotation: the caller reports it
        track = [root]
        for i in range(1, k):
            track.append(self._solve_sample(model, y[i], track[-1], two_t, h2, accel_scale))
        track = np.array(track)
        if k == 1:
            return track[0], float(two_t), float(h2)
        # joint fit of ω at the k samples and the two constants (eqs. 13, 2, 3)
        ref_t, ref_h = float(two_t), float(h2)

        def residuals(z):
            w = z[:-2].reshape(k, 3)
            tt, hh = z[-2] * ref_t, z[-1] * ref_h
            ct, ch = model.constants(w)
            return np.concatenate([((model.readings(w) - y) / accel_scale).ravel(), (tt - ct) / ref_t, (hh - ch) / ref_h])

        def jac(z):
            w = z[:-2].reshape(k, 3)
            na = y.shape[1]
            J = np.zeros((k * na + 2 * k, 3 * k + 2))
            i_ = model.inertia
            for j in range(k):
                J[j * na:(j + 1) * na, 3 * j:3 * j + 3] = model.jacobian(w[j]) / accel_scale
                J[k * na + j, 3 * j:3 * j + 3] = -2 * i_ * w[j] / ref_t
                J[k * na + k + j, 3 * j:3 * j + 3] = -2 * i_ * i_ * w[j] / ref_h
            J[k * na:k * na + k, -2] = 1.0
            J[k * na + k:, -1] = 1.0
            return sparse.csr_matrix(J)

        z0 = np.concatenate([track.ravel(), [1.0, 1.0]])
        r = least_squares(residuals, z0, jac=jac, method="trf", tr_solver="lsmr", xtol=1e-14, ftol=1e-14, gtol=1e-14)
        w = r.x[:-2].reshape(k, 3)
        return w[0], float(r.x[-2] * ref_t), float(r.x[-1] * ref_h)

    @staticmethod
    def _solve_sample(model, y_i, w_start, two_t, h2, accel_scale):
        """McGinnis, Perkins & King 2012, eq. 14 at one sample, from ``w_start``."""
        i_ = model.inertia

        def residuals(w):
            ww = w * w
            ct, ch = i_ @ ww, (i_ * i_) @ ww
            return np.concatenate([(y_i - model.readings_one(w)) / accel_scale, [(two_t - ct) / two_t, (h2 - ch) / h2]])

        def jac(w):
            return np.vstack([-model.jacobian(w) / accel_scale, -2 * i_ * w / two_t, -2 * i_ * i_ * w / h2])

        r = least_squares(residuals, w_start, jac=jac, method="trf", xtol=1e-13, ftol=1e-13, gtol=1e-13)
        return r.x

    @staticmethod
    def _sigma(array, model, omega):
        sig = array.noise_std_per_axis_mps2
        if not np.all(np.isfinite(sig)) or np.any(sig <= 0):
            raise InputError(f"array {array.name!r}: compute_sigma needs noise_std_mps2 for every accelerometer axis")
        s_w = np.empty_like(omega)
        s_dw = np.empty_like(omega)
        for i, w in enumerate(omega):
            Jw = model.jacobian(w) / sig[:, None]
            try:
                cov = np.linalg.inv(Jw.T @ Jw)
            except np.linalg.LinAlgError:
                s_w[i] = s_dw[i] = np.inf
                continue
            D = euler_omega_dot_jacobian(model.inertia, w)
            s_w[i] = np.sqrt(np.clip(np.diag(cov), 0, None))
            s_dw[i] = np.sqrt(np.clip(np.diag(D @ cov @ D.T), 0, None))
        return {"omega_b_radps": s_w, "omega_dot_b_radps2": s_dw}
