"""``python -m bayesprog``: the command line, as ``bayesprog``."""

from bayesprog.cli import command

raise SystemExit(command())
