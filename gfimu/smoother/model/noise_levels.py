"""The noise levels of one smoothing problem, as a frozen value.

Each factor group computes its own noise from the options and the log
(:meth:`gfimu.smoother.model.groups.FactorGroup.noise`: the accelerometers' std, the motion model's step
stds, the priors' stds, ...); the problem gathers them into one :class:`NoiseLevels` when it is
built. Nothing changes it afterwards: the re-weightings (motion-dependent accelerometer noise,
robust losses, the local motion density, the tuner's accelerometer scale) make a new value with
:meth:`NoiseLevels.replace`, and a new problem around it
(:meth:`gfimu.smoother.model.problem.SmootherProblem.with_noise`). Its arrays are read-only.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from types import MappingProxyType

import numpy as np


def _frozen(value):
    if isinstance(value, np.ndarray):
        value = value.view()
        value.flags.writeable = False
    return value


class NoiseLevels(Mapping):
    """Name -> noise value (a float, a read-only array, or None), read as attributes too
    (``levels.trapezoid_sigma``). Immutable: :meth:`replace` returns a new value."""

    __slots__ = ("_values",)

    def __init__(self, values: Mapping | None = None) -> None:
        object.__setattr__(self, "_values", MappingProxyType({k: _frozen(v) for k, v in dict(values or {}).items()}))

    def __getattr__(self, name: str):
        if name.startswith("__"):
            raise AttributeError(name)
        try:
            return self._values[name]
        except KeyError:
            raise AttributeError(f"no noise level {name!r} (the model's groups give: {', '.join(sorted(self._values))})") from None

    def __setattr__(self, name: str, value) -> None:
        raise AttributeError(f"noise levels are frozen: use replace({name}=...)")

    def __getitem__(self, name: str):
        return self._values[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self._values)

    def __len__(self) -> int:
        return len(self._values)

    def replace(self, **changes) -> NoiseLevels:
        """A new value with ``changes`` (new names allowed: a group's own levels)."""
        return NoiseLevels({**self._values, **changes})

    def __repr__(self) -> str:
        return f"NoiseLevels({', '.join(sorted(self._values))})"


class ReadsNoiseLevels:
    """Mixin: the object's noise levels (its ``noise`` attribute, a mapping) read as attributes,
    ``problem.trapezoid_sigma``, by the factor groups' terms (a problem, a view of a few samples of a stream)."""

    def __getattr__(self, name: str):
        if name.startswith("__") or name in ("noise", "_built"):
            raise AttributeError(name)
        try:
            return self.__dict__["noise"][name]
        except KeyError:
            raise AttributeError(f"{type(self).__name__} has no attribute or noise level {name!r}") from None

