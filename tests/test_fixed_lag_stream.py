"""The streaming API's defined behaviour: duplicates and out-of-order samples dropped and counted, clock
resets restart the window with a warning, push after close is a clear error, containers stay bounded."""

import warnings

import numpy as np
import pytest

from gfimu.array import cube_array
from gfimu.simulate import simulate
from gfimu.smoother.stream.fixed_lag import ClockResetWarning, FixedLagSmoother, FixedLagSmootherClosed
from gfimu.smoother.model.problem import SmootherOptions

RATE_HZ = 200.0
OPTS = SmootherOptions(tune_process_noise=False)


@pytest.fixture(scope="module")
def log():
    return simulate("random3d", cube_array(0.05, 0.07), rate_hz=RATE_HZ, duration_s=4.0, seed=12)


def stream(sm, times, rows):
    out, drops = [], []
    for t, y in zip(times, rows):
        upd = sm.push(t, y)
        out.extend(upd.smoothed)
        drops.append(upd.dropped)
    return out, drops


def test_duplicates_and_out_of_order_samples_are_dropped_counted_and_change_nothing(log):
    clean = FixedLagSmoother(log.array, OPTS.model_groups, lag_s=0.1, rate_hz=RATE_HZ)
    ref, _ = stream(clean, log.timestamps_ns, log.accel_mps2)
    ref += list(clean.flush())
    # every 50th sample sent twice, every 70th followed by a late copy of an older sample
    times, rows, expect = [], [], []
    for i, (t, y) in enumerate(zip(log.timestamps_ns, log.accel_mps2)):
        times.append(t), rows.append(y), expect.append(None)
        if i % 50 == 10:
            times.append(t), rows.append(y + 5.0), expect.append("duplicate")
        if i % 70 == 20 and i > 5:
            times.append(log.timestamps_ns[i - 3]), rows.append(log.accel_mps2[i - 3]), expect.append("out-of-order")
    sm = FixedLagSmoother(log.array, OPTS.model_groups, lag_s=0.1, rate_hz=RATE_HZ)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # neither is a warning, let alone an error
        out, drops = stream(sm, times, rows)
    out += list(sm.flush())
    assert drops == expect
    assert sm.counts == {"duplicates": expect.count("duplicate"), "out_of_order": expect.count("out-of-order"),
                         "clock_resets": 0}
    assert [s.timestamp_ns for s in out] == [s.timestamp_ns for s in ref]
    np.testing.assert_array_equal([s.omega_b_radps for s in out], [s.omega_b_radps for s in ref])


def test_clock_reset_restarts_the_window_with_a_warning_and_goes_on(log):
    n = len(log) // 2
    back_ns = log.timestamps_ns[n] - log.timestamps_ns[0] + 5_000_000_000  # the clock restarts 5 s earlier
    times = np.r_[log.timestamps_ns[:n], log.timestamps_ns[n:] - back_ns]
    sm = FixedLagSmoother(log.array, OPTS.model_groups, lag_s=0.1, rate_hz=RATE_HZ, clock_reset_s=0.5)
    out = []
    for i in range(len(log)):
        if i == n:
            with pytest.warns(ClockResetWarning, match=r"clock went back by .* s .*new segment"):
                upd = sm.push(times[i], log.accel_mps2[i])
            # the whole old window comes out at once, smoothed with what it had; the new segment warms up
            assert [s.timestamp_ns for s in out + list(upd.smoothed)] == list(times[:n])
            assert upd.filtered is None and upd.dropped is None
        else:
            upd = sm.push(times[i], log.accel_mps2[i])
        out.extend(upd.smoothed)
    out.extend(sm.flush())
    assert [s.timestamp_ns for s in out] == list(times)
    assert sm.n_clock_resets == 1 and sm.n_out_of_order == 0
    w = np.array([s.omega_b_radps for s in out])
    err = np.sqrt(np.mean(np.sum((w - log.truth.omega_b_radps) ** 2, axis=1)))
    assert err < 0.05


