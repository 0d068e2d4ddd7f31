"""``python -m controller`` works like ``fleet``."""

import sys

from controller.cli import main

sys.exit(main())
