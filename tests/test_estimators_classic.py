"""Per-sample estimators: integration, pure integration and the context-based IMM (Ho & Lin 2009; Lin et al. 2011)."""

import numpy as np
import pytest

from gfimu.array import cube_array
from gfimu.methods import make_estimator
from gfimu.estimators.imm import IMMEstimator, case_rule, context_memberships, imm_case, imm_weights
from gfimu.estimators.integration import SIGN_CANDIDATES, select_candidate
from gfimu.log import Log
from gfimu.motion import Motion
from gfimu.rigid_body import quadratic_terms


def analytic_log(array, omega_fn, rate_hz=500.0, duration_s=4.0, noise_std=0.0, seed=0, t_ns=None, gyro=False):
    """Log of an analytic motion: omega_fn(t) -> (ω, ω̇) (N, 3) each; f(t) smooth, readings exact + noise."""
    if t_ns is None:
        t_ns = np.round(np.arange(int(rate_hz * duration_s)) * 1e9 / rate_hz).astype(np.int64)
    t = t_ns * 1e-9
    w, dw = omega_fn(t)
    f = np.column_stack([0.8 * np.sin(1.3 * t), -0.5 * np.cos(0.7 * t), 9.80665 + 0.3 * np.sin(2.1 * t)])
    acc = array.predict_readings(f, dw, w)
    rng = np.random.default_rng(seed)
    acc = acc + noise_std * rng.standard_normal(acc.shape)
    return Log(array, t_ns, acc, gyro_b_radps=w.copy() if gyro else None,
               truth=Motion(t_ns, omega_b_radps=w, omega_dot_b_radps2=dw, specific_force_b_mps2=f))


def sines(amp=(3.0, 2.0, 4.0), freq=(0.3, 0.45, 0.2), phase=(0.3, 1.0, 2.0), offset=(0.0, 0.0, 0.0)):
    amp, freq, phase, offset = (np.asarray(v, float) for v in (amp, freq, phase, offset))

    def fn(t):
        arg = 2 * np.pi * freq * t[:, None] + phase
        return offset + amp * np.sin(arg), amp * 2 * np.pi * freq * np.cos(arg)

    return fn


def slow_crossing(t):
    """ω = (0.8 sin(0.5 t), 0, 0): the whole ω passes slowly through zero at t = 2π."""
    w = np.column_stack([0.8 * np.sin(0.5 * t), 0 * t, 0 * t])
    dw = np.column_stack([0.4 * np.cos(0.5 * t), 0 * t, 0 * t])
    return w, dw


NOISELESS = cube_array(noise_std_mps2=None)


def test_candidate_selection_is_componentwise_sign_choice():
    rng = np.random.default_rng(4)
    mag = np.abs(rng.normal(size=(500, 3)))
    pred = rng.normal(size=(500, 3))
    brute = np.array([min((s * m for s in SIGN_CANDIDATES), key=lambda c: np.sum((c - p) ** 2)) for m, p in zip(mag, pred)])
    np.testing.assert_array_equal(select_candidate(mag, pred), brute)
    np.testing.assert_array_equal(select_candidate(mag, pred), np.where(pred >= 0, mag, -mag))


@pytest.mark.parametrize("method", ["integration", "imm"])
def test_noise_free_recovery(method):
    log = analytic_log(NOISELESS, sines())
    m = make_estimator(method, initial_omega=tuple(log.truth.omega_b_radps[0])).estimate(log).motion
    tol = 1e-9 if method == "integration" else 1e-4  # the IMM uses the trapezoid prediction between T1 and T2
    np.testing.assert_allclose(m.omega_b_radps, log.truth.omega_b_radps, atol=tol)
    np.testing.assert_allclose(m.omega_dot_b_radps2, log.truth.omega_dot_b_radps2, atol=1e-10)
    np.testing.assert_allclose(m.specific_force_b_mps2, log.truth.specific_force_b_mps2, atol=1e-11)


def test_pure_integration_is_second_order_and_drift_free_without_noise():
    errs = []
    for rate in (200.0, 400.0):
        log = analytic_log(NOISELESS, sines(), rate_hz=rate)
        m = make_estimator("pure-integration", initial_omega=tuple(log.truth.omega_b_radps[0])).estimate(log).motion
        errs.append(np.abs(m.omega_b_radps - log.truth.omega_b_radps).max())
    assert errs[0] < 1e-3
    assert errs[0] / errs[1] == pytest.approx(4.0, rel=0.05)


