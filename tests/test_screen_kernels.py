"""The stream screening's compiled spike rule (gfimu.screen_kernels.spike_mask) against the numpy expression it
replaces (gfimu.readings._spike_mask): the same mask, bit for bit, on buffers with spikes, missing readings,
constant channels and windows cut by the buffer's ends; and a stream screened through it decides as before."""

import numpy as np
import pytest

from gfimu import readings
from gfimu.screen_kernels import spike_mask


def _buffer(rng, n, m, nan_share=0.0, spikes=0, constant=()):
    work = np.cumsum(rng.normal(scale=0.05, size=(n, m)), axis=0) + rng.normal(scale=0.01, size=(n, m))
    for _ in range(spikes):
        work[rng.integers(n), rng.integers(m)] += rng.choice([-1.0, 1.0]) * rng.uniform(2.0, 50.0)
    work[rng.random((n, m)) < nan_share] = np.nan
    for c in constant:
        work[:, c] = 9.81  # a still, quantised channel: no local scale, the floor decides
    return work


@pytest.mark.parametrize("n, m, nan_share, spikes, constant", [
    (51, 3, 0.0, 0, ()), (60, 12, 0.0, 4, ()), (83, 24, 0.05, 6, (1,)), (200, 6, 0.3, 10, (0, 5)),
    (51, 2, 1.0, 0, ()), (120, 9, 0.0, 30, (2,))])
def test_the_compiled_mask_is_the_numpy_one_to_the_bit(n, m, nan_share, spikes, constant):
    rng = np.random.default_rng(n * 31 + m)
    work = _buffer(rng, n, m, nan_share, spikes, constant)
    typical = readings._nanmedian_flat(np.abs(work))
    floor = 1e-6 * max(float(typical) if np.isfinite(typical) else 1.0, 1.0)
    want = readings._spike_mask(work, (False, False), floor)
    got = spike_mask(work, readings.MEDIAN_HALF_WIDTH, readings.SCALE_HALF_WIDTH, floor, readings.SPIKE_SCALES,
                     readings._WHITE_SECOND_DIFFERENCE)
    np.testing.assert_array_equal(got, want)
    if spikes and nan_share < 1.0:
        assert want.any()  # (the cases hold spikes the rule finds)


def test_a_stream_screened_through_the_compiled_rule_decides_as_the_numpy_one(monkeypatch):
    """Readings pushed one by one (a live stream's decisions, one every block) with spikes, a lost reading and a
    stuck run: the same rows and the same counts whether the spike rule is compiled or not."""
    from gfimu.simulate import simulate

    log = simulate("random3d", rate_hz=100.0, duration_s=6.0, seed=4)
    accel = log.accel_mps2.copy()
    accel[150, 1] += 300.0
    accel[320, 4] = np.nan
    accel[400:460, 7] = accel[400, 7]

    def screened():
        screen = readings.StreamScreen(log.array, 100.0)
        rows = []
        for i in range(len(log)):
            rows += screen.push(log.timestamps_ns[i], accel[i])
        rows += screen.flush()
        return np.vstack([r[1] for r in rows]), screen.screening()

    compiled_rows, compiled = screened()
    numpy_spikes = readings._spikes
    monkeypatch.setattr(readings, "_spikes", lambda *a, **k: numpy_spikes(*a, **{**k, "compiled": False}))
    monkeypatch.setattr(readings.StreamScreen, "compiled", False)
    numpy_rows, reference = screened()
    assert compiled_rows.tobytes() == numpy_rows.tobytes()
    assert (compiled.spikes, compiled.stuck, compiled.non_finite) == (reference.spikes, reference.stuck,
                                                                      reference.non_finite)
    assert compiled.spikes >= 1 and compiled.stuck >= 1


