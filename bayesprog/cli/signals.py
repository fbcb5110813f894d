"""How a command stops: SIGTERM and Ctrl-C are raised where the command is (but never
inside a finaliser, where Python could only print them and go on), and a reader of the output
that goes away (``bayesprog query ... | head``) ends the command quietly; each with its exit
status.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable
from typing import Any

#: The exit status when the reader of the output went away (a shell's for SIGPIPE, 128 + 13),
#: and when the command was asked to stop (SIGTERM, 128 + 15).
EXIT_CLOSED_PIPE = 141
EXIT_TERMINATED = 143


class _Terminated(BaseException):
    """SIGTERM, raised where the command is, so that it stops as after Ctrl-C: its workers
    stopped, what is finished kept, its files and semaphores released."""


def _terminate(signum: int, frame: Any) -> None:
    if not _in_finaliser(frame, signum):
        raise _Terminated()


def _interrupt(signum: int, frame: Any) -> None:
    """Ctrl-C, raised where the command is; but not inside a finaliser (see below)."""
    if not _in_finaliser(frame, signum):
        raise KeyboardInterrupt


#: the files whose functions run as finalisers: weakref callbacks, multiprocessing's Finalize
_FINALISERS = ("weakref.py", "multiprocessing/util.py", "multiprocessing\\util.py")


def _in_finaliser(frame: Any, signum: int) -> bool:
    """Whether the signal arrived while a finaliser runs (a ``__del__``, a weakref callback,
    multiprocessing's cleanup of a lock or a queue). An exception raised there would be printed
    and lost, and the finaliser cut short (a semaphore left registered, reported as leaked at
    exit): the signal is then sent again a moment later, once the finaliser has returned."""
    while frame is not None:
        code = frame.f_code
        if code.co_name == "__del__" or code.co_filename.endswith(_FINALISERS):
            _send_again(signum)
            return True
        frame = frame.f_back
    return False


def _send_again(signum: int) -> None:
    import signal
    import threading

    # a real signal, not a flag: it also wakes a main thread blocked in a system call
    again = threading.Timer(_AGAIN_AFTER, signal.pthread_kill,
                            (threading.main_thread().ident, signum))
    again.daemon = True
    again.start()


def _deliver_again(unraisable: Any) -> None:
    """``sys.unraisablehook`` while a command runs. Python cannot raise from a finaliser or a
    weakref callback: a Ctrl-C or SIGTERM that lands in one would be printed as "Exception
    ignored in ..." and lost, and the command would go on. Such a stop is sent to the main
    thread again a moment later, once the finaliser has returned, to be raised where the command
    is (a signal that lands in a finaliser again is sent again); anything else is reported as
    Python does. (The signal handlers themselves send a stop again when it arrives inside a
    finaliser; this catches what they cannot see, such as a stop raised by other code.)"""
    import signal

    if isinstance(unraisable.exc_value, KeyboardInterrupt):
        _send_again(signal.SIGINT)
    elif isinstance(unraisable.exc_value, _Terminated):
        _send_again(signal.SIGTERM)
    else:
        sys.__unraisablehook__(unraisable)


#: seconds after which a stop that landed in a finaliser is sent again
_AGAIN_AFTER = 0.01


def run_stoppable(run: Callable[[], int]) -> int:
    """``run()``, its exit status; SIGTERM and Ctrl-C raised where it is (in the main thread),
    143 when terminated, 141 when the output's reader closed the pipe."""
    import signal
    import threading

    main_thread = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGTERM, _terminate) if main_thread else None
    previous_int = signal.getsignal(signal.SIGINT)
    previous_hook = sys.unraisablehook
    if main_thread:
        if previous_int is signal.default_int_handler:  # (an ignored Ctrl-C stays ignored)
            signal.signal(signal.SIGINT, _interrupt)
        sys.unraisablehook = _deliver_again
    try:
        return run()
    except _Terminated:
        print("bayesprog: terminated", file=sys.stderr)
        return EXIT_TERMINATED
    except BrokenPipeError:
        # the reader is gone: nothing more can be said to it, and the interpreter must not
        # complain when it flushes standard output at exit
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
        return EXIT_CLOSED_PIPE
    finally:
        if main_thread:
            signal.signal(signal.SIGTERM, previous)
            signal.signal(signal.SIGINT, previous_int)
            sys.unraisablehook = previous_hook
