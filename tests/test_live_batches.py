"""gfimu live reads its source a batch at a time: the rows of a read parsed at once (the same readings and the same
reasons as row by row), the reader's queue bounded in samples with the oldest dropped and counted, and the rows the
batch finishes written together, without losing one when the output or the smoother fails half-way."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from gfimu.array import random_array
from gfimu.io.sources import BadRow, Reading, RowParser, Source, default_header


def _rows():
    """(where, text) rows of every kind a text source meets, for a 3-sensor array with readings in g."""
    array = random_array(3, 0.05, seed=1)
    header = "#timestamp [ns]," + ",".join(f"{c} [g]" for c in array.accel_columns)
    good = ",".join(f"{0.01 * k - 0.03:.6f}" for k in range(9))
    texts = [
        f"1000,{good}",
        f" 2000 , {good.replace(',', ' , ')} ",  # spaces around the fields
        f"0003000,{good}",  # leading zeros
        f"99999999999999999999,{good}",  # beyond 64-bit nanoseconds
        f"9223372036854775807,{good}",  # the largest 64-bit nanosecond: 19 digits, read by the exact rule
        f"1e3,{good}",  # a timestamp in exponent form
        f"4000,{good.replace('0.000000', 'abc', 1)}",  # text in a number field
        f"5000,{good},7",  # a field too many
        f"6000,{good.replace('0.000000', 'inf', 1)}",  # not finite
        f"7000,{good.replace('0.000000', '2e6', 1)}",  # beyond any accelerometer's range (2e6 g)
        f"8000,{good.replace('0.000000', 'nan', 1)}",
        f"-9000,{good}",  # a negative timestamp (a reading: the smoother judges its order)
        f"10000,{good.replace('0.000000', '1_0', 1)}",  # an underscore, as float() reads it
    ]
    return array, header, [(f"line {k + 2}", t) for k, t in enumerate(texts)]


def _same(a, b) -> bool:
    if isinstance(a, BadRow) or isinstance(b, BadRow):
        return a == b
    return (a.timestamp_ns == b.timestamp_ns and np.array_equal(a.accel, b.accel, equal_nan=True)
            and (a.gyro is None) == (b.gyro is None))


@pytest.mark.parametrize("keep_gross_errors", [False, True])
def test_a_batch_of_rows_reads_as_row_by_row(keep_gross_errors):
    """RowParser.parse_many gives, row for row, what parse gives (bit-identical readings, the same bad-row reasons), on
    rows of every kind: spaces, leading zeros, a 19-digit timestamp, text, a field too many, inf, nan, beyond range,
    a negative timestamp; in g, converted alike."""
    array, header, rows = _rows()
    parser = RowParser(array, header, "rows", keep_gross_errors=keep_gross_errors)
    one = []
    for where, text in rows:
        try:
            one.append(parser.parse(text))
        except (ValueError, OverflowError) as exc:
            one.append(BadRow(where, str(exc)))
    many = parser.parse_many(rows)
    assert len(many) == len(one)
    assert all(_same(a, b) for a, b in zip(one, many)), [(a, b) for a, b in zip(one, many) if not _same(a, b)]
    kinds = [type(r).__name__ for r in many]
    assert kinds.count("BadRow") == (3 if keep_gross_errors else 6)
    assert many[4].timestamp_ns == 9223372036854775807 and many[5].timestamp_ns == 1000
    np.testing.assert_array_equal(many[0].accel, (0.01 * np.arange(9) - 0.03).round(6) * 9.80665)


class _Burst(Source):
    """A source that delivers ``n`` readings in one read, then ends."""

    name = "burst"

    def __init__(self, array, n):
        super().__init__(array)
        self.n = n

    def batches(self, stop):
        yield [Reading(1000 * k, np.zeros(self.array.n_axes)) for k in range(self.n)]
        self.ended = "end of input"


def test_a_burst_larger_than_the_queue_drops_the_oldest_and_counts_them():
    """25 readings in one read into a queue of 10: the 15 oldest dropped and counted, the newest 10 handed out in
    order, then the end."""
    from gfimu.live import _Reader

    array = random_array(3, 0.05, seed=1)
    reader = _Reader(_Burst(array, 25), threading.Event(), 10)
    reader.thread.start()
    reader.thread.join()
    items = reader.get()
    assert reader.overrun == 15
    assert [r.timestamp_ns for r, _ in items] == [1000 * k for k in range(15, 25)]
    assert reader.get() is None


def test_the_rows_of_a_batch_reach_the_output_before_a_failure(tmp_path):
    """A smoother that fails on the 150th reading of one batch: the rows finished before it are written (none lost
    in the batch not yet written), and the session ends with the failure."""
    import io

    from gfimu.live import EstimateSink, run
    from gfimu.methods import make_estimator
    from gfimu.simulate import simulate

    array = random_array(4, 0.05, noise_std_mps2=0.01, seed=2)
    log = simulate("random3d", array=array, seed=3, rate_hz=500.0, duration_s=1.0)

    class Log(Source):
        name = "log"

        def batches(self, stop):
            yield [Reading(int(t), a) for t, a in zip(log.timestamps_ns, log.accel_mps2)]
            self.ended = "end of input"

    estimator = make_estimator("fixed-lag", tune_process_noise=False, auto_model=False, hold_max_s=0.0)
    from gfimu.smoother.stream import session as ss

    push = ss.StreamSession.push
    count = [0]

    def failing(self, *a, **k):
        count[0] += 1
        if count[0] == 150:
            raise OSError(5, "Input/output error", "the smoother")
        return push(self, *a, **k)

    made = []  # the rows the session hands out by each reading, without a failure

    def counted(self, *a, **k):
        out = push(self, *a, **k)
        made.append(len(out) + (made[-1] if made else 0))
        return out

    ss.StreamSession.push = counted
    try:
        run(Log(array), estimator, EstimateSink(io.StringIO()), rate_hz=500.0, signals=False)
    finally:
        ss.StreamSession.push = push
    buf = io.StringIO()
    ss.StreamSession.push = failing
    try:
        result = run(Log(array), estimator, EstimateSink(buf), rate_hz=500.0, signals=False)
    finally:
        ss.StreamSession.push = push
    assert result.ended == "stopped by an error" and result.failure == "the smoother: Input/output error"
    lines = buf.getvalue().splitlines()
    assert result.counts.rows_out == len(lines) - 1 == made[148] > 0  # every row finished by the 149th reading


def test_the_default_queue_holds_ten_seconds_of_the_stream():
    """By default the source's queue grows to QUEUE_S of samples at the stream's rate once it is known (a start held
    for ~2 s at 20 kHz is caught up after, not dropped), never below QUEUE_MIN; a --queue given stays as given; the
    command's help says the same numbers."""
    from gfimu.live import QUEUE_MIN, QUEUE_S, _Reader

    array = random_array(3, 0.05, seed=1)
    reader = _Reader(_Burst(array, 1), threading.Event(), QUEUE_MIN)
    reader.grows = True
    reader.fit(None)
    assert reader.size == QUEUE_MIN
    reader.fit(62.5)
    assert reader.size == QUEUE_MIN  # 625 samples: the least stays
    reader.fit(20000.0)
    assert reader.size == int(QUEUE_S * 20000.0) == 200_000
    reader.fit(500.0)
    assert reader.size == 200_000  # never smaller
    given = _Reader(_Burst(array, 1), threading.Event(), 300)
    given.fit(20000.0)
    assert given.size == 300
    import contextlib
    import io

    from gfimu.cli import main

    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.suppress(SystemExit):
        main(["live", "--help"])
    help_text = " ".join(out.getvalue().split())
    assert f"default: {QUEUE_S:g} s of samples at the stream's rate, at least {QUEUE_MIN}" in help_text


