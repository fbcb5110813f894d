"""``python -m bayesprog.cli``: the command line, as ``bayesprog``."""

import sys

from bayesprog.cli import main

sys.exit(main())
