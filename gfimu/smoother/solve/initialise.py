"""Initial states for the smoothers, in the right basin even when ω crosses zero.

1. Linear smoothing of the lifted per-sample unknowns ``z = [f, ω̇, q(ω)]``
   (Ho & Lin 2009's linear model ``y = S z``) with random-walk priors: the
   per-sample inversion when S is well conditioned, a regularised version of
   it for near-planar arrays (e.g. MIMU4444) where S alone fails. One banded
   solve, linear in length.
2. Sign of ω, window by window: over a short window ``ω(t) = ω₀ + W(t)``
   with ``W`` the trapezoid integral of ω̇ from the window start, and
   ``q(ω₀ + W) = q(ω₀) + J_q(W) ω₀ + q(W)`` is linear in ω₀ and in the
   constant ``c = q(ω₀)``; a linear least-squares solve plus a Gauss-Newton
   polish over the eight sign candidates of ``|ω₀|`` picks ω₀ with its sign
   wherever ω̇ varies within the window (a constant ω has an unobservable
   sign from accelerometers alone: ``q(ω) = q(-ω)``; then continuity with
   the previous window decides).
3. With a gyroscope ω comes from it; in free flight (McGinnis, Perkins & King 2012) ω is tracked
   sample by sample through the accelerometer model with Euler's equations,
   and the global sign (unobservable per sample) is chosen so that the
   integral of ω̇ agrees with ω.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import cho_solve_banded, cholesky_banded

from ... import noise, rigid_body
from ...errors import InputError
from ...estimators.ml import MLEstimator
from ...factors import so3 as _so3
from ...log import Log
from ...rigid_body import quadratic_terms
from ...rotations import skew
from .banded import band_structure_of
from ..model.option_groups import ModelGroups, ModelOptions
from ..model.problem import STATE_SIZE
from ..model.layout import OMEGA, OMEGA_DOT, SPECIFIC_FORCE
from .gravity_sign import gravity_sign_score, steady_rotation

LIFTED = 12


def lifted_smoothing(log: Log, model: ModelOptions, quadratic_density: float = 300.0,
                     prior_std: float = 1e4) -> np.ndarray:
    """Linear smoother of ``z = [f, ω̇, q]`` (N, 12) from the accelerometers alone.

    Measurement ``S z_k = y_k`` (per-axis noise), random walks of densities
    (specific force, ω̇ of ``model``, ``quadratic_density`` [rad²/s²/√s]) and a weak zero
    prior of std ``prior_std`` on every unknown.
    """
    arr = log.array
    S = arr.structure_matrix()
    sigma = noise.accel_noise_std(arr, model.default_accel_noise_std_mps2)
    A = S / sigma[:, None]
    n = len(log)
    y = log.accel_mps2 / sigma
    info = A.T @ A + np.eye(LIFTED) / prior_std**2
    dens = np.repeat([model.specific_force_random_walk_mps2_per_sqrt_s, model.omega_dot_random_walk_radps2_per_sqrt_s,
                      quadratic_density], [3, 3, 6])
    dt = log.dt_s
    w = 1.0 / (dens[None, :] ** 2 * dt[:, None])  # (N-1, 12) random-walk information
    # each unknown is tied only to itself across samples: a band of 12 sub-diagonals (not 23), written
    # straight from its parts (the same numbers as BandStructure.band of the blocks, unscaled): band row
    # d < 12 holds the constant info[p + d, p] (the diagonal: info + the walks on either side), row 12
    # the walk -w between a sample and the next
    diagonal = np.broadcast_to(np.diag(info), (n, LIFTED)).copy()
    diagonal[:-1] += w
    diagonal[1:] += w
    ab = np.zeros((LIFTED + 1, n, LIFTED))
    ab[0] = diagonal
    for d in range(1, LIFTED):
        ab[d, :, : LIFTED - d] = np.diagonal(info, -d)
    ab[LIFTED, : n - 1] = -w
    ab = ab.reshape(LIFTED + 1, n * LIFTED)
    structure = band_structure_of(np.eye(LIFTED, dtype=bool))  # the state order itself
    cb = cholesky_banded(ab, lower=True, check_finite=False)
    rhs = structure.to_band_order((y @ A).reshape(-1), n)
    return structure.from_band_order(cho_solve_banded((cb, True), rhs, check_finite=False), n).reshape(n, LIFTED)


def trapezoid_integral(omega_dot: np.ndarray, dt_s: np.ndarray) -> np.ndarray:
    """``W_t = ∫ω̇`` from the first sample (W_0 = 0), trapezoid rule; (L, 3)."""
    inc = 0.5 * (omega_dot[1:] + omega_dot[:-1]) * dt_s[:, None]
    return np.concatenate([np.zeros((1, 3)), np.cumsum(inc, axis=0)])


_SIGNS = np.array([[sx, sy, sz] for sx in (1, -1) for sy in (1, -1) for sz in (1, -1)], dtype=float)


_QUADRATIC_FORMS = np.zeros((6, 3, 3))
"""A_l with ``q_l(ω) = ωᵀ A_l ω`` (:func:`gfimu.rigid_body.quadratic_terms`); its Jacobian is ``2 A_l ω``."""
for _l, (_i, _j) in enumerate([(0, 1), (0, 2), (1, 2)]):
    _QUADRATIC_FORMS[_l, _i, _i] = _QUADRATIC_FORMS[_l, _j, _j] = 1.0
for _l, (_i, _j) in enumerate([(0, 1), (0, 2), (1, 2)], start=3):
    _QUADRATIC_FORMS[_l, _i, _j] = _QUADRATIC_FORMS[_l, _j, _i] = 0.5


def window_moments(q_meas: np.ndarray, integral: np.ndarray, starts: np.ndarray) -> tuple:
    """Sums over each window (starting at ``starts``) that :func:`window_initial_omega` needs: with
    ``W`` the integral of ω̇ from the window start and ``d = q(W) - q_meas``, the count, ΣW (3),
    ΣW Wᵀ (3, 3), Σd (6), Σd² (6), ΣW d_l (6, 3), and the first q_meas of the window."""
    n = len(q_meas)
    d = rigid_body.quadratic_terms(integral) - q_meas
    count = np.diff(np.append(starts, n)).astype(float)
    s1 = np.add.reduceat(integral, starts, axis=0)
    s2 = np.add.reduceat(integral[:, :, None] * integral[:, None, :], starts, axis=0)
    d1 = np.add.reduceat(d, starts, axis=0)
    d2 = np.add.reduceat(d * d, starts, axis=0)
    e = np.add.reduceat(d[:, :, None] * integral[:, None, :], starts, axis=0)
    return count, s1, s2, d1, d2, e, q_meas[starts]


def _omega_from_moments(count, s1, s2, d1, d2, e, q_first, previous, continuity_std_radps, iterations):
    """:func:`window_initial_omega` from the window's sums (:func:`window_moments`).

    With ω = ω₀ + W_t, each residual ``q_l(ω₀ + W_t) - q_meas = a_l + b_lt + d_lt`` (``a_l = q_l(ω₀)``,
    ``b_lt = 2 ω₀ᵀ A_l W_t``), so the cost, its gradient and the Gauss-Newton matrix over the
    window are polynomials in ω₀ whose coefficients are the sums above: no pass over the samples."""
    A = _QUADRATIC_FORMS
    # linear start: q(ω₀ + W) = q(W) + J_q(W) ω₀ + c with c = q(ω₀), least squares in (ω₀, c)
    jtj = np.trace(s2) * np.eye(3) + 5.0 * s2 + 2.0 * np.diag(np.diag(s2))  # Σ J_q(W)ᵀ J_q(W)
    jsum = rigid_body.quadratic_terms_jacobian(s1)  # Σ J_q(W) (J_q is linear)
    normal = np.zeros((9, 9))
    normal[:3, :3], normal[:3, 3:], normal[3:, :3], normal[3:, 3:] = jtj, jsum.T, jsum, count * np.eye(6)
    rhs = np.concatenate([-2.0 * np.einsum("lij,lj->i", A, e), -d1])
    theta = np.linalg.solve(normal + 1e-9 * np.trace(normal) * np.eye(9), rhs)
    mags = rigid_body.omega_from_quadratic_terms(theta[3:])
    w0 = np.vstack([theta[:3][None], _SIGNS * mags, _SIGNS * rigid_body.omega_from_quadratic_terms(q_first)])
    w_c2 = 1.0 / continuity_std_radps**2
    a_s1 = A @ s1  # (6, 3)
    a_e = np.einsum("lij,lj->i", A, e)  # Σ_l A_l E_l
    a_s2_a = np.einsum("lij,jk,lkm->im", A, s2, A)  # Σ_l A_l S2 A_l

    def products(w):  # (C, 3) -> A_l ω₀ (C, 6, 3), ω₀ᵀ A_l ω₀ (C, 6), ω₀ᵀ A_l S1 (C, 6)
        aw = np.einsum("lij,cj->cli", A, w)
        return aw, np.einsum("cli,ci->cl", aw, w), aw @ s1

    def cost_of(w):  # (C, 3) -> cost (C,)
        aw, a, was1 = products(w)
        cost = np.sum(count * a * a + 4.0 * np.einsum("cli,ij,clj->cl", aw, s2, aw) + d2 + 4.0 * a * was1
                      + 2.0 * a * d1 + 4.0 * np.einsum("cli,li->cl", aw, e), axis=1)
        if previous is not None:
            dp = w - previous
            cost = cost + w_c2 * np.sum(dp * dp, axis=1)
        return cost

    def step_of(w):  # (C, 3) -> JᵀJ (C, 3, 3), Jᵀr (C, 3) (the cost is not needed for the step)
        aw, a, was1 = products(w)
        g = 2.0 * (np.einsum("cli,cl->ci", aw, count * a + 2.0 * was1 + d1) + a @ a_s1 + 2.0 * w @ a_s2_a + a_e)
        m2 = count * w[:, :, None] * w[:, None, :] + w[:, :, None] * s1 + s1[:, None] * w[:, None, :] + s2
        tr = np.trace(m2, axis1=1, axis2=2)
        H = tr[:, None, None] * np.eye(3) + 5.0 * m2 + 2.0 * np.einsum("cii->ci", m2)[:, :, None] * np.eye(3)
        if previous is not None:
            g = g + w_c2 * (w - previous)
            H = H + w_c2 * np.eye(3)
        return H, g

    for _ in range(iterations):
        H, g = step_of(w0)
        w0 = w0 - np.linalg.solve(H + 1e-9 * np.eye(3), g[..., None])[..., 0]
    cost = cost_of(w0)
    best = int(np.argmin(cost))
    return w0[best], float(cost[best])


def window_initial_omega(q_meas: np.ndarray, integral: np.ndarray, previous: np.ndarray | None = None,
                         continuity_std_radps: float = 0.5, iterations: int = 8) -> tuple[np.ndarray, float]:
    """ω₀ of one window from measured quadratic terms (L, 6) and ∫ω̇ (L, 3).

    Returns ω₀ and the best cost. ``previous`` (ω expected at the window
    start from the window before) adds a weak continuity term.
    """
    moments = [m[0] for m in window_moments(q_meas, integral, np.array([0]))]
    return _omega_from_moments(*moments, previous, continuity_std_radps, iterations)


def sign_resolved_omega(q_meas: np.ndarray, omega_dot: np.ndarray, dt_s: np.ndarray, window: int) -> np.ndarray:
    """ω (N, 3) window by window from quadratic terms and ω̇ of one contiguous segment (the sums of
    every window at once, :func:`window_moments`; then the windows in turn, each continuing the last)."""
    n = q_meas.shape[0]
    starts = []
    start = 0
    while start < n:
        stop = min(start + window, n)
        if n - stop < window // 2:
            stop = n
        starts.append(start)
        start = stop
    starts = np.array(starts)
    stops = np.append(starts[1:], n)
    # ∫ω̇ from each window's start: the trapezoid sum along the segment less its value at the start
    whole = trapezoid_integral(omega_dot, dt_s)
    integral = whole - np.repeat(whole[starts], stops - starts, axis=0)
    moments = window_moments(q_meas, integral, starts)
    out = np.zeros((n, 3))
    previous = None
    for k, (start, stop) in enumerate(zip(starts, stops)):
        w0, _ = _omega_from_moments(*(m[k] for m in moments), previous, 0.5, 8)
        out[start:stop] = w0 + integral[start:stop]
        if stop < n:
            previous = out[stop - 1] + 0.5 * (omega_dot[stop - 1] + omega_dot[stop]) * dt_s[stop - 1]
    return out


SIGN_CHAIN_SCALE_FACTOR = 2.0 * np.sqrt(3.0) / 1.538
"""The sign chain's Cauchy scale over the median norm of the log's own step residuals (with the
better sign): a three-axis Gaussian step of std σ per axis has median norm 1.538 σ, and the scale
is 2 σ on each of its three axes, c² = 3 (2 σ)², as the accelerometer and motion-model losses
(2 σ)."""


def _step_costs(omega_b_radps: np.ndarray, omega_dot_b_radps2: np.ndarray, dt_s: np.ndarray) -> np.ndarray:
    """(N-1, 2, 2) ``||s_b ω_{k+1} - s_a ω_k - h_k/2 (ω̇_k + ω̇_{k+1})||²`` for signs s_a, s_b in (+1, -1)."""
    w = np.asarray(omega_b_radps, dtype=float)
    d = np.asarray(omega_dot_b_radps2, dtype=float)
    h = np.broadcast_to(np.asarray(dt_s, dtype=float), (len(w) - 1,))
    inc = 0.5 * h[:, None] * (d[:-1] + d[1:])  # (N-1, 3)
    signs = np.array([1.0, -1.0])
    diff = signs[None, None, :, None] * w[1:, None, None, :] - signs[None, :, None, None] * w[:-1, None, None, :] \
        - inc[:, None, None, :]
    return np.sum(diff**2, axis=3)


def _scale_of_steps(step: np.ndarray) -> float | None:
    """:func:`sign_chain_scale` from :func:`_step_costs`."""
    if len(step) < 2:
        return None
    better = np.sqrt(np.minimum(step[:, 0, 0], step[:, 0, 1]))
    better = better[np.isfinite(better)]
    c = SIGN_CHAIN_SCALE_FACTOR * float(np.median(better)) if better.size else 0.0
    return c if np.isfinite(c) and c > 0 else None


def sign_chain_scale(omega_b_radps: np.ndarray, omega_dot_b_radps2: np.ndarray, dt_s: np.ndarray) -> float | None:
    """Cauchy scale [rad/s] of :func:`sign_chain` measured from the data: :data:`SIGN_CHAIN_SCALE_FACTOR`
    times the median over the samples of ``min_s ||s ω_{k+1} - ω_k - h_k/2 (ω̇_k + ω̇_{k+1})||``;
    None (plain squares) when that is zero or there are too few samples."""
    if len(omega_b_radps) < 3:
        return None
    return _scale_of_steps(_step_costs(omega_b_radps, omega_dot_b_radps2, dt_s))


def sign_chain(omega_b_radps: np.ndarray, omega_dot_b_radps2: np.ndarray, dt_s: np.ndarray,
               robust_scale_radps: float | str | None = "data") -> np.ndarray:
    """Signs s_k = ±1 (N,) minimising ``Σ_k ρ(||s_{k+1} ω_{k+1} - s_k ω_k - h_k/2 (ω̇_k + ω̇_{k+1})||)``.

    The accelerometers fix ω only up to its sign per sample (the quadratic terms, Ho & Lin 2009, eq. 6)
    while ω̇ is sign-free: the sign sequence that best follows the trapezoid of ω̇ is found exactly
    by dynamic programming (Viterbi, two states per sample, linear in N). It keeps a rotation that
    slows through zero and reverses (ω̇ keeps its sign) apart from one that bounces back.

    ρ is the Cauchy loss ``c² log(1 + e²/c²)`` with ``c = robust_scale_radps`` ('data': measured
    from these samples by :func:`sign_chain_scale`; None: the plain square ``e²``): one sample whose
    per-sample ω̇ (or ω) is off by hundreds of rad/s², e.g. from a reading spike, costs at most a few
    c² whichever its sign, instead of flipping the run that follows it onto the wrong sign branch.
    """
    data = isinstance(robust_scale_radps, str) and robust_scale_radps == "data"
    if not data and robust_scale_radps is not None and (
            isinstance(robust_scale_radps, str) or not (np.isfinite(robust_scale_radps) and robust_scale_radps > 0)):
        raise InputError(f"sign_chain: robust_scale_radps must be a positive number, 'data' or None, got {robust_scale_radps!r}")
    n = len(omega_b_radps)
    if n < 2:
        return np.ones(n)
    step = _step_costs(omega_b_radps, omega_dot_b_radps2, dt_s)  # from sign a at k to sign b at k+1
    if data:
        robust_scale_radps = _scale_of_steps(step)
    if robust_scale_radps is not None:
        step = robust_scale_radps**2 * np.log1p(step / robust_scale_radps**2)
    # two states: per sample the two 2-way minima, on plain floats (the sums in the same order, and the
    # choices of numpy's argmin: the first of equal costs, a NaN before any number)
    back0, back1 = [], []
    a0, a1 = 0.0, 0.0
    for c00, c01, c10, c11 in step.reshape(n - 1, 4).tolist():
        n0a, n0b, n1a, n1b = a0 + c00, a1 + c10, a0 + c01, a1 + c11
        if n0a == n0a and not n0b >= n0a:  # the second is smaller, or a NaN after a number
            back0.append(1)
            b0 = n0b
        else:
            back0.append(0)
            b0 = n0a
        if n1a == n1a and not n1b >= n1a:
            back1.append(1)
            a1 = n1b
        else:
            back1.append(0)
            a1 = n1a
        a0 = b0
    state = 1 if a0 == a0 and not a1 >= a0 else 0
    path = [state]
    for k in range(n - 2, -1, -1):
        state = back1[k] if state else back0[k]
        path.append(state)
    return np.where(np.array(path[::-1]) == 0, 1.0, -1.0)


def free_flight_omega(log: Log) -> np.ndarray:
    """Track ω through the single-sensor free-flight model (McGinnis, Perkins & King 2012, eqs. 1, 13).

    Per sample, Gauss-Newton on ``y = S_axes [0, Ψ(ω), q(ω)]`` with
    ``Ψ(ω) = -I⁻¹ (ω × I ω)``, started from the previous sample (the first
    from a spread of candidates); the overall sign, which the readings do
    not show, is picked so that the trapezoid integral of Ψ(ω) agrees with ω.
    """
    arr = log.array
    inertia = np.asarray(arr.body.principal_inertia_kgm2)
    S = arr.structure_matrix()
    Sd, Sq = S[:, 3:6], S[:, 6:12]
    y = log.accel_mps2
    n = len(log)

    def model(w):  # (C, 3) -> readings (C, n_axes), Jacobian (C, n_axes, 3)
        iw = w * inertia
        psi = -np.cross(w, iw) / inertia
        # d(ω × Iω)/dω = [ω]× I - [Iω]×
        dpsi = -(skew(w) * inertia - skew(iw)) / inertia[:, None]
        pred = psi @ Sd.T + quadratic_terms(w) @ Sq.T
        J = Sd @ dpsi + np.einsum("aj,cjk->cak", Sq, rigid_body.quadratic_terms_jacobian(w))
        return pred, J

    def polish(w, yk, iters):
        for _ in range(iters):
            pred, J = model(w)
            r = pred - yk
            JT = np.swapaxes(J, 1, 2)
            w = w - np.linalg.solve(JT @ J + 1e-6 * np.eye(3), np.einsum("cij,cj->ci", JT, r)[..., None])[..., 0]
        pred, _ = model(w)
        return w, np.sum((pred - yk) ** 2, axis=1)

    rng = np.random.default_rng(0)
    cands = rng.normal(size=(200, 3)) * 10.0
    w_all, cost = polish(cands, y[0][None], 30)
    def euler_step(w, h):  # Heun step of the torque-free Euler equations
        h = np.reshape(h, (-1, 1))
        k1 = -np.cross(w, w * inertia) / inertia
        w1 = w + h * k1
        return w + 0.5 * h * (k1 - np.cross(w1, w1 * inertia) / inertia)

    # track every ~10 ms: propagate by Euler's equations, polish on the readings;
    # then start every sample from the tracked state propagated to it
    stride = max(1, int(round(0.01 * log.rate_hz)))
    tracked_idx = np.arange(0, n, stride)
    dt = np.append(log.dt_s, log.nominal_dt_s)
    tracked = np.zeros((tracked_idx.size, 3))
    tracked[0] = w_all[np.argmin(cost)]
    for j in range(1, tracked_idx.size):
        w = tracked[j - 1][None]
        for k in range(tracked_idx[j - 1], tracked_idx[j]):
            w = euler_step(w, dt[k])
        w, _ = polish(w, y[tracked_idx[j]][None], 4)
        tracked[j] = w[0]
    start = np.zeros((n, 3))
    w = tracked.copy()
    for offset in range(stride):
        idx = tracked_idx + offset
        ok = idx < n
        start[idx[ok]] = w[ok]
        w[ok] = euler_step(w[ok], dt[idx[ok]])
    out, _ = polish(start, y, 4)
    # the readings are even in ω: align each solution's sign with its predecessor
    flips = np.sign(np.einsum("ni,ni->n", out[1:], out[:-1]))
    flips[flips == 0] = 1.0
    out[1:] *= np.cumprod(flips)[:, None]
    psi = -np.cross(out, out * inertia) / inertia
    dw = np.diff(out, axis=0)
    integ = 0.5 * (psi[1:] + psi[:-1]) * log.dt_s[:, None]
    return out if np.sum(dw * integ) >= 0 else -out


def initial_states(log: Log, groups: ModelGroups) -> np.ndarray:
    """Initial states for :class:`gfimu.smoother.model.problem.SmootherProblem` of the option ``groups`` (its model,
    solve and batch model): ``[ω, ω̇, f]`` (N, 9), with ω̈ = 0 appended (N, 12) for the 'snap' motion model."""
    x0 = _initial_states(log, groups)
    if groups.model.motion_model == "snap":
        x0 = np.hstack([x0, np.zeros((len(log), 3))])
    return x0


def initial_estimate(log: Log, groups: ModelGroups) -> np.ndarray:
    """Initial states of one solve window as ``groups.solve.initialisation`` asks: the sign-resolving
    initialisation (:func:`initial_states`) or the per-sample ML estimate (``'ml'``, its ω signs
    chained over time when ``ml_sign_chain``); free flight (``batch_model.free_flight``) always uses its own
    initialisation."""
    if groups.solve.initialisation != "ml" or groups.batch_model.free_flight:
        return initial_states(log, groups)
    m = MLEstimator().estimate_motion(log)
    omega = m.omega_b_radps
    if groups.solve.ml_sign_chain:
        omega = omega * sign_chain(omega, m.omega_dot_b_radps2, log.dt_s)[:, None]
    x = np.hstack([omega, m.omega_dot_b_radps2, m.specific_force_b_mps2])
    if groups.model.motion_model == "snap":
        x = np.hstack([x, np.gradient(m.omega_dot_b_radps2, log.times_s, axis=0)])
    return x


def _initial_states(log: Log, groups: ModelGroups) -> np.ndarray:
    n = len(log)
    x0 = np.zeros((n, STATE_SIZE))
    arr = log.array
    model = groups.model
    if groups.batch_model.free_flight:
        w = free_flight_omega(log)
        inertia = np.asarray(arr.body.principal_inertia_kgm2)
        x0[:, OMEGA] = w
        x0[:, OMEGA_DOT] = -np.cross(w, w * inertia) / inertia
        return x0
    gyro = arr.gyroscope is not None and model.use_gyro and log.gyro_b_radps is not None
    if gyro and arr.n_axes < 12:
        # f and ω̇ from the accelerometers given ω (Lu, Tsai & Lin 2010's gyro-aided model), smoothed lightly
        S = arr.structure_matrix()
        y = log.accel_mps2 - rigid_body.quadratic_terms(log.gyro_b_radps) @ S[:, 6:12].T
        lin = np.linalg.lstsq(S[:, :6], y.T, rcond=1e-8)[0].T
        x0[:, OMEGA] = log.gyro_b_radps
        x0[:, OMEGA_DOT] = lin[:, 3:6]
        x0[:, SPECIFIC_FORCE] = lin[:, 0:3]
        return x0
    z = lifted_smoothing(log, model)
    x0[:, SPECIFIC_FORCE] = z[:, 0:3]
    x0[:, OMEGA_DOT] = z[:, 3:6]
    if gyro:
        x0[:, OMEGA] = log.gyro_b_radps
        return x0
    window = max(int(round(groups.solve.init_window_s * log.rate_hz)), 8)
    for seg in log.segments():
        idx = np.arange(seg.start, seg.stop)
        if idx.size < 2:
            continue
        dt = log.dt_s[seg.start:seg.stop - 1]
        w = sign_resolved_omega(z[seg, 6:12], z[seg, 3:6], dt, window)
        x0[seg, OMEGA] = w * steady_rotation_sign(w, z[seg, 0:3], dt, window)
    return x0


STEADY_OMEGA_CHANGE_SIGMA_RADPS = 0.03
"""Noise of ω̇ integrated over an initialisation window, below which (times five) a window's
change of ω does not decide the sign of ω (see :func:`gfimu.smoother.solve.gravity_sign.steady_rotation`)."""


def steady_rotation_sign(omega_b_radps: np.ndarray, specific_force_b_mps2: np.ndarray, dt_s: np.ndarray,
                         window: int, min_samples: int = 50, min_score: float = 0.5) -> float:
    """-1 to flip ω of a whole segment whose rotation is steady and whose gravity turns the other way.

    A steady rotation's sign is unobservable from the lever-arm terms (``q(ω) = q(-ω)``) and ω̇
    carries none; gravity seen from the body turns as ``ḟ ≈ -ω × f``, which decides it
    (:mod:`gfimu.smoother.solve.gravity_sign`). Returns +1 unless that evidence is clear.
    """
    if not steady_rotation(omega_b_radps, STEADY_OMEGA_CHANGE_SIGMA_RADPS, window):
        return 1.0
    score, used = gravity_sign_score(omega_b_radps, specific_force_b_mps2, dt_s)
    return -1.0 if used >= min_samples and score > min_score else 1.0


def level_attitude(up_b: np.ndarray) -> np.ndarray:
    """R (W←B) with ``Rᵀ e_z = up_b`` and zero yaw (body x projected on the horizontal maps to world x)."""
    u = np.asarray(up_b, dtype=float)
    u = u / np.linalg.norm(u)
    ref = np.array([1.0, 0.0, 0.0]) if abs(u[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = ref - (ref @ u) * u
    x /= np.linalg.norm(x)
    return np.vstack([x, np.cross(u, x), u])


def initial_attitude(log: Log, omega_b_radps: np.ndarray, specific_force_b_mps2: np.ndarray,
                     start_wb: np.ndarray | None = None, use_inclinometer: bool = False) -> np.ndarray:
    """Attitudes (N, 3, 3): the first from ``start_wb``, else levelled from the inclinometer or the
    mean specific force of the first 0.2 s (zero yaw); then propagated with
    ``R_{k+1} = R_k Exp(h (ω_k + ω_{k+1}) / 2)`` (Li et al. 2021, eq. 10)."""
    n = len(log)
    if start_wb is not None:
        R0 = np.asarray(start_wb, dtype=float)
    else:
        m = max(1, min(n, int(round(0.2 * log.rate_hz))))
        up = specific_force_b_mps2[:m].mean(axis=0)
        if use_inclinometer and log.tilt_rad is not None:
            c = np.cos(log.tilt_rad[:m].mean(axis=0))
            z = np.sqrt(max(0.0, 1.0 - c @ c))
            up = np.array([c[0], c[1], z if up[2] >= 0 else -z])
        R0 = level_attitude(up)
    steps = _so3.exp(0.5 * log.dt_s[:, None] * (omega_b_radps[1:] + omega_b_radps[:-1]))
    R = np.empty((n, 3, 3))
    R[0] = R0
    for k in range(n - 1):
        R[k + 1] = R[k] @ steps[k]
    return R


STILL_Z = 3.0
"""Margin of the stillness tests (:func:`still_start`), in standard deviations of their χ² statistic
(``χ² ≤ dof + STILL_Z √(2 dof)``): a body at rest is called moving in about 1.5 % of stretches (both
tests; 100 samples of the 10 cm cube at 0.07 m/s²), which then start as a moving one does."""


def _within_noise(chi2: float, dof: int) -> bool:
    return chi2 <= dof + STILL_Z * np.sqrt(2.0 * dof)


def still_start(times_s: np.ndarray, accel_mps2: np.ndarray, structure: np.ndarray,
                sigma_mps2: np.ndarray) -> float | None:
    """Whether a stretch of readings shows a body at rest, from the readings alone; if so, the std
    [rad/s] of a prior ω = 0 on its first state, else None.

    ``times_s`` (N,), ``accel_mps2`` (N, m): the stretch; ``structure`` (m, 12): the array's
    ``S`` (readings = S [f, ω̇, q(ω)]); ``sigma_mps2`` (m,): each reading's white-noise std (the
    noise the model check measured). The stretch is still when both hold, each as a χ² test
    against that noise (:data:`STILL_Z`):

    - every reading varies about its mean by the noise alone (χ² with (N - 1) m degrees of
      freedom): f, ω̇ and q(ω) constant over the stretch, so the body neither turns gravity
      round nor changes its rotation;
    - the mean of [ω̇, q(ω)] over the stretch, fitted to the mean readings, is zero within its
      std (χ² with 9 degrees of freedom): no rotation the quadratic terms can see.

    A body at rest has ω = 0; how well the stretch tells that is the ω its ω̇ could have built up
    unseen over the stretch, the integral of the fitted ω̇'s noise: ``σ_ω̇ T / √N`` with σ_ω̇ the
    per-sample std of ω̇ (RMS over the axes) and T the stretch's length. None when the stretch has
    fewer than two samples or S does not determine all twelve unknowns (no such test then).
    """
    y = np.asarray(accel_mps2, dtype=float)
    t = np.asarray(times_s, dtype=float)
    n, m = y.shape
    S = np.asarray(structure, dtype=float)
    sigma = np.asarray(sigma_mps2, dtype=float)
    if n < 2 or m < LIFTED or not np.all(np.isfinite(y)) or not np.all(sigma > 0):
        return None
    A = S / sigma[:, None]
    info = A.T @ A
    s = np.linalg.svd(A, compute_uv=False)
    if s[-1] <= 1e-9 * s[0]:
        return None
    cov = np.linalg.inv(info)  # of one sample's [f, ω̇, q]
    mean = y.mean(axis=0)
    if not _within_noise(float(np.sum(((y - mean) / sigma) ** 2)), (n - 1) * m):
        return None
    z = cov @ (A.T @ (mean / sigma))  # [f, ω̇, q] of the mean readings, covariance cov / n
    rest = slice(3, LIFTED)
    if not _within_noise(float(n * z[rest] @ np.linalg.solve(cov[rest, rest], z[rest])), LIFTED - 3):
        return None
    sigma_omega_dot = float(np.sqrt(np.mean(np.diag(cov)[3:6])))
    return sigma_omega_dot * float(t[-1] - t[0]) / np.sqrt(n)
