"""What securing the explorer costs a step of the closed loop over ROS 2 (not a test).

``bayesprog explore SCENARIO --ros`` runs in its own process, this process is the robot (the
scenario's simulated sensor, seed 0, run 0): a probe published, timed until the
``next_target`` it answers arrives, then the next probe there, for ``--steps`` steps. Three
ways, each ``--repeats`` times with a fresh explorer, in turn:

- ``open``: as today, no secret;
- ``secret``: ``explore --secret FILE``, every line carrying it (``"secret"``);
- ``dds-security``: ``explore --secure KEYSTORE`` (SROS2, made by ``bayesprog keystore create``),
  the robot in the driver's enclave; where the middleware cannot run DDS Security, the
  explorer's refusal is reported instead of figures.

Reported per way: the median of the repeats' median round trips (and their spread), and the
median 90th percentile. Beside them, what the secret's check adds to answering a line in the
explorer's process (the same lines answered by a session with and without a secret, in turn),
which the round trips' noise would hide. Discovery stays on the loopback interface, on a
random domain.

    python benchmarks/ros_security.py [--steps 300] [--repeats 5]
        [--out results/benchmarks/ros_security.json]
"""

from __future__ import annotations

import argparse
import json
import os
import random
import signal
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
from ros import drive  # the robot's loop over ROS, as the plain benchmark drives it

ROOT = Path(__file__).parents[1]
BAYESPROG = str(Path(sys.executable).with_name("bayesprog"))
for name, value in (("ROS_DOMAIN_ID", str(random.SystemRandom().randint(1, 100))),
                    ("ROS_LOCALHOST_ONLY", "1"), ("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")):
    os.environ.setdefault(name, value)


class Robot:
    """The scenario's simulated sensor, probing wherever it is sent (seed 0, run 0)."""

    def __init__(self, scenario_path: Path, secret: str | None):
        from runner.experiments.loop import make_sensor, reading_seed, start_cell
        from runner.world.scenario import load_scenario

        self.scenario = load_scenario(scenario_path)
        self.sensor = make_sensor(self.scenario, [reading_seed(0, 0)])
        self.cell = [int(i) for i in start_cell(self.scenario.shape, 0, 0)]
        self.secret = secret

    def signed(self, line: dict) -> str:
        return json.dumps(line if self.secret is None else {**line, "secret": self.secret})

    def line(self) -> str:
        from runner.robot.session import probe_line

        flat = np.ravel_multi_index(tuple(self.cell), self.scenario.shape)
        return self.signed(probe_line(self.cell, self.sensor.probe(np.array([flat]))))


#: the namespace of the secured way, the one its keystore grants
SECURED_NAMESPACE = "/bench_secured"


