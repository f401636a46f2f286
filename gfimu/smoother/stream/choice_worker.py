"""A forked process that makes a stream's later model choices, beside the stream.

A later choice of the fixed-lag smoother's model (:meth:`FixedLagSmoother._choose
<gfimu.smoother.stream.fixed_lag.FixedLagSmoother._choose>`) runs the per-sample ML estimate and the model
check on the history, most of it Python. In a thread of the stream's process it holds the interpreter's
lock for most of its run, so the stream's own Python waits for it: on a 2-core machine the two run one after
the other, not side by side. A process of its own runs it on the other core.

The process is forked once, when the first later choice is asked for, and serves every later choice of the
smoother that forked it: what the choice reads of the smoother is fixed when the stream starts (its rules,
array and options), and what changes (the model in use, the history) is sent with each request. It ends
with the smoother (:meth:`ChoiceProcess.close`), and with its parent however the parent ends
(:func:`gfimu.parallel.die_with_parent`). Where no process may be forked (:func:`gfimu.parallel.can_fork`)
there is none and the choices run in a thread, with the same numbers.

:class:`ChoiceProcess` serves any function one request at a time, and two other pieces of work use one of
their own the same way: the held start's re-solves (half of each check's starts,
:meth:`FixedLagSmoother._solved_from <gfimu.smoother.stream.fixed_lag.FixedLagSmoother._solved_from>`) and,
for a log, the guard's per-sample estimate made while the stream runs
(:meth:`FixedLagEstimator._per_sample_ahead <gfimu.smoother.stream.fixed_lag.FixedLagEstimator._per_sample_ahead>`).
"""

from __future__ import annotations

import os
import signal
import time
from collections.abc import Callable


def _serve(func: Callable, conn, parent: int, idle: Callable | None = None) -> None:
    """The process's loop: each request ``func(request)``, answered ``(True, result, warnings)`` or ``(False,
    error, warnings)``, until None or the end of the pipe. The warnings it raised go back with the answer
    (each ``(message, category)``), to be raised in the parent where the model is used: the process writes
    nothing itself (another thread of the parent may have held the output's lock when it was forked).
    ``idle()`` runs after each answer unless the next request is already there (work done ahead of a request
    it may be asked for: whatever it raises is its own to keep)."""
    import warnings

    from ...parallel import die_with_parent, one_blas_thread

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # an interruption is the parent's to handle
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    die_with_parent(parent)
    one_blas_thread()
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT, signal.SIGTERM})  # (blocked while forked)
    while True:
        try:
            request = conn.recv()
        except (EOFError, OSError):
            break
        if request is None:
            break
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                answer = (True, func(request))
            except BaseException as exc:  # noqa: BLE001 - raised again in the parent, where the model is used
                answer = (False, exc)
        raised = [(str(w.message), w.category) for w in caught]
        try:
            conn.send((*answer, raised))
        except Exception as exc:  # noqa: BLE001 - an answer that does not pickle
            conn.send((False, RuntimeError(f"the model choice's answer could not be sent: {exc!r}"), raised))
        if idle is not None and not conn.poll():
            try:
                idle()
            except Exception:  # noqa: BLE001 - work ahead that failed is not used (the request computes it)
                pass
    conn.close()
    os._exit(0)


class ChoiceProcess:
    """One forked process serving ``func(request)`` one request at a time (:meth:`submit`, then
    :meth:`result`), running ``idle()`` between them (:func:`_serve`); :meth:`start` returns None where no
    process may be forked."""

    def __init__(self, func: Callable, idle: Callable | None = None) -> None:
        import multiprocessing

        ctx = multiprocessing.get_context("fork")
        self._conn, child = ctx.Pipe()
        mask = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGTERM})
        try:  # (no stop signal between the fork and the child's own handlers)
            self._process = ctx.Process(target=_serve, args=(func, child, os.getpid(), idle), name="gfimu-model-choice",
                                        daemon=True)
            self._process.start()
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, mask)
        child.close()
        self.busy = False

    @classmethod
    def start(cls, func: Callable, idle: Callable | None = None) -> ChoiceProcess | None:
        """A process serving ``func`` (``idle`` between requests), or None where none may be forked (or none
        starts)."""
        from ...parallel import can_fork
        from .. import preload

        if not can_fork():
            return None
        preload.wait()
        try:
            return cls(func, idle)
        except (OSError, ImportError):  # no processes left, no semaphores
            return None

    def submit(self, request) -> None:
        if self.busy:  # an answer left unread (its choice was dropped): read first, not used
            try:
                self.result()
            except Exception:  # noqa: BLE001 - nothing uses it
                pass
        self._conn.send(request)
        self.busy = True

    @property
    def done(self) -> bool:
        """Whether the answer to the last request is there."""
        return self._conn.poll()

    def result(self):
        """The answer to the last request (waiting for it), or what computing it raised; the warnings it
        raised are raised here first."""
        import warnings

        try:
            ok, value, raised = self._conn.recv()
        except (EOFError, OSError) as exc:
            raise RuntimeError(f"the model choice's process ended without an answer ({exc!r})") from None
        finally:
            self.busy = False
        for message, category in raised:
            warnings.warn(message, category, stacklevel=2)
        if not ok:
            raise value
        return value

    def close(self) -> None:
        """End the process (its answer, if any, unread; work it does ahead of a request cut short)."""
        try:
            self._conn.send(None)
        except (OSError, ValueError):
            pass
        self._conn.close()
        self._process.join(timeout=0.0 if self.busy else 0.05)
        if self._process.is_alive():  # (busy with work ahead: nothing of it is wanted now)
            self._process.terminate()
        self._process.join(timeout=1.0)
        if self._process.is_alive():
            self._process.terminate()
            self._process.join(timeout=1.0)


class ForkedChoice:
    """:class:`~gfimu.smoother.stream.fixed_lag.PendingChoice` made in a :class:`ChoiceProcess`: the same
    ``swap_at``, ``outgrown``, ``waited_s``, :attr:`done` and :meth:`result`. ``finish(answer)`` turns the
    process's answer into the chosen model (and keeps what the choice computed for the next)."""

    def __init__(self, process: ChoiceProcess, request, finish: Callable, swap_at: int, outgrown: bool):
        self.swap_at = int(swap_at)
        self.outgrown = bool(outgrown)
        self.waited_s = 0.0
        self._process = process
        self._finish = finish
        process.submit(request)

    @property
    def done(self) -> bool:
        return self._process.done

    def result(self):
        t0 = time.perf_counter()
        waited = not self._process.done
        answer = self._process.result()
        if waited:
            self.waited_s = time.perf_counter() - t0
        return self._finish(answer)
