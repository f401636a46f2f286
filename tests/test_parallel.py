"""Forked workers (gfimu.parallel): the same results in the same order as in one process, errors passed
on, no fork where it may not happen; the CSV reader and writer give the same arrays, text and errors
with workers as without."""

import multiprocessing
import os
import time

import numpy as np
import pytest

from gfimu.array import cube_array
from gfimu.io import tables
from gfimu.io.errors import LogFormatError
from gfimu.log import Log
from gfimu.parallel import can_fork, fork_workers, forked_map, started_map

needs_fork = pytest.mark.skipif(not can_fork(), reason="worker processes cannot be forked here")
ARRAY = cube_array(0.05, 0.07)


def test_worker_count_policy():
    assert fork_workers(1, 10) == 1
    assert fork_workers(5, 1) == 1  # one task: no worker
    assert 1 <= fork_workers(0, 100) <= 100
    if can_fork():
        assert fork_workers(3, 2) == 2  # at most one per task
        assert fork_workers(2, 10) == 2
    for bad in (-1, 1.5, True, "2"):
        with pytest.raises(ValueError, match="workers must be 0"):
            fork_workers(bad, 3)


def _count_in_daemon(queue):
    queue.put(fork_workers(4, 4))


@needs_fork
def test_no_workers_inside_a_daemonic_process():
    queue = multiprocessing.get_context("fork").Queue()
    p = multiprocessing.get_context("fork").Process(target=_count_in_daemon, args=(queue,), daemon=True)
    p.start()
    p.join(30)
    assert queue.get(timeout=5) == 1


@needs_fork
def test_forked_map_inherits_the_function_and_keeps_the_order():
    data = np.arange(1000.0)
    square = lambda k: float(np.sum(data[k::7] ** 2))  # noqa: E731  (a lambda cannot be pickled: inherited)
    expected = [square(k) for k in range(7)]
    assert list(forked_map(square, range(7), 2)) == expected
    assert sorted(forked_map(square, range(7), 2, ordered=False)) == list(enumerate(expected))
    assert list(forked_map(square, range(7), 1)) == expected


@needs_fork
def test_short_work_stays_in_this_process():
    here = os.getpid()
    assert set(forked_map(lambda k: os.getpid(), range(3), 2, min_tasks=4)) == {here}
    assert here not in set(forked_map(lambda k: os.getpid(), range(4), 2, min_tasks=4))


@needs_fork
def test_started_map_works_before_it_is_read(tmp_path):
    """The workers take the tasks before started_map returns: the tasks are done while this process does
    something else (here: waits), and their results come in task order; closed unread, the workers stop."""
    def task(k):
        (tmp_path / f"done-{k}").write_text(str(os.getpid()))
        return k * k

    results = started_map(task, range(4), 2)
    for _ in range(200):  # at most 20 s, before anything is read
        if len(list(tmp_path.glob("done-*"))) == 4:
            break
        time.sleep(0.1)
    assert len(list(tmp_path.glob("done-*"))) == 4
    assert list(results) == [0, 1, 4, 9]
    assert str(os.getpid()) not in {f.read_text() for f in tmp_path.glob("done-*")}
    here = os.getpid()
    assert list(started_map(lambda k: (k, os.getpid()), range(3), 2, min_tasks=4)) == [(k, here) for k in range(3)]
    dropped = started_map(lambda k: k, range(5), 2)
    dropped.close()  # the workers stopped, their results unread


def test_work_stays_here_when_workers_cannot_start(monkeypatch):
    import multiprocessing.context

    def refuse(*args, **kwargs):
        raise OSError(38, "Function not implemented")  # as sem_open without /dev/shm

    monkeypatch.setattr(multiprocessing.context.ForkContext, "Pool", refuse, raising=False)
    monkeypatch.setattr("gfimu.parallel.can_fork", lambda: True)
    here = os.getpid()
    assert list(forked_map(lambda k: (k, os.getpid()), range(5), 2)) == [(k, here) for k in range(5)]


@needs_fork
def test_an_error_in_a_worker_reaches_the_caller():
    def task(k):
        if k == 3:
            raise ArithmeticError(f"task {k} failed")
        return k

    with pytest.raises(ArithmeticError, match="task 3 failed"):
        list(forked_map(task, range(6), 2))


