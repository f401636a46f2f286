"""The stream's compiled kernels loaded from numba's on-disk cache in a background thread.

A fixed-lag run first imports numba (about 0.25 s) and loads each kernel's machine code from the cache
the first time it is called (about 0.45 s for the stream's kernels and the per-sample ML's, most of it
LLVM's start, which runs outside Python's lock). :func:`start` does both in a daemon thread while the
command reads and screens its log, so the stream finds them ready. Only overloads the cache holds for
this source and this machine are loaded (their index key is checked first): nothing is compiled here
that the stream would not compile anyway; a kernel the stream calls while it is being loaded waits for
numba's own lock, as two threads calling it would. Any failure leaves the kernels to load where they
are first called, as without this module.
"""

from __future__ import annotations

import threading

_thread: threading.Thread | None = None


def start() -> None:
    """Begin loading the kernels in the background (once per process)."""
    global _thread
    if _thread is None:
        _thread = threading.Thread(target=_load, name="gfimu-kernel-preload", daemon=True)
        _thread.start()


def wait() -> None:
    """Until the loading started by :func:`start` has ended (at once when none was started): before a fork,
    so that no lock of numba's is held in the child by a thread that is not there."""
    if _thread is not None:
        _thread.join()


def _load() -> None:
    try:
        from ...estimators import ml_kernels
        from . import kernels

        for module in (kernels, ml_kernels):
            for dispatcher in list(vars(module).values()):
                _load_cached(dispatcher)
    except Exception:  # noqa: BLE001 - a preload is an optimisation: the kernels then load when first called
        return


def _load_cached(dispatcher) -> None:
    """The overloads of ``dispatcher`` (a numba function with ``cache=True``) that its cache holds for this
    source and machine, loaded (``compile`` finds them in the cache)."""
    cache = getattr(dispatcher, "_cache", None)
    index_file = getattr(cache, "_cache_file", None)
    if index_file is None:
        return
    codegen = dispatcher.targetctx.codegen()
    for key in index_file._load_index():
        signature = key[0]
        if key == cache._index_key(signature, codegen):
            dispatcher.compile(signature)