def test_a_smoother_behind_its_stream_is_said_once_and_in_the_status():
    """Half the queue waiting: one warning that the smoother runs behind (how many samples, how many seconds at the
    stream's rate, the queue's bound); the status line says what waits."""
    import io
    from collections import deque

    from gfimu.live import EstimateSink, _Live, _Reader
    from gfimu.methods import make_estimator
    from gfimu.smoother.stream.session import StreamSession

    array = random_array(3, 0.05, seed=1)
    said = []
    live = _Live(_Burst(array, 1), make_estimator("fixed-lag"), EstimateSink(io.StringIO()), 1000.0, said.append, 1.0)
    live.session = StreamSession(array, live.estimator, 1000.0)
    reader = _Reader(_Burst(array, 1), threading.Event(), 10)
    reader.items = deque([object()] * 4)
    live.behind(reader)
    assert said == []
    reader.items = deque([object()] * 5 + [None])
    live.behind(reader)
    live.behind(reader)
    assert said == ["warning: the smoother runs behind the stream: 5 waiting (0.0 s behind); beyond 10 (--queue) the "
                    "oldest are dropped (a faster machine, a lower rate or fewer sensors keep up)"]
    live.status(reader)
    assert said[-1].startswith("0 in, 0 out, processing p50 nan ms") and said[-1].endswith(", 5 waiting (0.0 s behind)")


