"""Solve windows spread over worker processes give the same numbers as one process."""

from __future__ import annotations

import numpy as np
import pytest

from gfimu.array import cube_array
from gfimu.simulate import simulate
from gfimu.smoother.batch import BatchSmootherEstimator, window_workers
from gfimu.smoother.initialise import initial_estimate


@pytest.fixture(scope="module")
def log():
    return simulate("random3d", cube_array(0.05, 0.07), rate_hz=250.0, duration_s=9.0, seed=3)


def _same(a, b):
    for name in ("omega_b_radps", "omega_dot_b_radps2", "specific_force_b_mps2"):
        assert np.array_equal(getattr(a.motion, name), getattr(b.motion, name)), name
    np.testing.assert_equal([t.as_dict() for t in a.tunings], [t.as_dict() for t in b.tunings])  # (nan == nan)
    assert (a.iterations, a.cost, a.windows, a.warnings) == (b.iterations, b.cost, b.windows, b.warnings)


def test_workers_give_the_numbers_of_one_process(log):
    options = dict(window_s=2.0, overlap_s=0.5, compute_sigma=True)
    one = BatchSmootherEstimator(workers=1, **options).result(log)
    two = BatchSmootherEstimator(workers=2, **options).result(log)
    assert one.windows >= 4
    _same(one, two)
    for name in ("omega_b_radps", "specific_force_b_mps2"):
        assert np.array_equal(one.sigma[name], two.sigma[name])


def test_workers_on_a_robust_log(log):
    """A log whose readings fail the rigid-body check (noise growing with |ω|): the moment-estimated
    robust model, its branch restarts and sign chain per window, in two processes."""
    rng = np.random.default_rng(1)
    wn = np.linalg.norm(log.truth.omega_b_radps, axis=1)
    noisy = log.replace(accel_mps2=log.accel_mps2 + rng.normal(size=log.accel_mps2.shape) * (0.05 * wn)[:, None])
    one = BatchSmootherEstimator(workers=1, window_s=2.0, overlap_s=0.5).result(noisy)
    two = BatchSmootherEstimator(workers=2, window_s=2.0, overlap_s=0.5).result(noisy)
    assert not one.model_check.consistent
    _same(one, two)


def test_an_error_in_a_worker_reaches_the_caller(log):
    calls = []

    def failing(part, options):
        calls.append(1)
        if part.timestamps_ns[0] > log.timestamps_ns[0]:
            raise ValueError("initial states refused for a later window")
        return initial_estimate(part, options)

    with pytest.raises(ValueError, match="refused for a later window"):
        BatchSmootherEstimator(workers=2, window_s=2.0, overlap_s=0.5).result(log, initial=failing)


def test_worker_count():
    assert window_workers(1, 10) == 1
    assert window_workers(3, 2) == 2  # at most one per window
    assert window_workers(4, 10, solver="gtsam") == 1
    assert 1 <= window_workers(0, 100) <= 100
    with pytest.raises(ValueError, match="workers"):
        window_workers(-1, 3)
    with pytest.raises(ValueError, match="workers"):
        BatchSmootherEstimator(workers=-2)


def test_logs_run_on_dask_solve_their_windows_in_one_process():
    """Many logs already run one per Dask worker (a daemonic process, which may not start others)."""
    from gfimu.batch import _one_process

    assert _one_process("smoother", {}) == {"workers": 1}
    assert _one_process("smoother", {"workers": 3}) == {"workers": 3}
    assert _one_process("ml", {}) == {}