def test_pure_integration_initial_omega_options():
    log = analytic_log(NOISELESS, sines(offset=(1.0, -2.0, 0.5)), duration_s=0.2)
    w0 = log.truth.omega_b_radps[0]
    zero = make_estimator("pure-integration").estimate(log).motion
    np.testing.assert_allclose(zero.omega_b_radps[0], 0.0)
    quad = make_estimator("pure-integration", initial_omega="quadratic").estimate(log).motion
    # 'quadratic' gives ω up to a global sign, with the largest component positive
    sign = np.sign(w0[np.argmax(np.abs(w0))])
    np.testing.assert_allclose(quad.omega_b_radps[0], sign * w0, atol=1e-9)
    with pytest.raises(ValueError, match="initial_omega"):
        make_estimator("pure-integration", initial_omega="bogus")
    with pytest.raises(ValueError, match="initial_omega"):
        make_estimator("integration", initial_omega=(1.0, 2.0))


def test_integration_keeps_sign_where_inversion_flips():
    log = analytic_log(NOISELESS, slow_crossing, rate_hz=200.0, duration_s=12.0)
    true = log.truth.omega_b_radps[:, 0]
    after = log.times_s > 2 * np.pi + 0.5
    assert np.any(after) and np.all(true[after] < -0.1)
    inv = make_estimator("inversion").estimate(log).motion.omega_b_radps[:, 0]
    integ = make_estimator("integration").estimate(log).motion.omega_b_radps[:, 0]
    # inversion: magnitude right, sign lost after the zero crossing
    np.testing.assert_allclose(np.abs(inv), np.abs(true), atol=1e-6)
    assert np.all(inv[after] > 0)
    # integration: the trapezoid prediction carries the sign through zero
    np.testing.assert_allclose(integ, true, atol=1e-6)


def test_integration_restarts_at_gaps():
    t_ns = np.round(np.arange(1000) * 2e6).astype(np.int64)
    t_ns[500:] += int(3e9)  # 3 s gap
    log = analytic_log(NOISELESS, sines(offset=(2.0, 0, 0)), t_ns=t_ns)
    assert len(log.segments()) == 2
    pure = make_estimator("pure-integration", initial_omega=tuple(log.truth.omega_b_radps[0])).estimate(log).motion
    # second segment restarts from the quadratic terms, not by integrating across the gap
    w = log.truth.omega_b_radps[500]
    sign = np.sign(w[np.argmax(np.abs(w))])
    np.testing.assert_allclose(pure.omega_b_radps[500], sign * w, atol=1e-9)
    assert np.abs(pure.omega_b_radps[:500] - log.truth.omega_b_radps[:500]).max() < 1e-3


@pytest.mark.parametrize("method", ["inversion", "integration", "imm"])
def test_error_grows_linearly_with_noise(method):
    """f and ω̇ errors scale with the noise std; ω stays bounded (no blow-up)."""
    fn = sines(amp=(6.0, 5.0, 7.0), offset=(8.0, -7.0, 9.0))
    rms = []
    for sd in (0.01, 0.02):
        log = analytic_log(cube_array(noise_std_mps2=sd), fn, duration_s=2.0, noise_std=sd, seed=3)
        m = make_estimator(method, initial_omega=tuple(log.truth.omega_b_radps[0])) if method != "inversion" \
            else make_estimator(method)
        est = m.estimate(log).motion
        rms.append([np.sqrt(np.mean((getattr(est, k) - getattr(log.truth, k)) ** 2))
                    for k in ("specific_force_b_mps2", "omega_dot_b_radps2", "omega_b_radps")])
    rms = np.array(rms)
    assert rms[1, 0] / rms[0, 0] == pytest.approx(2.0, rel=0.1)
    assert rms[1, 1] / rms[0, 1] == pytest.approx(2.0, rel=0.1)
    # far from zero, |ω| error ≈ σ(ω²)/(2|ω|): linear in the noise too
    assert rms[1, 2] / rms[0, 2] == pytest.approx(2.0, rel=0.2)
    assert rms[1, 2] < 0.05


# --- IMM: contexts and the four cases (Lin et al. 2011 §3.2) ---------------------

T1, T2 = 0.1, 4.0


def q_of(w):
    return quadratic_terms(np.asarray(w, float))[None, :]