def test_flush_lets_a_new_stream_start_at_any_time(log):
    sm = FixedLagSmoother(log.array, OPTS.model_groups, lag_s=0.1, rate_hz=RATE_HZ)
    stream(sm, log.timestamps_ns[:300], log.accel_mps2[:300])
    sm.flush()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        out, drops = stream(sm, log.timestamps_ns[:300] - 10**9, log.accel_mps2[:300])
    assert drops == [None] * 300 and sm.counts["clock_resets"] == 0
    assert len(out) + len(sm.flush()) == 300


def test_push_and_flush_after_close_are_clear_errors(log):
    sm = FixedLagSmoother(log.array, OPTS.model_groups, lag_s=0.1, rate_hz=RATE_HZ)
    out, _ = stream(sm, log.timestamps_ns[:100], log.accel_mps2[:100])
    rest = sm.close()
    assert len(out) + len(rest) == 100 and len(rest) >= int(0.1 * RATE_HZ) and sm.closed
    assert sm.close() == ()
    with pytest.raises(FixedLagSmootherClosed, match="push after close"):
        sm.push(log.timestamps_ns[100], log.accel_mps2[100])
    with pytest.raises(FixedLagSmootherClosed, match="flush after close"):
        sm.flush()
    with FixedLagSmoother(log.array, OPTS.model_groups, lag_s=0.1, rate_hz=RATE_HZ) as sm2:
        sm2.push(log.timestamps_ns[0], log.accel_mps2[0])
    with pytest.raises(FixedLagSmootherClosed):
        sm2.push(log.timestamps_ns[1], log.accel_mps2[1])


def test_internal_containers_stay_bounded_through_drops_resets_and_gaps(log):
    """A 40 s stream at 200 Hz replayed ten times over the same 4 s of motion, with a clock reset, a gap,
    duplicates and late samples every few steps: every container the smoother keeps stays within its
    window's size from the first repetition to the last."""
    sm = FixedLagSmoother(log.array, SmootherOptions().model_groups, lag_s=0.1, rate_hz=RATE_HZ, tune_window_s=1.0,
                          clock_reset_s=0.5)
    sizes = []
    n_out = n_in = 0
    step = log.timestamps_ns[1] - log.timestamps_ns[0]
    span = log.timestamps_ns[-1] - log.timestamps_ns[0] + step
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ClockResetWarning)
        for rep in range(10):
            offset = rep * span if rep != 5 else -10**10  # the 6th replay: the clock goes back 10 s
            offset += 2 * 10**9 if rep > 6 else 0  # a 2 s gap before the 8th
            for i in range(len(log)):
                t = log.timestamps_ns[i] + offset
                upd = sm.push(t, log.accel_mps2[i])
                n_in += upd.dropped is None
                n_out += len(upd.smoothed)
                if i % 7 == 3:
                    sm.push(t, log.accel_mps2[i])  # duplicate
                    sm.push(t - 3 * step, log.accel_mps2[i])  # late
                if i % 50 == 0:
                    seg = sm._segment
                    sizes.append((len(seg.window), len(seg.raw), len(sm._choice.buffer), len(seg.warmup),
                                  0 if seg.engine is None else seg.engine.n_slots, len(sm.model._step_cache)))
    n_out += len(sm.flush())
    assert n_out == n_in == 10 * len(log)
    assert sm.n_clock_resets == 1
    sizes = np.array(sizes)
    lag_n = int(0.1 * RATE_HZ)
    assert sizes[:, 0].max() <= lag_n + 1 and sizes[:, 1].max() <= lag_n + 1
    assert sizes[:, 2].max() <= int(1.0 * RATE_HZ) and sizes[:, 3].max() <= int(0.2 * RATE_HZ)
    half = len(sizes) // 2
    assert sizes[half:, 4].max() <= sizes[:half, 4].max()  # the preallocated window never grows
    assert sizes[:, 5].max() <= 65
