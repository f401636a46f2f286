"""The state layout names every column of the smoother's state, for every model."""

import numpy as np
import pytest

from gfimu.simulate import simulate
from gfimu.smoother.model.problem import SmootherOptions, SmootherProblem
from gfimu.smoother.model.layout import StateLayout


@pytest.mark.parametrize("snap, attitude, size", [(False, False, 9), (True, False, 12), (False, True, 12), (True, True, 15)])
def test_layouts(snap, attitude, size):
    lay = StateLayout(snap, attitude)
    assert lay.size == size
    cols = np.arange(size)
    used = np.concatenate([cols[s] for s in (lay.omega, lay.omega_dot, lay.specific_force, lay.omega_ddot, lay.rotation)
                           if s is not None])
    np.testing.assert_array_equal(np.sort(used), cols)  # every column named once
    x = np.arange(2 * 9, dtype=float).reshape(2, 9)
    y = lay.resize(x)
    assert y.shape == (2, size) and np.all(y[:, :9] == x) and np.all(y[:, 9:] == 0)


def test_problem_uses_the_layout_of_its_options():
    log = simulate("turntable", duration_s=0.05, seed=0)
    for opt in (SmootherOptions(), SmootherOptions(motion_model="snap"), SmootherOptions(estimate_attitude=True)):
        problem = SmootherProblem.of(log, opt)
        assert problem.layout == StateLayout.from_options(opt)
        assert problem.state_size == problem.layout.size
        X = np.zeros((problem.n, problem.state_size))
        assert sum(t.residual.shape[-1] for t in problem.terms(X, np.zeros(problem.n_global))) > 0
