"""Solve windows spread over worker processes give the same numbers as one process."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from gfimu.array import cube_array
from gfimu.simulate import simulate
from gfimu.smoother.batch.engine import BatchSmootherEstimator, smooth, window_workers
from gfimu.smoother.solve.initialise import initial_estimate


@pytest.fixture(scope="module")
def log():
    return simulate("random3d", cube_array(0.05, 0.07), rate_hz=250.0, duration_s=6.6, seed=3)  # four 2 s windows


def _same(a, b):
    for name in ("omega_b_radps", "omega_dot_b_radps2", "specific_force_b_mps2"):
        assert np.array_equal(getattr(a.motion, name), getattr(b.motion, name)), name
    a, b = a.report, b.report
    np.testing.assert_equal([t.as_dict() for t in a.tunings], [t.as_dict() for t in b.tunings])  # (nan == nan)
    assert (a.iterations, a.cost, a.windows, a.warnings) == (b.iterations, b.cost, b.windows, b.warnings)
    assert a.guard == b.guard


def test_workers_give_the_numbers_of_one_process(log):
    options = dict(window_s=2.0, overlap_s=0.5, compute_sigma=True)
    one = BatchSmootherEstimator(workers=1, **options).estimate(log)
    two = BatchSmootherEstimator(workers=2, **options).estimate(log)
    assert one.report.windows >= 4
    _same(one, two)
    for name in ("omega_b_radps", "specific_force_b_mps2"):
        assert np.array_equal(one.motion.sigma[name], two.motion.sigma[name])


def test_workers_on_a_robust_log(log):
    """A log whose readings fail the rigid-body check (noise growing with |ω|): the moment-estimated
    robust model, its branch restarts and sign chain per window, in two processes."""
    rng = np.random.default_rng(1)
    wn = np.linalg.norm(log.truth.omega_b_radps, axis=1)
    noisy = log.replace(accel_mps2=log.accel_mps2 + rng.normal(size=log.accel_mps2.shape) * (0.05 * wn)[:, None])
    one = BatchSmootherEstimator(workers=1, window_s=2.0, overlap_s=0.5).estimate(noisy)
    two = BatchSmootherEstimator(workers=2, window_s=2.0, overlap_s=0.5).estimate(noisy)
    assert not one.report.model_check.consistent
    _same(one, two)


def test_an_error_in_a_worker_reaches_the_caller(log):
    calls = []

    def failing(part, groups):
        calls.append(1)
        if part.timestamps_ns[0] > log.timestamps_ns[0]:
            raise ValueError("initial states refused for a later window")
        return initial_estimate(part, groups)

    estimator = BatchSmootherEstimator(workers=2, window_s=2.0, overlap_s=0.5)
    with pytest.raises(ValueError, match="refused for a later window"):  # the engine's hook for initial states
        smooth(log, estimator.model_groups, estimator.batch, initial=failing)


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
    assert _one_process("ml", {}) == {"workers": 1}
    assert _one_process("inversion", {}) == {}  # no workers of its own


@pytest.mark.slow
@pytest.mark.parametrize("sig, status", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_interrupted_command_stops_its_workers(tmp_path, log, sig, status):
    """Ctrl-C (SIGINT to the whole process group) or SIGTERM to the command while its workers solve
    windows: one message, the usual status, no estimate, no process left behind."""
    from gfimu import io as gio

    folder = tmp_path / "log"
    gio.write_log(log, folder)
    out = tmp_path / "est.csv"
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    proc = subprocess.Popen([sys.executable, "-m", "gfimu", "estimate", str(folder), "--method", "smoother",
                             "-O", "window_s=1.2", "-O", "overlap_s=0.2", "-O", "workers=2", "--out", str(out),
                             "--no-progress"], stderr=subprocess.PIPE, text=True, env=env, start_new_session=True)
    deadline = time.monotonic() + 60
    children: list = []
    while proc.poll() is None and time.monotonic() < deadline and len(children) < 2:
        children = _children(proc.pid)
        time.sleep(0.02)
    assert len(children) == 2, "the workers never started"
    if sig == signal.SIGINT:
        os.killpg(proc.pid, sig)  # as a terminal's Ctrl-C
    else:
        proc.send_signal(sig)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == status, err
    assert err.count("stopped by") == 1 and "Traceback" not in err, err
    assert not out.exists()
    time.sleep(0.5)
    assert not [pid for pid in children if os.path.exists(f"/proc/{pid}")]


def _children(pid: int) -> list[int]:
    """Process ids whose parent is ``pid`` (from /proc)."""
    out = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/stat") as f:
                    if int(f.read().rsplit(")", 1)[1].split()[1]) == pid:
                        out.append(int(entry))
            except (OSError, IndexError, ValueError):
                pass
    return out
