"""The running σ scale's compiled row (gfimu.smoother.solve.sigma_kernels) against the numpy expression it
replaces (gfimu.smoother.solve.sigma_scale.kinematic_shares), which stays the oracle."""

import numpy as np
import pytest

from gfimu.smoother.solve import sigma_scale as ss
from gfimu.smoother.solve.sigma_kernels import kinematic_shares_row


def _rows(rng, n):
    single = 10.0 ** rng.uniform(-8, 2, size=(n, 9))
    t = 10.0 ** rng.uniform(-12, -2, size=(n, 3))
    s = 10.0 ** rng.uniform(-8, 0, size=(n, 3))
    h = 10.0 ** rng.uniform(-4.7, -1.3, size=n)  # 20 kHz to 20 Hz
    # the edges the numpy expression handles: a variance not known (inf), none (0), not a number
    single[0, 0], single[1, 4], single[2, 1], single[3, :6] = np.inf, 0.0, np.nan, np.inf
    return single, t, s, h


def test_the_compiled_row_is_the_numpy_expression():
    """Per row and axis, share, a and b as kinematic_shares gives them, to a few ulps of the sums (the 32-point
    quadrature summed in another order), over variances across 10 decades, steps from 20 kHz to 20 Hz and the
    rows whose variances are infinite, zero or NaN."""
    rng = np.random.default_rng(5)
    single, t, s, h = _rows(rng, 400)
    share, a, b = ss.kinematic_shares(single, t, s, h)
    quad = ss._quadrature(ss.QUADRATURE_POINTS)
    for k in range(len(h)):
        out = np.empty(3), np.empty(3), np.empty(3)
        kinematic_shares_row(single[k], t[k], s[k], float(h[k]), *quad, *out)
        for got, want in zip(out, (share[k], a[k], b[k])):
            np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-15)
    assert np.any(share == 0.0) and np.all((share >= 0) & (share <= 1))


def test_the_running_scale_takes_the_compiled_row():
    """RunningTrapezoid.shares (what the running σ scale calls per state) is kinematic_shares' first row."""
    rng = np.random.default_rng(6)
    single, t, s, h = _rows(rng, 5)
    for k in range(5):
        got = ss.RunningTrapezoid.shares(single[k], t[k], s[k], float(h[k]))
        want = ss.kinematic_shares(single[k:k + 1], t[k:k + 1], s[k:k + 1], h[k:k + 1])
        for g, w in zip(got, want):
            assert g == pytest.approx(w[0], rel=1e-12, abs=1e-15)


@pytest.mark.parametrize("robust", [None, ("huber", 1.5), ("cauchy", 2.0)])
@pytest.mark.parametrize("array_kind", ["cube", "pair"])
def test_the_compiled_parity_is_the_numpy_expression(robust, array_kind):
    """RunningSigmaScale's per-sample parity (its compiled row) against gfimu.smoother.solve.sigma_scale.parity
    over many samples: the parity residual to rounding of the whitened readings, the rank, and each state's
    single-sample variance to rounding of the SVD (infinite where the sample cannot see it: a planar array
    does not see every ω̇ and f component from one sample), with and without the robust re-weighting."""
    from gfimu.array import Accelerometer, SensorArray, cube_array

    rng = np.random.default_rng(7)
    if array_kind == "cube":
        array = cube_array(0.05, 0.02)
    else:  # two triads: six readings for nine states, some of them unseen by one sample
        pos = np.array([[0.05, 0.01, 0.0], [-0.05, 0.0, 0.02]])
        array = SensorArray(tuple(Accelerometer(f"a{i}", p, noise_std_mps2=0.02) for i, p in enumerate(pos)), "pair")
    n, m = 300, array.n_axes
    X = np.column_stack([rng.normal(0, 5, (n, 3)), rng.normal(0, 50, (n, 3)), rng.normal(0, 10, (n, 3))])
    X[:5, :3] = 0.0  # at rest one sample does not see ω (q(ω)'s Jacobian vanishes): its variance unknown
    y = rng.normal(0, 10, (n, m))
    std = 10.0 ** rng.uniform(-2, 0, (n, m))
    p0, r0, s0, d0 = ss.parity(array, y, X, std, robust, slopes=True)
    scale = ss.RunningSigmaScale(array)
    scale.robust = robust
    for k in range(n):
        p1, r1, s1, d1 = scale._parity(y[k], X[k], std[k])
        assert r1 == r0[k]
        z = np.abs(y[k] / std[k]) + 1.0  # the whitened readings' size
        # sums of m terms: weights and leverages within 0 … 1, slopes within -1 … 1, p² at most z²
        np.testing.assert_allclose(d1, d0[k], rtol=0, atol=1e-9 * m * np.max(z) ** 2)
        assert np.all(np.abs(p1 - p0[k]) <= 1e-9 * np.max(z))
        finite = np.isfinite(s0[k])
        assert np.array_equal(np.isfinite(s1), finite)
        np.testing.assert_allclose(s1[finite], s0[k][finite], rtol=1e-8)
    if array_kind == "cube":
        assert np.all(np.isinf(s0[:5, :3])) and np.all(np.isfinite(s0[5:]))