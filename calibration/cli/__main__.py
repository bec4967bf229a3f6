"""``python -m calibration.cli``: the same as ``reach-cal``."""

import sys

from .main import main

sys.exit(main())
