"""One streaming session (gfimu.smoother.stream.session.StreamSession) for gfimu estimate --method fixed-lag and
gfimu live: the same rows from a log and from its readings as they come, and a model chosen off the stream
used at a sample fixed by the data, however late its worker is."""

from __future__ import annotations

import time

import numpy as np
import pytest

from gfimu.simulate import simulate
from gfimu.smoother.stream import fixed_lag
from gfimu.smoother.stream.fixed_lag import FixedLagEstimator
from gfimu.smoother.stream.session import RATE_ROWS, StreamSession

RATE_HZ = 200.0


@pytest.fixture(scope="module")
def log():
    """6 s of random motion at 200 Hz with two gross errors the screening replaces."""
    log = simulate("random3d", rate_hz=RATE_HZ, duration_s=6.0, seed=3)
    accel = log.accel_mps2.copy()
    accel[300, 2] += 400.0  # a spike
    accel[700, 5] = np.nan  # a reading lost
    return log.replace(accel_mps2=accel)


def _estimator(**options):
    # the model chosen on the first second, then again every second: several choices made off the stream
    return FixedLagEstimator(tune_window_s=1.0, retune_every_s=1.0, model_window_s=2.0, **options)


def _rows(states) -> np.ndarray:
    return np.array([np.concatenate([[s.timestamp_ns], s.omega_b_radps, s.omega_dot_b_radps2,
                                     s.specific_force_b_mps2]) for s in states])


def _stream(est, log, rate_hz=RATE_HZ):
    """The log's readings one by one through a session, as gfimu live sends them: (rows, session)."""
    session = StreamSession(log.array, est, rate_hz)
    states = []
    for i in range(len(log)):
        states += session.push(log.timestamps_ns[i], log.accel_mps2[i])
    states += session.finish()
    return _rows(states), session


def test_a_log_and_its_readings_as_they_come_give_the_same_rows(log):
    """estimate's path (the log screened whole by estimator.screen, then result()) and live's (readings
    screened and smoothed one by one, the rate measured on the first 64 timestamps) give the same numbers,
    to the last bit, through several models chosen off the stream; both replace the same 2 readings."""
    est = _estimator()
    screened, screening = est.screen(log)
    assert screening.count == 2
    whole = est.result(screened)
    m = whole.motion
    expected = np.column_stack([m.timestamps_ns, m.omega_b_radps, m.omega_dot_b_radps2, m.specific_force_b_mps2])
    got, session = _stream(est, log, rate_hz=None)
    assert session.rate_from == "stream" and session.rate_hz == pytest.approx(RATE_HZ, rel=1e-9)
    assert session.take_notes()[0] == (f"rate 200 Hz, from the median period of the first {RATE_ROWS} samples "
                                       "(array.toml states no rate_hz; --rate-hz sets it)")
    assert len(session.models) >= 4  # the first choice and at least three made off the stream
    assert session.counts.replaced_readings == 2 and session.counts.late_or_repeated == 0
    np.testing.assert_array_equal(got, expected)
    assert [t.density for t in whole.report.tunings] == [t.density for t in dict.fromkeys(
        m.tuning for m in session.models if m.tuning is not None)]


def test_the_model_changes_at_a_sample_fixed_by_the_data_not_by_the_clock(log, monkeypatch):
    """A choice whose worker takes 0.3 s longer (a busy machine): the stream waits for it at its sample,
    counts the wait, and gives the same rows to the last bit as when the worker is quick."""
    est = _estimator()
    quick, session = _stream(est, log)
    assert session.counts.choice_waits == 0 or session.counts.choice_wait_s < 5.0
    n_models = len(session.models)
    chosen_model = fixed_lag.FixedLagSmoother._chosen_model

    def slow(self, *args, **kwargs):
        if not kwargs.get("first"):
            time.sleep(0.3)
        return chosen_model(self, *args, **kwargs)

    monkeypatch.setattr(fixed_lag.FixedLagSmoother, "_chosen_model", slow)
    late, session = _stream(est, log)
    assert len(session.models) == n_models >= 4
    c = session.counts
    assert c.choice_waits >= 1 and 0.0 < c.choice_wait_s <= 0.3 * c.choice_waits + 1.0
    np.testing.assert_array_equal(late, quick)


