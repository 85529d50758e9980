"""``python -m handsim.cli``."""

import sys

from handsim.cli.main import main

sys.exit(main())
