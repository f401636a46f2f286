"""Motion tables: truth, reference and estimates, all in the body frame B.

One class serves the three roles of the log format (truth.csv,
reference.csv, estimate CSVs). Quantities a source cannot give are ``None``,
never zeros.

pandas bridge (``pip install 'gfimu[pandas]'``): :meth:`Motion.to_dataframe` gives the columns of
the CSV format without their units (``w_x`` ..., ``dw_x`` ..., ``a_x`` ..., ``f_x`` ..., ``q_w``
..., ``sigma_w_x`` ...), the units in ``df.attrs["units"]``, indexed by the integer timestamps in
nanoseconds (index name ``timestamp_ns``); :meth:`Motion.from_dataframe` reads it back exactly.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from .errors import InputError, MissingExtraError

# field name -> (CSV column prefix, CSV unit, number of components, component suffixes)
QUANTITIES: dict[str, tuple[str, str, tuple[str, ...]]] = {
    "omega_b_radps": ("w", "rad s^-1", ("x", "y", "z")),
    "omega_dot_b_radps2": ("dw", "rad s^-2", ("x", "y", "z")),
    "accel_b_mps2": ("a", "m s^-2", ("x", "y", "z")),
    "specific_force_b_mps2": ("f", "m s^-2", ("x", "y", "z")),
    "quaternion_wb": ("q", "", ("w", "x", "y", "z")),
}


TIME_INDEX = "timestamp_ns"
"""Name of the index of the pandas frames: integer nanoseconds, as the CSV files' first column."""


def index_ns(df, source: str) -> np.ndarray:
    """The int64 nanoseconds of a frame's index: integer nanoseconds (``timestamp_ns``) as they are, or a
    ``DatetimeIndex`` as nanoseconds since the epoch (a time zone converted to UTC; naive times taken as
    UTC); ``ValueError`` names any other index and a missing time (NaT)."""
    pd = _require_pandas("from_dataframe")
    index = df.index
    if isinstance(index, pd.DatetimeIndex):
        if index.hasnans:
            k = int(np.flatnonzero(np.asarray(index.isna()))[0])
            raise InputError(f"{source}: the DatetimeIndex holds a missing time (NaT) at row {k}")
        if index.tz is not None:
            index = index.tz_convert("UTC").tz_localize(None)
        return np.asarray(index.to_numpy(dtype="datetime64[ns]")).view(np.int64).copy()
    if not np.issubdtype(index.dtype, np.integer):
        raise InputError(f"{source}: the index must hold integer timestamps in nanoseconds ({TIME_INDEX}) or be a "
                         f"pandas.DatetimeIndex, got dtype {index.dtype}")
    return np.asarray(index, dtype=np.int64)


def _require_pandas(what: str):
    try:
        import pandas
    except ImportError:
        raise MissingExtraError(what, "pandas", "pandas") from None
    return pandas


def motion_column_names() -> list[tuple[str, str, str, int, bool]]:
    """(column, unit, quantity, component, is sigma) of every column a Motion can have, in CSV order."""
    out = []
    for is_sigma in (False, True):
        for name, (prefix, unit, comps) in QUANTITIES.items():
            out += [(f"{'sigma_' if is_sigma else ''}{prefix}_{c}", unit, name, j, is_sigma)
                    for j, c in enumerate(comps)]
    return out


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

    def to_dataframe(self):
        """A ``pandas.DataFrame``: index ``timestamp_ns`` (int64 nanoseconds), one float column per component
        named as in the CSV format without its unit (``w_x``, ``q_w``, ``sigma_w_x`` ...), only for the
        quantities present; the units in ``df.attrs["units"]``."""
        pd = _require_pandas("Motion.to_dataframe")
        data, units = {}, {}
        for column, unit, name, j, is_sigma in motion_column_names():
            values = self.sigma.get(name) if is_sigma else getattr(self, name)
            if values is not None:
                data[column] = np.asarray(values, dtype=float)[:, j]
                units[column] = unit
        df = pd.DataFrame(data, index=pd.Index(self.timestamps_ns.copy(), name=TIME_INDEX))
        df.attrs["units"] = units
        return df

    @classmethod
    def from_dataframe(cls, df, source: str = "<dataframe>") -> "Motion":
        """A Motion from a frame laid out as :meth:`to_dataframe` writes it (integer nanosecond index); a
        quantity needs all its components or none (an :class:`~gfimu.errors.InputError` names the missing one); other columns are
        ignored."""
        pd = _require_pandas("Motion.from_dataframe")
        if not isinstance(df, pd.DataFrame):
            raise TypeError(f"{source}: expected a pandas.DataFrame, got {type(df).__name__}")
        t_ns = index_ns(df, source)
        kw: dict = {}
        sigma: dict = {}
        for is_sigma in (False, True):
            for name, (prefix, _, comps) in QUANTITIES.items():
                cols = [f"{'sigma_' if is_sigma else ''}{prefix}_{c}" for c in comps]
                present = [c in df.columns for c in cols]
                if any(present) and not all(present):
                    missing = cols[present.index(False)]
                    raise InputError(f"{source}: column {missing!r} is missing (a quantity needs all of "
                                     f"{', '.join(cols)})")
                if all(present):
                    (sigma if is_sigma else kw)[name] = df[cols].to_numpy(dtype=float)
        return cls(t_ns, sigma=sigma, **kw)
