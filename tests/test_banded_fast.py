"""The banded core's fast paths against the plain ones on the same normal equations: the factor in
the reordered, narrower band against the band of the state order and the dense matrix."""

import numpy as np
import pytest
from scipy.linalg import cho_solve_banded, cholesky_banded

from gfimu.array import cube_array
from gfimu.simulate import simulate
from gfimu.smoother.solve.banded import (
    band_structure,
    factorise,
    marginal_covariances,
    normal_equations,
    solve_step,
    to_lower_banded,
)
from gfimu.smoother.model.problem import SmootherOptions, SmootherProblem
from gfimu.smoother.solve.initialise import initial_states
from gfimu.smoother.model.layout import StateLayout

CUBE = cube_array(0.05, noise_std_mps2=0.07)

# numerically stiff systems (white snap; the attitude's yaw held by one weak prior) agree to fewer digits
TOLERANCE = {"snap": 1e-5, "attitude": 1e-5}

OPTIONS = {
    "jerk": SmootherOptions(),
    "oscillator": SmootherOptions(process_axis_frequencies_hz=(0.0, 1.0, 0.0)),
    "snap": SmootherOptions(motion_model="snap"),
    "attitude": SmootherOptions(estimate_attitude=True),
    "calibration": SmootherOptions(self_calibrate_bias=True, self_calibrate_scale=True),
}


@pytest.fixture(scope="module")
def log():
    return simulate("random3d", CUBE, rate_hz=200.0, duration_s=0.4, seed=3)


def system(log, name, damping=0.0):
    opt = OPTIONS[name]
    problem = SmootherProblem.of(log, opt)
    x = StateLayout.from_options(opt).resize(initial_states(log, opt.model_groups))
    if problem.layout.attitude:
        x[:, problem.AT] = 0.01 * np.random.default_rng(1).normal(size=(problem.n, 3))
    p = 0.01 * np.random.default_rng(2).normal(size=problem.n_global)
    return problem, normal_equations(problem, x, p)


def dense(ne, damping=0.0):
    n, m = ne.diag.shape[:2]
    A = np.zeros((n * m, n * m))
    for k in range(n):
        A[m * k:m * k + m, m * k:m * k + m] = ne.diag[k]
        if k < n - 1:
            A[m * k + m:m * k + 2 * m, m * k:m * k + m] = ne.lower[k]
            A[m * k:m * k + m, m * k + m:m * k + 2 * m] = ne.lower[k].T
    if damping:
        A[np.diag_indices_from(A)] += damping * (np.diag(A) + 1e-9)
    return A


@pytest.mark.parametrize("name", list(OPTIONS))
@pytest.mark.parametrize("damping", [0.0, 1e-3])
def test_reordered_band_factor_equals_the_state_order_band_and_the_dense_matrix(log, name, damping):
    problem, ne = system(log, name)
    n, m = ne.diag.shape[:2]
    fac = factorise(ne, damping)
    assert fac.cb.shape[0] <= 2 * m
    A = dense(ne, damping)
    # the plain path: the whole 2m-row band in the state order, same Jacobi scaling
    d = np.diag(A)
    s = 1.0 / np.sqrt(d)
    As = A * s[:, None] * s[None, :]
    ab = to_lower_banded(As.reshape(n, m, n, m)[np.arange(n), :, np.arange(n), :],
                         np.stack([As[m * k + m:m * k + 2 * m, m * k:m * k + m] for k in range(n - 1)]))
    cb_plain = cholesky_banded(ab, lower=True, check_finite=False)
    tol = TOLERANCE.get(name, 1e-9)
    # same determinant
    logdet_fast = 2.0 * np.sum(np.log(fac.cb[0])) - 2.0 * np.sum(np.log(fac.scale))
    logdet_plain = 2.0 * np.sum(np.log(cb_plain[0])) - 2.0 * np.sum(np.log(s))
    assert logdet_fast == pytest.approx(logdet_plain, rel=tol * 1e-2, abs=1e-9)
    # same solutions, vector and matrix right-hand sides; a small backward error
    b = np.random.default_rng(5).normal(size=(n * m, 3))
    plain = s[:, None] * cho_solve_banded((cb_plain, True), s[:, None] * b, check_finite=False)
    fast = fac.solve(b)
    np.testing.assert_allclose(fast, plain, rtol=tol, atol=tol * np.abs(plain).max())
    np.testing.assert_allclose(fac.solve(b[:, 0]), fast[:, 0], rtol=1e-12, atol=1e-14 * np.abs(plain).max())
    backward = np.abs(As @ (fast / s[:, None]) - s[:, None] * b).max() / (np.abs(fast / s[:, None]).max())
    assert backward < 1e-10


