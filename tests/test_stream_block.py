"""The fixed-lag smoother over a block of samples in one compiled call (:mod:`gfimu.smoother.stream.block`)
against the same samples pushed one by one: the same states to the last bit, and the block taking most of a
steady stream at once."""

import warnings

import numpy as np
import pytest

from gfimu.array import cube_array
from gfimu.errors import DataError
from gfimu.methods import make_estimator
from gfimu.simulate import simulate
from gfimu.simulate.sensor_errors import SensorErrors
from gfimu.smoother.stream import kernels
from gfimu.smoother.stream.fixed_lag import ClockResetWarning, StateRows


def _rows(items):
    """(timestamps, values (n, 9)) of a push's or a block's states."""
    times, values = [], []
    for item in items:
        if isinstance(item, StateRows):
            times.extend(item.timestamp_ns.tolist())
            values.extend(item.values)
        else:
            times.append(item.timestamp_ns)
            values.append(np.concatenate([item.omega_b_radps, item.omega_dot_b_radps2, item.specific_force_b_mps2]))
    return times, values


def _run(log, times, accel, blocks: bool):
    """Every state of the fixed-lag smoother (the estimator's defaults) over ``times``, ``accel``; the number of
    calls it took."""
    sm = make_estimator("fixed-lag").smoother(log.array, log.rate_hz)
    times_out, values = [], []
    i, calls = 0, 0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ClockResetWarning)
        while i < len(times):
            if blocks:
                i, items = sm.push_block(times, accel, i, len(times))
            else:
                items = sm.push(int(times[i]), accel[i]).smoothed
                i += 1
            calls += 1
            for part, got in zip((times_out, values), _rows(items)):
                part.extend(got)
        for part, got in zip((times_out, values), _rows(sm.flush())):
            part.extend(got)
    return np.array(times_out), np.array(values).reshape(-1, 9), calls, sm


def _same_both_ways(log, times=None, accel=None):
    times = log.timestamps_ns if times is None else times
    accel = log.accel_mps2 if accel is None else accel
    t_one, x_one, _, one = _run(log, times, accel, blocks=False)
    t_blk, x_blk, calls, blk = _run(log, times, accel, blocks=True)
    np.testing.assert_array_equal(t_blk, t_one)
    np.testing.assert_array_equal(x_blk, x_one)  # to the last bit: the same compiled arithmetic, in the same order
    assert blk.counts == one.counts
    assert [m.chosen_at_ns for m in blk.models] == [m.chosen_at_ns for m in one.models]
    return calls, len(times), blk


CASES = {
    # a Gaussian model chosen again at 10 s (a choice due and put in use inside the stream)
    "gaussian-500Hz": dict(scenario="random3d", array=cube_array(0.05, noise_std_mps2=0.05), rate_hz=500.0,
                           duration_s=12.0, seed=3),
    # readings that disagree with a rigid body: the robust model, its motion factor on every step, the branch
    # decision's re-solves and the sign chain's moves
    "robust-62Hz": dict(scenario="random3d", array=cube_array(0.08, noise_std_mps2=0.05), rate_hz=62.5,
                        duration_s=40.0, seed=5, omega_rms_radps=4.0,
                        noise=SensorErrors(accel_scale_std=0.03, accel_misalignment_std_rad=0.03)),
    # a long window: its older states' epochs, and the window moved to the start of its arrays
    "epochs-4kHz": dict(scenario="random3d", array=cube_array(0.025, noise_std_mps2=0.01), rate_hz=4000.0,
                        duration_s=2.5, seed=7),
    # slow motion: a model chosen on a still-looking stretch and the once-a-second look for a slow turn
    "slow-200Hz": dict(scenario="slow3d", array=cube_array(0.05, noise_std_mps2=0.07), rate_hz=200.0, duration_s=14.0,
                       seed=2),
}


@pytest.mark.parametrize("case", [pytest.param(c, marks=pytest.mark.slow) if c == "epochs-4kHz" else c
                                  for c in sorted(CASES)])
def test_a_block_gives_the_states_of_one_sample_at_a_time(case):
    calls, n, sm = _same_both_ways(simulate(**CASES[case]))
    # the block took the steady stream: a call per hundred samples or fewer, once the start is decided
    # (the start, the first model's stretch and the held rows, goes sample by sample)
    steady = n - sm.starts[0]["held_s"] * CASES[case]["rate_hz"] if sm.starts else n
    assert calls < 0.1 * n + (n - steady), (calls, n)


def test_gaps_repeated_and_backward_timestamps_and_a_clock_reset_alike():
    log = simulate("random3d", array=cube_array(0.05, noise_std_mps2=0.05), rate_hz=200.0, duration_s=14.0, seed=4)
    times, accel = list(log.timestamps_ns), list(log.accel_mps2)
    del times[1500:1700], accel[1500:1700]  # a 1 s gap: a new segment
    times.insert(2200, times[2200])  # a repeated timestamp: dropped
    accel.insert(2200, accel[2200])
    times.insert(2400, times[2399] - 3_000_000)  # a sample 3 ms before the one before it: dropped as out of order
    accel.insert(2400, accel[2400])
    back = np.array(times[2500:]) - 5_000_000_000  # the clock back by 5 s: a reset, the window restarts
    times = np.array(times[:2500] + back.tolist(), dtype=np.int64)
    accel = np.vstack(accel)
    _, _, sm = _same_both_ways(log, times, accel)
    assert sm.counts == {"duplicates": 1, "out_of_order": 1, "clock_resets": 1}


