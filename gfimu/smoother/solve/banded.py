"""Banded Gauss-Newton / Levenberg-Marquardt core of the batch smoother, linear in the length.

The factors of a :class:`gfimu.smoother.model.problem.SmootherProblem` are evaluated
vectorised over all samples; their Gauss-Newton normal equations are
block-tridiagonal in the per-sample states (plus a dense border for the
calibration variables), solved by a banded Cholesky factorisation and a
Schur complement on the border. The marginal covariances come from the same
factor by a backward block recursion (selected inversion), also linear in
the length.

Also the re-weighting schedule of the motion-dependent accelerometer noise and the robust
losses (:func:`solve_reweighted`). This module holds the solver only; the batch estimator
(:mod:`gfimu.smoother.batch.engine`), the noise tuner (:mod:`gfimu.smoother.tuning.evidence`)
and the initialisation (:mod:`gfimu.smoother.solve.initialise`) build on it.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from scipy.linalg import cho_solve_banded, cholesky_banded

from ..model.option_groups import BatchModelOptions, BatchOptions
from ..model.groups import AccelerometerGroup, MotionModelGroup
from ..model.problem import SmootherProblem, robust_weight


@dataclass
class NormalEquations:
    """Gauss-Newton system ``H δ = -g`` with H = [[A, C], [Cᵀ, B]], A block-tridiagonal.

    ``diag`` (N, 9, 9) and ``lower`` (N-1, 9, 9) are A's blocks (``lower[k]``
    = A[k+1, k]); ``coupling`` (N, 9, G) = C; ``border`` (G, G) = B.
    """

    diag: np.ndarray
    lower: np.ndarray
    grad: np.ndarray
    coupling: np.ndarray
    border: np.ndarray
    grad_global: np.ndarray
    cost: float
    rows: int | None = None
    """Number of whitened residual rows."""
    terms: list | None = None
    """The terms summed, when every row came from one (None when a group added its products in
    closed form, :meth:`gfimu.smoother.model.groups.FactorGroup.accumulate`)."""


def normal_equations(problem: SmootherProblem, states: np.ndarray, params: np.ndarray, terms=None) -> NormalEquations:
    """Accumulate JᵀJ and Jᵀr of all factors (or of ``terms``), vectorised."""
    n, G, M = problem.n, problem.n_global, problem.state_size
    diag = np.zeros((n, M, M))
    lower = np.zeros((n - 1, M, M))
    grad = np.zeros((n, M))
    coupling = np.zeros((n, M, G))
    border = np.zeros((G, G))
    grad_g = np.zeros(G)
    cost = 0.0
    rows = 0
    complete = terms is not None
    if terms is None:  # the groups with closed-form products add them directly (FactorGroup.accumulate)
        terms, complete = [], True
        for group in problem.groups:
            done = group.accumulate(problem, states, params, diag, lower, grad)
            if done is None:
                terms.extend(group.terms(problem, states, params))
            else:
                cost += done[0]
                rows += done[1]
                complete = False
    for t in terms:
        r = t.residual
        cost += 0.5 * float(np.sum(r * r))
        rows += r.size
        if t.kind == "unary":
            J = t.jac["x"]
            k0, k1 = t.first, t.first + r.shape[0]
            JT = np.swapaxes(J, 1, 2)
            diag[k0:k1] += JT @ J
            grad[k0:k1] += np.einsum("nij,nj->ni", JT, r)
            if t.jac_global is not None:
                Jg = t.jac_global
                coupling[k0:k1] += JT @ Jg
                border += np.einsum("nri,nrj->ij", Jg, Jg)
                grad_g += np.einsum("nri,nr->i", Jg, r)
        elif t.kind == "binary":
            J0, J1 = t.jac["x0"], t.jac["x1"]
            J0T, J1T = np.swapaxes(J0, 1, 2), np.swapaxes(J1, 1, 2)
            diag[:-1] += J0T @ J0
            diag[1:] += J1T @ J1
            lower += J1T @ J0
            grad[:-1] += np.einsum("nij,nj->ni", J0T, r)
            grad[1:] += np.einsum("nij,nj->ni", J1T, r)
        else:
            Jg = t.jac_global
            border += np.einsum("nri,nrj->ij", Jg, Jg)
            grad_g += np.einsum("nri,nr->i", Jg, r)
    return NormalEquations(diag, lower, grad, coupling, border, grad_g, cost, rows, list(terms) if complete else None)


def add_normal_equations(a: NormalEquations, b: NormalEquations) -> NormalEquations:
    """Normal equations of the union of two sets of factors on the same states."""
    terms = a.terms + b.terms if a.terms is not None and b.terms is not None else None
    return NormalEquations(a.diag + b.diag, a.lower + b.lower, a.grad + b.grad, a.coupling + b.coupling, a.border + b.border,
                           a.grad_global + b.grad_global, a.cost + b.cost, (a.rows or 0) + (b.rows or 0), terms)


def to_lower_banded(diag: np.ndarray, lower: np.ndarray) -> np.ndarray:
    """LAPACK lower band storage (2m, N m) of a block-tridiagonal symmetric matrix."""
    n, m, _ = diag.shape
    ab = np.zeros((2 * m, n * m))
    for c in range(m):
        for d in range(2 * m):
            row = c + d
            if row < m:
                ab[d, c::m] = diag[:, row, c]
            elif row < 2 * m:
                ab[d, c::m][: n - 1] = lower[:, row - m, c]
    return ab


def factor_blocks(cb: np.ndarray, n: int, m: int) -> tuple[np.ndarray, np.ndarray]:
    """Blocks L[k, k] (N, m, m) and L[k+1, k] (N-1, m, m) of a lower band Cholesky factor (any
    number of band rows up to 2m; entries beyond the band are zero)."""
    Lkk = np.zeros((n, m, m))
    Lnext = np.zeros((n - 1, m, m))
    for c in range(m):
        for d in range(min(2 * m, cb.shape[0])):
            row = c + d
            if row < m:
                Lkk[:, row, c] = cb[d, c::m]
            elif row < 2 * m:
                Lnext[:, row - m, c] = cb[d, c::m][: n - 1]
    return Lkk, Lnext


@dataclass(frozen=True)
class BandStructure:
    """Where the entries of a block-tridiagonal matrix go in LAPACK lower band storage, reordering
    the state within each sample so that the band is as narrow as the coupling allows.

    The coupling between neighbouring samples (the ``lower`` blocks) is sparse: the motion model
    ties ω and ω̇ of one axis to the same axis at the next sample, the specific force to itself.
    Ordering the state per sample by groups of variables coupled across samples (e.g.
    ``ωx, ω̇x, ωy, ω̇y, ωz, ω̇z, fx, fy, fz``) narrows the band from 2m - 1 to m + 1 sub-diagonals
    for the white-jerk model (17 -> 10), and the banded Cholesky costs grow with its square. The
    factor is then that of the reordered matrix: same solution, same determinant."""

    m: int
    order: np.ndarray
    """Position in the band order -> state column."""
    inverse: np.ndarray
    """State column -> position in the band order."""
    bandwidth: int
    """Sub-diagonals of the band (kd)."""
    index: np.ndarray
    """(kd + 1, m) flat indices into ``[diag (m²), lower (m²), 0]`` of one sample (see :meth:`band`)."""

    @classmethod
    def of(cls, lower_pattern: np.ndarray) -> BandStructure:
        """The structure for the (m, m) nonzero pattern of the ``lower`` blocks (any sample)."""
        m = lower_pattern.shape[0]
        # groups: connected variables of the cross-sample coupling, in order of their first column
        group = np.arange(m)
        for j, i in zip(*np.nonzero(lower_pattern)):
            gj, gi = group[j], group[i]
            if gj != gi:
                group[group == max(gj, gi)] = min(gj, gi)
        order = np.array(sorted(range(m), key=lambda c: (group[c], c)))
        inverse = np.argsort(order)
        kd = m - 1
        for j, i in zip(*np.nonzero(lower_pattern)):
            kd = max(kd, m + int(inverse[j]) - int(inverse[i]))
        kd = min(kd, 2 * m - 1)
        index = np.full((kd + 1, m), 2 * m * m)
        for d in range(kd + 1):
            for p in range(m):
                q = p + d
                if q < m:
                    index[d, p] = order[q] * m + order[p]
                elif q < 2 * m:
                    index[d, p] = m * m + order[q - m] * m + order[p]
        return cls(m, order, inverse, kd, index)

    def blocks(self, diag: np.ndarray, lower: np.ndarray) -> np.ndarray:
        """(kd + 1, N, m) entries of A in the band order, unscaled: ``[d, k, p]`` is the entry d rows
        below the diagonal in column p of sample k (``diag`` (N, m, m), ``lower`` (N-1, m, m));
        :meth:`scaled` turns it into LAPACK band storage in place."""
        n, mm = diag.shape[0], self.m * self.m
        d2, l2 = diag.reshape(n, mm), lower.reshape(n - 1, mm)
        # one band row at a time, gathered straight from the blocks by the flat indices of one sample
        # into [diag (m²), lower (m²), 0] (the last sample has no lower block): no copy of both blocks
        # side by side, no transpose of the whole band
        out = np.empty((self.bandwidth + 1, n, self.m))
        for d, (from_diag, cols, from_lower, lower_cols) in enumerate(self.gathers):
            if from_diag is None:  # the whole band row from the diagonal blocks
                np.take(d2, cols, axis=1, out=out[d])
                continue
            row = out[d]
            row[...] = 0.0
            if cols.size:
                row[:, from_diag] = d2[:, cols]
            if lower_cols.size:
                row[: n - 1, from_lower] = l2[:, lower_cols]
        return out

    @cached_property
    def gathers(self) -> list:
        """Per band row d: ``(None, diagonal columns, None, None)`` when every entry of the row comes from the
        diagonal block, else ``(positions, diagonal columns, positions, lower columns)`` of the entries
        that come from the diagonal and from the lower block (the rest are zero)."""
        mm = self.m * self.m
        out = []
        for row in self.index:
            if np.all(row < mm):
                out.append((None, row.copy(), None, None))
            else:
                in_diag, in_lower = np.flatnonzero(row < mm), np.flatnonzero((row >= mm) & (row < 2 * mm))
                out.append((in_diag, row[in_diag], in_lower, row[in_lower] - mm))
        return out

    def scaled(self, blocks: np.ndarray, scale: np.ndarray, diagonal: np.ndarray) -> np.ndarray:
        """Lower band storage (kd + 1, N m) of ``S A S`` from :meth:`blocks` (scaled in place), with
        ``scale`` (N, m) the diagonal of S and ``diagonal`` (N, m) the diagonal to use (e.g.
        damped), both in the band order."""
        _, n, m = blocks.shape
        blocks[0] = diagonal
        ab = blocks.reshape(self.bandwidth + 1, n * m)
        s = scale.reshape(-1)
        for d in range(self.bandwidth + 1):
            ab[d, : n * m - d] *= s[: n * m - d] * s[d:]
        return ab

    def band(self, diag: np.ndarray, lower: np.ndarray, scale: np.ndarray, diagonal: np.ndarray) -> np.ndarray:
        """Lower band storage (kd + 1, N m) of ``S A S`` in the band order: ``diag`` (N, m, m),
        ``lower`` (N-1, m, m), ``scale`` (N, m) the diagonal of S, ``diagonal`` (N, m) A's diagonal
        to use (e.g. damped) in place of the diagonal of ``diag``, both in the state order."""
        return self.scaled(self.blocks(diag, lower), scale[:, self.order], diagonal[:, self.order])

    def to_band_order(self, b: np.ndarray, n: int) -> np.ndarray:
        """(N m[, k]) in state order -> band order."""
        return b.reshape((n, self.m) + b.shape[1:])[:, self.order].reshape(b.shape)

    def from_band_order(self, b: np.ndarray, n: int) -> np.ndarray:
        """(N m[, k]) in band order -> state order."""
        return b.reshape((n, self.m) + b.shape[1:])[:, self.inverse].reshape(b.shape)


_STRUCTURES: dict = {}


def band_structure(lower: np.ndarray) -> BandStructure:
    """:class:`BandStructure` of the nonzero pattern of ``lower`` (N-1, m, m), kept per pattern."""
    m = lower.shape[-1]
    return band_structure_of((np.count_nonzero(lower.reshape(-1, m * m), axis=0) > 0).reshape(m, m))


def band_structure_of(pattern: np.ndarray) -> BandStructure:
    """:class:`BandStructure` of an (m, m) nonzero pattern of the ``lower`` blocks, kept per pattern."""
    pattern = np.asarray(pattern, dtype=bool)
    key = (pattern.shape[0], pattern.tobytes())
    structure = _STRUCTURES.get(key)
    if structure is None:
        structure = _STRUCTURES[key] = BandStructure.of(pattern)
    return structure


@dataclass
class Factorisation:
    """Banded Cholesky factor of the Jacobi-scaled ``S A S`` (``scale`` = diag of S), plus the border.

    ``cb`` is the factor in the band order of ``structure`` (the state reordered within each
    sample, :class:`BandStructure`; None: the state order with 2m band rows)."""

    cb: np.ndarray
    scale: np.ndarray  # (N m,)
    Y: np.ndarray | None  # A⁻¹ C, (N m, G)
    schur: np.ndarray | None  # B - Cᵀ A⁻¹ C
    structure: BandStructure | None = None

    def solve(self, b: np.ndarray) -> np.ndarray:
        """A⁻¹ b for b (N m,) or (N m, k)."""
        s = self.scale if b.ndim == 1 else self.scale[:, None]
        if self.structure is None:
            return s * cho_solve_banded((self.cb, True), s * b, check_finite=False)
        n = self.scale.size // self.structure.m
        x = cho_solve_banded((self.cb, True), self.structure.to_band_order(s * b, n), check_finite=False)
        return s * self.structure.from_band_order(x, n)


def factorise(ne: NormalEquations, damping: float = 0.0, band: tuple | None = None) -> Factorisation:
    """Factor A (+ Marquardt damping) after symmetric Jacobi scaling, which keeps the
    factorisation accurate when the states have very different scales (e.g. ω̈); the band is
    narrowed by reordering the state within each sample (:class:`BandStructure`). ``band``:
    :func:`band_of` ``ne`` when already made (the damping changes only the diagonal: Levenberg-Marquardt's
    retries of one step gather the band once)."""
    d = np.einsum("nii->ni", ne.diag)
    if damping:
        d = d + damping * (d + 1e-9)
    structure, blocks = band_of(ne) if band is None else (band[0], band[1].copy())
    return factorise_blocks(structure, blocks, d[:, structure.order], ne, damping)


def band_of(ne: NormalEquations) -> tuple:
    """(:class:`BandStructure`, :meth:`BandStructure.blocks`) of the normal equations ``ne``."""
    structure = band_structure(ne.lower)
    return structure, structure.blocks(ne.diag, ne.lower)


def factorise_blocks(structure: BandStructure, blocks: np.ndarray, diagonal: np.ndarray, ne: NormalEquations,
                     damping: float = 0.0) -> Factorisation:
    """:func:`factorise` of A given as :meth:`BandStructure.blocks` (overwritten) and the diagonal to
    use (N, m), both in the band order; ``ne`` gives the border (``coupling``, ``border``) only."""
    if np.any(~(diagonal > 0)):
        k, p = np.argwhere(~(diagonal > 0))[0]
        raise np.linalg.LinAlgError(f"normal equations not positive definite: state {structure.order[p]} of sample {k} "
                                    "is unobserved")
    n, M = diagonal.shape
    sc = 1.0 / np.sqrt(diagonal)
    cb = cholesky_banded(structure.scaled(blocks, sc, diagonal), lower=True, check_finite=False)
    fac = Factorisation(cb, sc[:, structure.inverse].reshape(-1), None, None, structure)
    if ne.border.size:
        C = ne.coupling.reshape(n * M, -1)
        Y = fac.solve(C)
        border = ne.border + (damping * (np.diag(np.diag(ne.border)) + 1e-9 * np.eye(len(ne.border))) if damping else 0.0)
        fac.Y, fac.schur = Y, border - C.T @ Y
    return fac


def solve_step(ne: NormalEquations, fac: Factorisation) -> tuple[np.ndarray, np.ndarray]:
    """Newton step (δx (N, m), δp (G,)) of the (damped) normal equations."""
    n, M = ne.grad.shape
    gx = ne.grad.reshape(-1)
    ax = fac.solve(gx)
    if fac.Y is None:
        return -ax.reshape(n, M), np.zeros(0)
    C = ne.coupling.reshape(n * M, -1)
    dp = np.linalg.solve(fac.schur, -ne.grad_global + C.T @ ax)
    dx = -ax - fac.Y @ dp
    return dx.reshape(n, M), dp


def marginal_covariances(ne: NormalEquations, fac: Factorisation) -> tuple[np.ndarray, np.ndarray | None]:
    """Diagonal blocks of H⁻¹ for the states (N, m, m) and the border (G, G).

    Backward recursion on the block-bidiagonal Cholesky factor L of the
    scaled A (A_s⁻¹ = L⁻ᵀ L⁻¹): ``Σ_k = P_k + M_kᵀ Σ_{k+1} M_k`` with
    ``P_k = L_kk⁻ᵀ L_kk⁻¹`` and ``M_k = L_{k+1,k} L_kk⁻¹``; unscaled by S; then
    the Schur correction ``Y_k S⁻¹ Y_kᵀ`` of the calibration variables.
    """
    n, M = ne.diag.shape[:2]
    Lkk, Lnext = factor_blocks(fac.cb, n, M)
    Linv = np.linalg.inv(Lkk)
    P = np.swapaxes(Linv, 1, 2) @ Linv
    Mk = Lnext @ Linv[:-1]
    MkT = np.swapaxes(Mk, 1, 2)
    sigma = np.empty((n, M, M))
    sigma[-1] = P[-1]
    for k in range(n - 2, -1, -1):
        sigma[k] = P[k] + MkT[k] @ sigma[k + 1] @ Mk[k]
    if fac.structure is not None:  # back to the state order
        inv = fac.structure.inverse
        sigma = sigma[:, inv][:, :, inv]
    sc = fac.scale.reshape(n, M)
    sigma *= sc[:, :, None] * sc[:, None, :]
    if fac.Y is None:
        return sigma, None
    s_inv = np.linalg.inv(fac.schur)
    Yk = fac.Y.reshape(n, M, -1)
    sigma += Yk @ s_inv @ np.swapaxes(Yk, 1, 2)
    return sigma, s_inv


REWEIGHTED_TOLERANCE = 0.01
"""Re-weighted solves stop when an iteration lowers the cost by less than this fraction of the
cost's statistical spread at the solution, ``sqrt(R / 2)`` for R whitened rows (the std of half a
χ² with R degrees of freedom): further iterations move the estimate by far less than its noise."""


@dataclass
class SolveResult:
    states: np.ndarray
    params: np.ndarray
    cost: float
    iterations: int
    converged: bool
    covariance: np.ndarray | None = None
    param_covariance: np.ndarray | None = None
    problem: SmootherProblem | None = None
    """The problem as the re-weighting left it at the solution (the one solved, without re-weighting)."""


def solve(problem: SmootherProblem, states: np.ndarray, params: np.ndarray | None = None,
          compute_sigma: bool = False, method: str = "lm", reweight=None,
          max_iterations: int | None = None) -> SolveResult:
    """Levenberg-Marquardt (or plain Gauss-Newton) on the banded normal equations.

    Each iteration first tries the undamped Gauss-Newton step (the problem is
    close to linear near a good initial point); Marquardt damping
    ``λ diag(H)`` is switched on, and raised tenfold, only while a step fails
    to lower the cost, and lowered again after each success.

    ``reweight(problem, states, params)``, when given, returns the problem re-weighted (motion-dependent noise,
    robust losses) at the current estimate before every iteration: iteratively re-weighted
    least squares with the Levenberg-Marquardt safeguard, each step accepted when it lowers the
    cost under the weights it was computed with. It stops when an iteration lowers that cost by
    less than ``relative_tolerance`` of it, or, re-weighting, by less than
    :data:`REWEIGHTED_TOLERANCE` of its statistical spread (or after ``max_iterations``, default
    the problem's solve options').
    """
    opt = problem.solve
    X = np.array(states, dtype=float)
    P = np.zeros(problem.n_global) if params is None else np.array(params, dtype=float)
    if reweight is not None:
        problem = reweight(problem, X, P)
    ne = normal_equations(problem, X, P)
    lam = 0.0
    converged = False
    it = 0
    limit = int(opt.max_iterations if max_iterations is None else max_iterations)
    for it in range(1, limit + 1):
        band = band_of(ne)
        while True:
            try:
                fac = factorise(ne, lam, band)
            except np.linalg.LinAlgError:  # numerically indefinite (very stiff process noise): damp more
                if lam > 1e10:
                    raise
                lam = 1e-6 if lam == 0.0 else lam * 10.0
                continue
            dx, dp = solve_step(ne, fac)
            Xn, Pn = problem.retract(X, dx), P + dp
            new_cost = problem.cost(Xn, Pn)
            if method != "lm" or new_cost <= ne.cost or lam > 1e10:
                break
            lam = 1e-6 if lam == 0.0 else lam * 10.0
        decrease = ne.cost - new_cost
        if method == "lm" and new_cost > ne.cost:
            converged = True
            break
        X, P = Xn, Pn
        lam = 0.0 if lam < 1e-8 else lam / 10.0
        enough = opt.relative_tolerance * max(new_cost, 1e-300)
        if reweight is None and (decrease <= enough or np.max(np.abs(dx)) < 1e-12):
            converged, final_cost, ne = True, new_cost, None  # (no normal equations needed at the solution)
            break
        if reweight is not None:
            problem = reweight(problem, X, P)
        ne = normal_equations(problem, X, P)
        if reweight is not None:  # the weights move with every step: stop within the cost's own spread
            enough = max(enough, REWEIGHTED_TOLERANCE * np.sqrt(0.5 * (ne.rows or 1)))
        if decrease <= enough or np.max(np.abs(dx)) < 1e-12:
            converged = True
            break
    result = SolveResult(X, P, ne.cost if ne is not None else final_cost, it, converged, problem=problem)
    if compute_sigma:
        if ne is None:
            ne = normal_equations(problem, X, P)
        cov, pcov = marginal_covariances(ne, factorise(ne, 0.0))
        result.covariance, result.param_covariance = cov, pcov
    return result


def reweighting(batch_model: BatchModelOptions):
    """The re-weighting of :func:`solve` for the motion-dependent accelerometer noise and the robust
    losses of ``batch_model``: ``reweight(problem, states, params) -> problem`` (a new problem), or None
    when neither is on."""
    slope = batch_model.accel_noise_slope_mps2_per_radps > 0 and batch_model.measurement == "accelerometer"
    if not (slope or batch_model.robust):
        return None

    def reweight(problem: SmootherProblem, states: np.ndarray, params: np.ndarray) -> SmootherProblem:
        if slope:
            problem = problem.with_noise(accel=problem.noise.accel.motion_dependent(
                states[:, 0:3], batch_model.accel_noise_slope_mps2_per_radps))
        if batch_model.robust:
            problem = robust_reweighted(problem, states, params)
        return problem

    return reweight


def robust_reweighted(problem: SmootherProblem, states: np.ndarray, params: np.ndarray | None = None) -> SmootherProblem:
    """The robust (Huber or Cauchy) re-weighting of ``problem`` at ``states`` (iteratively re-weighted least
    squares), as its batch model asks.

    Each accelerometer axis (``accel_robust_threshold``, :meth:`AccelerometerGroup.reweighted`) and each
    motion-model step (``process_robust_threshold``, :meth:`MotionModelGroup.reweighted`) gets the IRLS
    weight ``w(e)`` of its whitened residual e (for a step: its norm / sqrt(rows)); the weight divides
    the factor's variance. Weights are computed against the un-reweighted noise (the motion-dependent
    one when set), so re-weighting a re-weighted problem does not compound.
    """
    opt = problem.batch_model
    P = np.zeros(problem.n_global) if params is None else params
    out = problem
    if opt.accel_robust_threshold > 0 and opt.measurement == "accelerometer":
        accel = problem.group(AccelerometerGroup).reweighted(
            problem, states, P, lambda e: robust_weight(e, opt.accel_robust_threshold, opt.robust_loss))
        out = out.with_noise(accel=accel)
    if opt.process_robust_threshold > 0:
        motion = problem.group(MotionModelGroup).reweighted(
            out, states, lambda e: robust_weight(e, opt.process_robust_threshold, opt.robust_loss))
        out = out.with_noise(motion=motion)
    return out


def solve_reweighted(problem: SmootherProblem, states: np.ndarray, batch: BatchOptions,
                     params: np.ndarray | None = None, compute_sigma: bool | None = None,
                     warm: bool = False) -> SolveResult:
    """Solve with the motion-dependent noise and robust losses of the problem's batch model: first
    ``batch.reweight_iterations - 1`` iterations under the plain noise (a start for the weights), then
    iteratively re-weighted Levenberg-Marquardt to convergence (:func:`solve`); σ as the problem's solve options
    ask (``compute_sigma``) unless ``compute_sigma`` is given."""
    sigma = problem.solve.compute_sigma if compute_sigma is None else compute_sigma
    reweight = reweighting(problem.batch_model)
    if reweight is None:
        return solve(problem, states, params, compute_sigma=sigma)
    if warm:  # ``states`` is already a re-weighted solution
        return solve(problem, states, params, compute_sigma=sigma, reweight=reweight)
    first = solve(problem, states, params, max_iterations=max(1, int(batch.reweight_iterations) - 1))
    return solve(problem, first.states, first.params if first.params.size else None,
                 compute_sigma=sigma, reweight=reweight)