def _dirty_log(rate_hz: float, seed: int):
    """A simulated log with what a stream decides block by block: isolated spikes on every channel, runs of
    adjacent spikes (windows with no good reading), a stuck run, readings clipped at the stated range and a
    lost reading."""
    from dataclasses import replace

    from gfimu.simulate import simulate

    log = simulate("random3d", rate_hz=rate_hz, duration_s=40.0, seed=seed)
    array = log.array.with_accelerometers(replace(a, range_mps2=120.0) for a in log.array.accelerometers)
    rng = np.random.default_rng(seed)
    accel = log.accel_mps2.copy()
    n, m = accel.shape
    rows = rng.choice(np.arange(5, n - 5), n // 40, replace=False)
    accel[rows, rng.integers(0, m, rows.size)] += rng.choice([-1.0, 1.0], rows.size) * rng.uniform(15.0, 80.0, rows.size)
    for r in range(300, n - 300, 700):
        accel[r:r + 4, (r // 700) % m] += 60.0  # four adjacent spikes: a window with no good reading
    accel[900:900 + int(0.5 * rate_hz), 3] = accel[900, 3]  # a stuck run of 0.5 s
    accel[1500:1503, 5] = 120.0  # clipped at the range
    accel[1800, 2] = np.nan
    return log.replace(array=array, accel_mps2=accel)


@pytest.mark.parametrize("rate_hz", [62.5, 500.0])
def test_a_decision_on_a_buffer_with_spikes_alone_is_the_numpy_one(monkeypatch, rate_hz):
    """StreamScreen's decisions made in one compiled call where a buffer's only faults can be spikes
    (gfimu.screen_kernels.spike_decision; the numpy expressions elsewhere) give every row, count and run the
    numpy expressions give, pushed one by one (a live stream) and through screen_stream (a log); at 62.5 Hz a
    decision per sample, most of them compiled."""
    import gfimu.screen_kernels as kernels

    log = _dirty_log(rate_hz, seed=int(rate_hz))

    def pushed():
        screen = readings.StreamScreen(log.array, rate_hz)
        rows = []
        for i in range(len(log)):
            rows += screen.push(log.timestamps_ns[i], log.accel_mps2[i])
        rows += screen.flush()
        return np.vstack([r[1] for r in rows]), screen.screening()

    calls = []
    decision = kernels.spike_decision
    monkeypatch.setattr(kernels, "spike_decision", lambda *a: calls.append(decision(*a)[0]) or decision(*a))
    rows, screening = pushed()
    whole, whole_screening = readings.screen_stream(log)
    assert sum(calls) >= 0.5 * len(calls) > 0  # (the compiled decision made most of them)
    monkeypatch.setattr(readings.StreamScreen, "compiled", False)
    want_rows, want = pushed()
    want_whole, want_whole_screening = readings.screen_stream(log)
    assert rows.tobytes() == want_rows.tobytes()
    assert whole.accel_mps2.tobytes() == want_whole.accel_mps2.tobytes()
    for got, ref in ((screening, want), (whole_screening, want_whole_screening)):
        np.testing.assert_array_equal(got.replaced, ref.replaced)
        assert (got.non_finite, got.out_of_range, got.spikes, got.clipped, got.stuck, got.runs) == (
            ref.non_finite, ref.out_of_range, ref.spikes, ref.clipped, ref.stuck, ref.runs)
    assert want.spikes > 50 and want.stuck >= 1 and want.clipped >= 1 and want.non_finite == 1


def test_the_selection_finds_numpys_order_statistic():
    """gfimu.screen_kernels._select (the median |reading| of a decision's buffer) gives the k-th smallest value
    numpy's sort gives, ties and all, the smaller values before it."""
    from gfimu.screen_kernels import _select

    rng = np.random.default_rng(11)
    for trial in range(300):
        a = rng.normal(size=int(rng.integers(1, 200)))
        if trial % 3 == 0:
            a = np.round(a, 1)  # ties
        k = int(rng.integers(0, a.size))
        b = a.copy()
        value = _select(b, k)
        assert value == np.sort(a)[k]
        assert np.all(b[:k] <= value) and np.all(b[k + 1:] >= value) and np.array_equal(np.sort(b), np.sort(a))
