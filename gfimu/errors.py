"""The errors gfimu raises on purpose, under one base, :class:`GfimuError`, in three kinds.

- :class:`InputError`: an option, argument or file the user gave is wrong (a malformed
  ``imu.csv`` line, an unknown method, an option out of range, an output onto an input).
  The message names the file and line, the key or the option.
- :class:`DataError`: the input is well formed, but the data cannot support what was asked
  (constant or non-finite readings, too few samples, streams that do not overlap, a problem
  the solver finds under-determined).
- :class:`ResourceError`: the machine refused (disk full, permission denied, interrupted
  I/O, a missing optional package: :class:`MissingExtraError`, which names the extra to
  install). Also an :class:`OSError`.

The classes of the modules (``LogFormatError``, ``ArrayModelError``, ``OptionError``,
``SourceError``, ...) subclass the kind they are. :class:`InputError` and
:class:`DataError` are also ``ValueError`` s, so that code written against the ``ValueError``
they replaced still catches them.

The command line (:mod:`gfimu.cli`) prints a :class:`GfimuError` as one line and exits with
its :attr:`~GfimuError.exit_status` (2 for the input and data kinds, 1 for a resource); any
other exception is a bug and is reported as an internal error (exit 1; ``--debug`` shows the
traceback). Checks of the code's own invariants stay plain ``ValueError`` / ``AssertionError``.
"""

from __future__ import annotations


class GfimuError(Exception):
    """An error gfimu raises on purpose; its message says what is wrong and names the thing."""

    kind = "error"
    exit_status = 2
    """The command line's exit status for this error."""


class InputError(GfimuError, ValueError):
    """An option, argument or file given by the user is wrong."""

    kind = "input"


class DataError(GfimuError, ValueError):
    """The data cannot support the request (constant readings, no overlap, too few samples, ...)."""

    kind = "data"


class ResourceError(GfimuError, OSError):
    """The system refused: no space, no permission, interrupted I/O, a package not installed."""

    kind = "resource"
    exit_status = 1


class MissingExtraError(ResourceError, RuntimeError):
    """An optional package is not installed; the message names the extra that installs it.

    ``MissingExtraError("gfimu plot", "matplotlib", "plot")`` reads ``gfimu plot needs matplotlib,
    which is not installed: pip install 'gfimu[plot]'``. The extras are those of ``pyproject.toml``:
    ``plot`` (matplotlib), ``kalibr`` (pyyaml), ``rosbag`` (rosbags), ``serial`` (pyserial),
    ``pandas`` and ``distributed`` (dask)."""

    def __init__(self, what: str, package: str | None = None, extra: str | None = None):
        self.package, self.extra = package, extra
        if package is None or extra is None:  # one message already written (as unpickling passes it back)
            super().__init__(what)
        else:
            super().__init__(f"{what} needs {package}, which is not installed: pip install 'gfimu[{extra}]'")
