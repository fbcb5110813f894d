"""The ROS 2 explorer's round trip in a closed loop (not a test).

``bayesprog explore SCENARIO --ros`` runs in its own process; this process is the robot: it
probes a cell with the scenario's simulated sensor, publishes the reading on ``probe``, and
times until the ``next_target`` it answers arrives, then probes that cell, for ``--steps``
steps. Beside it, in the same run, the same closed loop over ``explore --stdio`` (a line in, its
reply read back through pipes): the reference, so the ratio says what ROS 2 adds to a step.

Reported: the median round trip and its 90th percentile, the medians of the first and last 100
steps and their ratio (a cost per step that grows with the session shows there), for both
interfaces, and the ratio of the medians. Discovery stays on the loopback interface, on a random
domain.

    python benchmarks/ros.py [--steps 1000] [--scenario models/scenarios/paper.yaml]
        [--task T2] [--out results/benchmarks/ros.json]
"""

from __future__ import annotations

import argparse
import json
import os
import random
import signal
import subprocess
import sys
import time
import warnings
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).parents[1]
BAYESPROG = str(Path(sys.executable).with_name("bayesprog"))
# DDS stays on this machine's loopback, on a domain of its own unless the user chose one: a
# setting already made is kept
for name, value in (("ROS_DOMAIN_ID", str(random.SystemRandom().randint(1, 100))),
                    ("ROS_LOCALHOST_ONLY", "1"), ("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")):
    os.environ.setdefault(name, value)


class Robot:
    """The scenario's simulated sensor, probing wherever it is sent (seed 0, run 0)."""

    def __init__(self, scenario_path: Path):
        from runner.experiments.loop import make_sensor, reading_seed, start_cell
        from runner.world.scenario import load_scenario

        self.scenario = load_scenario(scenario_path)
        self.sensor = make_sensor(self.scenario, [reading_seed(0, 0)])
        self.cell = [int(i) for i in start_cell(self.scenario.shape, 0, 0)]

    def line(self) -> str:
        from runner.robot.session import probe_line

        flat = np.ravel_multi_index(tuple(self.cell), self.scenario.shape)
        return json.dumps(probe_line(self.cell, self.sensor.probe(np.array([flat]))))


def summary(times: list[float]) -> dict:
    ms = np.asarray(times) * 1000
    first, last = float(np.median(ms[:100])), float(np.median(ms[-100:]))
    return {"median_ms": float(np.median(ms)), "p90_ms": float(np.percentile(ms, 90)),
            "first_100_median_ms": first, "last_100_median_ms": last,
            "last_over_first": last / first, "steps": len(ms)}


def drive(node: Any, robot: Any, steps: int, reset: str) -> list[float]:
    """``steps`` probes of ``robot`` (its ``line()`` and ``cell``) sent by ``node`` on its
    namespace's probe topic, each timed until the explorer's next target arrives; first the
    ``reset`` line until the explorer replies (a reset is a no-op on a fresh session)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        from geometry_msgs.msg import PointStamped
        from rclpy.executors import SingleThreadedExecutor
        from std_msgs.msg import String

    executor = SingleThreadedExecutor()
    executor.add_node(node)
    targets: list = []
    replies: list = []
    node.create_subscription(PointStamped, "next_target", targets.append, 10)
    node.create_subscription(String, "reply", replies.append, 10)
    probe = node.create_publisher(String, "probe", 10)
    times = []
    while not (probe.get_subscription_count() and node.count_publishers("next_target")):
        executor.spin_once(timeout_sec=0.05)
    while not replies:  # the explorer hears us
        probe.publish(String(data=reset))
        end = time.monotonic() + 0.5
        while not replies and time.monotonic() < end:
            executor.spin_once(timeout_sec=0.01)
    for _ in range(steps):
        line = robot.line()
        n = len(targets)
        start = time.perf_counter()
        probe.publish(String(data=line))
        while len(targets) == n:
            executor.spin_once(timeout_sec=1.0)
        times.append(time.perf_counter() - start)
        p = targets[-1].point
        robot.cell = [int(np.floor(v / robot.scenario.cell))
                      for v in (p.x, p.y, p.z)[:robot.scenario.dims]]
    return times


def over_ros(scenario: Path, task: str, steps: int) -> list[float]:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        import rclpy
        from rclpy.signals import SignalHandlerOptions

    namespace = f"/bench{random.SystemRandom().randrange(10**6)}"
    explorer = subprocess.Popen([BAYESPROG, "explore", str(scenario), "--ros", "--task", task,
                                 "--namespace", namespace], cwd=ROOT, stderr=subprocess.DEVNULL)
    rclpy.init(args=[], signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node("bench_robot", namespace=namespace)
    try:
        return drive(node, Robot(scenario), steps, '{"reset": {}}')
    finally:
        node.destroy_node()
        rclpy.shutdown()
        explorer.send_signal(signal.SIGINT)
        explorer.wait(timeout=10)


def over_stdio(scenario: Path, task: str, steps: int) -> list[float]:
    process = subprocess.Popen([BAYESPROG, "explore", str(scenario), "--stdio", "--task", task],
                               cwd=ROOT, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    assert process.stdin is not None and process.stdout is not None
    robot = Robot(scenario)
    times = []
    try:
        for _ in range(steps):
            line = robot.line()
            start = time.perf_counter()
            process.stdin.write(line + "\n")
            process.stdin.flush()
            reply = json.loads(process.stdout.readline())
            times.append(time.perf_counter() - start)
            robot.cell = reply["next"]
    finally:
        process.stdin.close()
        process.wait(timeout=30)
    return times


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=1000)
    parser.add_argument("--scenario", default=str(ROOT / "models" / "scenarios" / "paper.yaml"))
    parser.add_argument("--task", default="T2")
    parser.add_argument("--out", default="results/benchmarks/ros.json")
    args = parser.parse_args(argv)
    scenario = Path(args.scenario)
    stdio = summary(over_stdio(scenario, args.task, args.steps))
    ros = summary(over_ros(scenario, args.task, args.steps))
    result = {"scenario": str(scenario.relative_to(ROOT) if scenario.is_relative_to(ROOT)
                              else scenario), "task": args.task, "ros": ros, "stdio": stdio,
              "ros_over_stdio_median": ros["median_ms"] / stdio["median_ms"],
              "cpu_count": os.cpu_count()}
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=1) + "\n")
    for name in ("ros", "stdio"):
        r = result[name]
        print(f"{name:>5}: median {r['median_ms']:.2f} ms (p90 {r['p90_ms']:.2f}), first 100 "
              f"{r['first_100_median_ms']:.2f} ms, last 100 {r['last_100_median_ms']:.2f} ms "
              f"({r['last_over_first']:.2f}x) over {r['steps']} steps")
    print(f"ROS 2 / stdio, median round trip: {result['ros_over_stdio_median']:.2f}x; "
          f"written to {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
