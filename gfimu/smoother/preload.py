"""The smoothers' compiled kernels loaded in a background thread while a command reads and screens its log.

The first call of a numba kernel in a process imports numba (about 0.25 s) and loads its machine code (from
numba's on-disk cache; LLVM's start is most of it and runs outside Python's lock). :func:`start` does that
in a daemon thread, once per process, so the smoother finds its kernels ready:

- ``"stream"``: the fixed-lag smoother's window kernels (:mod:`gfimu.smoother.stream.kernels`, and its block of
  samples, :mod:`gfimu.smoother.stream.block`), its running σ
  scale's (:mod:`gfimu.smoother.solve.sigma_kernels`), the per-sample ML's (:mod:`gfimu.estimators.ml_kernels`),
  the stream screening's spike rule (:mod:`gfimu.screen_kernels`) and the batch solve's (:mod:`gfimu.smoother.model.kernels`: the
  held start and the tuning stretch are solved whole). Only the overloads the cache holds for this source and
  this machine are loaded (their index key is checked first): nothing is compiled that the stream would not
  compile anyway; a kernel called while it is being loaded waits for numba's own lock.
- ``"batch"``: the batch solve's kernels, each called once with the argument types of every call
  (:func:`gfimu.smoother.model.kernels.warm`: loaded from the cache, or compiled where it holds none). The
  solve windows' worker processes, forked after :func:`wait`, inherit the machine code.

Either then imports the guard (:mod:`gfimu.smoother.guard`), which runs after the smoother.

Nothing may be forked while the thread runs (a child would inherit the locks it holds, without the thread
that releases them): :func:`wait` comes first. Any failure leaves the kernels to load where they are first
called, as without this module.
"""

from __future__ import annotations

import threading

_threads: dict[str, threading.Thread] = {}
"""The loading of each kind begun in this process."""


def start(kind: str) -> None:
    """Begin loading the kernels of ``kind`` (``"stream"`` or ``"batch"``) in the background (once per kind
    and process: a second call does nothing)."""
    if kind not in _threads:
        _threads[kind] = threading.Thread(target=_LOADERS[kind], name=f"gfimu-{kind}-kernel-preload", daemon=True)
        _threads[kind].start()


def wait() -> None:
    """Until every loading begun by :func:`start` is over (at once where none was begun)."""
    for thread in list(_threads.values()):
        thread.join()


def _stream() -> None:
    try:
        from .. import screen_kernels
        from ..estimators import ml_kernels
        from .model import kernels as model_kernels
        from .solve import sigma_kernels
        from .stream import block, kernels

        for module in (screen_kernels, kernels, ml_kernels, model_kernels, sigma_kernels, block):  # (in the order used)
            for dispatcher in list(vars(module).values()):
                _load_cached(dispatcher)
        _guard()
    except Exception:  # noqa: BLE001 - a preload is an optimisation: the kernels then load when first called
        return


def _batch() -> None:
    try:
        from .model import kernels

        kernels.warm()
        _guard()
    except Exception:  # noqa: BLE001 - as above
        return


def _guard() -> None:
    """The guard's module imported (with the χ² quantile of :mod:`scipy.special` it reads: about 0.08 s), which
    both smoothers run once their estimate is made."""
    from . import guard  # noqa: F401


_LOADERS = {"stream": _stream, "batch": _batch}


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
