"""Per-sample maximum-likelihood estimator (Skog et al. 2016)."""

import numpy as np
import pytest

from gfimu import array as layouts
from gfimu.array import Accelerometer, SensorArray, cube_array, mimu4444_array, paper001_array, single_triad
from gfimu.crb import crb_per_sample
from gfimu.methods import make_estimator
from gfimu.estimators.ml import MLEstimator
from gfimu.log import Log
from gfimu.motion import Motion
from gfimu.rotations import matrix_from_rotation_vector


def random_array(seed=0, n=5, noise=0.05):
    return layouts.random_array(n, half_extent_m=0.05, noise_std_mps2=noise, seed=seed, name="random-5")


def smooth_motion(n, rate_hz=500.0, seed=0, offset=(3.0, -1.5, 2.1)):
    """Smooth ω(t), its exact derivative, and a varying specific force."""
    t = np.arange(n) / rate_hz
    rng = np.random.default_rng(seed)
    amp, freq, phase = rng.uniform(2, 6, 3), rng.uniform(0.2, 1.0, 3), rng.uniform(0, 6, 3)
    arg = 2 * np.pi * freq * t[:, None] + phase
    w = amp * np.sin(arg) + np.asarray(offset)
    dw = amp * 2 * np.pi * freq * np.cos(arg)
    f = np.array([0.5, -1.0, 9.81]) + np.sin(3 * t)[:, None] * [1.0, 2.0, -0.5]
    return t, w, dw, f


def make_log(array, t, w, dw, f, noise_std=0.0, seed=1, gyro_noise=None):
    y = array.predict_readings(f, dw, w)
    rng = np.random.default_rng(seed)
    y = y + rng.normal(size=y.shape) * noise_std
    gyro = None
    if array.gyroscope is not None:
        gyro = w + (0 if gyro_noise is None else rng.normal(size=w.shape) * gyro_noise)
    ts = np.round(t * 1e9).astype(np.int64)
    truth = Motion(ts, omega_b_radps=w, omega_dot_b_radps2=dw, specific_force_b_mps2=f)
    return Log(array, ts, y, gyro_b_radps=gyro, truth=truth)


@pytest.mark.parametrize("array", [cube_array(), random_array(), mimu4444_array()], ids=["cube", "random-5", "mimu4444"])
def test_noise_free_recovery(array):
    t, w, dw, f = smooth_motion(3000)
    assert np.linalg.norm(w, axis=1).min() > 1.0
    m = MLEstimator().estimate(make_log(array, t, w, dw, f)).motion
    np.testing.assert_allclose(m.omega_b_radps, w, atol=1e-8)
    np.testing.assert_allclose(m.omega_dot_b_radps2, dw, atol=1e-8)
    np.testing.assert_allclose(m.specific_force_b_mps2, f, atol=1e-8)
    assert m.accel_b_mps2 is None and m.quaternion_wb is None


def test_sign_follows_omega_through_zero():
    """ω = d·4 sin(πt) changes sign twice; the integral of ω̇ keeps the branch."""
    t = np.arange(2000) / 500.0 + 0.0013
    d = np.array([0.48, -0.6, 0.64])
    w = 4 * np.sin(np.pi * t)[:, None] * d
    dw = 4 * np.pi * np.cos(np.pi * t)[:, None] * d
    f = np.tile([0.0, 0.0, 9.81], (len(t), 1))
    m = MLEstimator().estimate(make_log(cube_array(), t, w, dw, f)).motion
    np.testing.assert_allclose(m.omega_b_radps, w, atol=1e-7)


@pytest.mark.parametrize("array, omega", [(cube_array(), [3.0, -2.0, 4.0]), (mimu4444_array(), [12.0, -8.0, 10.0])],
                         ids=["cube", "mimu4444"])
