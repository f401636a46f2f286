import signal
import sys

# A signal before gfimu.cli.main installs its handler (while gfimu.cli is imported): the same status,
# and from then on ignored (main installs its own handler first thing).
signal.signal(signal.SIGINT, lambda signum, frame: (signal.signal(signum, signal.SIG_IGN), sys.exit(130)))
signal.signal(signal.SIGTERM, lambda signum, frame: (signal.signal(signum, signal.SIG_IGN), sys.exit(143)))

from gfimu.cli import main  # noqa: E402

sys.exit(main())
