"""Where the project's work is computed: local processes or a Dask cluster, each unit saved as
soon as it is finished, workers that die replaced; and the progress bar. Every local process
of the project comes from :func:`process_pool` (the experiment's units, the report's Fig. 11,
the parameter search): its workers die with their parent whatever the moment, and leave
Ctrl-C to it (:mod:`runner.experiments.child`)."""

from __future__ import annotations

import os
import sys
from collections.abc import Callable
from typing import Any

from bayesprog import BayesprogError
from runner.experiments.store import ResultStore, Unit


def run_processes(workers: int, job: Callable[[Unit], dict], todo: list[Unit], store: ResultStore,
                  bar: Any, max_deaths: int, pool: Any = None) -> None:
    """The units on local processes (first on ``pool``, when it is given: started while the
    caller prepared); a pool whose worker dies is replaced and the units it had not finished
    are computed again (numbers do not depend on which process computes them)."""
    from concurrent.futures import as_completed
    from concurrent.futures.process import BrokenProcessPool

    left, deaths = list(todo), 0
    while left:
        if pool is None:
            pool = process_pool(min(workers, len(left)))
        futures: dict[Any, Unit] = {}
        broken = False
        try:
            try:
                for u in left:
                    futures[pool.submit(job, u)] = u
            except BrokenProcessPool:  # a worker died before taking any of them
                broken = True
            for future in [] if broken else as_completed(futures):
                if isinstance(future.exception(), BrokenProcessPool):
                    broken = True
                    break
                store.save(futures[future], future.result())
                left.remove(futures[future])
                deaths = 0
                bar.update(1)
            if broken:  # keep what finished before the pool broke
                for future, unit in futures.items():
                    if unit in left and future.done() and future.exception() is None:
                        store.save(unit, future.result())
                        left.remove(unit)
                        bar.update(1)
        except BaseException:
            # Ctrl-C or a failed chunk: what is saved stays; stop the workers at once
            stop_pool(pool)
            raise
        if not broken:
            pool.shutdown()
            return
        stop_pool(pool)
        pool = None
        deaths += 1
        if deaths > max_deaths:
            raise BayesprogError(f"worker processes died {deaths} times in a row (killed, out "
                                 "of memory, or failing as they start: see the errors above): "
                                 "the finished chunks are kept; run again to resume")
        print(f"a worker process died: {len(left)} chunk(s) left go to new workers",
              file=sys.stderr)


def process_pool(workers: int, preload: tuple[str, ...] = (), start: bool = False) -> Any:
    """A pool of ``workers`` local processes (a ``ProcessPoolExecutor``): spawned, dying with
    this process, Ctrl-C left to it, one compiled-kernel thread each (no oversubscription),
    each importing the modules ``preload`` as it starts. With ``start``, the processes are
    started now (a pool starts them at its first tasks): they import while this process
    prepares the work."""
    from concurrent.futures import ProcessPoolExecutor

    from runner.experiments.child import WatchedContext

    pool = ProcessPoolExecutor(max_workers=workers, mp_context=WatchedContext(),
                               initializer=worker_init, initargs=(preload,))
    if start:
        for _ in range(workers):  # a process is started for each task no idle one takes
            pool.submit(int)
    return pool


#: seconds a stopped worker has to end as a Python program does before it is killed
STOP_GRACE = 1.0


def stop_pool(pool: Any) -> None:
    """Stop ``pool`` now: its queued work cancelled, its processes terminated (SIGTERM: they
    end as Python programs do), and killed if they are still there after :data:`STOP_GRACE`
    seconds: a worker whose SIGTERM lands in a job only ends that job (the pool's worker loop
    catches what the job raises and takes the next one already queued), and the interpreter's
    exit would wait for it."""
    import time

    processes = list((getattr(pool, "_processes", None) or {}).values())
    manager = getattr(pool, "_executor_manager_thread", None)
    pool.shutdown(wait=False, cancel_futures=True)
    for process in processes:
        process.terminate()
    deadline = time.monotonic() + STOP_GRACE
    for process in processes:
        process.join(max(deadline - time.monotonic(), 0.0))
        if process.is_alive():
            process.kill()
    if manager is not None:
        # the pool's thread ends once its processes have, closing its wake-up pipe; at exit,
        # Python (3.11) wakes every such thread, and a wake-up that races the close is printed
        # as an error ("Bad file descriptor")
        manager.join(STOP_GRACE)


