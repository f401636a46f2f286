"""Motion tables: truth, reference and estimates, all in the body frame B.

One class serves the three roles of the log format (truth.csv,
reference.csv, estimate CSVs). Quantities a source cannot give are ``None``,
never zeros.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

# field name -> (CSV column prefix, CSV unit, number of components, component suffixes)
QUANTITIES: dict[str, tuple[str, str, tuple[str, ...]]] = {
    "omega_b_radps": ("w", "rad s^-1", ("x", "y", "z")),
    "omega_dot_b_radps2": ("dw", "rad s^-2", ("x", "y", "z")),
    "accel_b_mps2": ("a", "m s^-2", ("x", "y", "z")),
    "specific_force_b_mps2": ("f", "m s^-2", ("x", "y", "z")),
    "quaternion_wb": ("q", "", ("w", "x", "y", "z")),
}


@dataclass(frozen=True)
class Motion:
    """Time series of rigid-body motion at the body origin.

    ``sigma`` maps a quantity's field name to its one-sigma uncertainty array
    of the same shape (``sigma_`` columns in CSV).
    """

    timestamps_ns: np.ndarray
    omega_b_radps: np.ndarray | None = None
    omega_dot_b_radps2: np.ndarray | None = None
    accel_b_mps2: np.ndarray | None = None
    specific_force_b_mps2: np.ndarray | None = None
    quaternion_wb: np.ndarray | None = None
    sigma: dict[str, np.ndarray] = field(default_factory=dict)

    def __post_init__(self) -> None:
        t = np.asarray(self.timestamps_ns, dtype=np.int64).reshape(-1)
        object.__setattr__(self, "timestamps_ns", t)
        for name, (_, _, comps) in QUANTITIES.items():
            v = getattr(self, name)
            if v is None:
                continue
            v = np.asarray(v, dtype=float)
            if v.shape != (t.size, len(comps)):
                raise ValueError(f"Motion.{name} has shape {v.shape}, expected {(t.size, len(comps))}")
            object.__setattr__(self, name, v)
        for name, v in self.sigma.items():
            if name not in QUANTITIES:
                raise ValueError(f"Motion.sigma has unknown quantity {name!r}")
            if np.asarray(v).shape != (t.size, len(QUANTITIES[name][2])):
                raise ValueError(f"Motion.sigma[{name!r}] has shape {np.asarray(v).shape}")

    def __len__(self) -> int:
        return int(self.timestamps_ns.size)

    @property
    def times_s(self) -> np.ndarray:
        """Seconds since the first sample."""
        return (self.timestamps_ns - self.timestamps_ns[0]) * 1e-9 if len(self) else np.zeros(0)

    def available(self) -> list[str]:
        """Field names of the quantities present."""
        return [n for n in QUANTITIES if getattr(self, n) is not None]

    def select(self, index) -> "Motion":
        """Rows picked by a slice, boolean mask or index array."""
        kw = {n: (None if getattr(self, n) is None else getattr(self, n)[index]) for n in QUANTITIES}
        return Motion(self.timestamps_ns[index], sigma={k: v[index] for k, v in self.sigma.items()}, **kw)

    def replace(self, **changes) -> "Motion":
        return replace(self, **changes)