def test_the_session_takes_a_log_in_blocks_with_the_rows_one_by_one_would_give():
    """:meth:`StreamSession.push_block`: the same states as its push, the rate watch and the summary's counts
    alike; a rate that changes mid-stream is measured again at the same sample."""
    from gfimu.smoother.stream.session import StreamSession

    log = simulate("random3d", array=cube_array(0.05, noise_std_mps2=0.05), rate_hz=500.0, duration_s=6.0, seed=8)
    times = log.timestamps_ns.copy()
    times[1500:] = times[1500] + (times[1500:] - times[1500]) * 2  # from 3 s on, 250 Hz
    est = make_estimator("fixed-lag")
    out = []
    for blocks in (False, True):
        session = StreamSession(log.array, est, 500.0, screen=False)
        got, i = [], 0
        while i < len(times):
            if blocks:
                i, items = session.push_block(times, log.accel_mps2, i, len(times))
            else:
                items = session.push(int(times[i]), log.accel_mps2[i])
                i += 1
            got += _rows(items)[1]
        got += _rows(session.finish())[1]
        out.append((np.array(got), session.counts, session.take_notes(), len(session.processing_s)))
    (x_one, counts_one, notes_one, kept_one), (x_blk, counts_blk, notes_blk, kept_blk) = out
    np.testing.assert_array_equal(x_blk, x_one)
    assert counts_blk == counts_one and notes_blk == notes_one and kept_blk == kept_one
    assert any("rate changed" in note for note in notes_one)


def test_the_kernels_helpers_are_the_numpy_expressions_to_rounding():
    """The loops the block and the per-sample code share (a lazy state's mean, a scaled step's process noise)
    against the numpy expressions they replace: equal within a few ulps of the terms summed."""
    rng = np.random.default_rng(1)
    for _ in range(50):
        m, C, u = rng.normal(size=9), rng.normal(size=(9, 9)), rng.normal(size=9)
        want = m + C @ u
        tol = 8 * np.finfo(float).eps * (np.abs(m) + np.abs(C) @ np.abs(u))
        assert np.all(np.abs(kernels.lazy_mean(m, C, u) - want) <= tol)
        M, s = rng.normal(size=(9, 9)), rng.uniform(0.1, 2.0, size=9)
        Q = (M * s) @ M.T
        want = 0.5 * (Q + Q.T)
        tol = 16 * np.finfo(float).eps * ((np.abs(M) * s) @ np.abs(M).T)
        got = kernels.scaled_process_noise(M, s)
        assert np.all(np.abs(got - want) <= tol)
        np.testing.assert_array_equal(got, got.T)


def test_a_stop_names_why_the_block_left_a_sample_to_the_per_sample_code():
    """A non-finite reading stops the block before it (the per-sample code raises the error naming it)."""
    log = simulate("random3d", array=cube_array(0.05, noise_std_mps2=0.05), rate_hz=500.0, duration_s=5.0, seed=9)
    accel = log.accel_mps2.copy()
    accel[2000, 3] = np.nan
    sm = make_estimator("fixed-lag").smoother(log.array, log.rate_hz)
    i = 0
    with pytest.raises(DataError, match=f"sample at {log.timestamps_ns[2000]} ns: non-finite accelerometer reading"):
        while i < len(accel):
            i, _ = sm.push_block(log.timestamps_ns, accel, i, len(accel))
    assert sm._clock.last_ns == log.timestamps_ns[1999]  # every sample before it taken, none after


def test_the_smoother_takes_the_compiled_batch_solves_whatever_was_imported_before():
    """The batch solves of the stream (its first model's stretch, the held start) take the compiled kernels
    wherever numba is loaded: a smoother loads it when it is made, so that its rows do not depend on whether
    anything imported numba before it (the block imports it; importing the smoother's module does not)."""
    import subprocess
    import sys

    code = ("import sys\n"
            "from gfimu.array import cube_array\n"
            "from gfimu.smoother.stream.fixed_lag import FixedLagSmoother\n"
            "assert 'numba' not in sys.modules, 'imported with the module'\n"
            "FixedLagSmoother(cube_array(0.05, noise_std_mps2=0.05), lag_s=0.2, rate_hz=500.0)\n"
            "assert 'numba' in sys.modules, 'not loaded with the smoother'\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr


@pytest.mark.slow
def test_a_real_recording_in_blocks_is_its_rows_one_by_one(mimu4444_dir, tmp_path):
    """The MIMU4444 recording exp_1 (37,439 samples at 62.5 Hz, eight triads, the robust model): every row the
    same to the last bit whether the stream takes it in blocks or one sample at a time, and the blocks take it
    in a call per few dozen samples."""
    import subprocess
    import sys

    from gfimu.io import read_log

    out = tmp_path / "log"
    proc = subprocess.run([sys.executable, "-m", "gfimu", "convert", "mimu4444", str(mimu4444_dir / "exp_1" / "data.bin"),
                           "--out", str(out), "--quiet", "--no-progress"], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    calls, n, sm = _same_both_ways(read_log(out))
    assert sm.models[-1].robust
    assert calls < n / 10
