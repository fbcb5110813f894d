"""The start of every worker process of the project, kept to the standard library so that a
child reads it before anything else: it dies with its parent whatever the moment, and leaves
Ctrl-C to the parent.

* **Ctrl-C**: the child is started with SIGINT ignored (an ignored signal stays ignored across
  ``exec``, and Python keeps it so), so a Ctrl-C to the process group, even while the child is
  still importing, reaches the parent alone, which stops its workers itself.
* **The parent killed**: the child's first Python code is :func:`child_main` (its ``-c``
  program, in place of multiprocessing's): on Linux it asks the kernel for SIGKILL when its
  parent ends (``prctl(PR_SET_PDEATHSIG)``), then looks whether the parent is already gone
  (killed while the child was being started), before importing anything else; elsewhere a
  thread watches the parent's pid.

:class:`WatchedContext` is a multiprocessing context of such processes (spawned, never forked:
the compiled ICP kernel runs on an OpenMP pool that a forked child must not inherit).
"""

from __future__ import annotations

import functools
import os
import signal
import sys
import threading
import time
from collections.abc import Callable
from multiprocessing import popen_spawn_posix
from multiprocessing import spawn as multiprocessing_spawn
from multiprocessing.context import SpawnContext, SpawnProcess
from typing import Any

#: prctl's option: the signal sent to this process when its parent ends
_PR_SET_PDEATHSIG = 1


def die_with(parent: int) -> None:
    """End this process when the process ``parent`` ends (now, if it already has)."""
    if sys.platform.startswith("linux"):
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
    else:
        def watch() -> None:
            while os.getppid() == parent:
                time.sleep(0.5)
            os._exit(1)

        threading.Thread(target=watch, daemon=True, name="parent-watch").start()
    if os.getppid() != parent:  # the parent ended before the request was made
        os._exit(1)


def child_main(parent: int, **spawn: Any) -> None:
    """A worker's first Python code (its ``-c`` program): die with ``parent``, then start as
    multiprocessing starts a spawned child. A parent killed before it could hand the child its
    work (the child reads the end of the pipe instead) ends the child quietly, not with a
    traceback."""
    die_with(parent)
    from multiprocessing.spawn import spawn_main

    try:
        spawn_main(**spawn)
    except (EOFError, OSError):
        if os.getppid() != parent:
            os._exit(1)
        raise


def _command_line(parent: int, stock: Callable[..., list[str]], **spawn: Any) -> list[str]:
    """multiprocessing's command line of a spawned child, its program :func:`child_main`."""
    command = stock(**spawn)
    arguments = ", ".join(f"{k}={v!r}" for k, v in dict(spawn, parent=parent).items())
    command[command.index("-c") + 1] = f"from runner.experiments.child import child_main; " \
                                        f"child_main({arguments})"
    # -P: the current folder is not put first on the child's path (``python -c`` would), so a
    # folder named like one of the package's, where the command is run, cannot hide it
    command.insert(command.index("-c"), "-P")
    return command


class _Popen(popen_spawn_posix.Popen):
    def _launch(self, process_obj: Any) -> None:
        stock = multiprocessing_spawn.get_command_line
        multiprocessing_spawn.get_command_line = functools.partial(
            _command_line, os.getpid(), stock)
        try:
            super()._launch(process_obj)  # type: ignore[misc]
        finally:
            multiprocessing_spawn.get_command_line = stock


class WatchedProcess(SpawnProcess):
    """A spawned process that starts with Ctrl-C ignored and dies with its parent."""

    def start(self) -> None:
        main = threading.current_thread() is threading.main_thread()
        previous = signal.signal(signal.SIGINT, signal.SIG_IGN) if main else None
        try:
            super().start()
        finally:
            if main:
                signal.signal(signal.SIGINT, previous)

    @staticmethod
    def _Popen(process_obj: Any) -> Any:  # noqa: N802 (multiprocessing's name)
        return _Popen(process_obj)


class WatchedContext(SpawnContext):
    """The spawn context with :class:`WatchedProcess` processes."""

    Process = WatchedProcess