def test_choices_made_in_a_process_of_their_own_give_the_rows_of_choices_in_a_thread(log, monkeypatch):
    """The later choices are made in a forked process (where one may be forked): the same models at the same
    samples, the same rows to the last bit, as when they are made in a thread of the stream's process."""
    from gfimu.parallel import can_fork
    from gfimu.smoother.stream import choice_worker

    if not can_fork():
        pytest.skip("no fork on this platform: the choices are made in a thread")
    est = _estimator()
    smoother = est.smoother(log.array, RATE_HZ)
    in_process = []
    for i in range(len(log)):
        in_process += smoother.push(log.timestamps_ns[i], np.nan_to_num(log.accel_mps2[i], nan=0.0)).smoothed
    process = smoother._worker.process
    assert process is not None and process._process.is_alive()
    in_process += smoother.close()
    assert not process._process.is_alive()  # ended with the smoother
    monkeypatch.setattr(choice_worker.ChoiceProcess, "start", classmethod(lambda cls, func, idle=None: None))
    threaded = est.smoother(log.array, RATE_HZ)
    in_thread = []
    for i in range(len(log)):
        in_thread += threaded.push(log.timestamps_ns[i], np.nan_to_num(log.accel_mps2[i], nan=0.0)).smoothed
    in_thread += threaded.close()
    assert threaded._worker.process is None and len(threaded.models) == len(smoother.models) >= 4
    assert [m.chosen_at_ns for m in threaded.models] == [m.chosen_at_ns for m in smoother.models]
    np.testing.assert_array_equal(_rows(in_process), _rows(in_thread))
    monkeypatch.undo()
    _, session = _stream(est, log)  # a session ends its smoother's process when the stream ends
    assert session.smoother._worker.tried and session.smoother._worker.process is None


