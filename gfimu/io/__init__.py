"""Input and output: log files, estimates, and the readers of recorded formats.

- :mod:`gfimu.io.errors`: :class:`LogFormatError` and the warnings of reading;
- :mod:`gfimu.io.units`: units of columns and timestamps;
- :mod:`gfimu.io.atomic`: the one atomic writer (temporary file, fsync, rename);
- :mod:`gfimu.io.tables`: ``imu.csv`` and motion tables (truth, reference, estimates);
- :mod:`gfimu.io.array_toml`: ``array.toml`` and the TOML writer;
- :mod:`gfimu.io.log_dir`: whole log folders;
- :mod:`gfimu.io.outputs`: the output policy of every command (never over an input or a
  non-regular file; ``-`` for standard output; log folders and ``--force``);
- :mod:`gfimu.io.plausibility`: warnings for likely unit, rate and size mistakes;
- :mod:`gfimu.io.time_grid`: the nominal period of a stream, its gaps, interpolation within them;
- :mod:`gfimu.io.readers`: one module per recorded format, found by
  :func:`gfimu.io.readers.reader_names`.

Use ``from gfimu import io as gio`` or ``from gfimu.io import read_log``.
"""

from .array_toml import (
    ARRAY_FORMAT,
    format_array_toml,
    format_toml,
    load_array_toml,
    parse_array_toml,
    read_array_toml,
    write_array_toml,
    write_toml,
)
from .atomic import atomic_path, atomic_write, atomic_write_bytes, atomic_write_text
from .errors import LogFormatError, LogFormatWarning, LogGapWarning, LogPlausibilityWarning, OutputError
from .log_dir import LOG_FILES, read_log, write_log
from .outputs import STDOUT, check_output, prepare_log_folder, write_output
from .tables import (
    GYRO_COLUMNS,
    TILT_COLUMNS,
    TIMESTAMP_HEADER,
    VALID_COLUMN,
    imu_columns,
    motion_columns,
    motion_csv_chunks,
    read_imu_csv,
    read_motion_csv,
    read_motion_table,
    write_imu_csv,
    write_motion_csv,
)
from .units import STANDARD_GRAVITY_MPS2, TIME_UNITS_NS, UNITS, canonical_unit, unit_factor

__all__ = [
    "ARRAY_FORMAT", "GYRO_COLUMNS", "LOG_FILES", "STANDARD_GRAVITY_MPS2", "STDOUT", "TILT_COLUMNS",
    "TIMESTAMP_HEADER", "TIME_UNITS_NS", "UNITS", "VALID_COLUMN", "LogFormatError", "LogFormatWarning",
    "LogGapWarning", "LogPlausibilityWarning", "OutputError", "atomic_path", "atomic_write", "atomic_write_bytes",
    "atomic_write_text", "canonical_unit", "check_output", "format_array_toml", "format_toml", "imu_columns",
    "load_array_toml", "motion_columns", "motion_csv_chunks", "parse_array_toml", "prepare_log_folder",
    "read_array_toml", "read_imu_csv", "read_log", "read_motion_csv", "read_motion_table", "unit_factor",
    "write_array_toml", "write_imu_csv", "write_log", "write_motion_csv", "write_output", "write_toml",
]
