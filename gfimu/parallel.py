"""Work spread over forked worker processes: the policy of when that is safe, and one ordered map.

A forked worker inherits the parent's memory (the log, the table being written) instead of
receiving a pickled copy, so only small task descriptions go out and results come back. Forking is
used only where it can be: the ``fork`` start method exists and this process is not daemonic (a Dask
worker, a pool's worker: they may not start processes). Elsewhere, and where the workers cannot start
(no semaphores without ``/dev/shm``, no processes left), everything runs in this process, with the
same numbers.

In a worker, SIGINT is left to the parent (which stops the workers and reports one interruption)
and SIGTERM ends the worker; an error or an interruption in the parent terminates the workers at once
(the parent's SIGINT and SIGTERM wait while it forks or stops them, so none is left behind).
"""

from __future__ import annotations

import multiprocessing
import os
import signal
from collections.abc import Callable, Iterable, Iterator

from .errors import InputError


def check_workers(workers) -> None:
    """An :class:`~gfimu.errors.InputError` unless ``workers`` is 0 (one per CPU) or a positive number of processes."""
    if not (isinstance(workers, int) and not isinstance(workers, bool) and workers >= 0):
        raise InputError(f"workers must be 0 (one per CPU) or a positive number of processes, got {workers!r}")


def cpu_count() -> int:
    """CPUs this process may run on."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)


def can_fork() -> bool:
    """Whether worker processes may be forked from this one now (module docstring)."""
    return "fork" in multiprocessing.get_all_start_methods() and not multiprocessing.current_process().daemon


def fork_workers(workers: int, tasks: int) -> int:
    """Processes to run ``tasks`` independent tasks with: ``workers`` (0: one per CPU), at most one per
    task; 1 (this process) where forking is not safe (:func:`can_fork`)."""
    check_workers(workers)
    if workers == 0:
        workers = cpu_count()
    if workers <= 1 or tasks <= 1 or not can_fork():
        return 1
    return max(1, min(workers, tasks))


_STOP_SIGNALS = {signal.SIGINT, signal.SIGTERM}


def _start_worker(func: Callable, parent: int | None = None) -> None:
    """In a forked worker: SIGINT is the parent's to handle, SIGTERM ends the worker; ``func`` is the job
    (handed over by the fork, not pickled). The worker starts with both signals blocked (the parent's
    mask while it forks) and takes them from here on. It ends with its parent (``parent``, the pid), however
    the parent ends (SIGKILL included): quietly, never writing a result into a closed pipe."""
    global _JOB
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    _JOB = func
    die_with_parent(parent)
    one_blas_thread()
    signal.pthread_sigmask(signal.SIG_UNBLOCK, _STOP_SIGNALS)


def one_blas_thread() -> None:
    """In a forked worker: its BLAS and OpenMP pools cut to one thread. A worker is one of several processes
    that share the CPUs already; pools of the parent's size in each (numpy's OpenBLAS starts one thread per
    CPU unless ``OPENBLAS_NUM_THREADS`` says otherwise: the command line sets 1, a Python session need not)
    spin against each other and against the parent: on 2 CPUs a stream's later model choices took several times
    the CPU so. One thread also gives the worker the numbers the command line's processes give."""
    from threadpoolctl import threadpool_limits

    threadpool_limits(1)


def die_with_parent(parent: int | None) -> None:
    """SIGTERM (its default action: the end, without a word) to this process when its parent dies (Linux's
    ``PR_SET_PDEATHSIG``); a parent already gone ends it at once. Elsewhere nothing."""
    if parent is None:
        return
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, int(signal.SIGTERM), 0, 0, 0)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        return
    if os.getppid() != parent:  # the parent died before the request was made
        os._exit(0)


_JOB: Callable | None = None
"""In a worker: the function it runs."""


def _run_job(task):
    return _JOB(task)


def _run_indexed(item):
    k, task = item
    return k, _JOB(task)


def _here(func: Callable, tasks: list, ordered: bool) -> Iterator:
    """:func:`forked_map` in this process, one task at a time."""
    for k, task in enumerate(tasks):
        yield func(task) if ordered else (k, func(task))


def forked_map(func: Callable, tasks: Iterable, workers: int, ordered: bool = True, min_tasks: int = 2) -> Iterator:
    """``func(task)`` for every task, in up to ``workers`` forked processes (:func:`fork_workers` decides how
    many; 1: in this process, one task at a time). ``func`` and whatever it reads are inherited, not
    pickled; the tasks and the results are pickled. Results come in task order (``ordered``), else as
    they are done, as ``(index, result)`` pairs (in this process too). Closing the iterator early, an
    error or an interruption stops the workers at once. Fewer than ``min_tasks`` tasks run in this
    process: starting and stopping workers costs about 20 ms, and copying their results back more,
    which short work does not repay."""
    return _forked(func, tasks, workers, ordered, min_tasks, False)


def started_map(func: Callable, tasks: Iterable, workers: int, min_tasks: int = 2) -> Iterator:
    """:func:`forked_map` (results in task order) with its workers forked and every task handed to them
    before this returns, so that they work while this process does something else; the results are read
    from the iterator later. In this process (one worker, fewer than ``min_tasks`` tasks, no forking)
    the tasks run when their results are read, as with :func:`forked_map`. Closing the iterator (or
    dropping it) stops the workers, their results unread."""
    results = _forked(func, tasks, workers, True, min_tasks, True)
    next(results)  # up to the workers' start: the tasks are theirs now
    return results


def _forked(func: Callable, tasks: Iterable, workers: int, ordered: bool, min_tasks: int, announce: bool) -> Iterator:
    """:func:`forked_map`; with ``announce``, first a None once the tasks are handed out (:func:`started_map`)."""
    tasks = list(tasks)
    n = fork_workers(workers, len(tasks)) if len(tasks) >= min_tasks else 1
    if n <= 1:
        if announce:
            yield None
        yield from _here(func, tasks, ordered)
        return
    # SIGINT and SIGTERM wait while the workers are forked and while they are stopped: a signal in the
    # middle of either would leave a worker behind, waiting for tasks for ever (and holding the
    # command's standard output open)
    mask = signal.pthread_sigmask(signal.SIG_BLOCK, _STOP_SIGNALS)
    try:
        pool = multiprocessing.get_context("fork").Pool(n, initializer=_start_worker, initargs=(func, os.getpid()))
    except (OSError, ImportError):  # no semaphores (a system without /dev/shm), no processes left: here
        pool = None
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, mask)
    if pool is None:
        if announce:
            yield None
        yield from _here(func, tasks, ordered)
        return
    try:
        results = (pool.imap(_run_job, tasks) if ordered
                   else pool.imap_unordered(_run_indexed, list(enumerate(tasks))))
        if announce:
            yield None
        yield from results
        pool.close()
        pool.join()
    finally:
        signal.pthread_sigmask(signal.SIG_BLOCK, _STOP_SIGNALS)
        try:
            pool.terminate()
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, mask)
