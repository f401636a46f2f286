"""The fixed-lag smoother's start waits for evidence: the first rows of a segment are held until the
data decide ω, then come out re-solved (gfimu.smoother.stream.fixed_lag, FixedLagSmoother._release_start)."""

import numpy as np
import pytest

from gfimu.array import cube_array
from gfimu.simulate import simulate
from gfimu.smoother.batch.engine import BatchSmootherEstimator
from gfimu.smoother.stream.fixed_lag import FixedLagEstimator


def _rmse(est, truth, rows=slice(None)):
    return float(np.sqrt(np.mean(np.sum((est[rows] - truth[rows]) ** 2, axis=1))))


@pytest.mark.slow
def test_slow_motion_start_is_held_and_the_log_stays_within_twice_the_batch_smoother():
    """Slow rotation (|ω| at most 1 rad/s), a 10 cm cube of four triads, 0.07 m/s², 500 Hz, 6 s: the
    readings see ω through q(ω) ~ |ω|², and a stream that commits at once starts 0.17 rad/s off over its
    first 2 s (5.8 times the batch smoother there; 2.7 times over the log; 1.9 % of those samples with
    the wrong sign). Held and re-solved: within twice the batch smoother over the log and within 2.5
    times over the first 2 s (measured 1.44 and 1.8), no wrong sign, far below the per-sample methods
    (imm: 0.49 rad/s)."""
    log = simulate("slow3d", array=cube_array(0.05, noise_std_mps2=0.07), rate_hz=500.0, duration_s=6.0, seed=0)
    truth = log.truth.omega_b_radps
    first = log.times_s - log.times_s[0] < 2.0
    batch = BatchSmootherEstimator().estimate(log).motion.omega_b_radps
    fl = FixedLagEstimator().estimate(log).motion.omega_b_radps
    assert _rmse(fl, truth) <= 2.0 * _rmse(batch, truth)
    assert _rmse(fl, truth, first) <= 2.5 * _rmse(batch, truth, first)
    moving = np.linalg.norm(truth, axis=1) > 0.1
    assert not np.any((np.sum(fl * truth, axis=1) < 0) & moving & first)
    from gfimu.methods import make_estimator

    imm = make_estimator("imm").estimate_motion(log).omega_b_radps
    assert _rmse(fl, truth) < 0.5 * _rmse(imm, truth)


def test_the_hold_is_bounded_and_every_row_comes_out_once_in_order():
    """hold_max_s bounds the hold: at 200 Hz with hold_max_s = 1 s and lag 0.2 s, the first rows come out
    at the latest when the held rows span 1 s (the sample 1.2 s in, plus one check), all at once, then
    one per push; every timestamp once, in order; the decision is recorded in ``starts``."""
    log = simulate("slow3d", array=cube_array(0.05, noise_std_mps2=0.07), rate_hz=200.0, duration_s=4.0, seed=1)
    sm = FixedLagEstimator(hold_max_s=1.0).smoother(log.array, 200.0)
    first_out, out = None, []
    for i in range(len(log)):
        upd = sm.push(log.timestamps_ns[i], log.accel_mps2[i])
        if upd.smoothed and first_out is None:
            first_out = i
            assert len(upd.smoothed) > 1  # the held rows together
        out.extend(upd.smoothed)
    out.extend(sm.flush())
    np.testing.assert_array_equal([s.timestamp_ns for s in out], log.timestamps_ns)
    assert first_out is not None and first_out <= int(round((3.0 + 1.0 + 0.2 + 0.5) * 200.0))
    assert len(sm.starts) >= 1 and sm.starts[0]["held_s"] <= 1.0 + 1e-9
    assert set(sm.starts[0]) == {"held_s", "evidence_nats", "agreement_chi2", "moved_chi2", "open"}


