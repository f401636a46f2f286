"""The states the fixed-lag smoother gives out: one sample's (:class:`StateEstimate`), or a block's at once
(:class:`StateRows`, :mod:`gfimu.smoother.stream.block`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class StateEstimate:
    """ω, ω̇ and f of one sample (body frame), with optional one-sigma values."""

    timestamp_ns: int
    omega_b_radps: np.ndarray
    omega_dot_b_radps2: np.ndarray
    specific_force_b_mps2: np.ndarray
    sigma_omega_b_radps: np.ndarray | None = None
    sigma_omega_dot_b_radps2: np.ndarray | None = None
    sigma_specific_force_b_mps2: np.ndarray | None = None


@dataclass(frozen=True)
class StateRows:
    """States given out at once by a block of samples (:meth:`FixedLagSmoother.push_block
    <gfimu.smoother.stream.fixed_lag.FixedLagSmoother.push_block>`): ``timestamp_ns`` (n,) and ``values`` (n, 9):
    ω, ω̇, f (no σ)."""

    timestamp_ns: np.ndarray
    values: np.ndarray

    def __len__(self) -> int:
        return len(self.timestamp_ns)


_STATE_FIELDS = tuple(StateEstimate.__dataclass_fields__)


def _state(*values) -> StateEstimate:
    """``StateEstimate(*values)``, made without the frozen dataclass's ``__init__``: that sets each field through
    ``object.__setattr__``, a call per field, and a stream makes one state per sample (the same object)."""
    state = object.__new__(StateEstimate)
    state.__dict__.update(zip(_STATE_FIELDS, values + (None,) * (len(_STATE_FIELDS) - len(values))))
    return state


def as_states(items) -> list:
    """``items`` (:class:`StateEstimate` objects and :class:`StateRows`) as StateEstimate objects, in order."""
    out: list = []
    for item in items:
        if isinstance(item, StateRows):
            out.extend(_state(int(t), v[0:3], v[3:6], v[6:9]) for t, v in zip(item.timestamp_ns.tolist(), item.values))
        else:
            out.append(item)
    return out
