"""The ``bayesprog`` command line: validate, show, graph, query, sample, learn, discover,
compare, import, export, examples, schema. An application adds its own commands: every runner
plugin found through the ``bayesprog.runners`` entry point group is asked for them (its
``add_commands(subparsers)``).

User errors print ``bayesprog: ...`` (or ``FILE:LINE:COL: ...`` lines) on stderr and exit with
status 2, never with a traceback.

This module builds the parser and runs a command; each command (its options, its help and what
it does) lives in the module of its kind: ``programs`` (validate, show, graph, examples,
schema), ``questions`` (query, sample), ``learning`` (learn, discover, compare) and
``networks`` (import, export), over the helpers they share in ``common``; ``signals`` says how
a command stops.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from bayesprog.cli import learning, networks, programs, questions
from bayesprog.cli.common import EXIT_USER_ERROR, UserError, plugins
from bayesprog.cli.signals import EXIT_CLOSED_PIPE, EXIT_TERMINATED, run_stoppable
from bayesprog.errors import BayesprogError, SpecError

__all__ = ["EXIT_CLOSED_PIPE", "EXIT_TERMINATED", "EXIT_USER_ERROR", "build_parser", "command",
           "main"]

#: The framework's commands, in the order ``bayesprog --help`` lists them; the plugins' follow.
_COMMANDS = (
    programs.add_validate,
    programs.add_show,
    programs.add_graph,
    questions.add_query,
    questions.add_sample,
    learning.add_learn,
    learning.add_discover,
    learning.add_compare,
    networks.add_import,
    networks.add_export,
    programs.add_examples,
    programs.add_schema,
)

#: Each framework command's ``add_...`` by the command's name.
_COMMAND_NAMED = {add.__name__.removeprefix("add_"): add for add in _COMMANDS}


def build_parser(argv: Sequence[str] | None = None) -> argparse.ArgumentParser:
    """The command line's parser: the framework's commands and those of the runner plugins
    (not loaded when ``argv`` names one of the framework's: a plugin cannot replace them).
    When ``argv`` starts with a framework command's name, only that command is built: the
    others' options are never read."""
    parser = argparse.ArgumentParser(
        prog="bayesprog",
        description="Bayesian programs as YAML files: check, show, draw and ask them questions.",
    )
    parser.add_argument("--version", action="version", version=_version())
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    named = _COMMAND_NAMED.get(argv[0]) if argv else None
    if named is not None:  # `bayesprog learn ...`: that command's parser only
        named(sub)
        return parser
    for add in _COMMANDS:
        add(sub)
    word = next((a for a in argv if not a.startswith("-")), None) if argv is not None else None
    if word not in sub.choices:
        _plugin_commands(sub)
    return parser


def _plugin_commands(sub: argparse._SubParsersAction) -> None:
    """The commands runner plugins add (their module's ``add_commands(subparsers)``); a plugin
    that cannot be loaded adds none, and says why on stderr."""
    for name, plugin in plugins():
        add = getattr(plugin, "add_commands", None)
        if add is None:
            continue
        try:
            add(sub)
        except argparse.ArgumentError as exc:  # e.g. a command the framework has already
            print(f"bayesprog: runner {name!r}: {exc}", file=sys.stderr)


def _version() -> str:
    from bayesprog import __version__

    return f"bayesprog {__version__}"


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit status (0 ok, 2 user error, 130 interrupted,
    141 when the output's reader closed the pipe, as ``bayesprog query ... | head``, 143 when
    terminated)."""
    return run_stoppable(lambda: _main(argv))


def command() -> int:
    """The ``bayesprog`` program (and ``python -m bayesprog``): :func:`main`, then the heap it
    leaves is frozen, so that the interpreter's last collections at exit do not visit every
    object the command's imports made (a third of a second after a report); what the command
    wrote is closed by then."""
    import gc

    status = main()
    gc.freeze()
    return status


def _main(argv: Sequence[str] | None) -> int:
    parser = build_parser(sys.argv[1:] if argv is None else argv)
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # argparse has printed the usage and the problem
        return int(exc.code or 0)
    try:
        status = int(args.func(args))
        sys.stdout.flush()  # a closed pipe is found here, not at the interpreter's exit
        return status
    except SpecError as exc:
        for d in exc.diagnostics:
            print(d, file=sys.stderr)
        return EXIT_USER_ERROR
    except (BayesprogError, UserError) as exc:
        print(f"bayesprog: {exc}", file=sys.stderr)
        return EXIT_USER_ERROR
    except KeyboardInterrupt:
        print("bayesprog: interrupted", file=sys.stderr)
        return 130