def test_start_hold_weighs_the_evidence_every_check_and_at_its_longest_span():
    """StartHold's bookkeeping (the held start's part of FixedLagSmoother): checks at spans of the stretch from
    the first row held to the newest sample that double up to the last one, made when the rows span ``max_s``
    (the first at least ``check_every_ns``), and at once when the rows span ``max_s``; the change of the
    re-solve between checks in its covariance; release ends the hold."""
    from gfimu.smoother.stream.fixed_lag import StartHold

    ms = 1_000_000
    hold = StartHold(max_s=2.0, check_every_ns=500 * ms)
    assert hold.deciding and hold.held == [] and hold.held_s == 0.0
    hold.held = [(t * ms, ("raw", t), None) for t in (100, 110, 120)]
    assert hold.held_s == pytest.approx(0.02, abs=1e-15)

    def due(newest_ms: int) -> bool:  # the rows held up to 280 ms before the newest sample (the lag), then due()
        while hold.held[-1][0] + 10 * ms <= (newest_ms - 280) * ms:
            t = hold.held[-1][0] // ms + 10
            hold.held.append((t * ms, ("raw", t), None))
        return hold.due(newest_ms * ms)

    # the newest sample 280 ms ahead of the last row held: the last check at a span of 2.0 s + 280 ms (the rows
    # then span max_s); before it, 1140 ms and 570 ms (the shortest of the halvings at least 500 ms)
    assert not due(400) and hold.next_check_ns == 670 * ms  # 100 ms + 570 ms
    assert not due(669) and due(670) and hold.next_check_ns == 1240 * ms
    assert not due(1239) and due(1240) and hold.next_check_ns == 2380 * ms
    assert not due(2379) and hold.held_s == pytest.approx(1.99) and due(2380)  # the rows span 2.0 s = max_s
    n = len(hold.held)
    hold.held.append((2200 * ms, ("raw", 2200), None))  # the rows span 2.1 s > max_s: due before the next check
    assert hold.due(2381 * ms)
    hold.held = hold.held[:n]
    # a hold whose longest span is less than twice the first check's: one check, the last
    short = StartHold(max_s=0.4, check_every_ns=500 * ms)
    short.held = [(0, ("raw", 0), None), (20 * ms, ("raw", 20), None)]
    assert not short.due(200 * ms) and short.next_check_ns == 580 * ms  # 0.4 s + the 180 ms ahead

    times = np.array([100, 110, 120]) * ms
    omega = np.zeros((3, 3))
    cov = np.stack([np.diag([0.01, 0.04, 0.25])] * 3)
    assert hold.moved(times, omega, cov) == np.inf  # the first check: nothing to compare with
    shifted = omega + np.array([0.1, 0.2, 0.5])  # one sigma on each axis: chi2 = 3 on each row
    assert hold.moved(times, shifted, cov) == pytest.approx(3.0, rel=1e-12)
    assert hold.moved(times[:2], shifted[:2], cov[:2]) == np.inf  # fewer rows than the last check's

    hold.record(hold.held_s, 7.5, 0.4, 0.2, False)
    assert hold.release() == [("raw", t) for t in range(100, 2101, 10)]
    assert not hold.deciding and hold.held == []
    assert hold.starts == [{"held_s": pytest.approx(2.0), "evidence_nats": 7.5, "agreement_chi2": 0.4,
                            "moved_chi2": 0.2, "open": False}]
    hold.begin_segment()  # a new segment: held again, the record of every start kept
    assert hold.deciding and hold.next_check_ns is None and hold.last_resolve is None and len(hold.starts) == 1
    assert not StartHold(max_s=0.0, check_every_ns=500 * ms).deciding  # no hold (the gtsam engine)


def test_a_start_released_from_the_stretchs_batch_solution_weighs_no_evidence():
    """A consistent first stretch whose process noise is tuned comes out as its batch solution, which also
    releases the rows held while the stretch is streamed: no evidence is weighed meanwhile (each check would
    solve the held stretch five times for rows the batch solution replaces). The start is recorded as decided
    from the batch solution (no evidence figure), and the rows are the batch solution's."""
    from gfimu.smoother.stream import fixed_lag

    log = simulate("random3d", array=cube_array(0.05, noise_std_mps2=0.07), rate_hz=500.0, duration_s=5.0, seed=3)
    sm = FixedLagEstimator().smoother(log.array, 500.0)
    checks = []
    original = fixed_lag.FixedLagSmoother._start_evidence

    def counted(self):
        checks.append(len(self._hold.held))
        return original(self)

    fixed_lag.FixedLagSmoother._start_evidence = counted
    try:
        out = []
        for i in range(len(log)):
            out.extend(sm.push(log.timestamps_ns[i], log.accel_mps2[i]).smoothed)
        out.extend(sm.flush())
    finally:
        fixed_lag.FixedLagSmoother._start_evidence = original
    np.testing.assert_array_equal([s.timestamp_ns for s in out], log.timestamps_ns)
    assert sm.starts and np.isnan(sm.starts[0]["evidence_nats"]) and not sm.starts[0]["open"]
    assert checks == []
    w = np.array([s.omega_b_radps for s in out])
    assert _rmse(w, log.truth.omega_b_radps) < 0.1


def test_the_held_start_s_solves_beside_the_stream_are_the_serial_ones_to_the_bit(monkeypatch):
    """The starts of a held stretch are solved half in a process of its own, half in the stream's: each solution
    the one solving them one after the other gives, bit for bit, in the order of the starts."""
    from gfimu.parallel import can_fork, cpu_count
    from gfimu.smoother.solve.banded import solve
    from gfimu.smoother.stream import fixed_lag

    if not can_fork() or cpu_count() < 2:
        pytest.skip("the starts are solved one after the other on this machine")
    seen = []
    solved_from = fixed_lag.FixedLagSmoother._solved_from

    def kept(self, problem, starts):
        solutions = solved_from(self, problem, starts)
        seen.append((problem, starts, solutions, self._solver.process))
        return solutions

    monkeypatch.setattr(fixed_lag.FixedLagSmoother, "_solved_from", kept)
    log = simulate("slow3d", array=cube_array(0.05, noise_std_mps2=0.07), rate_hz=200.0, duration_s=3.0, seed=1)
    FixedLagEstimator().estimate(log)
    assert len(seen) >= 2 and all(p is not None for *_, p in seen)
    assert not seen[-1][3]._process.is_alive()  # ended with the stream
    for problem, starts, solutions, _ in seen:
        assert len(solutions) == len(starts) >= 4
        for x0, got in zip(starts, solutions):
            want = solve(problem, x0)
            assert got.states.tobytes() == want.states.tobytes() and got.cost == want.cost