def closed_loop(scenario: Path, task: str, steps: int, explorer_args: list[str],
                secret_file: Path | None, keystore: Path | None = None) -> list[float] | str:
    """The round trips of ``steps`` probes to an explorer started with ``explorer_args`` (this
    robot in the driver's enclave of ``keystore`` when given), or why it did not start."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        import rclpy
        from rclpy.signals import SignalHandlerOptions

    namespace = (f"/bench{random.SystemRandom().randrange(10**6)}" if keystore is None
                 else SECURED_NAMESPACE)
    explorer = subprocess.Popen([BAYESPROG, "explore", str(scenario), "--ros", "--task", task,
                                 "--namespace", namespace, *explorer_args], cwd=ROOT,
                                stderr=subprocess.PIPE, text=True)
    assert explorer.stderr is not None
    while True:  # its status line once it serves, or its refusal
        line = explorer.stderr.readline()
        if not line:
            explorer.wait(timeout=30)
            return "the explorer did not start: " + "".join(explorer.stderr).strip()
        if "probes on" in line:
            break
        if line.startswith("bayesprog:"):
            explorer.wait(timeout=30)
            return line.strip()
    secret = secret_file.read_text().strip() if secret_file is not None else None
    secured = {"ROS_SECURITY_KEYSTORE": str(keystore), "ROS_SECURITY_ENABLE": "true",
               "ROS_SECURITY_STRATEGY": "Enforce"} if keystore is not None else {}
    os.environ.update(secured)
    rclpy.init(args=["--ros-args", "--enclave", "/bayesprog/driver"] if secured else [],
               signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node("bench_robot", namespace=namespace)
    robot = Robot(scenario, secret)
    try:
        return drive(node, robot, steps, robot.signed({"reset": {}}))
    finally:
        node.destroy_node()
        rclpy.shutdown()
        for name in secured:
            del os.environ[name]
        explorer.send_signal(signal.SIGINT)
        explorer.communicate(timeout=10)


def in_process(scenario: Path, task: str, steps: int, repeats: int) -> dict[str, float]:
    """The median time a session takes to answer a probe, with and without a secret (µs)."""
    from runner.attention.explorer import Explorer
    from runner.robot.session import Session
    from runner.world.scenario import load_scenario

    loaded = load_scenario(scenario)
    secret = "a-secret-of-43-characters-0123456789abcdefg"
    per_way: dict[str, list[float]] = {"open": [], "secret": []}
    for _ in range(repeats):
        for way in per_way:
            robot = Robot(scenario, secret if way == "secret" else None)
            session = Session(Explorer(loaded, task), secret=robot.secret)
            times = []
            for _ in range(steps):
                line = robot.line()
                start = time.perf_counter()
                reply = session.answer(line)
                times.append(time.perf_counter() - start)
                assert reply is not None and "next" in reply, reply
                robot.cell = reply["next"]
            per_way[way].append(float(np.median(times)) * 1e6)
    return {way: float(np.median(v)) for way, v in per_way.items()}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--scenario", default=str(ROOT / "models" / "scenarios" / "paper.yaml"))
    parser.add_argument("--task", default="T2")
    parser.add_argument("--out", default="results/benchmarks/ros_security.json")
    args = parser.parse_args(argv)
    scenario = Path(args.scenario)
    work = Path(tempfile.mkdtemp(prefix="bayesprog-bench-"))
    secret_file = work / "explorer.secret"
    keystore = work / "keystore"
    subprocess.run([BAYESPROG, "keystore", "create", str(keystore), "--enclaves",
                    "/bayesprog/explorer", "/bayesprog/driver", "--namespace", SECURED_NAMESPACE],
                   check=True, capture_output=True)
    ways: dict[str, tuple[list[str], Path | None]] = {
        "open": ([], None),
        "secret": (["--secret", str(secret_file)], secret_file),
        "dds-security": (["--secure", str(keystore)], None),
    }
    result: dict = {"scenario": scenario.name, "task": args.task, "steps": args.steps,
                    "repeats": args.repeats, "cpu_count": os.cpu_count(), "ways": {}}
    medians: dict[str, list[float]] = {way: [] for way in ways}
    p90s: dict[str, list[float]] = {way: [] for way in ways}
    refused: dict[str, str] = {}
    for _ in range(args.repeats):  # the ways in turn, so that a slow moment hits them alike
        for way, (explorer_args, secret) in ways.items():
            if way in refused:
                continue
            times = closed_loop(scenario, args.task, args.steps, explorer_args, secret,
                                keystore if way == "dds-security" else None)
            if isinstance(times, str):
                refused[way] = times
                continue
            ms = np.asarray(times) * 1000
            medians[way].append(float(np.median(ms)))
            p90s[way].append(float(np.percentile(ms, 90)))
    for way in ways:
        if way in refused:
            result["ways"][way] = {"refused": refused[way]}
            print(f"{way:>12}: not measured: {refused[way]}")
            continue
        row = {"median_ms": float(np.median(medians[way])),
               "repeat_medians_ms": medians[way], "p90_ms": float(np.median(p90s[way]))}
        result["ways"][way] = row
        print(f"{way:>12}: median {row['median_ms']:.2f} ms a step (repeats "
              f"{min(medians[way]):.2f}..{max(medians[way]):.2f}), p90 {row['p90_ms']:.2f} ms")
    answering = in_process(scenario, args.task, args.steps, args.repeats)
    result["answer_in_process_us"] = answering
    print(f"answering a probe in the explorer's process: {answering['open']:.0f} µs open, "
          f"{answering['secret']:.0f} µs with the secret "
          f"({answering['secret'] - answering['open']:+.0f} µs)")
    if "median_ms" in result["ways"].get("secret", {}):
        ratio = result["ways"]["secret"]["median_ms"] / result["ways"]["open"]["median_ms"]
        result["secret_over_open"] = ratio
        print(f"secret / open, median round trip: {ratio:.3f}x")
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=1) + "\n")
    print(f"written to {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
