"""The start of every worker process of the project, kept to the standard library so that a
child reads it before anything else: it dies with its parent whatever the moment, and leaves
Ctrl-C to the parent.

* **Ctrl-C**: the child is started with SIGINT ignored (an ignored signal stays ignored across
  ``exec``, and Python keeps it so), so a Ctrl-C to the process group, even while the child is
  still importing, reaches the parent alone, which stops its workers itself.
* **The parent killed**: on Linux the child asks the kernel for SIGKILL when its parent ends
  (``prctl(PR_SET_PDEATHSIG)``), first thing once it runs Python code of its own, and then looks
  whether the parent is already gone (killed while the child was starting). Elsewhere a thread
  watches the parent's pid.

:class:`WatchedContext` is a multiprocessing context of such processes (spawned, never forked:
the compiled ICP kernel runs on an OpenMP pool that a forked child must not inherit).
"""

from __future__ import annotations

import os
import signal
import sys
import threading
import time
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


class WatchedProcess(SpawnProcess):
    """A spawned process that starts with Ctrl-C ignored and dies with its parent."""

    def start(self) -> None:
        self._watched_parent = os.getpid()
        main = threading.current_thread() is threading.main_thread()
        previous = signal.signal(signal.SIGINT, signal.SIG_IGN) if main else None
        try:
            super().start()
        finally:
            if main:
                signal.signal(signal.SIGINT, previous)

    def _bootstrap(self, parent_sentinel: Any = None) -> int:  # runs in the child
        die_with(self._watched_parent)
        return super()._bootstrap(parent_sentinel)  # type: ignore[misc]


class WatchedContext(SpawnContext):
    """The spawn context with :class:`WatchedProcess` processes."""

    Process = WatchedProcess
