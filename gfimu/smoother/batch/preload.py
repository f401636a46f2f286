"""The batch smoother's compiled kernels (:mod:`gfimu.smoother.model.kernels`) loaded in a background
thread while the command reads and screens its log.

Loading them costs numba's import and LLVM's start (about half a second, most of it outside Python's lock)
before the first call; paid in this thread while the log is read, it is not paid again by the solve
windows' worker processes, which are forked after :func:`wait` and inherit the machine code. Nothing may
be forked while the thread runs (a child would inherit the import locks it holds): :func:`wait` comes
first (:func:`gfimu.smoother.batch.engine.smooth`, before the model check starts its workers). Any failure
leaves the kernels to load where they are first called, as without this module.
"""

from __future__ import annotations

import threading

_thread: threading.Thread | None = None


def start() -> None:
    """Begin loading the kernels in the background (once per process)."""
    global _thread
    if _thread is None:
        _thread = threading.Thread(target=_load, name="gfimu-batch-kernel-preload", daemon=True)
        _thread.start()


def wait() -> None:
    """Until the loading begun by :func:`start` is over (at once where none was begun)."""
    if _thread is not None:
        _thread.join()


def _load() -> None:
    try:
        from ..model import kernels

        kernels.warm()
    except Exception:  # noqa: BLE001 - a preload is an optimisation: the kernels then load when first called
        return