def test_monte_carlo_covariance_reaches_the_bound(array, omega):
    """At high SNR the ML estimate is efficient: its covariance equals the CRB (Skog et al. 2016)."""
    n = 1500
    w0, f0, dw0 = np.asarray(omega), np.array([1.0, 2.0, 9.0]), np.array([5.0, -3.0, 2.0])
    t = np.arange(n) / 500.0
    log = make_log(array, t, np.tile(w0, (n, 1)), np.tile(dw0, (n, 1)), np.tile(f0, (n, 1)),
                   noise_std=array.noise_std_per_axis_mps2, seed=7)
    m = MLEstimator(compute_sigma=True).estimate(log).motion
    # constant ω carries no sign information (ω̇ = 0): compare modulo the sign
    w = m.omega_b_radps * np.sign(m.omega_b_radps @ w0)[:, None]
    err = np.hstack([m.specific_force_b_mps2 - f0, m.omega_dot_b_radps2 - dw0, w - w0])
    emp = err.T @ err / n
    bound = crb_per_sample(array, w0[None]).covariance[0]
    np.testing.assert_allclose(np.diag(emp) / np.diag(bound), 1.0, atol=0.15)
    # the mean error is within 4 standard errors of zero (no visible bias)
    assert np.all(np.abs(err.mean(axis=0)) < 4 * np.sqrt(np.diag(bound) / n))
    # sigma reported by the estimator is the bound at the estimate
    s = m.sigma["omega_b_radps"]
    np.testing.assert_allclose(np.median(s, axis=0), np.sqrt(np.diag(bound)[6:]), rtol=0.05)


def test_gyro_makes_a_nine_axis_array_usable():
    arr = paper001_array()
    assert "gyroscope" in MLEstimator().applicable(arr)
    est = MLEstimator(use_gyro=True)
    assert est.applicable(arr) is None
    t, w, dw, f = smooth_motion(1000)
    m = est.estimate(make_log(arr, t, w, dw, f)).motion
    np.testing.assert_allclose(m.omega_b_radps, w, atol=1e-9)
    np.testing.assert_allclose(m.omega_dot_b_radps2, dw, atol=1e-8)
    np.testing.assert_allclose(m.specific_force_b_mps2, f, atol=1e-8)


def test_gyro_improves_the_cube_with_noise():
    arr = SensorArray(cube_array().accelerometers, "cube+gyro", gyroscope=paper001_array().gyroscope)
    t, w, dw, f = smooth_motion(2000)
    log = make_log(arr, t, w, dw, f, noise_std=0.07, gyro_noise=0.01)
    e_acc = MLEstimator().estimate(log).motion.omega_b_radps - w
    e_gyro = MLEstimator(use_gyro=True).estimate(log).motion.omega_b_radps - w
    rms_gyro = np.sqrt(np.mean(e_gyro**2))
    assert rms_gyro < 0.01 and rms_gyro < 0.2 * np.sqrt(np.mean(e_acc**2))


def test_applicability_and_bad_input():
    assert "free-flight" in MLEstimator().applicable(single_triad())
    assert "no gyroscope" in MLEstimator(use_gyro=True).applicable(cube_array())
    assert isinstance(make_estimator("ml", compute_sigma=True), MLEstimator)
    t, w, dw, f = smooth_motion(10)
    log = make_log(cube_array(), t, w, dw, f)
    y = log.accel_mps2.copy()
    y[4, 7] = np.nan
    with pytest.raises(ValueError, match="sample 4, column a3_y"):
        MLEstimator().estimate(log.replace(accel_mps2=y)).motion
    with pytest.raises(ValueError, match="no gyro"):
        MLEstimator(use_gyro=True).estimate(make_log(paper001_array(), t, w, dw, f).replace(gyro_b_radps=None)).motion


def test_unknown_noise_still_estimates_but_sigma_needs_it():
    arr = cube_array(noise_std_mps2=None)
    t, w, dw, f = smooth_motion(200)
    log = make_log(arr, t, w, dw, f)
    np.testing.assert_allclose(MLEstimator().estimate(log).motion.omega_b_radps, w, atol=1e-8)
    with pytest.raises(ValueError, match="noise_std_mps2"):
        MLEstimator(compute_sigma=True).estimate(log).motion
    m = MLEstimator(compute_sigma=True, noise_std_mps2=0.07).estimate(log).motion
    np.testing.assert_allclose(m.sigma["specific_force_b_mps2"], 0.035, rtol=1e-9)


def test_monte_carlo_with_gyro_reaches_the_bound_with_gyro():
    arr = SensorArray(cube_array().accelerometers, "cube+gyro", gyroscope=paper001_array().gyroscope)
    n, w0 = 1500, np.array([1.0, -0.5, 2.0])
    t = np.arange(n) / 500.0
    log = make_log(arr, t, np.tile(w0, (n, 1)), np.zeros((n, 3)), np.tile([0.0, 0.0, 9.81], (n, 1)),
                   noise_std=0.07, gyro_noise=0.01, seed=9)
    m = MLEstimator(use_gyro=True, compute_sigma=True).estimate(log).motion
    emp = np.mean((m.omega_b_radps - w0) ** 2, axis=0)
    bound = crb_per_sample(arr, w0[None], gyro=True).sigma_omega[0] ** 2
    np.testing.assert_allclose(emp / bound, 1.0, atol=0.15)
    assert np.all(bound < 0.01**2)  # the gyro alone would give σ_g² = 1e-4
    np.testing.assert_allclose(m.sigma["omega_b_radps"][0], np.sqrt(bound), rtol=0.02)


