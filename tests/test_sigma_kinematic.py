"""ω's σ and the path's own trapezoid level (gfimu.smoother.solve.sigma_scale: kinematic_shares, trapezoid_level):
checked on a linear-Gaussian chain where everything is exact: one body axis, ω and ω̇ observed every sample,
tied by the white-jerk model's trapezoid rows and ω̇ steps."""

import math

import numpy as np
import pytest

from gfimu.smoother.solve import sigma_scale as ss

H = 0.01  # step [s]
Q = 30.0  # jerk density [rad/s²/√s]
SIGMA_W, SIGMA_D = 0.02, 0.5  # one sample's std of ω [rad/s] and ω̇ [rad/s²]
T_VAR, S_VAR = Q * Q * H ** 3 / 12.0, Q * Q * H  # trapezoid and ω̇-step variances


def chain(n):
    """(G (rows, 2n) whitened design, (meas rows, trapezoid rows, step rows) slices) of the chain with states
    [ω_0, ω̇_0, ω_1, ω̇_1, …]."""
    G = np.zeros((2 * n + 2 * (n - 1), 2 * n))
    k = np.arange(n)
    G[k, 2 * k] = 1.0 / SIGMA_W
    G[n + k, 2 * k + 1] = 1.0 / SIGMA_D
    j = np.arange(n - 1)
    r = 2 * n + j
    G[r, 2 * j + 2], G[r, 2 * j], G[r, 2 * j + 1], G[r, 2 * j + 3] = 1, -1, -H / 2, -H / 2
    G[r] /= math.sqrt(T_VAR)
    r = 2 * n + n - 1 + j
    G[r, 2 * j + 3], G[r, 2 * j + 1] = 1, -1
    G[r] /= math.sqrt(S_VAR)
    return G, (slice(0, 2 * n), slice(2 * n, 3 * n - 1), slice(3 * n - 1, 4 * n - 2))


def stationary(points=ss.QUADRATURE_POINTS):
    single = np.array([[SIGMA_W ** 2] * 3 + [SIGMA_D ** 2] * 3])
    share, a, b = ss.kinematic_shares(single, np.full((1, 3), T_VAR), np.full((1, 3), S_VAR), np.array([H]), points)
    return share[0, 0], a[0, 0], b[0, 0]


def test_shares_of_the_stationary_model_are_the_chains_own_in_its_middle():
    n = 400
    G, (meas, trap, step) = chain(n)
    P = np.linalg.inv(G.T @ G)
    At = G[trap]
    D = P @ At.T @ At @ P  # ω's variance the trapezoid rows' noise makes: P Aᵀ Q⁻¹ A P
    i = 2 * (n // 2)  # ω of the middle sample
    hat = G @ P @ G.T
    row = trap.start + n // 2
    a = np.sum((np.eye(len(G))[row, trap] - hat[row, trap]) ** 2)  # E r̂² from the trapezoid rows' own noise
    b = np.sum(hat[row, meas] ** 2)  # ... from the readings' noise
    share, a_s, b_s = stationary()
    assert D[i, i] / P[i, i] == pytest.approx(share, abs=2e-3)
    assert a == pytest.approx(a_s, rel=1e-2)
    assert b == pytest.approx(b_s, rel=1e-2)
    # more quadrature points do not move them (the quadrature has converged)
    assert np.allclose(stationary(4 * ss.QUADRATURE_POINTS), (share, a_s, b_s), rtol=1e-3)
    assert 0.2 < share < 0.8  # the trapezoid rows carry a good part of ω's variance here


@pytest.mark.parametrize("level", [0.0, 1.0])
def test_level_and_sigma_of_a_path_smoother_than_the_model_or_drawn_from_it(level):
    """Paths drawn with the trapezoid rows' noise times √level (0: a path whose ω follows its ω̇ exactly), the
    model's noise on the readings: the level the residuals give, and ω's error variance against
    P (1 − (1 − level) share), the sandwich P (GᵀG)_readings P + level D."""
    n, draws = 400, 200
    G, (meas, trap, step) = chain(n)
    P = np.linalg.inv(G.T @ G)
    rng = np.random.default_rng(11)
    mid = slice(2 * (n // 4), 2 * (3 * n // 4), 2)  # ω of the middle half (no end effects)
    err2, r2 = [], []
    dt = np.full(n - 1, H)
    steps = ss.jerk_steps(np.full((n - 1, 3), Q), np.zeros(3), dt)
    for _ in range(draws):
        # the truth: ω̇ a random walk, ω its trapezoid integral plus √level times the trapezoid noise
        d = np.concatenate([[0.0], np.cumsum(rng.normal(0, math.sqrt(S_VAR), n - 1))])
        w = np.concatenate([[0.0], np.cumsum(0.5 * H * (d[1:] + d[:-1]) + math.sqrt(level * T_VAR) * rng.normal(size=n - 1))])
        x = np.empty(2 * n)
        x[0::2], x[1::2] = w, d
        y = x + np.repeat([[SIGMA_W, SIGMA_D]], n, axis=0).ravel() * rng.normal(size=2 * n)
        W = np.repeat([[1 / SIGMA_W, 1 / SIGMA_D]], n, axis=0).ravel()
        xh = P @ (W * W * y)  # the readings observe each state directly; the process rows have no data
        err2.append((xh - x)[mid] ** 2)
        states = np.zeros((n, 6))
        states[:, 0], states[:, 3] = xh[0::2], xh[1::2]
        r2.append(ss.trapezoid_residuals(states, steps)[n // 4:3 * n // 4, 0] ** 2)
    share, a, b = stationary()
    got = float(ss.trapezoid_level(np.sum(r2), a * np.size(r2), b * np.size(r2), 1.0))
    # the level from 200 × 200 residuals r̂² of mean a + b ≈ 0.18 (level 1), correlated over ~5 samples: the mean's
    # std is about 0.18 √(2 / 8000) ≈ 0.003, over a ≈ 0.073 some 0.03 in the level; 3 of them
    assert got == pytest.approx(level, abs=0.1)
    i = 2 * (n // 2)
    predicted = P[i, i] * (1.0 - (1.0 - got) * share)
    realised = float(np.mean(err2))
    # the error variance over 200 draws × 200 samples (errors correlated over ~10 samples: 4000 independent ones,
    # a relative std of √(2 / 4000) ≈ 2.2 %): within 3 of those
    assert realised == pytest.approx(predicted, rel=0.07)
    if level == 0.0:
        assert realised < 0.8 * P[i, i]  # the model's σ would be too wide by the share