@pytest.mark.parametrize(
    "omega, case, alpha, beta",
    [
        ((3.0, -2.5, 2.0), 1, [0, 0, 0], [1, 1, 1]),  # a, b, c >= T2
        ((1.0, 1.0, 3.0), 2, [1, 1, 0], [0, 0, 1]),  # a = 2 in [T1, T2), b = c = 10
        ((1.0, 3.0, 1.0), 2, [1, 0, 1], [0, 1, 0]),  # b = 2 in [T1, T2): y quadratic
        ((0.1, 0.1, 3.0), 3, [0, 0, 0], [0, 0, 1]),  # a = 0.02 < T1, b = c ≈ 9
        ((3.0, 0.0, 0.0), 3, [0, 0, 0], [1, 0, 0]),  # c = 0 < T1, a = b = 9: x quadratic, y, z zero
        ((0.1, 0.15, 0.1), 4, [0, 0, 0], [0, 0, 0]),  # all < T1
        ((1.0, 1.0, 1.0), 0, [1, 1, 1], [0, 0, 0]),  # all in [T1, T2): fall-back
        ((1.5, 0.0, 0.0), 0, [1, 1, 1], [0, 0, 0]),  # a = b = 2.25 in [T1, T2), c = 0 < T1: fall-back
    ],
)
def test_imm_cases(omega, case, alpha, beta):
    q = q_of(omega)
    assert imm_case(q, T1, T2)[0] == case
    a, b = imm_weights(q, T1, T2, 0.0, 0.0)
    np.testing.assert_array_equal(a[0], alpha)
    np.testing.assert_array_equal(b[0], beta)


def test_imm_case_rule_covers_27_combinations():
    counts = {}
    for la in range(3):
        for lb in range(3):
            for lc in range(3):
                counts[case_rule((la, lb, lc))[1]] = counts.get(case_rule((la, lb, lc))[1], 0) + 1
    assert counts == {1: 1, 2: 3, 3: 3, 4: 1, 0: 19}
    # the axis left out of the non-quadratic sum is the quadratic one
    assert case_rule((2, 1, 2))[0] == (1, 2, 1)  # b = ωx²+ωz² in [T1, T2): y from the quadratic model
    assert case_rule((2, 2, 0))[0] == (2, 0, 0)  # c = ωy²+ωz² < T1: x quadratic, y and z zero


def test_imm_negative_sum_falls_back_to_integration():
    q = np.array([[-0.3, 9.0, 9.0, 0.0, 0.0, 0.0]])
    assert imm_case(q, T1, T2)[0] == 0
    alpha, beta = imm_weights(q, T1, T2, 0.02, 0.02)
    np.testing.assert_array_equal(alpha, [[1, 1, 1]])
    np.testing.assert_array_equal(beta, [[0, 0, 0]])


def test_imm_soft_switching_is_linear_across_the_bands():
    h = 0.1
    delta = T2 - T1
    s = np.array([T1 - h * delta, T1, T1 + h * delta, T2 - h * delta, T2, T2 + h * delta, 0.5 * (T1 + T2)])
    p = context_memberships(s, T1, T2, h, h)
    np.testing.assert_allclose(p.sum(axis=1), 1.0)
    np.testing.assert_allclose(p[:, 0], [1, 0.5, 0, 0, 0, 0, 0])
    np.testing.assert_allclose(p[:, 2], [0, 0, 0, 0, 0.5, 1, 0])
    # blending near T1: half zero model, half integration for the axes of that sum (eq. 16)
    q = np.array([[T1, 9.0, 9.0, 0.0, 0.0, 0.0]])
    alpha, beta = imm_weights(q, T1, T2, h, h)
    np.testing.assert_allclose(alpha, [[0.5, 0.5, 0.0]])
    np.testing.assert_allclose(beta, [[0.0, 0.0, 1.0]])


