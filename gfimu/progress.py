"""Progress bars for long loops (tqdm on stderr, silent when disabled)."""

from __future__ import annotations

from typing import Iterable, TypeVar

T = TypeVar("T")


def progress(iterable: Iterable[T], *, total: int | None = None, desc: str = "", enable: bool = False) -> Iterable[T]:
    if not enable:
        return iterable
    from tqdm import tqdm

    return tqdm(iterable, total=total, desc=desc, mininterval=0.5, leave=False)
