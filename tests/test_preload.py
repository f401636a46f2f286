"""The fixed-lag smoother's kernels loaded from numba's cache in the background (gfimu.smoother.preload):
only what the cache holds for the source as it is, nothing compiled."""

import subprocess
import sys
import textwrap

import pytest

pytest.importorskip("numba")

KERNEL = """
from numba import njit


@njit(cache=True)
def plus(x):
    return x + {k}
"""

LOAD = """
import sys
sys.path.insert(0, {folder!r})
import kern
from gfimu.smoother.preload import _load_cached
_load_cached(kern.plus)
print(len(kern.plus.overloads), sum(kern.plus.stats.cache_hits.values()), sum(kern.plus.stats.cache_misses.values()))
"""


def _run(code: str) -> str:
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()


def test_a_cached_kernel_is_loaded_and_a_changed_one_is_not_compiled(tmp_path):
    folder = str(tmp_path)
    (tmp_path / "kern.py").write_text(KERNEL.format(k=1))
    assert _run(f"import sys; sys.path.insert(0, {folder!r}); import kern; print(kern.plus(1.0))") == ["2.0"]
    # a fresh process: the overload the first one cached is loaded from the cache
    assert _run(textwrap.dedent(LOAD.format(folder=folder))) == ["1", "1", "0"]
    # the source changed: its cache no longer matches, and nothing is compiled ahead of a call
    (tmp_path / "kern.py").write_text(KERNEL.format(k=2))
    assert _run(textwrap.dedent(LOAD.format(folder=folder))) == ["0", "0", "0"]


def test_the_preload_starts_once_and_the_stream_runs_beside_it():
    import numpy as np

    from gfimu.simulate import simulate
    from gfimu.smoother import preload
    from gfimu.smoother.stream.fixed_lag import FixedLagEstimator

    est = FixedLagEstimator()
    est.preload()
    first = preload._threads["stream"]
    est.preload()
    assert preload._threads["stream"] is first  # one thread per process
    log = simulate("random3d", seed=2, duration_s=2.0, rate_hz=200.0)
    w = est.estimate(log).motion.omega_b_radps  # while the kernels may still be loading
    first.join(timeout=120)
    assert not first.is_alive() and np.all(np.isfinite(w))
    assert np.sqrt(np.mean(np.sum((w - log.truth.omega_b_radps) ** 2, axis=1))) < 0.2