def test_an_empty_batch_from_a_source_is_no_item():
    """A source of its own that yields an empty list between readings: nothing queued for it, the readings after it
    come through."""
    from gfimu.live import _Reader

    array = random_array(3, 0.05, seed=1)

    class Gappy(Source):
        def batches(self, stop):
            yield []
            yield [Reading(1000, np.zeros(array.n_axes))]
            yield []
            self.ended = "end of input"

    reader = _Reader(Gappy(array), threading.Event(), 10)
    reader.thread.start()
    reader.thread.join()
    assert not reader.fatal and reader.overrun == 0
    assert [r.timestamp_ns for r, _ in reader.get()] == [1000] and reader.get() is None


def test_a_second_signal_drops_the_samples_still_waiting():
    """Stopped (a first signal) with samples waiting: they are handed out, to be estimated, and the command says so
    once when more than one take waits; a second signal (hurry) drops them instead, counted as dropped, and the
    end comes next."""
    import io
    from collections import deque

    from gfimu.live import ITEMS_AT_ONCE, EstimateSink, _Live, _Reader, _Signals
    from gfimu.methods import make_estimator
    from gfimu.smoother.stream.session import StreamSession

    array = random_array(3, 0.05, seed=1)
    stop = threading.Event()
    signals = _Signals(stop, enabled=False)
    reader = _Reader(_Burst(array, 1), stop, 10_000)
    reader.hurry = signals.hurry
    reading = (Reading(1000, np.zeros(array.n_axes)), 0.0)
    reader.items = deque([reading] * (ITEMS_AT_ONCE + 10) + [None])
    signals._on_signal(2, None)  # SIGINT
    assert stop.is_set() and signals.caught == ["SIGINT"] and not signals.hurry.is_set()
    said = []
    live = _Live(_Burst(array, 1), make_estimator("fixed-lag"), EstimateSink(io.StringIO()), 1000.0, said.append, None)
    live.session = StreamSession(array, live.estimator, 1000.0)
    live.stopping(reader)
    live.stopping(reader)
    assert said == [f"stopping: {ITEMS_AT_ONCE + 10} waiting ({(ITEMS_AT_ONCE + 10) / 1000:.1f} s behind), estimated "
                    "first; a second SIGINT or SIGTERM drops them"]
    assert len(reader.get()) == ITEMS_AT_ONCE  # still handed out, to be estimated
    signals._on_signal(15, None)  # a second signal
    assert signals.hurry.is_set() and signals.caught == ["SIGINT"]
    assert reader.get() is None and reader.overrun == 10 and list(reader.items) == [None]