def test_real_mimu4444_recording_against_the_gyros(mimu4444_dir):
    """Uncalibrated MIMU4444 board (nominal geometry): ML vs the mean of its eight gyros.

    Near-planar array (z = ±1 mm): the 12-unknown inversion is useless there,
    while the per-sample ML follows the gyros; the remaining error comes from
    the uncalibrated sensors, well above the CRB of white noise.
    """
    from gfimu.io.readers.mimu4444 import read_mimu4444
    from gfimu.estimators.inversion import InversionEstimator

    log, _ = read_mimu4444(mimu4444_dir / "exp_1")
    log = log.select(slice(30000, None))  # the hand-rotated part (the start is the static calibration phase)
    ref = log.reference.omega_b_radps
    moving = ~log.invalid_reference & (np.linalg.norm(ref, axis=1) > 15.0)
    assert moving.sum() > 1000
    w_ml = MLEstimator().estimate(log).motion.omega_b_radps[moving]
    e_ml = np.linalg.norm(w_ml - ref[moving], axis=1)
    e_inv = np.linalg.norm(InversionEstimator().estimate(log).motion.omega_b_radps[moving] - ref[moving], axis=1)
    assert np.median(e_ml) < 3.5
    assert np.median(e_ml) < 0.2 * np.median(e_inv)
    assert np.sqrt(np.mean(e_ml**2)) < 10.0
    # the integral of ω̇ keeps the sign at 62.5 Hz as well
    assert np.mean(np.sum(w_ml * ref[moving], axis=1) < 0) < 0.02


@pytest.mark.parametrize("scenario", ["reversal", "random3d"])
def test_signs_with_noise_on_the_cube(scenario):
    """Zero crossings on every axis (reversal) and random 3-D motion, cube with 0.07 m/s² noise:
    the ω̇ integral keeps the sign wherever |ω| > 1 rad/s, and ω̇, f reach their bounds."""
    from gfimu.simulate import simulate

    log = simulate(scenario, array=cube_array(), duration_s=5.0, seed=1)
    m = MLEstimator().estimate(log).motion
    truth = log.truth
    big = np.linalg.norm(truth.omega_b_radps, axis=1) > 1.0
    assert big.sum() > 1000
    wrong = np.sum(m.omega_b_radps * truth.omega_b_radps, axis=1) < 0
    assert wrong[big].mean() < 0.01
    # ω̇ and f do not depend on the sign of ω; for the cube their bound does not depend on ω at all
    bound = crb_per_sample(log.array, np.array([[3.0, -2.0, 4.0]]))
    rms_dw = np.sqrt(np.mean(np.sum((m.omega_dot_b_radps2 - truth.omega_dot_b_radps2) ** 2, axis=1)))
    rms_f = np.sqrt(np.mean(np.sum((m.specific_force_b_mps2 - truth.specific_force_b_mps2) ** 2, axis=1)))
    assert rms_dw == pytest.approx(bound.rmse_bound_omega_dot(), rel=0.1)
    assert rms_f == pytest.approx(bound.rmse_bound_specific_force(), rel=0.1)


def test_three_triads_are_refused_and_one_more_axis_suffices():
    """9 axes leave 3 equations for ω after eliminating f and ω̇: several exact roots per sample.
    One more axis (off the span) makes ω unique again, found by the cone multi-start."""
    three = random_array(seed=7, n=3)
    assert "several exact solutions" in MLEstimator().applicable(three)
    assert MLEstimator(use_gyro=True).applicable(SensorArray(three.accelerometers, gyroscope=paper001_array().gyroscope)) is None
    extra = Accelerometer("e", [0.04, -0.03, 0.02], matrix_from_rotation_vector([0.4, 1.1, -0.7]), axes=("x",), noise_std_mps2=0.05)
    ten = SensorArray(three.accelerometers + (extra,), "ten-axis")
    assert MLEstimator().applicable(ten) is None
    t, w, dw, f = smooth_motion(1000)
    m = MLEstimator().estimate(make_log(ten, t, w, dw, f)).motion
    np.testing.assert_allclose(m.omega_b_radps, w, atol=1e-8)
    np.testing.assert_allclose(m.specific_force_b_mps2, f, atol=1e-8)


