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
    numpy_rows, reference = screened()
    assert compiled_rows.tobytes() == numpy_rows.tobytes()
    assert (compiled.spikes, compiled.stuck, compiled.non_finite) == (reference.spikes, reference.stuck,
                                                                      reference.non_finite)
    assert compiled.spikes >= 1 and compiled.stuck >= 1
