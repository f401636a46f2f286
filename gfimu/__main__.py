import signal
import sys


def _early_signal(signum, frame):  # noqa: ARG001
    """A signal before gfimu.cli.main installs its own handler (while gfimu.cli is imported): the same
    status as later (130 / 143), and a second one ignored."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    sys.exit(128 + signum)


signal.signal(signal.SIGINT, _early_signal)
signal.signal(signal.SIGTERM, _early_signal)

from gfimu.cli import main  # noqa: E402

sys.exit(main())
