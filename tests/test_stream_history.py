"""The history a stream's model is chosen on (gfimu.smoother.stream.history): the newest samples in order
as the ring wraps, the ML rows a choice computed kept for the samples still held, and a process's copy
kept up from what is sent to it equal to the stream's own."""

import numpy as np

from gfimu.smoother.stream.history import History, Stretch, same_samples

AXES = 6


def _sample(k: int, gyro: bool = True):
    return 1000 * k, np.full(AXES, float(k)), (np.full(3, -float(k)) if gyro else None)


def _filled(n: int, capacity: int, no_gyro=()) -> History:
    history = History(capacity, AXES)
    for k in range(n):
        history.append(*_sample(k, k not in no_gyro))
    return history


def test_the_newest_samples_in_order_as_the_ring_wraps():
    history = _filled(11, 4)
    stretch = history.stretch()
    assert len(history) == len(stretch) == 4
    assert stretch.first == 7
    np.testing.assert_array_equal(stretch.times_ns, [7000, 8000, 9000, 10000])
    np.testing.assert_array_equal(stretch.accel[:, 0], [7.0, 8.0, 9.0, 10.0])
    np.testing.assert_array_equal(stretch.gyro[:, 2], [-7.0, -8.0, -9.0, -10.0])
    assert not stretch.has_row.any()
    assert len(_filled(3, 4).stretch()) == 3


def test_the_newest_readings_are_the_last_n_held_in_order():
    history = _filled(11, 4)
    np.testing.assert_array_equal(history.newest_accel(2)[:, 0], [9.0, 10.0])
    np.testing.assert_array_equal(history.newest_accel(9)[:, 0], [7.0, 8.0, 9.0, 10.0])  # no more than it holds
    assert history.newest_accel(2).shape == (2, AXES)


def test_a_stretch_has_gyro_readings_only_where_every_sample_has_one():
    assert _filled(6, 4, no_gyro={1}).stretch().gyro is not None  # (sample 1 no longer held)
    assert _filled(6, 4, no_gyro={3}).stretch().gyro is None


def test_rows_are_kept_for_the_samples_still_held_after_the_ring_moved_on():
    history = _filled(6, 4)
    stretch = history.stretch()  # samples 2..5
    stretch.rows[:] = np.arange(4.0)[:, None]
    stretch.has_row[:] = True
    stretch.rows[1], stretch.has_row[1] = 0.0, False  # sample 3: not computed
    for k in (6, 7):  # samples 2 and 3 leave
        history.append(*_sample(k))
    history.keep_rows(stretch)
    later = history.stretch()  # samples 4..7
    np.testing.assert_array_equal(later.has_row, [True, True, False, False])
    np.testing.assert_array_equal(later.rows[:2, 0], [2.0, 3.0])


def test_a_copy_kept_up_from_what_is_sent_equals_the_history():
    history = History(5, AXES)
    copy = History(5, AXES)
    rng = np.random.default_rng(3)
    k = 0
    for burst in (3, 0, 1, 4, 12, 2, 5, 7):
        for _ in range(burst):
            history.append(*_sample(k, bool(rng.random() > 0.2)))
            k += 1
        copy.extend(*history.since())
        a, b = history.stretch(), copy.stretch()
        assert (a.first, len(a)) == (b.first, len(b)) and copy.total == history.total
        np.testing.assert_array_equal(a.times_ns, b.times_ns)
        np.testing.assert_array_equal(a.accel, b.accel)
        assert (a.gyro is None) == (b.gyro is None)
        if a.gyro is not None:
            np.testing.assert_array_equal(a.gyro, b.gyro)


def test_a_copy_forked_with_the_history_skips_what_it_holds_already():
    history = _filled(3, 5)
    forked = _filled(3, 5)  # (the process's copy, made when it was forked)
    history.append(*_sample(3))
    forked.extend(*history.since())  # every sample held is sent the first time
    np.testing.assert_array_equal(forked.stretch().times_ns, [0, 1000, 2000, 3000])
    assert forked.total == 4


def test_a_stretch_of_samples():
    stretch = Stretch.of_samples([_sample(k) for k in range(3)])
    np.testing.assert_array_equal(stretch.times_ns, [0, 1000, 2000])
    assert stretch.gyro.shape == (3, 3) and stretch.rows.shape == (3, 9) and not stretch.has_row.any()
    assert Stretch.of_samples([_sample(0), _sample(1, gyro=False)]).gyro is None


def test_samples_told_ahead_match_what_is_sent_once_they_are_appended():
    """:meth:`History.ahead` numbers the samples to come as :meth:`History.since` sends them once appended (the
    newest ``capacity`` at most); :func:`same_samples` tells them apart by a single bit, and not by a gyro
    reading where a sample has none."""
    for n_ahead in (3, 5, 9):  # within, at and beyond the capacity (5)
        history = _filled(4, 5)
        history.since()
        samples = [_sample(k, gyro=k != 6) for k in range(4, 4 + n_ahead)]
        told = history.ahead(np.array([s[0] for s in samples]), np.array([s[1] for s in samples]),
                             np.array([np.zeros(3) if s[2] is None else s[2] for s in samples]),
                             np.array([s[2] is not None for s in samples]))
        for s in samples:
            history.append(*s)
        sent = history.since()
        assert told[0] == sent[0] == 4 + n_ahead - min(n_ahead, 5)
        assert same_samples(told, sent)
        bumped = (told[0], told[1], told[2].copy(), told[3], told[4])
        bumped[2][-1, 0] = np.nextafter(bumped[2][-1, 0], np.inf)
        assert not same_samples(bumped, sent)
        assert not same_samples((told[0] + 1, *told[1:]), sent)
    stale = _filled(2, 5)
    stale.since()
    told = stale.ahead(np.array([2000]), np.ones((1, AXES)) * 2.0, np.full((1, 3), 9.0), np.array([False]))
    stale.append(2000, np.ones(AXES) * 2.0, None)  # (its gyro row keeps what the slot held)
    assert same_samples(told, stale.since())


def test_a_copy_of_a_history_is_its_own():
    history = _filled(3, 4)
    copy = history.copy()
    copy.append(*_sample(3))
    copy.rows[:] = 1.0
    assert history.total == 3 and copy.total == 4 and not history.rows.any()
    np.testing.assert_array_equal(history.stretch().times_ns, [0, 1000, 2000])