class _EveryStartEveryPass(MLEstimator):
    """The neighbour passes without skipping starts that did not change (the plain definition), and the
    restarts found for the samples that call for one after the passes (not beforehand)."""

    def _finish_chunk(self, model, prepared, gyro, gyro_var, previous):
        from gfimu.estimators.ml import _cost

        b, c, w, cost, _ = prepared
        level = self._misfit_level(model, cost)  # the block's level, from its costs before the passes
        w, cost = w.copy(), cost.copy()
        for _ in range(self.neighbour_passes):
            first = w[:1] if previous is None else np.asarray(previous)[None, :]
            prev = np.vstack([first, w[:-1]])
            gap = np.minimum(np.linalg.norm(prev - w, axis=1), np.linalg.norm(prev + w, axis=1))
            idx = np.nonzero(gap > 0.1 * np.linalg.norm(w, axis=1) + 1e-6)[0]
            if idx.size == 0:
                break
            cand = self._iterate(model, b[idx], c[idx], prev[idx], None, gyro_var)
            cand_cost = _cost(model, b[idx], cand, None, gyro_var)
            better = cand_cost < cost[idx] * (1 - 1e-9)
            if not np.any(better):
                break
            w[idx[better]] = cand[better]
            cost[idx[better]] = cand_cost[better]
        return self._take_restarts(w, cost, *self._restarts(model, b, c, self._restart_rows(model, cost, level)))


def test_neighbour_passes_skip_only_starts_that_cannot_change_the_answer():
    # a noisy array turning slowly through zero: many samples take their neighbour's start; five blocks
    from gfimu.simulate import SensorErrors, simulate

    log = simulate("reversal", mimu4444_array(), rate_hz=100.0, duration_s=170.0, noise=SensorErrors(accel_noise_std_mps2=0.3), seed=3)
    fast = MLEstimator().estimate(log).motion.omega_b_radps
    plain = _EveryStartEveryPass(workers=1).estimate(log).motion.omega_b_radps
    assert np.array_equal(fast, plain)
    assert np.array_equal(MLEstimator(workers=1).estimate(log).motion.omega_b_radps, fast)  # blocks in workers or here


@pytest.mark.slow
def test_restarts_found_ahead_are_those_of_the_plain_definition():
    """The restarts are worked out for every sample that calls for one before the neighbour passes, in
    the blocks' workers, and taken for those that still call for one after them: the same estimate as
    restarting after the passes. Ten axes (rank below 6): every sample restarts and some move.
    Three estimates of 17,000 samples that all restart (about 10 s): in the slow set; the fast set keeps
    the same equality for the neighbour passes (test_neighbour_passes_skip_only_starts_that_cannot_change_the_answer)."""
    from gfimu.simulate import SensorErrors, simulate

    three = random_array(seed=7, n=3)
    extra = Accelerometer("e", [0.04, -0.03, 0.02], matrix_from_rotation_vector([0.4, 1.1, -0.7]), axes=("x",), noise_std_mps2=0.05)
    ten = SensorArray(three.accelerometers + (extra,), "ten-axis")
    log = simulate("random3d", ten, rate_hz=100.0, duration_s=170.0, noise=SensorErrors(accel_noise_std_mps2=0.05), seed=3)  # five blocks
    fast = MLEstimator().estimate(log).motion.omega_b_radps
    plain = _EveryStartEveryPass(workers=1).estimate(log).motion.omega_b_radps
    assert np.array_equal(fast, plain)
    no_restarts = MLEstimator(workers=1)
    no_restarts._take_restarts = lambda w, cost, rows, best, best_cost: w
    assert np.sum(np.any(no_restarts.estimate(log).motion.omega_b_radps != fast, axis=1)) > 100  # restarts were taken


