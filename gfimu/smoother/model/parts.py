"""One attribute of a class kept in one of its parts: the classes of the smoothers hold their values in a few
small named parts (a dataclass each) and keep the names their readers use as properties made here."""

from __future__ import annotations

from operator import attrgetter


def delegated(part: str, name: str, doc: str = "", settable: bool = False) -> property:
    """A property reading ``self.<part>.<name>`` (and writing it when ``settable``); the reading is
    :func:`operator.attrgetter`'s, with no Python frame (the stream reads some of them at every sample)."""
    get = attrgetter(f"{part}.{name}")

    def set_(self, value) -> None:
        setattr(getattr(self, part), name, value)

    return property(get, set_ if settable else None, doc=doc or None)