def worker_init(preload: tuple[str, ...] = ()) -> None:
    """A worker process (already dying with its parent, :mod:`runner.experiments.child`): one
    compiled-kernel thread, Ctrl-C left to the parent; stopped (SIGTERM), it ends as a Python
    program does, its files and semaphores released; its progress bars lock with a thread
    lock, not a semaphore of the machine's that a killed process would leave behind. The
    modules ``preload`` are imported then. What they made is frozen out of the garbage
    collector's reach (module objects live as long as the process), and so is everything alive
    when the process ends: the interpreter's last collections do not visit a heap of
    imported modules (a quarter of a second after a figure) while the parent waits for it."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    # stopped while it starts (its parent refused the command, or was stopped), it leaves at
    # once: it has taken no work, and SystemExit raised in the pool's initializer would be
    # printed with a traceback
    signal.signal(signal.SIGTERM, _leave_now)
    import atexit
    import gc
    import importlib
    import threading

    import numba
    from tqdm import tqdm

    numba.set_num_threads(1)
    tqdm.set_lock(threading.RLock())
    for module in preload:
        importlib.import_module(module)
    signal.signal(signal.SIGTERM, _exit_quietly)
    gc.freeze()
    atexit.register(gc.freeze)


def _exit_quietly(signum: int, frame: Any) -> None:
    # stopped inside a call from compiled code back into Python (numba's compiler, through
    # llvmlite's callbacks, while it caches a kernel), SystemExit would be printed with a
    # traceback and ignored there: the worker leaves at once instead, as while it starts
    while frame is not None:
        if "llvmlite" in frame.f_code.co_filename:
            os._exit(128 + signum)
        frame = frame.f_back
    raise SystemExit(128 + signum)


def _leave_now(signum: int, frame: Any) -> None:
    os._exit(128 + signum)


def run_dask(address: str, job: Callable[[Unit], dict], todo: list[Unit], store: ResultStore,
             bar: Any, max_deaths: int, worker_timeout: float) -> None:
    """The units on an existing Dask cluster; a unit whose workers died goes to the others."""
    with dask_client(address) as client:
        def save(index: int, result: dict) -> None:
            store.save(todo[index], result)
            bar.update(1)

        dask_map(client, address, job, todo, save, max_deaths, worker_timeout,
                 kept="the finished chunks are kept", name=lambda unit: unit.name)


def dask_client(address: str) -> Any:
    """A client of the Dask scheduler at ``address`` (a clear error when Dask is not installed
    or the scheduler cannot be reached)."""
    try:
        from dask.distributed import Client
    except ImportError:
        raise BayesprogError("--scheduler needs Dask: pip install 'bayesprog[dask]'") from None
    try:
        return Client(address, timeout="10s")
    except (OSError, ValueError, TypeError) as exc:
        raise BayesprogError(f"--scheduler {address}: cannot reach a Dask scheduler ({exc})") \
            from None


def dask_map(client: Any, address: str, function: Callable[[Any], Any], items: list[Any],
             done: Callable[[int, Any], None], max_deaths: int, worker_timeout: float,
             kept: str, name: Callable[[Any], str] = str) -> None:
    """``function`` of every item on the cluster of ``client``, ``done(index, result)`` called
    as each finishes (in the order they finish); an item whose workers died is submitted
    again (up to ``max_deaths`` times per item in all), and a cluster without a worker for
    ``worker_timeout`` seconds stops the work. ``kept`` says, in the errors, what is kept."""
    import time

    from dask.distributed import wait
    from distributed.client import FutureCancelledError
    from distributed.scheduler import KilledWorker

    futures = {client.submit(function, item, pure=False): i for i, item in enumerate(items)}
    pending, deaths, alone_since = set(futures), 0, None
    while pending:
        try:
            finished, still = wait(list(pending), timeout=1.0, return_when="FIRST_COMPLETED")
            pending = set(still)
        except TimeoutError:  # nothing finished in that second
            finished = set()
        for future in finished:
            index = futures.pop(future)
            try:
                result = future.result()
            except (KilledWorker, FutureCancelledError):
                # the item was on workers that died: give it to the others
                deaths += 1
                if deaths > max_deaths * max(1, len(items)):
                    raise BayesprogError(f"--scheduler {address}: workers keep dying on "
                                         f"{name(items[index])}; {kept}") from None
                again = client.submit(function, items[index], pure=False)
                futures[again] = index
                pending.add(again)
                continue
            done(index, result)
        if finished or client.scheduler_info().get("workers"):
            alone_since = None
        elif alone_since is None:
            alone_since = time.monotonic()
        elif time.monotonic() - alone_since > worker_timeout:
            raise BayesprogError(f"--scheduler {address}: no worker for "
                                 f"{worker_timeout:.0f} s: start workers (dask worker "
                                 f"{address}); {kept}")


def progress_bar(total: int, what: str, unit: str = "step", done: int = 0,
                 enabled: bool | None = None, leave: bool = False) -> Any:
    """A tqdm bar, shown on a terminal (or as ``enabled`` says)."""
    from tqdm import tqdm

    disable = not sys.stderr.isatty() if enabled is None else not enabled
    return tqdm(total=total, initial=done, desc=what, unit=unit, leave=leave, disable=disable)