def test_closed_forms_of_the_iterations_match_the_direct_products():
    """The LM pieces written out (Gram of J_q, J_qᵀ v, the 3 × 3 solve, the reduced cost) against the
    plain products, solve and residual on random inputs."""
    from gfimu import rigid_body
    from gfimu.estimators.ml import (_SYMMETRIC_FLAT, _ProjectedModel, _cost, _det_symmetric_3x3, _jacobian_gram, _monomials,
                                     _quadratic_terms_jacobian_t, _solve_symmetric_3x3)
    from gfimu.noise import accel_noise_std

    rng = np.random.default_rng(4)
    w = rng.normal(scale=5.0, size=(500, 3))
    v = rng.normal(size=(500, 6))
    Mx = rng.normal(size=(6, 6))
    Mx = Mx @ Mx.T
    J = rigid_body.quadratic_terms_jacobian(w)
    direct = np.swapaxes(J, 1, 2) @ (Mx @ J)
    np.testing.assert_allclose((_monomials(w) @ _jacobian_gram(Mx)).reshape(-1, 3, 3), direct, rtol=1e-12, atol=1e-12 * np.abs(direct).max())
    np.testing.assert_allclose(_quadratic_terms_jacobian_t(w, v), np.einsum("nja,nj->na", J, v), rtol=1e-12, atol=1e-12)
    # ill-scaled but definite systems (diagonals over twelve decades), and one nearly singular one (LU fallback)
    B = rng.normal(size=(500, 3, 3))
    S = B @ np.swapaxes(B, 1, 2) + 1e-3 * np.eye(3)
    S *= np.geomspace(1e-6, 1e6, 500)[:, None, None]
    S[0] = [[1.0, 1.0, 0.0], [1.0, 1.0 + 1e-14, 0.0], [0.0, 0.0, 1.0]]
    rhs = rng.normal(size=(500, 3))
    packed = S.reshape(-1, 9)[:, _SYMMETRIC_FLAT]
    np.testing.assert_allclose(_solve_symmetric_3x3(packed, rhs), np.linalg.solve(S, rhs[..., None])[..., 0], rtol=1e-7)
    np.testing.assert_allclose(_det_symmetric_3x3(packed)[1:], np.linalg.det(S[1:]), rtol=1e-9)
    model = _ProjectedModel.build(mimu4444_array(), accel_noise_std(mimu4444_array()))
    y = rng.normal(size=(500, model.proj.shape[0]))
    b, c = model.readings(y)
    full = y @ model.proj.T
    residual = full - rigid_body.quadratic_terms(w) @ model.A.T
    np.testing.assert_allclose(_cost(model, b, w, None, None), np.sum(residual**2, axis=1), rtol=1e-10)
    np.testing.assert_allclose(c, full @ model.A, rtol=1e-12, atol=1e-12)


def test_viterbi_signs_minimise_the_transition_cost_over_every_sign_sequence():
    """The two-state recursion against every one of the 2^m sign sequences of a short run (up to the overall
    sign, which the costs do not see when the integral is zero, and which the integral fixes otherwise)."""
    import itertools

    from gfimu.estimators.ml import _viterbi_signs

    rng = np.random.default_rng(11)
    for trial in range(20):
        m = 8
        u = rng.normal(size=(m, 3))
        integral = np.cumsum(rng.normal(size=(m, 3)) * rng.choice([0.1, 1.0, 3.0]), axis=0)
        inc = np.diff(integral, axis=0)

        def cost(s):
            v = np.asarray(s)[:, None] * u
            return float(np.sum((v[1:] - v[:-1] - inc) ** 2))

        best = min(itertools.product((1.0, -1.0), repeat=m), key=cost)
        got = _viterbi_signs(u, integral)
        assert set(np.unique(got)) <= {1.0, -1.0}
        assert cost(got) == pytest.approx(cost(best), rel=1e-12, abs=1e-12)


def test_grid_start_taken_block_by_block_equals_the_whole_grid_at_once():
    """``_grid_best`` (blocks of ``_GRID_ROWS`` samples) picks the same grid point, at the same cost, as the
    minimum over the whole (N, G) cost matrix, also for a length that is not a whole number of blocks."""
    from gfimu.estimators import ml

    est = MLEstimator()
    array = cube_array(0.05, noise_std_mps2=0.07)
    model = ml._ProjectedModel.build(array, np.full(array.n_axes, 0.07))
    t, w, dw, f = smooth_motion(2 * ml._GRID_ROWS + 37, seed=4)
    y = make_log(array, t, w, dw, f, noise_std=0.07).accel_mps2
    _, c = model.readings(y)
    grid, _ = est._grid()
    whole = est._grid_cost(model, c, grid)
    best, cost = est._grid_best(model, c, grid)
    np.testing.assert_array_equal(best, np.argmin(whole, axis=1))
    np.testing.assert_array_equal(cost, whole[np.arange(len(c)), best])


