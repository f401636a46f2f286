"""tools/sigma_cause_study.py: the fit of the parity residuals with calibration errors, on known numbers."""

import numpy as np
from dataclasses import replace

from gfimu.array import cube_array
from gfimu.rigid_body import quadratic_terms
from tool_modules import load_tool

study = load_tool("sigma_cause_study")


def test_positions_off_are_found_from_the_parity_residual_up_to_a_common_shift():
    """Noise-free readings of a cube whose triads sit δ off the positions array.toml states, at the true
    states: the parity residual is the positions' error alone (to first order in δ: δ ~ 1 mm against 5 cm,
    a second-order part of ~(δ/size)² of it), the fit explains all of it, and the fitted δ equals the true
    one up to the two errors no residual sees: a common shift of the triads (it moves f only) and a common
    scale of their positions about the origin (δ_s = ε r_s: the readings of ω̇ (1 + ε) and ω √(1 + ε),
    like a common gain)."""
    stated = cube_array(0.05, 0.01)
    rng = np.random.default_rng(3)
    delta = rng.normal(0.0, 1e-3, (len(stated.accelerometers), 3))
    true = stated.with_accelerometers(replace(a, position_m=np.asarray(a.position_m) + d)
                                      for a, d in zip(stated.accelerometers, delta))
    n = 600
    states = np.hstack([rng.normal(0, 3, (n, 3)), rng.normal(0, 10, (n, 3)), rng.normal(0, 5, (n, 3))])
    S = true.structure_matrix()
    accel = np.hstack([states[:, 6:9], states[:, 3:6], quadratic_terms(states[:, 0:3])]) @ S.T
    fit = study.calibration_fit(stated, accel, states, np.full(S.shape[0], 0.01))
    assert fit["explained"] > 1 - 1e-9
    found = fit["errors"][:3 * fit["triads"]].reshape(-1, 3)
    r = np.array([a.position_m for a in stated.accelerometers])
    unseen = np.column_stack([np.tile(np.eye(3), (len(r), 1)), r.reshape(-1)])  # shifts, and the scale
    assert fit["rank"] == 3 * len(r) - 4 + 11  # the gains: all but the common one
    left = (found - delta).reshape(-1)
    coef = np.linalg.lstsq(unseen, left, rcond=None)[0]
    np.testing.assert_allclose(left - unseen @ coef, 0.0, atol=1e-12)
    assert np.max(np.abs(left)) > 1e-5  # the unseen part is there (the fit takes the least-squares one)
    np.testing.assert_allclose(fit["errors"][3 * fit["triads"]:], 0.0, atol=1e-12)  # no gain error
