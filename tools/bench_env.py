"""The environment the timing scripts in this folder run the command line in.

An installed package imports its modules from Python's bytecode cache; a process started with
``PYTHONDONTWRITEBYTECODE`` set (some shells and CI images set it) compiles every module of the
package again at each start, about 0.1 s for ``gfimu estimate``. The timed processes therefore run
with the cache on, filled once beforehand (``compileall``), so that they time what a user's command
does, not the compiler. They also run with ``PYTHONSAFEPATH``: ``python -m gfimu`` started in a
checkout would otherwise import that checkout's package before the one on PYTHONPATH, and a
comparison with another checkout (``--baseline``) would time the same code twice.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path


def command_env(root: Path, threads: int | None = 1) -> dict:
    """Environment for timed ``python -m gfimu`` processes of the checkout at ``root`` (its package on
    PYTHONPATH, bytecode cache on and filled, ``threads`` BLAS threads or the default when None)."""
    env = {**os.environ, "PYTHONPATH": str(root) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    env["PYTHONSAFEPATH"] = "1"  # `python -m`/`-c` would put the working folder first, before PYTHONPATH
    if threads is not None:
        env["OMP_NUM_THREADS"] = str(threads)
    subprocess.run([sys.executable, "-m", "compileall", "-q", str(Path(root) / "gfimu")], env=env, check=True,
                   stdout=subprocess.DEVNULL)
    return env