def test_imm_estimate_follows_the_cases():
    """ω = (0, 0, 3): case 3 zeroes x, y exactly even when the prediction is wrong."""
    t = np.arange(200) * 0.002

    def spin(t):
        return np.column_stack([0 * t, 0 * t, 3.0 + 0 * t]), np.zeros((t.size, 3))

    log = analytic_log(NOISELESS, spin, duration_s=0.4)
    est = IMMEstimator(t2=T2, initial_omega=(0.5, -0.4, 2.0)).estimate(log).motion
    np.testing.assert_allclose(est.omega_b_radps, np.tile([0, 0, 3.0], (len(t), 1)), atol=1e-12)
    # all sums large: case 1 gives the quadratic magnitudes with the predicted signs
    log = analytic_log(NOISELESS, lambda t: (np.tile([3.0, -2.5, 2.0], (t.size, 1)), np.zeros((t.size, 3))),
                       duration_s=0.4)
    est = IMMEstimator(t2=T2, initial_omega=(1.0, -1.0, 1.0)).estimate(log).motion
    np.testing.assert_allclose(est.omega_b_radps, np.tile([3.0, -2.5, 2.0], (log.timestamps_ns.size, 1)), atol=1e-12)
    # all sums tiny: case 4 gives zero
    log = analytic_log(NOISELESS, lambda t: (np.tile([0.05, 0.04, 0.05], (t.size, 1)), np.zeros((t.size, 3))),
                       duration_s=0.4)
    est = IMMEstimator(t2=T2, initial_omega=(1.0, -1.0, 1.0)).estimate(log).motion
    np.testing.assert_array_equal(est.omega_b_radps, 0.0)


def test_imm_t2_from_trend_line_and_option_checks():
    est = IMMEstimator(t2_intercept=3.0, t2_slope=0.02)
    q = quadratic_terms(np.tile([3.0, 4.0, 5.0], (10, 1)))
    assert est.thresholds(q) == (0.1, pytest.approx(3.0 + 0.02 * 2 * (9 + 16 + 25)))
    assert IMMEstimator(t2=6.0).thresholds(q) == (0.1, 6.0)
    with pytest.raises(ValueError, match="t2 must exceed"):
        IMMEstimator(t1=1.0, t2=0.5)
    with pytest.raises(ValueError, match="h1"):
        IMMEstimator(h1=-0.1)


def test_estimators_refuse_arrays_they_cannot_invert():
    from gfimu.array import single_triad

    for name in ("inversion", "integration", "pure-integration", "imm"):
        reason = make_estimator(name).applicable(single_triad())
        assert reason is not None and "needs at least 12" in reason
    assert make_estimator("imm").applicable(cube_array()) is None


def test_bad_readings_are_named():
    log = analytic_log(NOISELESS, sines(), duration_s=0.1)
    acc = log.accel_mps2.copy()
    acc[7, 4] = np.nan
    with pytest.raises(ValueError, match=r"sample 7 column 'a2_y'"):
        make_estimator("integration").estimate(log.replace(accel_mps2=acc)).motion


def test_sign_tracking_beats_inversion_through_zero_crossings_with_noise():
    """Each component crosses zero many times; the cube's noise level of Ho & Lin 2009 (0.07 m/s²)."""
    log = analytic_log(cube_array(noise_std_mps2=0.07), sines(amp=(3.0, 2.5, 3.5), freq=(0.55, 0.75, 0.95)),
                       duration_s=10.0, noise_std=0.07, seed=1)
    w0 = tuple(log.truth.omega_b_radps[0])

    def rmse(est):
        return np.sqrt(np.mean(np.sum((est.omega_b_radps - log.truth.omega_b_radps) ** 2, axis=1)))

    inv = rmse(make_estimator("inversion").estimate(log).motion)
    integ = rmse(make_estimator("integration", initial_omega=w0).estimate(log).motion)
    imm = rmse(make_estimator("imm", initial_omega=w0).estimate(log).motion)
    assert inv > 1.5
    assert integ < 0.5 * inv and integ < 1.0
    assert imm < 0.5 * inv and imm < 1.0


def test_imm_restarts_at_gaps():
    t_ns = np.round(np.arange(1000) * 2e6).astype(np.int64)
    t_ns[500:] += int(3e9)
    log = analytic_log(NOISELESS, sines(amp=(1.0, 1.0, 1.0), offset=(0.5, 0.5, 0.5)), t_ns=t_ns)
    est = IMMEstimator(t2=4.0, initial_omega="zero").estimate(log).motion
    # all sums in [T1, T2): the IMM integrates; each segment starts from zero again
    assert np.all(imm_case(quadratic_terms(log.truth.omega_b_radps), 0.1, 4.0) == 0)
    np.testing.assert_allclose(est.omega_b_radps[[0, 500]], 0.0)
    w = log.truth.omega_b_radps
    np.testing.assert_allclose(est.omega_b_radps[500:] - est.omega_b_radps[500], w[500:] - w[500], atol=1e-4)
