"""A step interface for a real robot: JSON lines in, JSON lines out.

Each input line is answered by :class:`runner.robot.session.Session` (its docstring gives the lines
and the replies); the ROS 2 node (:mod:`runner.robot.ros`) answers the same lines the same way.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Iterator
from typing import IO

from runner.attention.explorer import Explorer
from runner.experiments.log import SessionLog
from runner.robot.session import MAX_LINE, Session


def _lines(stdin: IO[str] | Iterable[str]) -> Iterator[str]:
    """The lines of ``stdin``; from a file, one longer than ``MAX_LINE`` is cut there (its
    rest dropped, never held)."""
    if not hasattr(stdin, "readline"):
        yield from stdin
        return
    while True:
        line = stdin.readline(MAX_LINE + 1)
        if not line:
            return
        if len(line) > MAX_LINE and not line.endswith("\n"):
            while True:  # drop the rest of the long line without holding it
                rest = stdin.readline(MAX_LINE)
                if not rest or rest.endswith("\n"):
                    break
        yield line


def serve(explorer: Explorer, stdin: IO[str] | Iterable[str], stdout: IO[str], seed: int = 0,
          log: SessionLog | None = None, secret: str | None = None) -> int:
    """Answer probes until end of input, each written to ``log`` when given (with a
    ``secret``, only lines that carry it). Returns the number of probes answered."""
    session = Session(explorer, seed, log=log, secret=secret)
    answered = 0
    for line in _lines(stdin):
        reply = session.answer(line)
        if reply is None:
            continue
        answered += session.stepped
        stdout.write(json.dumps(reply) + "\n")
        stdout.flush()
    return answered
