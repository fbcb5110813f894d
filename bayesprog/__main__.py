"""``python -m bayesprog``: the command line, as ``bayesprog``."""

from bayesprog.cli import main

raise SystemExit(main())