def _imu_file(tmp_path, n=400, seed=1):
    rng = np.random.default_rng(seed)
    t = 1_700_000_000_000_000_000 + np.arange(n, dtype=np.int64) * 2_000_000  # beyond float precision
    y = rng.normal(0, 3, (n, ARRAY.n_axes)) * 10.0 ** rng.integers(-8, 8, (n, ARRAY.n_axes))
    path = tmp_path / "imu.csv"
    tables.write_imu_csv(Log(ARRAY, t, y), path)
    return path, t, y


@needs_fork
@pytest.mark.parametrize("block_bytes", [64, 1000, 1 << 20])
def test_reading_with_workers_gives_the_same_arrays(tmp_path, monkeypatch, block_bytes):
    monkeypatch.setattr(tables, "_BLOCK_BYTES", block_bytes)
    path, t, y = _imu_file(tmp_path)
    csv = tables._Csv(path)
    cols = list(range(1, 1 + ARRAY.n_axes))
    t1, v1 = csv.timestamps_and_values(cols, workers=1)
    t2, v2 = csv.timestamps_and_values(cols, workers=2)
    np.testing.assert_array_equal(t1, t)
    np.testing.assert_array_equal(v1, y)  # exact: shortest round-trip text
    np.testing.assert_array_equal(t2, t)
    np.testing.assert_array_equal(v2, y)


@needs_fork
@pytest.mark.parametrize("defect, message", [
    ("timestamp", "timestamp"),
    ("value", "value 'abc' is not a number"),
    ("step back", "not after the previous one"),
])
def test_errors_name_the_same_line_with_workers(tmp_path, monkeypatch, defect, message):
    monkeypatch.setattr(tables, "_BLOCK_BYTES", 500)
    path, t, y = _imu_file(tmp_path)
    lines = path.read_text().split("\n")
    row = 301  # a later block
    fields = lines[row + 1].split(",")
    if defect == "value":
        fields[3] = "abc"
    elif defect == "step back":
        fields[0] = str(t[row - 2])
    else:
        fields[0] = "x"
    lines[row + 1] = ",".join(fields)
    path.write_text("\n".join(lines))
    errors = []
    for workers in (1, 2):
        with pytest.raises(LogFormatError) as info:
            tables._Csv(path).timestamps_and_values(list(range(1, 1 + ARRAY.n_axes)), workers=workers)
        errors.append(str(info.value))
    assert errors[0] == errors[1]
    assert f"imu.csv:{row + 2}: " in errors[0] and message in errors[0]


@needs_fork
def test_writing_with_workers_gives_the_same_text(monkeypatch):
    monkeypatch.setattr(tables, "_ROWS_PER_BLOCK", 7)
    rng = np.random.default_rng(3)
    t = np.arange(100, dtype=np.int64) * 1000
    values = rng.normal(size=(100, 4))
    values[5, 2] = np.nan
    flags = rng.integers(0, 2, 100)
    for fmt in (float.__repr__, "%.5g".__mod__):
        one = "".join(tables._csv_chunks(["#timestamp [ns]", "a", "b", "c", "d"], t, values, fmt, flags, workers=1))
        two = "".join(tables._csv_chunks(["#timestamp [ns]", "a", "b", "c", "d"], t, values, fmt, flags, workers=2))
        assert one == two
        assert one.count("\n") == 101 and ",nan," in one


def _blas_threads(_task=None) -> int:
    from threadpoolctl import threadpool_info

    return max((pool["num_threads"] for pool in threadpool_info()), default=1)


@needs_fork
def test_a_worker_runs_one_blas_thread_whatever_the_parent_has():
    from threadpoolctl import threadpool_limits

    with threadpool_limits(2):  # a Python session without OPENBLAS_NUM_THREADS: a pool per CPU
        counts = list(forked_map(_blas_threads, range(4), 2, min_tasks=1))
    assert set(counts) == {1}


@needs_fork
def test_the_model_choice_process_runs_one_blas_thread():
    from threadpoolctl import threadpool_limits

    from gfimu.smoother.stream.choice_worker import ChoiceProcess

    with threadpool_limits(2):
        process = ChoiceProcess.start(_blas_threads)
        try:
            process.submit(0)
            assert process.result() == 1
        finally:
            process.close()