def test_a_log_s_scheduled_choices_made_ahead_give_the_same_rows(log):
    """Given the readings to come (a log), the choice's process makes each scheduled choice before it is asked
    for; the stream uses it only where the samples it took are those it was made on: the same models at the
    same samples and the same rows to the last bit as without; a reading changed after a choice was made
    ahead (so that it no longer holds) is made again on the readings the stream took."""
    from gfimu.parallel import can_fork

    if not can_fork():
        pytest.skip("no fork on this platform: the choices are made in a thread")
    est = _estimator()
    screened, _ = est.screen(log)
    accel = screened.accel_mps2

    def run(upcoming, readings=accel):
        session = StreamSession(screened.array, est, RATE_HZ, screen=False, upcoming=upcoming)
        states = []
        for i in range(len(screened)):
            states += session.push(screened.timestamps_ns[i], readings[i])
        used = session.smoother._ahead.used
        states += session.finish()
        return _rows(states), [m.chosen_at_ns for m in session.models], used

    plain, plain_at, none_used = run(None)
    ahead, ahead_at, used = run((screened.timestamps_ns, accel, None))
    assert none_used == 0 and used >= 2 and len(ahead_at) >= 4
    assert ahead_at == plain_at
    np.testing.assert_array_equal(ahead, plain)
    changed = accel.copy()
    changed[len(changed) // 2:, 0] += 1e-9  # what the process was told is to come is not what comes
    reference, reference_at, _ = run(None, changed)
    told, told_at, told_used = run((screened.timestamps_ns, accel, None), changed)
    assert told_used < used and told_at == reference_at
    np.testing.assert_array_equal(told, reference)


def test_the_choice_process_works_ahead_between_requests():
    """``idle`` runs in the process after each answer: what it did is there for the next request."""
    from gfimu.parallel import can_fork
    from gfimu.smoother.stream.choice_worker import ChoiceProcess

    if not can_fork():
        pytest.skip("no fork on this platform")
    done = []
    process = ChoiceProcess.start(lambda x: (x, len(done)), lambda: done.append(1))
    process.submit("a")
    assert process.result() == ("a", 0)
    time.sleep(0.5)  # (a request already waiting would skip the work ahead)
    process.submit("b")
    assert process.result() == ("b", 1)
    process.close()
    assert not process._process.is_alive()


def test_the_choice_process_answers_in_order_and_raises_what_a_request_raised():
    from gfimu.parallel import can_fork
    from gfimu.smoother.stream.choice_worker import ChoiceProcess

    if not can_fork():
        pytest.skip("no fork on this platform")
    process = ChoiceProcess.start(lambda x: 1.0 / x)
    process.submit(4.0)
    assert process.result() == 0.25
    process.submit(0.0)
    with pytest.raises(ZeroDivisionError):
        process.result()
    process.submit(0.0)  # an answer left unread is read before the next request
    process.submit(2.0)
    assert process.result() == 0.5
    process.close()
    assert not process._process.is_alive()


def test_a_choice_pending_at_the_end_is_used_before_the_window_is_flushed(log):
    """The stream ends 0.1 s after a choice was asked (before its sample): the choice is used at the end, the
    rows all come out, once each, in time order."""
    est = _estimator()
    smoother = est.smoother(log.array, RATE_HZ)
    out = []
    for i in range(len(log)):
        out += smoother.push(log.timestamps_ns[i], np.nan_to_num(log.accel_mps2[i], nan=0.0)).smoothed
        if smoother._choice.pending is not None and i > 3 * RATE_HZ:
            break
    assert smoother._choice.pending is not None
    n_models = len(smoother.models)
    out += smoother.flush()
    assert smoother._choice.pending is None and len(smoother.models) == n_models + 1
    t = [s.timestamp_ns for s in out]
    assert t == list(log.timestamps_ns[:i + 1])


def test_the_summary_says_the_waits():
    from gfimu.live import LiveCounts, LiveResult, LiveTimes

    r = LiveResult(LiveCounts(rows_in=10, rows_out=10, choice_waits=2),
                   LiveTimes(latency_ms=(201.0, 240.5, 250.0), choice_wait_ms=35.25), rate_hz=500.0, rate_from="given",
                   ended="end of input")
    text = r.summary()
    assert "latency arrival -> estimate written p50 201.0 ms, p99 240.5 ms, max 250.0 ms" in text
    assert text.endswith("; waited 2 time(s) for a model chosen off the stream, 35.2 ms in all; ended: end of input")


def test_a_choice_that_fails_in_its_worker_raises_where_its_model_is_used():
    """The worker's exception is not lost in its thread: it is raised by result(), on the stream's thread."""
    from gfimu.smoother.stream.fixed_lag import PendingChoice

    failing = PendingChoice(lambda: 1 / 0, swap_at=5, outgrown=False)
    with pytest.raises(ZeroDivisionError):
        failing.result()
    slow = PendingChoice(lambda: time.sleep(0.2) or "model", swap_at=5, outgrown=True)
    assert slow.result() == "model" and slow.done and 0.1 < slow.waited_s < 5.0


def test_the_rate_watch_shortcut_says_what_the_full_rule_says():
    """RateWatch skips the median when the newest step rules a change out; on streams whose rate jumps,
    jitters and drifts, it returns what the rule computed in full at every step would."""
    from gfimu.smoother.stream.session import RATE_WATCH_STEPS, RateWatch

    def full_rule(rate_hz, steps):
        s = np.asarray(steps, dtype=float)
        median = float(np.median(s))
        if median <= 0 or np.max(np.abs(s - median)) > 0.1 * median:
            return None
        ratio = median * 1e-9 * rate_hz
        return None if 1 / 1.5 <= ratio <= 1.5 else 1e9 / median

    rng = np.random.default_rng(11)
    nominal = 2_000_000  # 500 Hz
    factors = np.concatenate([np.full(300, 1.0), np.full(300, 2.0), rng.uniform(0.6, 1.6, 400),
                              np.full(200, 0.5), np.full(200, 1.36), np.full(200, 0.73)])
    steps = (nominal * factors * rng.uniform(0.97, 1.03, factors.size)).astype(np.int64)
    watch, t, said = RateWatch(500.0), 0, 0
    for step in steps:
        t += int(step)
        before, window = watch.rate_hz, (watch.steps + [int(step)])[-RATE_WATCH_STEPS:]
        got = watch.step(t)
        want = full_rule(before, window) if len(window) == RATE_WATCH_STEPS and watch.last is not None else None
        assert got == want
        said += got is not None
    assert said >= 3  # the watch did see the jumps


@pytest.mark.slow
def test_what_a_long_stream_keeps_does_not_grow_with_its_length():
    """The memory a session holds at the end of a stream does not grow with the stream's length: between
    its 2,000th and its 6,000th sample (past the first choice of the model, the history it is chosen on
    full) what gfimu allocated and still holds grows by less than 8 bytes a sample (2.4 measured): the
    timings kept for the summary sit in arrays made at the start (lists of floats grew by 44 bytes a
    sample, 176 KB here). No model is chosen again in between (retune_every_s 60 s): every model chosen
    is kept, one per retune_every_s, not one per sample."""
    import gc
    import tracemalloc

    long_log = simulate("random3d", rate_hz=RATE_HZ, duration_s=30.0, seed=5)
    est = FixedLagEstimator(tune_window_s=1.0, retune_every_s=60.0, model_window_s=2.0)
    session = StreamSession(long_log.array, est, RATE_HZ)
    t, a = long_log.timestamps_ns, long_log.accel_mps2
    held = {}
    out = 0
    try:
        for i in range(len(long_log)):
            if i == 1000:
                tracemalloc.start()
            out += len(session.push(t[i], a[i]))
            if i + 1 in (2000, 6000):
                gc.collect()
                # what gfimu's own lines allocated (numpy's internal cache of small buffers left out)
                ours = tracemalloc.take_snapshot().filter_traces([tracemalloc.Filter(True, "*gfimu*")])
                held[i + 1] = sum(stat.size for stat in ours.statistics("filename"))
    finally:
        tracemalloc.stop()
    out += len(session.finish())
    assert out == len(long_log) == 6000
    assert len(session.processing_s) == 6000 and len(session.models) == 1
    assert held[2000] > 0
    assert (held[6000] - held[2000]) / 4000 < 8.0  # a Python float kept per sample: 32


def test_the_history_holds_the_screened_readings_not_the_screenings_buffers():
    """The screening decides a block on a scratch array of its whole buffer; the history the model is chosen
    on copies the readings into a ring of its own (38 KB for 2 s here), not views that keep the scratch arrays
    alive (710 KB were the rows views of the scratch array once), and holds the newest readings in order."""
    long_log = simulate("random3d", rate_hz=RATE_HZ, duration_s=8.0, seed=6)
    est = FixedLagEstimator(tune_window_s=1.0, retune_every_s=60.0, model_window_s=2.0)
    session = StreamSession(long_log.array, est, RATE_HZ)
    for i in range(len(long_log)):
        session.push(long_log.timestamps_ns[i], long_log.accel_mps2[i])
    history = session.smoother._choice.history
    n = int(2.0 * RATE_HZ)
    assert len(history) == n
    assert history.accel.base is None and history.accel.nbytes == n * long_log.array.n_axes * 8
    stretch = history.stretch()
    first = int(np.searchsorted(long_log.timestamps_ns, stretch.times_ns[0]))  # (the screening holds the newest back)
    assert first + n > len(long_log) - RATE_HZ
    np.testing.assert_array_equal(stretch.times_ns, long_log.timestamps_ns[first:first + n])
    np.testing.assert_allclose(stretch.accel, long_log.accel_mps2[first:first + n], rtol=0, atol=1e-12)
    session.finish()


def test_a_warning_raised_in_the_choice_process_is_raised_where_its_answer_is_read():
    import warnings

    from gfimu.parallel import can_fork
    from gfimu.smoother.stream.choice_worker import ChoiceProcess

    if not can_fork():
        pytest.skip("no fork on this platform")

    def warns(x):
        warnings.warn(f"odd stretch {x}", RuntimeWarning)
        return x

    process = ChoiceProcess.start(warns)
    process.submit(3)
    with pytest.warns(RuntimeWarning, match="odd stretch 3"):
        assert process.result() == 3
    process.close()
