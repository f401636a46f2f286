import sys

from gfimu.cli import main

sys.exit(main())
