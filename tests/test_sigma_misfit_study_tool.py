"""tools/sigma_misfit_study.py: the variance factor and the coverage shares it prints, on known numbers."""

import numpy as np

from gfimu.array import cube_array
from tool_modules import load_tool

study = load_tool("sigma_misfit_study")


def test_variance_factor_of_white_noise_at_the_true_states_is_one_and_a_spike_raises_it_unless_weighted():
    """Readings of a body at rest, f = (0, 0, 9.81), with white noise of the stated std: the parity
    residual's power over its degrees of freedom (12 axes − 9 states = 3 a sample, 6000 in all) is 1
    within 4 std of its scatter √(2 / 6000) = 1.8 %. One reading in a hundred 20σ off adds 0.01 · 400
    = 4 to the power of each whitened axis, the same in every direction (isotropic), so 4 to the
    factor: 5, within ± 1 (the count of spikes, about 240, scatters by 6.5 %). The Cauchy weights at
    2σ take nearly all of that away."""
    sigma = 0.05
    array = cube_array(0.025, noise_std_mps2=sigma)
    S = array.structure_matrix()
    n = 2000
    states = np.zeros((n, 9))
    states[:, 8] = 9.81
    rng = np.random.default_rng(1)
    clean = np.tile(S[:, 0:3] @ states[0, 6:9], (n, 1))
    accel = clean + rng.standard_normal(clean.shape) * sigma
    rows = np.ones(n, bool)
    noise = np.full(S.shape[0], sigma)
    s2 = study.variance_factor(array, accel, states, noise, None, rows)
    assert abs(s2 - 1.0) < 4 * np.sqrt(2.0 / (3 * n))
    hit = rng.random(accel.shape) < 0.01
    spiky = accel + np.where(hit, 20 * sigma * rng.choice([-1.0, 1.0], accel.shape), 0.0)
    s2_spiky = study.variance_factor(array, spiky, states, noise, None, rows)
    assert 4.0 < s2_spiky < 6.0
    weighted = [study.variance_factor(array, a, states, noise, ("cauchy", 2.0), rows) for a in (accel, spiky)]
    assert weighted[1] - weighted[0] < 0.1 * (s2_spiky - s2)  # measured 0.07 of 4.1


def test_shares_per_axis():
    err = np.array([[0.5, 1.5, 2.5], [0.5, 0.5, 0.5], [np.nan, 0.0, 0.0]])
    sd = np.ones((3, 3))
    # the row with a NaN does not count; x: both within 1σ, y: one within 1σ and both within 2σ, z: one and one
    assert study.shares(err, sd) == "100-100 / 50-100 / 50-50 %"
