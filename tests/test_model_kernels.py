"""The compiled rows of the batch smoother's normal equations (gfimu.smoother.model.kernels) against the
numpy expressions they replace (``compiled = False``): the accelerometer rows' JᵀJ, Jᵀr, cost, row count
and whitened residuals on random states, with one whitening for every sample and with per-sample noise,
on a cube, on rotated triads (non-planar) and on the near-planar MIMU4444 board; the white-jerk motion
model's rows with uneven steps and robust weights.

Tolerances: each accelerometer entry is a sum over the axes of products of whitened terms, summed in
another order by the kernel, so the two differ by a few units of rounding of the terms summed (relative
~1e-16 each, times the axes): each entry is held to 1e-12 of the sum of the magnitudes of its terms,
which leaves room for that and catches any wrong term (a change of 1e-6 in one factor fails)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from gfimu.array import cube_array, mimu4444_array, random_array
from gfimu.simulate import simulate
from gfimu.smoother.model.groups import AccelerometerGroup, MotionModelGroup
from gfimu.smoother.model.problem import SmootherOptions, SmootherProblem
from gfimu.smoother.solve.banded import robust_reweighted

pytest.importorskip("numba")

REL = 1e-12


ARRAYS = {
    "cube": lambda: cube_array(0.05, 0.07),  # non-planar, axes along the body's
    "random": lambda: random_array(5, 0.03, 0.07, seed=3),  # non-planar, each triad rotated
    "mimu4444": lambda: mimu4444_array(0.05),  # (near-)planar: two layers 2 mm apart, as the recordings'
}


def _problem(array, per_sample: bool, attitude: bool = False):
    log = simulate("random3d", array, rate_hz=400.0, duration_s=0.5, seed=7)
    options = SmootherOptions()
    if attitude:
        options = replace(options, estimate_attitude=True)
    problem = SmootherProblem.of(log, options)
    rng = np.random.default_rng(9)
    m = problem.state_size
    states = rng.normal(scale=[4.0] * 3 + [40.0] * 3 + [8.0] * 3 + [0.5] * (m - 9), size=(len(log), m))
    if per_sample:
        sigma = problem.noise.accel.sigma * rng.uniform(0.5, 3.0, size=log.accel_mps2.shape)
        problem = problem.with_noise(accel=problem.noise.accel.with_per_sample(sigma))
    assert (problem.noise.accel.per_sample is not None) == per_sample
    return problem, states


def _both(group, problem, states):
    out = {}
    n, m = problem.n, problem.state_size
    for compiled in (False, True):
        g = replace_compiled(group, compiled)
        diag, lower, grad = np.zeros((n, m, m)), np.zeros((n - 1, m, m)), np.zeros((n, m))
        diag += 1.0  # added to, not overwritten
        grad += 1.0
        half, rows = g.accumulate(problem, states, np.zeros(problem.n_global), diag, lower, grad)
        out[compiled] = diag, lower, grad, half, rows, g.squared_norm(problem, states, np.zeros(problem.n_global))
    return out[False], out[True]


def _residuals(group, problem, states):
    return [replace_compiled(group, c).whitened_residual(problem, states, np.zeros(problem.n_global)) for c in (False, True)]


def replace_compiled(group, compiled):
    g = type(group)()
    g.compiled = compiled
    return g


def _bounds(group, problem, states):
    """Per entry, the magnitude of the terms summed into it: ``Σ_a |J_a,i| |J_a,j|`` for JᵀJ and
    ``Σ_a |J_a,i| |e_a|`` for Jᵀe (from the numpy Jacobians, :meth:`AccelerometerGroup.terms`)."""
    (term,) = group.terms(problem, states, np.zeros(problem.n_global))
    aj, ae = np.abs(term.jac["x"]), np.abs(term.residual)
    return np.swapaxes(aj, 1, 2) @ aj, np.einsum("nai,na->ni", aj, ae)


def _check(problem, states):
    group = problem.group(AccelerometerGroup)
    (d0, l0, g0, h0, r0, s0), (d1, l1, g1, h1, r1, s1) = _both(group, problem, states)
    bound_d, bound_g = _bounds(group, problem, states)
    assert r1 == r0 == problem.n * problem.log.array.n_axes
    assert np.all(np.abs(d1 - d0) <= REL * bound_d + 1e-15)  # (+ the 1.0 each entry started from)
    assert np.all(np.abs(g1 - g0) <= REL * bound_g + 1e-15)
    np.testing.assert_array_equal(l1, l0)  # (no ties between samples)
    assert h1 == pytest.approx(h0, rel=REL)
    assert s1 == pytest.approx(s0, rel=REL)
    assert s1 == pytest.approx(2 * h1, rel=REL)
    # one rigid-body equation in the kernels: the cost a step is accepted on is, bit for bit, the one its
    # normal equations were built at, and the sum of the residuals' squares
    assert s1 == 2 * h1
    assert s0 == 2 * h0
    # the whitened residuals w (h - y): rounding of the prediction's terms and the reading, times w
    r0, r1 = _residuals(group, problem, states)
    white = problem.noise.accel.whitening(r0.shape)
    assert np.all(np.abs(r1 - r0) <= REL * (2.0 * white * np.abs(problem.log.accel_mps2) + np.abs(r0)))
    assert float(np.sum(r1 * r1)) == pytest.approx(s0, rel=REL)
    # only the [ω, ω̇, f] block is touched
    np.testing.assert_array_equal(d1[:, 9:, :], 1.0)
    np.testing.assert_array_equal(d1[:, :, 9:], 1.0)
    np.testing.assert_array_equal(g1[:, 9:], 1.0)


@pytest.mark.parametrize("array", sorted(ARRAYS))
@pytest.mark.parametrize("per_sample", [False, True])
def test_kernel_matches_numpy(array, per_sample):
    _check(*_problem(ARRAYS[array](), per_sample))


def test_kernel_matches_numpy_with_the_attitude():
    problem, states = _problem(cube_array(0.05, 0.07), False, attitude=True)
    assert problem.state_size > 9
    _check(problem, states)


def test_preload_loads_the_kernels():
    from gfimu.smoother import preload
    from gfimu.smoother.model import kernels

    preload.wait()  # nothing begun: returns at once
    preload.start("batch")
    preload.wait()
    for kernel in (kernels.accumulate, kernels.squared_norm, kernels.whitened_residual, kernels.white_jerk):
        assert len(kernel.signatures) >= 1


@pytest.mark.parametrize("robust", [False, True])
def test_white_jerk_kernel_matches_numpy(robust):
    """The white-jerk motion model's rows (MotionModelGroup.accumulate) compiled against numpy, with uneven
    steps, a gap, per-axis factors and (robust) per-step weights. The kernel makes each entry by the same
    operations in the same order as numpy, so they agree to rounding of single terms at most (1e-14 of
    the terms summed into an entry; equal bits where neither fuses a product and a sum)."""
    log = simulate("random3d", cube_array(0.05, 0.07), rate_hz=500.0, duration_s=0.6, seed=4)
    rng = np.random.default_rng(11)
    steps = rng.uniform(1.5e6, 2.5e6, len(log) - 1).astype(np.int64)
    steps[len(steps) // 2] = 40_000_000
    log = replace(log, timestamps_ns=log.timestamps_ns[0] + np.concatenate([[0], np.cumsum(steps)]))
    options = SmootherOptions(process_axis_factors=(1.0, 3.0, 0.2))
    if robust:
        options = replace(options, process_robust_threshold=1.0, robust_loss="cauchy")
    problem = SmootherProblem.of(log, options)
    states = rng.normal(scale=[3.0] * 3 + [30.0] * 3 + [5.0] * 3, size=(len(log), 9))
    if robust:
        problem = robust_reweighted(problem, states, np.zeros(0))
    group = problem.group(MotionModelGroup)
    n, m = problem.n, problem.state_size
    out = {}
    for compiled in (False, True):
        g = type(group)()
        g.compiled = compiled
        diag, lower, grad = np.full((n, m, m), 1.0), np.full((n - 1, m, m), 1.0), np.full((n, m), 1.0)
        half, rows = g.accumulate(problem, states, np.zeros(0), diag, lower, grad)
        out[compiled] = diag, lower, grad, half, rows
    (d0, l0, g0, h0, r0), (d1, l1, g1, h1, r1) = out[False], out[True]
    (term,) = group.terms(problem, states, np.zeros(0))
    a0, a1, ae = np.abs(term.jac["x0"]), np.abs(term.jac["x1"]), np.abs(term.residual)
    bound_d = np.zeros_like(d0)
    bound_d[:-1] += np.swapaxes(a0, 1, 2) @ a0
    bound_d[1:] += np.swapaxes(a1, 1, 2) @ a1
    bound_l = np.swapaxes(a1, 1, 2) @ a0
    bound_g = np.zeros_like(g0)
    bound_g[:-1] += np.einsum("nri,nr->ni", a0, ae)
    bound_g[1:] += np.einsum("nri,nr->ni", a1, ae)
    tol = 1e-14
    assert np.all(np.abs(d1 - d0) <= tol * (bound_d + 1.0))  # (+ the 1.0 each entry started from)
    assert np.all(np.abs(l1 - l0) <= tol * (bound_l + 1.0))
    assert np.all(np.abs(g1 - g0) <= tol * (bound_g + 1.0))
    assert h1 == pytest.approx(h0, rel=tol) and r1 == r0 == 6 * (n - 1)
    assert np.any(d0 != 1.0)  # (it added something)


def test_the_batch_preload_waits_for_a_log_large_enough_to_repay_numba(monkeypatch):
    """BatchSmootherEstimator.preload starts the loading for a log of PRELOAD_MIN_BYTES or more (or of an
    unknown size), not for a smaller one, which the numpy expressions solve."""
    from gfimu.smoother import preload
    from gfimu.smoother.batch.engine import PRELOAD_MIN_BYTES, BatchSmootherEstimator

    started = []
    monkeypatch.setattr(preload, "start", lambda kind: started.append(kind))
    est = BatchSmootherEstimator()
    est.preload(PRELOAD_MIN_BYTES - 1)
    assert started == []
    est.preload(PRELOAD_MIN_BYTES)
    est.preload(None)
    assert started == ["batch", "batch"]


def test_without_numba_loaded_the_groups_use_the_numpy_expressions():
    """In a process that has not loaded numba, the batch smoother does not load it: its accelerometer and
    motion-model rows come from the numpy expressions (the same numbers to rounding)."""
    import subprocess
    import sys

    code = ("import sys, numpy as np\n"
            "from gfimu.simulate import simulate\n"
            "from gfimu.smoother.batch.engine import BatchSmootherEstimator\n"
            "log = simulate('random3d', rate_hz=200.0, duration_s=3.0, seed=1)\n"
            "w = BatchSmootherEstimator(workers=1).estimate(log).motion.omega_b_radps\n"
            "e = np.sqrt(np.mean(np.sum((w - log.truth.omega_b_radps) ** 2, axis=1)))\n"
            "print('numba' in sys.modules, e < 0.1)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    assert out == ["False", "True"]