@pytest.mark.parametrize("name", ["jerk", "oscillator", "calibration"])
def test_step_and_marginals_of_the_reordered_band_equal_the_dense_inverse(log, name):
    problem, ne = system(log, name)
    n, m = ne.diag.shape[:2]
    G = ne.border.shape[0]
    H = np.zeros((n * m + G, n * m + G))
    H[:n * m, :n * m] = dense(ne)
    H[:n * m, n * m:] = ne.coupling.reshape(n * m, G)
    H[n * m:, :n * m] = ne.coupling.reshape(n * m, G).T
    H[n * m:, n * m:] = ne.border
    inv = np.linalg.inv(H)
    fac = factorise(ne)
    dx, dp = solve_step(ne, fac)
    g = np.concatenate([ne.grad.reshape(-1), ne.grad_global])
    ref = -inv @ g
    np.testing.assert_allclose(np.concatenate([dx.reshape(-1), dp]), ref, rtol=1e-6, atol=1e-8 * np.abs(ref).max())
    cov, pcov = marginal_covariances(ne, fac)
    for k in (0, n // 2, n - 1):
        block = inv[m * k:m * k + m, m * k:m * k + m]
        np.testing.assert_allclose(cov[k], block, rtol=1e-6, atol=1e-9 * np.abs(block).max())
    if G:
        np.testing.assert_allclose(pcov, inv[n * m:, n * m:], rtol=1e-6, atol=1e-12)


def test_white_jerk_band_is_narrowed_to_m_plus_one(log):
    _, ne = system(log, "jerk")
    structure = band_structure(ne.lower)
    assert structure.bandwidth == 10  # ωx ω̇x ωy ω̇y ωz ω̇z fx fy fz: 9 + 1
    assert sorted(structure.order) == list(range(9))
    _, ne = system(log, "snap")
    assert band_structure(ne.lower).bandwidth == 14  # ω, ω̇, ω̈ of an axis together: 12 + 2


# --- the tuner's process basis ----------------------------------------------

from gfimu.smoother.tuning.evidence import ProcessBasis, linearised_log_evidence, make_problem, measurement_normal_equations, tune  # noqa: E402


@pytest.mark.parametrize("name", ["jerk"])
def test_process_basis_gives_the_evidence_of_the_factors_evaluated_per_setting(log, name):
    opt = OPTIONS[name]
    x = StateLayout.from_options(opt).resize(initial_states(log, opt.model_groups))
    field = "omega_ddot_random_walk_radps3_per_sqrt_s" if name == "snap" else "omega_dot_random_walk_radps2_per_sqrt_s"
    basis = ProcessBasis.of(log, opt.model_groups, field, x, np.zeros(0))
    assert basis is not None
    rng = np.random.default_rng(7)
    for _ in range(3):
        q, force = np.exp(rng.uniform(0, 5)), np.exp(rng.uniform(-1, 4))
        factors = tuple(np.exp(rng.uniform(-3, 1, size=3)))
        settings = SmootherOptions(**{**opt.__dict__, field: q, "process_axis_factors": factors,
                                      "specific_force_random_walk_mps2_per_sqrt_s": force})
        problem = make_problem(log, settings.model_groups)
        meas = measurement_normal_equations(problem, x)
        direct = linearised_log_evidence(problem, x, None, meas)
        summed = basis.banded(meas)
        total, fac = summed.system(q, factors, force)  # summed in the band order
        fast = linearised_log_evidence(problem, x, None, total=total, factorisation=fac,
                                       minimum=lambda dx, dp: summed.half_cost(dx, dp, q, factors, force))
        assert fast == pytest.approx(direct, rel=1e-12, abs=1e-8)
        # without the row-by-row minimum: the same to the rounding of c(x̄) - ½ gᵀH⁻¹g at moderate settings
        assert linearised_log_evidence(problem, x, None, total=total, factorisation=fac) == pytest.approx(direct, rel=1e-9)
        assert total.cost == pytest.approx(normal_equations(problem, x, np.zeros(0)).cost, rel=1e-13)


def test_process_basis_at_new_states_keeps_the_split_and_products_and_equals_one_made_afresh(log):
    """At a second linearisation point the white-jerk and random-walk factors have the same Jacobians
    (they are linear in the states): the basis made with the first as ``previous`` keeps its JᵀJ (the
    same arrays) and its band entries, and its gradients, costs and the evidence they give are those of a
    basis made afresh there, bit for bit (the same products in the same order)."""
    opt = OPTIONS["jerk"]
    field = "omega_dot_random_walk_radps2_per_sqrt_s"
    x = initial_states(log, opt.model_groups)
    y = x + np.random.default_rng(3).normal(scale=0.05, size=x.shape)  # another point, e.g. a solver's
    first = ProcessBasis.of(log, opt.model_groups, field, x, np.zeros(0))
    kept = ProcessBasis.of(log, opt.model_groups, field, y, np.zeros(0), previous=first)
    fresh = ProcessBasis.of(log, opt.model_groups, field, y, np.zeros(0))
    assert kept.parts.keys() == fresh.parts.keys() == first.parts.keys()
    for key, part in kept.parts.items():
        assert part.diag is first.parts[key].diag and part.lower is first.parts[key].lower
        for name in ("diag", "lower", "grad"):
            for got, want in zip(getattr(part, name), getattr(fresh.parts[key], name)):
                np.testing.assert_array_equal(got, want)
        assert part.cost == fresh.parts[key].cost
    assert not np.array_equal(kept.parts["force"].grad[1], first.parts["force"].grad[1])  # the residuals moved
    problem = make_problem(log, opt.model_groups)
    meas = measurement_normal_equations(problem, y)
    summed_first = first.banded(measurement_normal_equations(problem, x))
    summed_kept, summed_fresh = kept.banded(meas, previous=summed_first), fresh.banded(meas)
    setting = (7.0, (1.0, 0.5, 2.0), 3.0)
    values = []
    for summed in (summed_kept, summed_fresh):
        total, fac = summed.system(*setting)
        values.append(linearised_log_evidence(problem, y, None, total=total, factorisation=fac,
                                              minimum=lambda dx, dp: summed.half_cost(dx, dp, *setting)))
    assert values[0] == values[1]
    # other terms, or one Jacobian entry off by its last bit: not the same, the basis is made afresh
    assert first.same_jacobians(first.unit_terms) and not first.same_jacobians(first.unit_terms[:-1])
    t = first.unit_terms[-1]
    jac = {k: v.copy() for k, v in t.jac.items()}
    k = sorted(jac)[0]
    jac[k].reshape(-1)[np.flatnonzero(jac[k])[0]] *= 1.0 + 2.0**-52
    moved = first.unit_terms[:-1] + [type(t)(t.kind, t.residual, jac, t.jac_global, t.first)]
    assert not first.same_jacobians(moved)


def test_process_basis_is_not_used_for_the_oscillator_or_white_snap(log):
    opt = OPTIONS["oscillator"]
    assert ProcessBasis.of(log, opt.model_groups, "omega_dot_random_walk_radps2_per_sqrt_s", initial_states(log, opt.model_groups), np.zeros(0)) is None
    opt = OPTIONS["snap"]
    x = StateLayout.from_options(opt).resize(initial_states(log, opt.model_groups))
    assert ProcessBasis.of(log, opt.model_groups, "omega_ddot_random_walk_radps3_per_sqrt_s", x, np.zeros(0)) is None


def test_tuner_with_the_process_basis_chooses_what_it_chose_without():
    log = simulate("random3d", cube_array(0.025, noise_std_mps2=0.07), rate_hz=250.0, duration_s=3.0, seed=2)
    opt = SmootherOptions()
    x = initial_states(log, opt.model_groups)
    fast, *_ = tune(log, opt.model_groups, x)
    plain, *_ = tune(log, opt.model_groups, x, basis=False)
    assert fast.evaluations == plain.evaluations
    assert fast.density == pytest.approx(plain.density, rel=1e-9)
    np.testing.assert_allclose(fast.axis_factors, plain.axis_factors, rtol=1e-9)
    np.testing.assert_allclose(fast.axis_frequencies_hz, plain.axis_frequencies_hz, rtol=1e-9)
    assert fast.specific_force_density == pytest.approx(plain.specific_force_density, rel=1e-9)
    assert fast.log_evidence == pytest.approx(plain.log_evidence, rel=1e-12, abs=1e-6)


def test_tuner_with_the_process_basis_on_a_turntable_reaches_the_same_evidence():
    """Motion about z only: the evidence is flat in the x and y densities (any small factor will do),
    where sums in another order may pick another point of the plateau (a nat or so apart out of
    ten thousand); the density and the oscillator are the same."""
    log = simulate("turntable", cube_array(0.025, noise_std_mps2=0.07), rate_hz=250.0, duration_s=3.0, seed=2)
    opt = SmootherOptions()
    x = initial_states(log, opt.model_groups)
    fast, *_ = tune(log, opt.model_groups, x)
    plain, *_ = tune(log, opt.model_groups, x, basis=False)
    assert fast.log_evidence == pytest.approx(plain.log_evidence, abs=2.0)
    assert fast.density == pytest.approx(plain.density, rel=1e-3)
    np.testing.assert_allclose(fast.axis_frequencies_hz, plain.axis_frequencies_hz, rtol=1e-4)
    assert max(fast.axis_factors[:2]) < 0.02 and max(plain.axis_factors[:2]) < 0.02


# --- the initialisation's window sign resolution ------------------------------

from gfimu import rigid_body  # noqa: E402
from gfimu.smoother.solve.initialise import _SIGNS, sign_resolved_omega, trapezoid_integral, window_initial_omega  # noqa: E402


def window_initial_omega_by_samples(q_meas, integral, previous=None, continuity_std_radps=0.5, iterations=8):
    """The per-sample form of :func:`window_initial_omega`: residuals and Jacobians of every sample
    of every candidate stacked, Gauss-Newton on them."""
    L = q_meas.shape[0]
    Jw = rigid_body.quadratic_terms_jacobian(integral)
    rhs = (q_meas - rigid_body.quadratic_terms(integral)).reshape(-1)
    design = np.concatenate([Jw, np.broadcast_to(np.eye(6), (L, 6, 6))], axis=2).reshape(-1, 9)
    normal = design.T @ design
    theta = np.linalg.solve(normal + 1e-9 * np.trace(normal) * np.eye(9), design.T @ rhs)
    mags = rigid_body.omega_from_quadratic_terms(theta[3:])
    cands = np.vstack([theta[:3][None], _SIGNS * mags, _SIGNS * rigid_body.omega_from_quadratic_terms(q_meas[0])])
    w_c = 1.0 / continuity_std_radps

    def residuals(w0):
        om = w0[:, None, :] + integral[None]
        r = (rigid_body.quadratic_terms(om) - q_meas[None]).reshape(len(w0), -1)
        J = rigid_body.quadratic_terms_jacobian(om).reshape(len(w0), -1, 3)
        if previous is not None:
            r = np.concatenate([r, w_c * (w0 - previous)], axis=1)
            J = np.concatenate([J, np.broadcast_to(w_c * np.eye(3), (len(w0), 3, 3))], axis=1)
        return r, J

    w0 = cands
    for _ in range(iterations):
        r, J = residuals(w0)
        JT = np.swapaxes(J, 1, 2)
        w0 = w0 - np.linalg.solve(JT @ J + 1e-9 * np.eye(3), np.einsum("cij,cj->ci", JT, r)[..., None])[..., 0]
    r, _ = residuals(w0)
    cost = np.sum(r * r, axis=1)
    best = int(np.argmin(cost))
    return w0[best], float(cost[best])


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("with_previous", [False, True])
def test_window_omega_from_sums_equals_the_per_sample_gauss_newton(seed, with_previous):
    rng = np.random.default_rng(seed)
    L = 200
    h = np.full(L - 1, 0.002)
    omega_dot = np.cumsum(rng.normal(size=(L, 3)) * 2.0, axis=0) + rng.normal(size=3) * 20
    integral = trapezoid_integral(omega_dot, h)
    w_true = rng.normal(size=3) * 3.0
    q = rigid_body.quadratic_terms(w_true + integral) + rng.normal(size=(L, 6)) * 0.3
    previous = w_true + rng.normal(size=3) * 0.3 if with_previous else None
    fast, fast_cost = window_initial_omega(q, integral, previous)
    plain, plain_cost = window_initial_omega_by_samples(q, integral, previous)
    np.testing.assert_allclose(fast, plain, rtol=1e-8, atol=1e-9)
    assert fast_cost == pytest.approx(plain_cost, rel=1e-7, abs=1e-8)


@pytest.mark.parametrize("scenario", ["reversal", "turntable-constant"])
def test_sign_resolved_omega_equals_window_by_window_resolution(scenario):
    log = simulate(scenario, CUBE, rate_hz=500.0, duration_s=3.0, seed=1)
    w, wd = log.truth.omega_b_radps, log.truth.omega_dot_b_radps2
    q = rigid_body.quadratic_terms(w) + np.random.default_rng(3).normal(size=(len(log), 6)) * 0.2
    window = 200
    fast = sign_resolved_omega(q, wd, log.dt_s, window)
    plain = np.zeros_like(fast)
    previous, start, n = None, 0, len(log)
    while start < n:
        stop = min(start + window, n)
        if n - stop < window // 2:
            stop = n
        integral = trapezoid_integral(wd[start:stop], log.dt_s[start:stop - 1])
        w0, _ = window_initial_omega_by_samples(q[start:stop], integral, previous)
        plain[start:stop] = w0 + integral
        if stop < n:
            previous = plain[stop - 1] + 0.5 * (wd[stop - 1] + wd[stop]) * log.dt_s[stop - 1]
        start = stop
    np.testing.assert_allclose(fast, plain, rtol=1e-7, atol=1e-7)
    assert np.sqrt(np.mean((fast - w) ** 2)) < 0.2



@pytest.mark.parametrize("m, n", [(9, 1), (9, 7), (12, 5)])
def test_band_blocks_gathered_row_by_row_equal_the_entry_by_entry_gather(m, n):
    """:meth:`BandStructure.blocks` (one gather over every sample per band row, straight from the blocks)
    against the entry-by-entry loop: the same numbers, exactly (a copy, no arithmetic), also for a band
    row that takes entries from both the diagonal and the lower block and zeros."""
    from gfimu.smoother.solve.banded import BandStructure

    rng = np.random.default_rng(m + n)
    pattern = np.zeros((m, m), bool)
    pattern[np.arange(m), np.arange(m)] = True
    pattern[0, 3] = pattern[2, m - 1] = True
    structure = BandStructure.of(pattern)
    assert any(g[0] is not None for g in structure.gathers) and any(g[0] is None for g in structure.gathers)
    diag, lower = rng.normal(size=(n, m, m)), rng.normal(size=(max(n - 1, 0), m, m)) * pattern
    want = np.zeros((structure.bandwidth + 1, n, m))
    d_flat, l_flat = diag.reshape(n, m * m), lower.reshape(n - 1, m * m)
    for d in range(structure.bandwidth + 1):
        for p in range(m):
            i = int(structure.index[d, p])
            if i < m * m:
                want[d, :, p] = d_flat[:, i]
            elif i < 2 * m * m:
                want[d, : n - 1, p] = l_flat[:, i - m * m]
    got = structure.blocks(diag, lower)
    assert got.flags.c_contiguous
    np.testing.assert_array_equal(got, want)


def test_lifted_smoothing_band_written_from_its_parts_equals_the_dense_normal_equations(log):
    """The lifted initialisation's band (row d < 12: the constant measurement information, row 12: the
    random walks) against the dense normal equations of the same linear smoother, solved directly: the
    same z to the rounding of a well-conditioned solve."""
    from gfimu import noise
    from gfimu.smoother.solve.initialise import LIFTED, lifted_smoothing

    opt = SmootherOptions()
    sub = log.select(slice(0, 30))
    n = len(sub)
    S = sub.array.structure_matrix()
    sigma = noise.accel_noise_std(sub.array, opt.default_accel_noise_std_mps2)
    A = S / sigma[:, None]
    dens = np.repeat([opt.specific_force_random_walk_mps2_per_sqrt_s, opt.omega_dot_random_walk_radps2_per_sqrt_s, 300.0],
                     [3, 3, 6])
    H = np.kron(np.eye(n), A.T @ A + np.eye(LIFTED) / 1e4**2)
    for k, dt in enumerate(sub.dt_s):
        D = np.zeros((LIFTED, n * LIFTED))
        D[:, k * LIFTED:(k + 1) * LIFTED], D[:, (k + 1) * LIFTED:(k + 2) * LIFTED] = -np.eye(LIFTED), np.eye(LIFTED)
        W = np.diag(1.0 / (dens**2 * dt))
        H += D.T @ W @ D
    rhs = ((sub.accel_mps2 / sigma) @ A).reshape(-1)
    want = np.linalg.solve(H, rhs).reshape(n, LIFTED)
    got = lifted_smoothing(sub, opt.model)
    np.testing.assert_allclose(got, want, rtol=1e-8, atol=1e-8 * np.abs(want).max())
