"""Starting the nodes from the command line, and ending them on SIGINT or SIGTERM."""

from __future__ import annotations

import json
import signal
import sys
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from bayesprog import BayesprogError
from runner.robot.ros import require, security

#: set by SIGINT or SIGTERM once :func:`catch_signals` has run: the node then ends cleanly
STOP = threading.Event()


def catch_signals() -> None:
    """From now on SIGINT and SIGTERM ask the node to stop (the spin loop ends at its next turn,
    a tenth of a second), even while it is still starting: called first thing by ``--ros``."""
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: STOP.set())


@contextmanager
def _ros(args: list[str] | None = None) -> Iterator[threading.Event]:
    """rclpy started without its own signal handlers (ours set :data:`STOP`), with ``args``
    (the enclave of ``--secure``)."""
    require()
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    catch_signals()
    try:
        rclpy.init(args=args or [], signal_handler_options=SignalHandlerOptions.NO)
    except Exception as exc:  # rclpy's RCLError and kin: the middleware refused to start
        raise BayesprogError(f"cannot start ROS 2: {exc}") from None
    try:
        yield STOP
    finally:
        rclpy.try_shutdown()


def _node(make: Callable[[], Any]) -> Any:
    """A node from ``make``, a bad namespace or name reported as a user error, and so is the
    middleware's refusal of a secured node."""
    from rclpy.exceptions import InvalidNamespaceException, NameValidationException

    try:
        return make()
    except (InvalidNamespaceException, NameValidationException) as exc:
        raise BayesprogError(f"--namespace: {exc}") from None
    except RuntimeError as exc:  # rclpy's RCLError: the participant was not created
        if security.enabled():
            raise security.refusal(exc) from None
        raise


def _secured(keystore: Path | None, enclave: str) -> list[str]:
    """rclpy's arguments for ``--secure KEYSTORE`` (none without it)."""
    return security.secure(keystore, enclave) if keystore is not None else []


def _spin(node: Any, stop: threading.Event, until: Callable[[], bool] = lambda: False,
          tick: Callable[[], None] = lambda: None) -> None:
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    executor = SingleThreadedExecutor()
    executor.add_node(node)
    try:
        while not stop.is_set() and not until() and rclpy.ok():
            executor.spin_once(timeout_sec=0.1)
            tick()
    finally:
        executor.remove_node(node)
        node.destroy_node()


def explore(session: Any, namespace: str, frame: str, secure: Path | None = None) -> int:
    """Serve ``session`` as ``bayesprog_explorer`` until SIGINT or SIGTERM (with ``secure``, a
    keystore, under DDS Security)."""
    with _ros(_secured(secure, security.EXPLORER_ENCLAVE)) as stop:
        from runner.robot.ros.explorer_node import ExplorerNode

        node = _node(lambda: ExplorerNode(session, namespace=namespace, frame=frame))
        e, name = session.explorer, node.get_fully_qualified_name()
        print(f"{name}: task {e.task} of {e.scenario.name} "
              f"({' x '.join(map(str, e.scenario.shape))} cells of {e.scenario.cell:g} m), "
              f"probes on {node.get_namespace().rstrip('/')}/probe, frame {frame!r}"
              + (", lines with its secret only" if session.secret is not None else "")
              + (", DDS Security enforced" if security.enabled() else ""),
              file=sys.stderr, flush=True)
        _spin(node, stop)
        print(f"{name}: stopped after {node.answered} probe(s)",
              file=sys.stderr, flush=True)
    return 0


def record(recorder: Any, namespace: str, secure: Path | None = None) -> int:
    """Record the presses sent to ``bayesprog_recorder`` until SIGINT or SIGTERM (with
    ``secure``, in the explorer's enclave of that keystore)."""
    with _ros(_secured(secure, security.EXPLORER_ENCLAVE)) as stop:
        from runner.robot.ros.recorder_node import RecorderNode

        node = _node(lambda: RecorderNode(recorder, namespace=namespace))
        name = node.get_fully_qualified_name()
        print(f"{name}: recording presses of {recorder.scenario.name} on "
              f"{node.get_namespace().rstrip('/')}/probe into {recorder.out}",
              file=sys.stderr, flush=True)
        _spin(node, stop)
        print(f"{name}: {recorder.summary()}", file=sys.stderr, flush=True)
    return 0


def robot(scenario: Any, options: Any, namespace: str, as_json: bool = False,
          secure: Path | None = None) -> int:
    """Drive an explorer with the simulated robot; print the run's Gamma and path length
    (with ``secure``, a keystore, in the driver's enclave)."""
    with _ros(_secured(secure, security.DRIVER_ENCLAVE)) as stop:
        from runner.robot.ros.robot_node import RobotNode

        node = _node(lambda: RobotNode(scenario, options, namespace=namespace))
        name = node.get_fully_qualified_name()
        _spin(node, stop, until=node.settled, tick=node.advance)
        outcome, summary = node.outcome, node.summary()
    if outcome.error is not None and outcome.no_explorer:
        print(f"{name}: {outcome.error}", file=sys.stderr)
        return 2
    if as_json:
        print(json.dumps({k: (None if isinstance(v, float) and v != v else v)  # NaN: null
                          for k, v in summary.items()}))
    else:
        what = f"{summary['probes']} probe(s)"
        if stop.is_set():
            what += " (interrupted)"
        print(f"{name}: task {options.task}, {what}; Gamma (eq. 16) {summary['gamma']:.4f} m "
              f"over {summary['border_cells']} border cells "
              f"({summary['gamma_per_border_cell_mm']:.1f} mm per cell); path length "
              f"{summary['path_length']:.3f} m")
    if outcome.error is not None:  # what it had done is printed above, then why it stopped
        print(f"{name}: {outcome.error}", file=sys.stderr)
        return 1
    return 0
