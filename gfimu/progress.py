"""Progress bars for long loops and long commands (tqdm on stderr, silent when disabled).

One style for every command: a tqdm bar on standard error that disappears when it
ends (``leave=False``); :func:`progress` wraps a loop, :func:`steps` follows the
named steps of a command (read, fit, write ...). The command line turns both off with
``--quiet`` (or ``--no-progress``, bars only).
"""

from __future__ import annotations

from typing import Iterable, Sequence, TypeVar

T = TypeVar("T")


def progress(iterable: Iterable[T], *, total: int | None = None, desc: str = "", enable: bool = False) -> Iterable[T]:
    if not enable:
        return iterable
    from tqdm import tqdm

    return tqdm(iterable, total=total, desc=desc, mininterval=0.5, leave=False)


class Steps:
    """A bar over the named steps of one command; ``step(name)`` starts the next one, ``close()`` ends it."""

    def __init__(self, desc: str, names: Sequence[str], enable: bool = False):
        self._bar = None
        self._started = False
        if enable and names:
            from tqdm import tqdm

            self._bar = tqdm(total=len(names), desc=desc, unit="step", leave=False, mininterval=0,
                             bar_format="{desc}: {n_fmt}/{total_fmt}{postfix} [{elapsed}]")

    def step(self, name: str) -> None:
        if self._bar is None:
            return
        if self._started:
            self._bar.update(1)
        self._started = True
        self._bar.set_postfix_str(name)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()
            self._bar = None

    def __enter__(self) -> "Steps":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def steps(desc: str, names: Sequence[str], enable: bool = False) -> Steps:
    """A :class:`Steps` bar (nothing when not ``enable``)."""
    return Steps(desc, names, enable)
