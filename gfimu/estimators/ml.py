"""Per-sample maximum-likelihood estimation of (f, ω̇, ω) for any array.

Skog, Nilsson, Händel & Nehorai, "Inertial sensor arrays, maximum
likelihood, and Cramér–Rao bound", IEEE TSP 2016. Per sample the readings are

    y = H [f, ω̇] + S_q q(ω) + e,   e ~ N(0, Σ),   Σ = diag(σ_i²)

(Ho & Lin 2009's model split into its linear part H = S[:, :6] and its quadratic
part S_q = S[:, 6:]). For a given ω the likelihood is maximised in closed
form by ``[f, ω̇] = H_w⁺ (y_w - S_q,w q(ω))`` (subscript w: whitened by
Σ^(-1/2)), so the ML problem reduces to the separable least squares in ω

    min_ω | P⊥ (y_w - S_q,w q(ω)) |²,   P⊥ = I - H_w H_w⁺

(variable projection). With ``A = P⊥ S_q,w`` constant for the array, the
cost is ``|b|² - 2 cᵀ q(ω) + q(ω)ᵀ M q(ω)`` with ``c = Aᵀ b`` (6 numbers per
sample) and ``M = AᵀA``, so the Newton steps (exact Hessian where it is
positive definite, else Gauss–Newton, with Levenberg–Marquardt damping) of
every sample run at once on 6-vectors. An optional gyro adds the residual
``(y_g - ω) / σ_g``.

The accelerometer-only cost is even in ω (q(-ω) = q(ω)): each sample gives ω
up to its sign. Starting points and signs:

1. every sample starts from the better (lower cost) of a coarse grid over ω
   (directions on a half sphere × log-spaced magnitudes up to
   ``max_omega_radps``) and, when S has full rank 12, the weighted least-squares
   inversion (ω from the dominant eigenvector of the estimated ω ωᵀ); a
   sample whose converged cost is implausible for the noise level of its block
   (the stated level, or the block's own where its readings misfit more)
   restarts from the best grid point of each of eight direction cones;
2. after the iterations, ``neighbour_passes`` vectorised passes restart every
   sample from its predecessor's estimate and keep the result if its cost is
   lower, which is the "start from the previous sample" rule of sequential
   ML, carried forward in parallel (a sample whose estimate is already
   within 10 % of its predecessor's, either sign, is in the same basin and
   is skipped). The result is each sample's global minimum whenever one of
   these starts reaches it;
3. the signs along each gap-free segment are chosen by a two-state Viterbi
   pass that makes ω most consistent with the trapezoidal integral of the
   estimated ω̇ (Ho & Lin 2009 resolves the sign by integrating ω̇ the same way),
   over the samples whose |ω| exceeds three times its bound, the integral
   bridging the stretches of small |ω| in between (``_resolve_signs``).
   ω̇ does not depend on the sign of ω, so this fixes the sign wherever ω
   changes over the segment; a segment with constant ω keeps the sign that
   makes its largest mean component positive.

With a gyro (``use_gyro=True``) every sample starts from the gyro reading
and the sign is fixed by the gyro.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass

import numpy as np

from .. import crb as crb_module
from .. import noise, rigid_body
from ..option import option
from ..array import SensorArray
from ..errors import DataError, InputError
from ..log import Log
from ..motion import Motion
from ..parallel import check_workers, started_map
from ..progress import progress as progress_bar
from ._common import PerSampleEstimator, checked_readings


def _fibonacci_hemisphere(n: int) -> np.ndarray:
    """(n, 3) nearly uniform unit vectors with z >= 0 (ω and -ω are equivalent)."""
    k = np.arange(n) + 0.5
    z = k / n
    phi = np.pi * (1 + 5**0.5) * k
    rho = np.sqrt(1 - z**2)
    return np.column_stack([rho * np.cos(phi), rho * np.sin(phi), z])


@dataclass(frozen=True)
class _ProjectedModel:
    """The array's model with f and ω̇ eliminated (variable projection)."""

    weights: np.ndarray  # (n,) 1/σ_i
    proj: np.ndarray  # (n, n) P⊥ W: whitened readings with the f, ω̇ directions removed
    A: np.ndarray  # (n, 6) P⊥ S_q,w
    M: np.ndarray  # (6, 6) AᵀA
    lin_y: np.ndarray  # (6, n): [f, ω̇] = lin_y @ y - lin_q @ q(ω)
    lin_q: np.ndarray  # (6, 6)
    rank: int  # rank of A: independent equations left for ω
    basis: np.ndarray  # (n, 6) Q of A = Q R (orthonormal columns)
    R: np.ndarray  # (6, 6)

    @classmethod
    def build(cls, array: SensorArray, sigma: np.ndarray) -> "_ProjectedModel":
        S = array.structure_matrix()
        wgt = 1.0 / sigma
        Hw = S[:, :6] * wgt[:, None]
        Sqw = S[:, 6:] * wgt[:, None]
        Hpinv = np.linalg.pinv(Hw)
        perp = np.eye(len(wgt)) - Hw @ Hpinv
        A = perp @ Sqw
        Q, R = np.linalg.qr(A)
        return cls(
            weights=wgt,
            proj=perp * wgt[None, :],
            A=A,
            M=A.T @ A,
            lin_y=Hpinv * wgt[None, :],
            lin_q=Hpinv @ Sqw,
            rank=int(np.sum(np.linalg.svd(A, compute_uv=False) > 1e-9 * max(np.linalg.norm(Sqw), 1e-300))),
            basis=Q,
            R=R,
        )

    def readings(self, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(z, c)`` of raw readings y (N, n): ``z`` (N, 7) holds ``Qᵀ b`` and ``|b - Q Qᵀ b|`` of the
        projected whitened readings ``b = P⊥ W y``, so that ``|b - A q|² = |z[:6] - R q|² + z[6]²``
        exactly (A = Q R; the cost :func:`_cost` works on 7 numbers per sample instead of n); ``c = Aᵀ b``."""
        b = y @ self.proj.T
        zq = b @ self.basis
        rest = b - zq @ self.basis.T
        return np.hstack([zq, np.sqrt(np.sum(rest * rest, axis=1))[:, None]]), b @ self.A


RESTART_LEVELS = ("measured", "stated")
"""The values of :attr:`MLEstimator.restart_level`."""

_CHUNK = 4096
"""Samples per block: the estimate goes block by block, each one starting its first sample's neighbour
pass from the last sample of the block before."""


class _PrepareChunk:
    """:meth:`MLEstimator._prepare_chunk` of one block (a job for :func:`gfimu.parallel.forked_map`)."""

    def __init__(self, estimator, array, model, y, gyro, gyro_var):
        self.estimator, self.array, self.model, self.y, self.gyro, self.gyro_var = estimator, array, model, y, gyro, gyro_var

    def __call__(self, sl: slice):
        return self.estimator._prepare_chunk(self.array, self.model, self.y[sl], None if self.gyro is None else self.gyro[sl],
                                             self.gyro_var)


class _Started:
    """An :meth:`MLEstimator.estimate_motion` under way (:meth:`MLEstimator.started`)."""

    def __init__(self, estimator, log, y, gyro, gyro_var, model, chunks, prepared):
        self._args = (log, y, gyro, gyro_var, model, chunks, prepared)
        self._estimator, self._prepared = estimator, prepared

    def motion(self, progress: bool = False) -> Motion:
        """The estimate (once)."""
        try:
            return self._estimator._finished(*self._args, progress)
        finally:
            self.close()

    def close(self) -> None:
        """Drop what is under way (the workers stopped, their results unread)."""
        self._prepared.close()
        self._args = None


@dataclass
class MLEstimator(PerSampleEstimator):
    """Per-sample maximum likelihood of f, ω̇ and ω (Skog et al. 2016).

    Options: ``gfimu estimate --method ml --list-options``.
    """

    method = "ml"

    compiled = True
    """The Levenberg–Marquardt iterations through the compiled kernel (:mod:`gfimu.estimators.ml_kernels`)
    in a process that has loaded numba already (the fixed-lag smoother's and the batch smoother's: their
    own kernels are compiled);
    False, or without numba loaded: the numpy expressions it replaces (the tests' oracle). The two agree
    to rounding."""

    use_gyro: bool = option(False, help=(
        "add the array's gyro as a measurement of ω (needs a gyro in the log and its noise_std_radps)"))
    compute_sigma: bool = option(False, help=(
        "one-sigma from the inverse Fisher information at the estimate (gfimu.crb); needs every axis' noise std"))
    noise_std_mps2: float | None = option(None, "m/s²", (
        "accelerometer noise std overriding array.toml (None: array.toml's; axes without one are weighted as the "
        "mean of the others, or 1 when none is given, which leaves the estimate unchanged when all are equal)"))
    max_iterations: int = option(30, help="Levenberg–Marquardt iterations per sample at most")
    tolerance_radps: float = option(1e-12, "rad/s", "Levenberg–Marquardt stops when its step in ω is smaller")
    max_omega_radps: float = option(100.0, "rad/s", "largest |ω| in the starting grid")
    neighbour_passes: int = option(3, help="restarts from the previous sample (module docstring)")
    restart_level: str = option("measured", help=(
        "noise level against which a sample's cost calls for a restart from the eight direction cones: "
        "'measured' (the stated level, or the block's own where its readings misfit more: a real array, "
        "whose every sample would restart otherwise) or 'stated' (the stated level alone: slower on such "
        "logs, restarts that seldom change the answer)"))
    grid_directions: int = option(64, help="directions of ω in the starting grid")
    grid_magnitudes: int = option(16, help="magnitudes of ω in the starting grid")
    workers: int = option(0, "processes", (
        "processes that start the blocks of 4,096 samples, from four blocks on: 0 = one per CPU, 1 = this "
        "process alone (the same numbers either way)"))

    def __post_init__(self):
        check_workers(self.workers)
        if self.restart_level not in RESTART_LEVELS:
            raise InputError(f"ml option restart_level must be one of {', '.join(RESTART_LEVELS)}, "
                             f"got {self.restart_level!r}")
        for name in ("grid_directions", "grid_magnitudes"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise InputError(f"ml option {name} must be a whole number >= 1 (the size of the starting grid), "
                                 f"got {value!r}")
        if not (isinstance(self.max_omega_radps, (int, float)) and math.isfinite(self.max_omega_radps)
                and self.max_omega_radps > 0):
            raise InputError(f"ml option max_omega_radps must be a number > 0 [rad/s] (the largest |ω| of the "
                             f"starting grid), got {self.max_omega_radps!r}")

    # ------------------------------------------------------------------
    def applicable(self, array: SensorArray) -> str | None:
        reason = array.geometry_reason()
        if reason:
            return reason
        S = array.structure_matrix()
        lin = S[:, :6]
        if np.linalg.matrix_rank(lin, tol=1e-9 * max(np.abs(lin).max(), 1e-300)) < 6:
            return (
                f"array {array.name!r}: the accelerometer directions and lever arms do not determine f and ω̇ "
                "(rank of the linear part below 6); use 'free-flight' for a single triad"
            )
        if self.use_gyro:
            if array.gyroscope is None:
                return f"array {array.name!r} has no gyroscope (use_gyro=True)"
            if array.gyroscope.noise_std_radps is None:
                return f"array {array.name!r}: gyroscope has no noise_std_radps (needed by use_gyro=True)"
            return None
        model = _ProjectedModel.build(array, np.ones(array.n_axes))
        if model.rank == 3:
            return (
                f"array {array.name!r}: once f and ω̇ are eliminated only 3 independent equations remain for "
                "the 3 components of ω, so each sample has several exact solutions; add an axis off the "
                "current layout, a gyroscope (use_gyro=True) or use method 'smoother'"
            )
        w = np.array([0.37, -0.81, 0.52])
        sens = model.A @ rigid_body.quadratic_terms_jacobian(w)  # (n, 3) projected ∂y/∂ω
        scale = np.linalg.norm(array.structure_matrix()[:, 6:] @ rigid_body.quadratic_terms_jacobian(w))
        if np.linalg.svd(sens, compute_uv=False)[-1] <= 1e-9 * max(scale, 1e-300):
            return (
                f"array {array.name!r}: ω is not observable from the accelerometers once f and ω̇ are "
                "eliminated (too few axes or degenerate layout); add a gyroscope and use use_gyro=True"
            )
        return None

    def _axis_sigma(self, array: SensorArray) -> np.ndarray:
        if self.noise_std_mps2 is not None:
            return crb_module.axis_noise_std(array, self.noise_std_mps2)
        return noise.accel_noise_std(array)

    # ------------------------------------------------------------------
    def estimate_motion(self, log: Log, progress: bool = False) -> Motion:
        return self.started(log).motion(progress)

    def started(self, log: Log) -> _Started:
        """:meth:`estimate_motion` begun: the log checked and the blocks' first part (:meth:`_prepare_chunk`)
        handed to the worker processes, which work on it while this process does something else;
        :meth:`_Started.motion` finishes it (the same numbers), :meth:`_Started.close` drops it."""
        array = log.array
        y = checked_readings(self, log, "ml")
        gyro = None
        gyro_var = None
        if self.use_gyro:
            if log.gyro_b_radps is None:
                raise InputError(f"{log.source}: use_gyro=True but the log has no gyro columns")
            gyro = log.gyro_b_radps
            if not np.all(np.isfinite(gyro)):
                raise DataError(f"{log.source}: non-finite gyro reading at sample {int(np.argwhere(~np.isfinite(gyro))[0, 0])}")
            gyro_var = float(array.gyroscope.noise_std_radps) ** 2
        sigma = self._axis_sigma(array)
        model = _ProjectedModel.build(array, sigma)
        n = len(log)
        chunks = [slice(start, min(start + _CHUNK, n)) for start in range(0, n, _CHUNK)]
        # what each block needs of no other, in worker processes; then the blocks in turn, each
        # continuing from the last sample of the one before
        prepared = started_map(_PrepareChunk(self, array, model, y, gyro, gyro_var), chunks, self.workers, min_tasks=4)
        return _Started(self, log, y, gyro, gyro_var, model, chunks, prepared)

    def _finished(self, log, y, gyro, gyro_var, model, chunks, prepared, progress) -> Motion:
        """The rest of :meth:`estimate_motion` from the blocks' first part (``prepared``, in block order)."""
        n = len(log)
        omega = np.empty((n, 3))
        previous = None
        for sl, prep in progress_bar(zip(chunks, prepared), total=len(chunks), desc="ml", enable=progress):
            omega[sl] = self._finish_chunk(model, prep, None if gyro is None else gyro[sl], gyro_var, previous)
            previous = omega[sl.stop - 1]
        q = rigid_body.quadratic_terms(omega)
        lin = y @ model.lin_y.T - q @ model.lin_q.T
        f, dw = lin[:, :3], lin[:, 3:]
        if gyro is None:
            omega = _resolve_signs(omega, dw, log, _omega_sigma(model, omega))
        sig = {}
        if self.compute_sigma:
            bound = crb_module.crb_per_sample(
                log.array, omega, noise_std_mps2=self.noise_std_mps2,
                gyro_noise_std_radps=None if gyro is None else float(np.sqrt(gyro_var)),
            )
            sig = {
                "omega_b_radps": bound.sigma_omega,
                "omega_dot_b_radps2": bound.sigma_omega_dot,
                "specific_force_b_mps2": bound.sigma_specific_force,
            }
        return Motion(log.timestamps_ns, omega_b_radps=omega, omega_dot_b_radps2=dw, specific_force_b_mps2=f, sigma=sig)

    # ------------------------------------------------------------------
    def _prepare_chunk(self, array, model, y, gyro, gyro_var):
        """The part of a block's estimate that needs no other block: (b, c, ω, cost, restarts) with ω
        iterated from the grid or inversion start and ``restarts`` (:meth:`_restarts`) for every sample
        whose cost at that ω calls for one (None with a gyro). The neighbour passes only lower costs,
        so the samples that call for a restart after them are among these."""
        b, c = model.readings(y)  # (N, 7) the projected whitened readings reduced, (N, 6) Aᵀ b
        w = self._iterate(model, b, c, self._start(array, model, y, c, gyro), gyro, gyro_var)
        cost = _cost(model, b, w, gyro, gyro_var)
        if gyro is not None:
            return b, c, w, cost, None
        level = self._misfit_level(model, cost)
        return b, c, w, cost, (level, *self._restarts(model, b, c, self._restart_rows(model, cost, level)))

    def _finish_chunk(self, model, prepared, gyro, gyro_var, previous):
        """The neighbour passes from ``previous`` (the estimate just before the block), then the restarts."""
        b, c, w, cost, restarts = prepared
        w, cost = w.copy(), cost.copy()
        moved = np.ones(len(w), bool)  # samples whose start (the sample before) changed in the last pass
        for _ in range(self.neighbour_passes):
            first = w[:1] if previous is None else np.asarray(previous)[None, :]
            prev = np.vstack([first, w[:-1]])
            # a start within 10 % of the current estimate (either sign) lies in its basin: skip it; so is
            # a start that has not changed since the last pass (the iterations per sample are independent
            # and deterministic: it would give the candidate already turned down)
            gap = np.minimum(np.linalg.norm(prev - w, axis=1), np.linalg.norm(prev + w, axis=1))
            idx = np.nonzero((gap > 0.1 * np.linalg.norm(w, axis=1) + 1e-6) & moved)[0]
            if idx.size == 0:
                break
            cand = self._iterate(model, b[idx], c[idx], prev[idx], None if gyro is None else gyro[idx], gyro_var)
            cand_cost = _cost(model, b[idx], cand, None if gyro is None else gyro[idx], gyro_var)
            better = cand_cost < cost[idx] * (1 - 1e-9)
            if not np.any(better):
                break
            w[idx[better]] = cand[better]
            cost[idx[better]] = cand_cost[better]
            moved = np.zeros(len(w), bool)
            changed = idx[better] + 1
            moved[changed[changed < len(w)]] = True
        if restarts is None:
            return w
        level, rows, best, best_cost = restarts
        keep = np.isin(rows, self._restart_rows(model, cost, level))
        return self._take_restarts(w, cost, rows[keep], best[keep], best_cost[keep])

    def _misfit_level(self, model, cost) -> float:
        """The block's noise level over the stated one, as the variance ratio s² ≥ 1 its costs show
        (``restart_level`` 'measured'; 1 with 'stated'): the median cost over the median of χ² with
        n_axes - 9 degrees of freedom (Wilson-Hilferty: ν (1 - 2/(9ν))³). A median, so that the samples
        stuck in local minima, a minority, do not raise it; on a block whose readings follow the stated
        noise it is 1 (the median of 4,096 costs scatters by under 1 %)."""
        if self.restart_level == "stated" or cost.size == 0:
            return 1.0
        dof = max(model.A.shape[0] - 9, 1)
        return max(1.0, float(np.median(cost)) / (dof * (1.0 - 2.0 / (9.0 * dof)) ** 3))

    @staticmethod
    def _restart_rows(model, cost, level: float = 1.0) -> np.ndarray:
        """The samples whose cost calls for a restart (:meth:`_restarts`, taken by :meth:`_take_restarts`):
        those whose cost is implausibly high for the noise level ``level`` × the stated one (variance
        ratio, :meth:`_misfit_level`).

        With the noise model right, the minimum cost is about χ² with
        n_axes - 9 degrees of freedom; a sample above its mean + 6 standard
        deviations (+ 3), the costs scaled by ``level``, sits in a local minimum. Measured rather than
        stated, the level keeps that test where the readings misfit more than the stated noise (a real
        array: on the MIMU4444 recordings every sample's cost is beyond the stated level's threshold, and
        restarting them all took 70 % of the estimate's time for answers that seldom changed). When
        the projected model has rank below 6 (fewer than 12 useful axes) the
        cost surface has plausible local minima, and every sample restarts.
        A restart replaces the estimate only if it at least halves the cost:
        on real recordings, whose errors are not the modelled noise, a
        slightly lower but distant minimum is more often wrong than the
        estimate that the grid, inversion and neighbour starts gave.
        """
        dof = max(model.A.shape[0] - 9, 1)
        if model.rank < 6:
            return np.arange(len(cost))  # few redundant equations: local minima are common, restart all
        return np.nonzero(cost > level * (dof + 6 * np.sqrt(2 * dof)) + 3)[0]

    def _restarts(self, model, b, c, rows):
        """(rows, best ω (k, 3), its cost (k,)) of the restarts of samples ``rows`` from the best grid point
        of every cone; each sample's own data alone decide them."""
        if rows.size == 0:
            return rows, np.zeros((0, 3)), np.zeros(0)
        grid, cone = self._grid()
        order = np.argsort(cone, kind="stable")  # the grid cone by cone, each in its own order
        grid, bounds = grid[order], np.searchsorted(cone[order], np.arange(_CONES + 1))
        grid_cost = self._grid_cost(model, c[rows], grid)
        starts = np.empty((rows.size, _CONES, 3))
        for k in range(_CONES):
            starts[:, k] = grid[bounds[k] + np.argmin(grid_cost[:, bounds[k]:bounds[k + 1]], axis=1)]
        rep = np.repeat(rows, _CONES)
        cand = self._iterate(model, b[rep], c[rep], starts.reshape(-1, 3), None, None)
        cand_cost = _cost(model, b[rep], cand, None, None).reshape(rows.size, _CONES)
        pick = np.argmin(cand_cost, axis=1)
        return rows, cand.reshape(rows.size, _CONES, 3)[np.arange(rows.size), pick], cand_cost[np.arange(rows.size), pick]

    @staticmethod
    def _take_restarts(w, cost, rows, best, best_cost):
        """``w`` with the restarts that at least halve the cost."""
        if rows.size == 0:
            return w
        better = best_cost < 0.5 * cost[rows]
        w = w.copy()
        w[rows[better]] = best[better]
        return w

    def _grid(self):
        """Starting grid: (G, 3) points and the index (G,) of the direction cone of each."""
        dirs = _fibonacci_hemisphere(self.grid_directions)
        centres = _fibonacci_hemisphere(_CONES)
        cone = np.argmax(np.abs(dirs @ centres.T), axis=1)  # ω and -ω are equivalent
        mags = np.geomspace(1e-2, self.max_omega_radps, self.grid_magnitudes)
        grid = (mags[:, None, None] * dirs[None, :, :]).reshape(-1, 3)
        return grid, np.tile(cone, len(mags))

    def _grid_cost(self, model, c, grid):
        Qg = rigid_body.quadratic_terms(grid)
        quad = np.sum(Qg * (Qg @ model.M), axis=1)
        out = c @ (-2.0 * Qg.T)
        out += quad[None, :]
        return out  # cost up to the per-sample constant |b|²

    def _grid_best(self, model, c, grid):
        """(index (N,), cost (N,)) of the grid point of least :meth:`_grid_cost` per sample: the same
        numbers, taken :data:`_GRID_ROWS` samples at a time so that the costs of one block stay in the
        cache between the product, the sum and the minimum."""
        best = np.empty(len(c), dtype=np.intp)
        cost = np.empty(len(c))
        for start in range(0, len(c), _GRID_ROWS):
            block = self._grid_cost(model, c[start:start + _GRID_ROWS], grid)
            k = np.argmin(block, axis=1)
            best[start:start + len(k)] = k
            cost[start:start + len(k)] = block[np.arange(len(k)), k]
        return best, cost

    def _start(self, array, model, y, c, gyro):
        """Starting ω per sample: gyro, else the best of grid and inversion."""
        if gyro is not None:
            return gyro.copy()
        grid, _ = self._grid()
        best, best_cost = self._grid_best(model, c, grid)
        start = grid[best]
        S = array.structure_matrix()
        if S.shape[0] >= 12 and np.linalg.matrix_rank(S) == 12:
            Sw = S * model.weights[:, None]
            x = (y * model.weights[None, :]) @ np.linalg.pinv(Sw).T
            inv_w = _omega_from_q(x[:, 6:])
            qi = rigid_body.quadratic_terms(inv_w)
            inv_cost = np.sum(qi * (qi @ model.M - 2 * c), axis=1)
            better = inv_cost < best_cost
            start = np.where(better[:, None], inv_w, start)
        return start

    def _iterate(self, model, b, c, w, gyro, gyro_var):
        """Levenberg–Marquardt on ω for all samples at once. The 3 × 3 matrices are symmetric and kept
        as their six entries (:data:`_SYMMETRIC`), the systems solved in closed form
        (:func:`_solve_symmetric_3x3`). With :attr:`compiled` (the default) and numba loaded the same
        iterations run sample by sample in :func:`gfimu.estimators.ml_kernels.iterate`; the numpy
        expressions below are its oracle."""
        gram = _jacobian_gram(model.M)[:, _SYMMETRIC_FLAT]
        qm = _MONOMIAL_TO_Q @ model.M  # q(ω) M from the monomials of ω
        curvature = _Q_HESSIAN_FLAT[:, _SYMMETRIC_FLAT]
        tol2 = self.tolerance_radps**2
        if self.compiled and len(w) and "numba" in sys.modules:
            # the same iterations sample by sample, compiled (gfimu.estimators.ml_kernels), where numba is
            # already loaded (the fixed-lag smoother's process): a command that loads it for nothing else
            # would pay more for its import than the compiled iterations save
            from .ml_kernels import iterate

            g = np.zeros((len(w), 3)) if gyro is None else np.ascontiguousarray(gyro, dtype=float)
            return iterate(np.ascontiguousarray(b, dtype=float), np.ascontiguousarray(c, dtype=float),
                           np.ascontiguousarray(w, dtype=float), np.ascontiguousarray(model.R, dtype=float),
                           np.ascontiguousarray(qm), np.ascontiguousarray(gram), np.ascontiguousarray(curvature), g,
                           1.0 if gyro_var is None else float(gyro_var), gyro is not None, int(self.max_iterations),
                           float(tol2))
        # the samples still iterating, compacted: each array holds only their rows, and a sample's
        # rows leave all of them at once when it stops (the arithmetic of every sample is its own)
        w = w.copy()
        rows = np.arange(len(w))
        wi, bi, ci = w.copy(), b, c
        gi = gyro
        lam = np.full(len(w), 1e-3)
        cost = _cost(model, bi, wi, gi, gyro_var)
        for _ in range(self.max_iterations):
            if rows.size == 0:
                break
            mono = _monomials(wi)
            g6 = ci - mono @ qm  # Aᵀ r with r = b - A q
            grad = _quadratic_terms_jacobian_t(wi, g6)  # -½ ∂cost/∂ω
            JtJ = mono @ gram  # J_qᵀ M J_q
            # exact Hessian: q is quadratic, so the residual curvature term is -Σ_j (Aᵀr)_j ∂²q_j/∂ω²;
            # with noise (non-zero residual) it turns Gauss–Newton's linear convergence into Newton's
            hess = JtJ - g6 @ curvature
            tr = np.maximum(JtJ[:, 0] + JtJ[:, 3] + JtJ[:, 5], 1e-300)
            h00, h01, h11 = hess[:, 0], hess[:, 1], hess[:, 3]
            pos_def = ((h00 > 1e-12 * tr) & (h00 * h11 - h01 * h01 > 1e-12 * tr**2)
                       & (_det_symmetric_3x3(hess) > 1e-12 * tr**3))  # Sylvester
            JtJ = np.where(pos_def[:, None], hess, JtJ)
            if gi is not None:
                grad = grad + (gi - wi) / gyro_var
                JtJ[:, _DIAGONAL] += 1.0 / gyro_var
            diag = JtJ[:, _DIAGONAL]
            scale = np.maximum(diag, 1e-12 * np.max(diag, axis=1, keepdims=True) + 1e-300)
            JtJ[:, _DIAGONAL] = diag + lam[:, None] * scale
            step = _solve_symmetric_3x3(JtJ, grad)
            trial = wi + step
            tcost = _cost(model, bi, trial, gi, gyro_var)
            ok = tcost <= cost
            gain = cost - tcost
            size = 1.0 + np.sqrt(np.einsum("ij,ij->i", wi, wi))
            wi = np.where(ok[:, None], trial, wi)
            cost = np.where(ok, tcost, cost)
            lam = np.where(ok, np.maximum(lam / 10, 1e-12), lam * 10)
            small = np.einsum("ij,ij->i", step, step) <= tol2 * size * size
            flat = gain <= 1e-15 * (tcost + 1e-300)  # cost settled to rounding (noisy data)
            done = (ok & (small | flat)) | (lam > 1e12)
            if np.any(done):
                w[rows[done]] = wi[done]
                keep = ~done
                rows, wi, bi, ci, lam, cost = rows[keep], wi[keep], bi[keep], ci[keep], lam[keep], cost[keep]
                gi = None if gi is None else gi[keep]
        w[rows] = wi
        return w


_Q_JACOBIAN_UNIT = rigid_body.quadratic_terms_jacobian(np.eye(3))
"""(3, 6, 3): ∂q/∂ω at the unit vectors; ∂q/∂ω at ω is Σ_i ω_i of these (q is quadratic)."""


def _jacobian_gram(M: np.ndarray) -> np.ndarray:
    """(6, 9) ``G`` with ``J_q(ω)ᵀ M J_q(ω) = (m(ω) G).reshape(3, 3)``, m the monomials of
    :func:`_monomials`: with ``J_q(ω) = Σ_i ω_i E_i`` the product is ``Σ_ik ω_i ω_k E_iᵀ M E_k``."""
    E = _Q_JACOBIAN_UNIT
    K = np.einsum("ija,jk,lkb->ilab", E, M, E)
    return np.stack([K[0, 0], K[1, 1], K[2, 2], K[0, 1] + K[1, 0], K[0, 2] + K[2, 0], K[1, 2] + K[2, 1]]).reshape(6, 9)


def _monomials(w: np.ndarray) -> np.ndarray:
    """(N, 6) ``x², y², z², xy, xz, yz`` of ω (N, 3)."""
    x, y, z = w[:, 0], w[:, 1], w[:, 2]
    return np.stack([x * x, y * y, z * z, x * y, x * z, y * z], axis=1)


def _quadratic_terms_jacobian_t(w: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``J_q(ω)ᵀ v`` (N, 3) for ω (N, 3) and v (N, 6), written out from :func:`gfimu.rigid_body.quadratic_terms_jacobian`."""
    x, y, z = w[:, 0], w[:, 1], w[:, 2]
    return np.stack([2 * x * (v[:, 0] + v[:, 1]) + y * v[:, 3] + z * v[:, 4],
                     2 * y * (v[:, 0] + v[:, 2]) + x * v[:, 3] + z * v[:, 5],
                     2 * z * (v[:, 1] + v[:, 2]) + x * v[:, 4] + y * v[:, 5]], axis=1)


def _det_symmetric_3x3(m: np.ndarray) -> np.ndarray:
    """Determinants of symmetric 3 × 3 matrices given as their six entries (N, 6) (:data:`_SYMMETRIC`)."""
    a, b, c, d, e, f = m.T
    return a * (d * f - e * e) + b * (c * e - b * f) + c * (b * e - c * d)


def _solve_symmetric_3x3(m: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """x (N, 3) with ``m x = rhs`` for symmetric positive definite 3 × 3 matrices given as their six
    entries m (N, 6) (:data:`_SYMMETRIC`; the damped LM systems): the adjugate over the determinant
    of each matrix scaled to unit diagonal (Jacobi), so that the closed form meets no range or
    cancellation issue the scaling can avoid; a matrix whose scaled determinant is not positive
    (not definite to rounding) falls back to LU."""
    s0, s1, s2 = 1.0 / np.sqrt(np.maximum(m[:, _DIAGONAL], 1e-300)).T
    a, d, f = m[:, 0] * s0 * s0, m[:, 3] * s1 * s1, m[:, 5] * s2 * s2
    b, c, e = m[:, 1] * (s0 * s1), m[:, 2] * (s0 * s2), m[:, 4] * (s1 * s2)
    r0, r1, r2 = rhs[:, 0] * s0, rhs[:, 1] * s1, rhs[:, 2] * s2
    c00, c01, c02 = d * f - e * e, c * e - b * f, b * e - c * d
    c11, c12, c22 = a * f - c * c, b * c - a * e, a * d - b * b
    det = a * c00 + b * c01 + c * c02
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        inv = 1.0 / det
        x = np.stack([(c00 * r0 + c01 * r1 + c02 * r2) * inv * s0, (c01 * r0 + c11 * r1 + c12 * r2) * inv * s1,
                      (c02 * r0 + c12 * r1 + c22 * r2) * inv * s2], axis=1)
    bad = ~(det > 1e-12)
    if np.any(bad):
        full = m[bad][:, _SYMMETRIC_UNPACK].reshape(-1, 3, 3)
        x[bad] = np.linalg.solve(full, rhs[bad][..., None])[..., 0]
    return x


_GRID_ROWS = 128
"""Samples whose starting-grid costs are taken at once (:meth:`MLEstimator._grid_best`): 128 x 1,024 costs,
1 MB, stay in the cache."""

_CONES = 8
"""Direction cones of the multi-start (see ``MLEstimator._restarts``)."""

_Q_HESSIAN = np.array(
    [
        [[2, 0, 0], [0, 2, 0], [0, 0, 0]],
        [[2, 0, 0], [0, 0, 0], [0, 0, 2]],
        [[0, 0, 0], [0, 2, 0], [0, 0, 2]],
        [[0, 1, 0], [1, 0, 0], [0, 0, 0]],
        [[0, 0, 1], [0, 0, 0], [1, 0, 0]],
        [[0, 0, 0], [0, 0, 1], [0, 1, 0]],
    ],
    dtype=float,
)
"""∂²q_j/∂ω² for the six quadratic terms (constant)."""
_Q_HESSIAN_FLAT = _Q_HESSIAN.reshape(6, 9)
_SYMMETRIC = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))
"""The six entries that a symmetric 3 × 3 matrix is kept as in the LM iterations."""
_SYMMETRIC_FLAT = np.array([3 * i + j for i, j in _SYMMETRIC])
_SYMMETRIC_UNPACK = np.array([0, 1, 2, 1, 3, 4, 2, 4, 5])  # the six entries -> the nine, row by row
_DIAGONAL = np.array([0, 3, 5])
_MONOMIAL_TO_Q = np.array([[1, 1, 0, 0, 0, 0], [1, 0, 1, 0, 0, 0], [0, 1, 1, 0, 0, 0],
                           [0, 0, 0, 1, 0, 0], [0, 0, 0, 0, 1, 0], [0, 0, 0, 0, 0, 1]], dtype=float)
"""q(ω) = m(ω) @ this, m the monomials x², y², z², xy, xz, yz (:func:`_monomials`)."""


def _cost(model: _ProjectedModel, b: np.ndarray, w: np.ndarray, gyro, gyro_var) -> np.ndarray:
    """Negative log-likelihood (×2, f and ω̇ eliminated) per sample, from the residual itself:
    ``|b - A q|²`` as ``|z - R q|² + |b⊥|²`` of the reduced readings ``b`` (:meth:`_ProjectedModel.readings`)."""
    r = b[:, :6] - rigid_body.quadratic_terms(w) @ model.R.T
    cost = np.sum(r * r, axis=1) + b[:, 6] * b[:, 6]
    if gyro is not None:
        cost = cost + np.sum((gyro - w) ** 2, axis=1) / gyro_var
    return cost


def _omega_from_q(q: np.ndarray) -> np.ndarray:
    """ω (up to sign) from estimated quadratic terms: dominant eigenpair of ω ωᵀ."""
    sq = 0.5 * np.stack([q[:, 0] + q[:, 1] - q[:, 2], q[:, 0] - q[:, 1] + q[:, 2], -q[:, 0] + q[:, 1] + q[:, 2]], axis=1)
    W = np.empty((len(q), 3, 3))
    W[:, [0, 1, 2], [0, 1, 2]] = sq
    W[:, 0, 1] = W[:, 1, 0] = q[:, 3]
    W[:, 0, 2] = W[:, 2, 0] = q[:, 4]
    W[:, 1, 2] = W[:, 2, 1] = q[:, 5]
    vals, vecs = np.linalg.eigh(W)
    return vecs[:, :, -1] * np.sqrt(np.clip(vals[:, -1], 0.0, None))[:, None]


def _omega_sigma(model: _ProjectedModel, omega: np.ndarray) -> np.ndarray:
    """sqrt(trace Cov ω) of the accelerometer-only bound at each ω (inf near ω = 0), (N,)."""
    Dq = rigid_body.quadratic_terms_jacobian(omega)
    info = np.swapaxes(Dq, 1, 2) @ (model.M @ Dq)
    tr = np.trace(info, axis1=1, axis2=2)
    det = np.linalg.det(info)
    ok = det > 1e-12 * np.maximum(tr, 1e-300) ** 3
    out = np.full(len(omega), np.inf)
    if np.any(ok):
        out[ok] = np.sqrt(np.trace(np.linalg.inv(info[ok]), axis1=1, axis2=2))
    return out


def _resolve_signs(omega: np.ndarray, omega_dot: np.ndarray, log: Log, sigma_omega: np.ndarray) -> np.ndarray:
    """Signs of ω along each gap-free segment (see module docstring).

    Samples with |ω| > 3 σ (σ from the bound at the estimate) are "confident":
    their signs come from a two-state Viterbi pass whose transition cost
    between consecutive confident samples j < k is
    ``|s_k u_k - s_j u_j - ∫_j^k ω̇|²``, so that stretches of small |ω| are
    bridged by the integral of ω̇ alone. (Weighting the transitions by the
    bound made the signs worse on real MIMU4444 recordings, whose errors are
    not the modelled white noise.) Every other sample takes the sign closest
    to the nearest confident sample's ω carried over by the integral of ω̇.
    """
    out = omega.copy()
    t = log.times_s
    for seg in log.segments():
        u = omega[seg]
        m = len(u)
        if m == 0:
            continue
        if m == 1:
            out[seg] = _canonical(u)
            continue
        dt = np.diff(t[seg])
        dw = omega_dot[seg]
        integral = np.vstack([np.zeros((1, 3)), np.cumsum(0.5 * dt[:, None] * (dw[1:] + dw[:-1]), axis=0)])
        sig = sigma_omega[seg]
        conf = np.linalg.norm(u, axis=1) > 3 * sig
        idx = np.nonzero(conf)[0]
        if idx.size == 0:
            idx = np.arange(m)
        signs = np.ones(m)
        signs[idx] = _viterbi_signs(u[idx], integral[idx])
        rest = np.setdiff1d(np.arange(m), idx)
        if rest.size:
            pos = np.searchsorted(idx, rest)  # first confident index after each rest sample
            before = pos > 0
            anchor = np.where(before, idx[np.maximum(pos - 1, 0)], idx[np.minimum(pos, idx.size - 1)])
            pred = signs[anchor][:, None] * u[anchor] + integral[rest] - integral[anchor]
            d = np.sum(u[rest] * pred, axis=1)
            signs[rest] = np.where(d < 0, -1.0, 1.0)
        out[seg] = u * signs[:, None]
    return out


def _viterbi_signs(u: np.ndarray, integral: np.ndarray) -> np.ndarray:
    """±1 per row of ``u`` minimising the transition costs (see :func:`_resolve_signs`)."""
    m = len(u)
    if m == 1:
        return _canonical(u)[0] @ u[0] / max(u[0] @ u[0], 1e-300) * np.ones(1)
    inc = np.diff(integral, axis=0)
    cur, prev = u[1:], u[:-1]
    costs = np.empty((m - 1, 2, 2))
    for a, sa in enumerate((1.0, -1.0)):
        for b, sb in enumerate((1.0, -1.0)):
            costs[:, a, b] = np.sum((sb * cur - sa * prev - inc) ** 2, axis=1)
    # the two-state recursion on plain floats (the sums and comparisons in the same order, one list of
    # back pointers per state): the loop is the only per-sample Python work of the estimate
    back0, back1 = [], []
    a0, a1 = 0.0, 0.0
    for c00, c01, c10, c11 in costs.reshape(m - 1, 4).tolist():
        n0a, n0b = a0 + c00, a1 + c10
        n1a, n1b = a0 + c01, a1 + c11
        if n0a <= n0b:
            back0.append(0)
            b0 = n0a
        else:
            back0.append(1)
            b0 = n0b
        if n1a <= n1b:
            back1.append(0)
            a1 = n1a
        else:
            back1.append(1)
            a1 = n1b
        a0 = b0
    tie = abs(a0 - a1) <= 1e-12 * max(a0, a1, 1e-300)
    s = 0 if tie else int(a1 < a0)
    path = [s]
    for k in range(m - 2, -1, -1):
        s = back1[k] if s else back0[k]
        path.append(s)
    state = np.array(path[::-1], dtype=np.int8)
    signs = np.where(state == 0, 1.0, -1.0)
    if tie:
        # no sign information (ω̇ = 0 throughout): largest mean component positive
        mean = (u * signs[:, None]).mean(axis=0)
        if mean[np.argmax(np.abs(mean))] < 0:
            signs = -signs
    return signs


def _canonical(u: np.ndarray) -> np.ndarray:
    idx = np.argmax(np.abs(u), axis=1)
    s = np.sign(u[np.arange(len(u)), idx])
    s[s == 0] = 1.0
    return u * s[:, None]
