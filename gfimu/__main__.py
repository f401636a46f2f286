import os
import signal
import sys


def _early_signal(signum, frame):  # noqa: ARG001
    """A signal before gfimu.cli.main installs its own handler (while gfimu.cli is imported): the same
    line and status as later (130 / 143). Nothing has been written yet, so the process ends at once: an
    exception raised here, inside a C extension's import, would come back as an ImportError."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    try:
        os.write(2, f"gfimu: stopped by {signal.Signals(signum).name}; no output was left half-written\n".encode())
    except OSError:
        pass
    os._exit(128 + signum)


signal.signal(signal.SIGINT, _early_signal)
signal.signal(signal.SIGTERM, _early_signal)

from gfimu.cli import main  # noqa: E402

sys.exit(main())