def test_iterations_on_the_shrinking_active_set_equal_each_sample_iterated_alone():
    """The numpy iterations keep only the samples still moving; each sample's answer is the one it gets
    when iterated alone (its arithmetic is its own), up to the rounding of the products, which BLAS may
    take in another order for one row than for many: a sample stops where its cost is flat to 1e-15 of
    itself, so a different rounding may stop it up to about √1e-15 ≈ 3e-8 (relative) from the other run."""
    from gfimu.estimators import ml

    est = MLEstimator()
    est.compiled = False  # the numpy expressions (the compiled kernel has its own test against them)
    array = cube_array(0.05, noise_std_mps2=0.07)
    model = ml._ProjectedModel.build(array, np.full(array.n_axes, 0.07))
    t, w, dw, f = smooth_motion(60, seed=5)
    y = make_log(array, t, w, dw, f, noise_std=0.07).accel_mps2
    b, c = model.readings(y)
    starts = w + np.random.default_rng(2).normal(scale=0.5, size=w.shape)
    together = est._iterate(model, b, c, starts, None, None)
    alone = np.vstack([est._iterate(model, b[k:k + 1], c[k:k + 1], starts[k:k + 1], None, None) for k in range(len(w))])
    np.testing.assert_allclose(together, alone, rtol=3e-7, atol=1e-8)
    assert np.sqrt(np.mean((together - w) ** 2)) < 1.0  # and they converge near the truth


@pytest.mark.parametrize("noise_factor", [1.0, 5.0])
def test_restarts_are_called_for_against_the_blocks_own_noise_level(noise_factor):
    """restart_level 'measured' (default): a sample restarts when its cost is implausible for the noise level its
    block shows (the median cost over the median of χ² with n_axes - 9 degrees of freedom), never below the stated
    level. Readings with the stated noise: the level is 1 within the median's scatter and the estimate is the one of
    'stated'. Readings 5 times noisier than stated (a variance 25 times): the level is 25 within the scatter (up to
    10 % more: at that noise q(ω) bends within the noise, and the costs are not quite χ²), a few samples restart
    where every one did against the stated level, and the estimate is as good."""
    from gfimu.estimators.ml import _cost, _ProjectedModel
    from gfimu.simulate import SensorErrors, simulate

    array = mimu4444_array(noise_std_mps2=0.05)
    log = simulate("random3d", array, rate_hz=200.0, duration_s=20.0, seed=4,
                   noise=SensorErrors(accel_noise_std_mps2=0.05 * noise_factor))
    est = MLEstimator(workers=1)
    model = _ProjectedModel.build(array, est._axis_sigma(array))
    b, c, w, cost, restarts = est._prepare_chunk(array, model, log.accel_mps2[:4096], None, None)
    level = restarts[0]
    dof = model.A.shape[0] - 9
    scatter = 3 * 1.2533 * np.sqrt(2 / dof) / np.sqrt(cost.size)  # 3 std of a median of chi2 / its median
    # with large noise the cost is not quite the linear model's χ² (q(ω) bends within the noise): up to 10 % more
    allowance = 1 + scatter if noise_factor == 1.0 else 1.1
    assert level == est._misfit_level(model, cost) and 1.0 <= level <= noise_factor ** 2 * allowance
    assert level >= noise_factor ** 2 * (1 - scatter)
    stated = MLEstimator(workers=1, restart_level="stated")
    assert stated._misfit_level(model, cost) == 1.0
    n_measured = est._restart_rows(model, cost, level).size
    n_stated = est._restart_rows(model, cost).size
    got = est.estimate_motion(log).omega_b_radps
    want = stated.estimate_motion(log).omega_b_radps
    truth = log.truth.omega_b_radps
    rmse = lambda w_: float(np.sqrt(np.mean(np.sum((w_ - truth) ** 2, axis=1))))  # noqa: E731
    if noise_factor == 1.0:
        assert n_measured <= n_stated and np.mean(np.all(got == want, axis=1)) > 0.999
    else:
        assert n_stated > 0.9 * cost.size and n_measured < 0.05 * cost.size
        assert rmse(got) <= 1.01 * rmse(want)


def test_an_unknown_restart_level_is_refused():
    from gfimu.errors import InputError

    with pytest.raises(InputError, match="restart_level"):
        MLEstimator(restart_level="always")
