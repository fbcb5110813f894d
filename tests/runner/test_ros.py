"""The ROS 2 nodes (runner/robot/ros) over real DDS, across processes: ``bayesprog explore
--ros`` and ``bayesprog robot --ros`` as commands, and a client node in this process that holds
them to the contract of docs/robot.md. Discovery stays on the loopback interface, on a domain of its own."""

from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
import time
import warnings
from collections import defaultdict
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import rclpy  # bayesprog[ros], which the test extras bring
from geometry_msgs.msg import PointStamped
from nav_msgs.msg import OccupancyGrid
from nav_msgs.msg import Path as PathMsg
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from sensor_msgs.msg import PointCloud2
from std_msgs.msg import String
from visualization_msgs.msg import Marker, MarkerArray

from runner.attention.explorer import Explorer
from runner.experiments.experiment import simulate, start_cells
from runner.robot.session import Session
from runner.world.scenario import load_scenario

with warnings.catch_warnings():
    # the message type support loads lark, which imports the deprecated sre_parse (pytest runs
    # with warnings as errors): load it once, quietly
    warnings.simplefilter("ignore", DeprecationWarning)
    import rosidl_generator_py  # noqa: F401

ROOT = Path(__file__).parents[2]
PAPER = ROOT / "models" / "scenarios" / "paper.yaml"
VOLUME = ROOT / "models" / "scenarios" / "volume.yaml"
BAYESPROG = str(Path(sys.executable).with_name("bayesprog"))
READINGS = {"silicone": (0.12, 0.35), "wood": (0.52, 0.08), "plush": (0.66, 0.62)}
FIELDS = ("belief", "posterior", "saliency", "uncertainty", "inhibition")

# Every node of this module, ours and the client, talks on this machine only, on a random domain.
DOMAIN = str(random.SystemRandom().randint(1, 100))
ROS_ENV = {"ROS_DOMAIN_ID": DOMAIN, "ROS_LOCALHOST_ONLY": "1",
           "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
os.environ.update(ROS_ENV)

RESET = '{"reset": {}}'
LATCHED = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)


def stamp(msg) -> tuple[int, int]:
    """When a message was stamped (a marker array: its first marker)."""
    head = msg.markers[0].header if isinstance(msg, MarkerArray) else msg.header
    return head.stamp.sec, head.stamp.nanosec


def probe(cell, material: str = "wood", **extra) -> str:
    e, c = READINGS[material]
    return json.dumps({"cell": list(cell), "texture": e, "compliance": c, **extra})


def walk(scenario, start, n: int, seed: int = 0) -> list[str]:
    """``n`` probes along a seeded random walk on the grid, each with its true material's
    readings (the lines do not depend on the replies)."""
    rng = np.random.default_rng(seed)
    cell, lines = np.array(start), []
    for _ in range(n):
        material = scenario.materials[scenario.material_map[tuple(cell)]]
        lines.append(probe(cell.tolist(), material))
        cell = np.clip(cell + rng.integers(-1, 2, len(cell)), 0, np.array(scenario.shape) - 1)
    return lines


class Client:
    """A node in this process that sends probe lines and records what the explorer publishes."""

    def __init__(self, namespace: str = "/bayesprog", volume: bool = False,
                 name: str = "contract_client"):
        self.context = rclpy.context.Context()
        rclpy.init(context=self.context, args=[], signal_handler_options=SignalHandlerOptions.NO)
        self.node = rclpy.create_node(name, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.ns = namespace.rstrip("/")
        self.got: dict[str, list] = defaultdict(list)
        field_type = PointCloud2 if volume else OccupancyGrid
        topics = {"reply": (String, 10), "next_target": (PointStamped, 10), "path": (PathMsg, LATCHED),
                  "shape": (MarkerArray, LATCHED), "probe": (String, 100),
                  **{name: (field_type, LATCHED) for name in FIELDS}}
        for name, (kind, qos) in topics.items():
            self.node.create_subscription(kind, f"{self.ns}/{name}",
                                          lambda msg, name=name: self.got[name].append(msg), qos)
        self.publisher = self.node.create_publisher(String, f"{self.ns}/probe", 10)

    def spin(self, until, timeout: float = 30.0) -> None:
        end = time.monotonic() + timeout
        while not until():
            if time.monotonic() > end:
                raise AssertionError(f"timed out after {timeout} s")
            self.executor.spin_once(timeout_sec=0.02)

    def connected(self) -> bool:
        """The explorer is there: it takes probes and publishes replies and the next cell
        (seen from here; it sees us a moment later, and waits for that before it answers)."""
        return (self.publisher.get_subscription_count() > 0
                and self.node.count_publishers(f"{self.ns}/reply") > 0
                and self.node.count_publishers(f"{self.ns}/next_target") > 0)

    def handshake(self) -> None:
        """Wait until the explorer hears us: a reader drops what a writer sent before the
        reader's side matched it, so a reset (a no-op on a fresh session) is sent each half
        second until one is answered. ``preamble`` counts the resets it answered: the lines a
        reference session must start with to number its lines alike."""
        self.spin(self.connected, timeout=60)
        end = time.monotonic() + 30
        while not self.got["reply"]:
            assert time.monotonic() < end, "the explorer never answered"
            self.publisher.publish(String(data=RESET))
            until = time.monotonic() + 0.5
            while not self.got["reply"] and time.monotonic() < until:
                self.executor.spin_once(timeout_sec=0.02)
        until = time.monotonic() + 0.3  # a reset sent twice is answered twice
        while time.monotonic() < until:
            self.executor.spin_once(timeout_sec=0.02)
        assert all(json.loads(m.data)["reset"] for m in self.got["reply"])
        self.preamble = len(self.got["reply"])
        for name in ("reply", "next_target", "probe"):
            self.got[name].clear()

    def ask(self, line: str) -> dict:
        """Send one line; its reply, and for a probe everything published with it."""
        self.spin(self.connected)
        n, targets = len(self.got["reply"]), len(self.got["next_target"])
        self.publisher.publish(String(data=line))
        self.spin(lambda: len(self.got["reply"]) > n)
        reply = json.loads(self.got["reply"][n].data)
        if "next" in reply:  # the step's messages share one stamp (topics arrive in any order)
            self.spin(lambda: len(self.got["next_target"]) > targets
                      and all(self.got[t] and stamp(self.got[t][-1])
                              == stamp(self.got["next_target"][-1])
                              for t in (*FIELDS, "path", "shape")))
        return reply

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.shutdown(context=self.context)


_STARTED: list[subprocess.Popen] = []


def start(*args: str) -> subprocess.Popen:
    process = subprocess.Popen([BAYESPROG, *args], cwd=ROOT, env={**os.environ, **ROS_ENV},
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    _STARTED.append(process)
    return process


@pytest.fixture(autouse=True)
def _no_node_left():
    """Whatever a test started ends with it, even when the test fails half-way."""
    yield
    while _STARTED:
        process = _STARTED.pop()
        if process.poll() is None:
            process.kill()
        process.communicate()


def stop(process: subprocess.Popen, sig: int = signal.SIGINT) -> tuple[int, float, str]:
    """Send ``sig``; the exit status, the seconds it took and what it wrote on stderr."""
    begun = time.monotonic()
    process.send_signal(sig)
    try:
        out, err = process.communicate(timeout=10)
    except subprocess.TimeoutExpired:
        process.kill()
        out, err = process.communicate()
    process.printed = out  # type: ignore[attr-defined]
    return process.returncode, time.monotonic() - begun, err


@pytest.fixture(scope="module")
def paper():
    return load_scenario(PAPER)


@pytest.fixture
def explorer_node(request):
    """``explore paper.yaml --ros`` in a namespace of its own, and a client connected to it."""
    namespace = f"/t{random.SystemRandom().randrange(10**6)}"
    args = getattr(request, "param", ["--task", "T2"])
    process = start("explore", str(PAPER), "--ros", "--namespace", namespace, *args)
    client = Client(namespace)
    try:
        client.handshake()
        yield client, process
    finally:
        client.close()
        if process.poll() is None:
            status, took, err = stop(process)
            assert status == 0, err
            assert "Traceback" not in err


def same_session(lines: list[str], task: str = "T2", seed: int = 0, preamble: int = 0
                 ) -> list[dict]:
    """The replies of the same lines from an in-process session (the stdio path's), after
    ``preamble`` resets (a client's handshake)."""
    session = Session(Explorer(load_scenario(PAPER), task), seed=seed)
    replies = [session.answer(line + "\n") for line in [RESET] * preamble + lines]
    return [r for r in replies if r is not None][preamble:]


# --- install and layering ----------------------------------------------------------------------


def test_importing_the_packages_never_imports_rclpy():
    code = ("import sys, bayesprog, runner, runner.plugin, runner.robot.ros, runner.robot.session, "
            "runner.robot.stdio; from bayesprog.cli import build_parser; build_parser(); "
            "print(sorted(m for m in sys.modules if m.split('.')[0] in "
            "('rclpy', 'std_msgs', 'nav_msgs', 'geometry_msgs')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT,
                         check=True)
    assert out.stdout.strip() == "[]"


@pytest.mark.parametrize("command", [["explore", str(PAPER), "--ros"],
                                     ["robot", str(PAPER), "--ros", "--task", "T2"]],
                         ids=["explore", "robot"])
def test_without_the_extra_ros_exits_2_in_one_line(command):
    # rclpy made unimportable, as on a machine without bayesprog[ros]
    code = ("import sys; sys.modules['rclpy'] = None; from bayesprog.cli import main; "
            f"sys.exit(main({command!r}))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT,
                         timeout=120)
    assert out.returncode == 2
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1, out.stderr
    assert 'pip install "bayesprog[ros]"' in lines[0]
    assert "Traceback" not in out.stderr


@pytest.mark.parametrize("command, expected", [
    (["explore", str(PAPER)], "one of --stdio"),
    (["explore", str(PAPER), "--stdio", "--ros"], "one of --stdio"),
    (["robot", str(PAPER), "--task", "T2"], "robot needs --ros"),
    (["robot", str(PAPER), "--ros", "--steps", "0"], "--steps: expected at least 1"),
    (["robot", str(PAPER), "--ros", "--run", "-1"], "--run: expected at least 0"),
    (["robot", str(PAPER), "--ros", "--task", "T9"], "unknown task 'T9'"),
    (["explore", str(PAPER), "--ros", "--namespace", "/bad ns"], "--namespace"),
])
def test_bad_options_are_user_errors(command, expected):
    out = subprocess.run([BAYESPROG, *command], capture_output=True, text=True, cwd=ROOT,
                         timeout=120, env={**os.environ, **ROS_ENV})
    assert out.returncode == 2, out.stderr
    assert expected in out.stderr
    assert "Traceback" not in out.stderr


@pytest.mark.parametrize("domain", ["abc", "999"])
def test_a_domain_dds_cannot_use_is_a_user_error(domain):
    out = subprocess.run([BAYESPROG, "explore", str(PAPER), "--ros"], capture_output=True,
                         text=True, cwd=ROOT, timeout=120,
                         env={**os.environ, **ROS_ENV, "ROS_DOMAIN_ID": domain})
    assert out.returncode == 2
    assert out.stderr.strip() == (f"bayesprog: ROS_DOMAIN_ID={domain!r}: expected an integer "
                                  "from 0 to 232 (0 to 101 is safe on Linux)")


# --- the contract, item by item ---------------------------------------------------------------


def test_topics_types_node_and_qos(explorer_node):
    client, _ = explorer_node
    node, ns = client.node, client.ns
    expected = {"reply": "std_msgs/msg/String", "next_target": "geometry_msgs/msg/PointStamped",
                "path": "nav_msgs/msg/Path", "shape": "visualization_msgs/msg/MarkerArray",
                **{f: "nav_msgs/msg/OccupancyGrid" for f in FIELDS}}
    # the graph names an endpoint's node once that node's description has arrived
    client.spin(lambda: ("bayesprog_explorer", ns) in node.get_node_names_and_namespaces()
                and all(i.node_name == "bayesprog_explorer"
                        for t in expected for i in node.get_publishers_info_by_topic(f"{ns}/{t}")))
    for topic, kind in expected.items():
        infos = node.get_publishers_info_by_topic(f"{ns}/{topic}")
        ours = [i for i in infos if i.node_name == "bayesprog_explorer"]
        assert len(ours) == 1, topic
        info = ours[0]
        assert info.node_namespace == ns and info.topic_type == kind
        assert info.qos_profile.reliability == ReliabilityPolicy.RELIABLE, topic
        latched = topic in (*FIELDS, "path", "shape")
        assert (info.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL) == latched, topic
    subs = [i for i in node.get_subscriptions_info_by_topic(f"{ns}/probe")
            if i.node_name == "bayesprog_explorer"]
    assert len(subs) == 1 and subs[0].topic_type == "std_msgs/msg/String"
    assert subs[0].qos_profile.reliability == ReliabilityPolicy.RELIABLE
    # the queues' depths are not sent over the wire: read them off a node made here
    from runner.robot.ros.explorer_node import ExplorerNode

    here = ExplorerNode(Session(Explorer(load_scenario(PAPER), "T2")), namespace="/depths",
                        context=client.context)
    try:
        endpoints = [here.reply, here.next_target, here.path, here.shape_markers, here.probes,
                     *here.fields.values()]
        assert len(endpoints) == 10
        for endpoint in endpoints:
            qos = endpoint.qos_profile
            assert qos.depth >= 10 and qos.reliability == ReliabilityPolicy.RELIABLE
    finally:
        here.destroy_node()


def test_a_probe_gets_the_stdio_reply_the_next_cell_and_the_maps(explorer_node, paper):
    client, _ = explorer_node
    line = probe((10, 12), "silicone")
    reply = client.ask(line)
    assert reply == same_session([line], preamble=client.preamble)[0]
    # next_target: the next cell's centre in metres, in the workspace frame, stamped
    target = client.got["next_target"][-1]
    ix, iy = reply["next"]
    assert target.header.frame_id == "workspace"
    assert (target.header.stamp.sec, target.header.stamp.nanosec) != (0, 0)
    assert target.point.x == pytest.approx((ix + 0.5) * paper.cell)
    assert target.point.y == pytest.approx((iy + 0.5) * paper.cell)
    assert target.point.z == 0.0
    # belief: P(task material) in percent at the probed cell, -1 elsewhere
    belief = client.got["belief"][-1]
    assert belief.header.frame_id == "workspace"
    assert belief.info.resolution == pytest.approx(paper.cell)
    assert (belief.info.width, belief.info.height) == paper.shape
    data = np.array(belief.data, dtype=int)
    expected = np.full(30 * 60, -1)
    expected[12 * 30 + 10] = round(100 * reply["probed"]["task_material"])
    np.testing.assert_array_equal(data, expected)
    # the other grids against the same session's fields, cell by cell
    session = Session(Explorer(load_scenario(PAPER), "T2"))
    session.answer(line + "\n")
    e = session.explorer
    fields = {"posterior": e.target_probabilities[0] / e.target_probabilities[0].max(),
              "saliency": e.last.saliency[0], "uncertainty": e.last.uncertainty[0],
              "inhibition": e.last.inhibition[0]}
    for name, values in fields.items():
        grid = np.array(client.got[name][-1].data, dtype=int).reshape(60, 30)  # [iy, ix]
        want = np.where(np.isnan(values), -1, np.rint(np.nan_to_num(values) * 100)).reshape(30, 60)
        np.testing.assert_array_equal(grid, want.T, err_msg=name)
    assert np.array(client.got["posterior"][-1].data).max() == 100
    assert (np.array(client.got["saliency"][-1].data) == -1).any()  # S not observed there
    # the path so far, and no shape yet
    path = client.got["path"][-1]
    assert [(p.pose.position.x, p.pose.position.y) for p in path.poses] == [
        pytest.approx((0.105, 0.125))]
    assert [m.action for m in client.got["shape"][-1].markers] == [Marker.DELETEALL]


def test_stdio_and_ros_give_the_same_replies_over_60_probes(explorer_node, paper):
    client, _ = explorer_node
    lines = walk(paper, (12, 14), 60, seed=5)
    # with the lines a session also gets: errors, a blank line, maps, a reset
    lines[7:7] = ["not json", json.dumps({"cell": [40, 2], "texture": 0.5, "compliance": 0.1}),
                  "", '{"maps": true}']
    lines[30:30] = [probe((3, 3), maps=True), '{"reset": {"seed": 4}}', '{"cell": [1]}']
    stdio = subprocess.run([BAYESPROG, "explore", str(PAPER), "--stdio", "--task", "T2"],
                           input="".join(line + "\n" for line in [RESET] * client.preamble
                                         + lines),
                           capture_output=True, text=True, cwd=ROOT, timeout=120, check=True)
    expected = [json.loads(line) for line in stdio.stdout.splitlines()][client.preamble:]
    replies = []
    for line in lines:
        if not line.strip():  # no reply, as on stdio; the line still counts
            client.publisher.publish(String(data=line))
            continue
        replies.append(client.ask(line))
    assert len(replies) == len(expected) == len(lines) - 1
    assert replies == expected
    assert sum("next" in r for r in replies) == 61
    assert ["error" in r for r in replies].count(True) == 3


def test_a_late_viewer_gets_the_last_grids_path_and_shape(explorer_node, paper):
    client, _ = explorer_node
    for line in walk(paper, (12, 14), 5, seed=1):
        client.ask(line)
    late = Client(client.ns, name="late_viewer")
    try:
        # (the queue holds the last ten: it arrives last)
        late.spin(lambda: all(late.got[t] and stamp(late.got[t][-1]) == stamp(client.got[t][-1])
                              for t in (*FIELDS, "path", "shape")), timeout=20)
        assert np.array_equal(late.got["belief"][-1].data, client.got["belief"][-1].data)
        assert len(late.got["path"][-1].poses) == 5
    finally:
        late.close()


def test_a_malformed_message_gets_an_error_and_the_node_goes_on(explorer_node, paper):
    client, process = explorer_node
    lines = [probe((10, 12), "silicone"), "{", "[]", '{"cell": [1, 2], "texture": "x"}',
             '{"reset": {"seed": -1}}', "x" * (1 << 20) + "}", probe((11, 12), "silicone")]
    replies = [client.ask(line) for line in lines]
    assert [("error" in r) for r in replies] == [False, True, True, True, True, True, False]
    assert replies == same_session(lines, preamble=client.preamble)
    assert process.poll() is None


def test_the_shape_marker_is_the_registered_outline_on_the_probed_border(paper):
    """In a closed loop the shape cue comes into force; the marker is then the registered
    outline of the most probable template, and the border cells probed lie on it."""
    namespace = f"/s{random.SystemRandom().randrange(10**6)}"
    explorer = start("explore", str(PAPER), "--ros", "--namespace", namespace, "--task", "T2")
    client = Client(namespace)
    try:
        client.spin(client.connected, timeout=60)
        robot = subprocess.run([BAYESPROG, "robot", str(PAPER), "--ros", "--task", "T2",
                                "--steps", "60", "--seed", "2024", "--run", "1", "--namespace",
                                namespace], capture_output=True, text=True, cwd=ROOT,
                               timeout=120, env={**os.environ, **ROS_ENV})
        assert robot.returncode == 0, robot.stderr
        client.spin(lambda: len(client.got["path"]) and len(client.got["path"][-1].poses) == 60)
        client.spin(lambda: stamp(client.got["shape"][-1]) == stamp(client.got["path"][-1]))
        replies = [json.loads(m.data) for m in client.got["reply"]]
    finally:
        client.close()
        stop(explorer)
    assert replies[-1]["shape"]["in_force"]
    posterior = replies[-1]["shape"]["posterior"]
    best = max(posterior, key=posterior.get)
    outline, label = client.got["shape"][-1].markers
    assert outline.type == Marker.LINE_STRIP and label.type == Marker.TEXT_VIEW_FACING
    assert label.text.startswith(best)
    vertices = np.array([(p.x, p.y) for p in outline.points])
    assert np.allclose(vertices[0], vertices[-1])  # closed
    # the probed cells on the true border lie within a cell of the registered outline
    border = paper.border("T2").ravel()
    probed = [int(np.ravel_multi_index((int(round(p.pose.position.x / paper.cell - 0.5)),
                                        int(round(p.pose.position.y / paper.cell - 0.5))),
                                       paper.shape)) for p in client.got["path"][-1].poses]
    on_border = paper.centres[[c for c in set(probed) if border[c]]]
    assert len(on_border) >= 5

    def to_segments(points):
        a, b = vertices[:-1], vertices[1:]
        t = np.clip(np.einsum("sd,psd->ps", b - a, points[:, None] - a)
                    / np.maximum(((b - a) ** 2).sum(-1), 1e-12), 0, 1)
        return np.linalg.norm(points[:, None] - (a + t[..., None] * (b - a)), axis=-1).min(1)

    assert np.median(to_segments(on_border)) < paper.cell


# --- the closed loop ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def experiment(tmp_path_factory):
    """A small experiment run with ``bayesprog run``, and its stored runs as a table."""
    folder = tmp_path_factory.mktemp("ros_experiment")
    spec = folder / "small.yaml"
    spec.write_text(f"experiment: 1\nname: small\nscenario: {PAPER}\ntasks: [T2]\n"
                    "configurations: [full, without_U]\nruns: 3\niterations: 40\nseed: 7\n"
                    "chunk: 3\n")
    subprocess.run([BAYESPROG, "run", str(spec), "--out", str(folder / "out"), "--quiet",
                    "--no-report"], check=True, cwd=ROOT, capture_output=True, timeout=300)
    subprocess.run([BAYESPROG, "results", str(folder / "out"), "-o", str(folder / "runs.csv")],
                   check=True, cwd=ROOT, capture_output=True, timeout=120)
    return pd.read_csv(folder / "runs.csv")


def stored_run(table: pd.DataFrame, configuration: str, run: int) -> pd.DataFrame:
    rows = table[(table.configuration == configuration) & (table.run == run)]
    return rows.sort_values("step")


@pytest.mark.parametrize("explorer_node", [["--task", "T2"]], indirect=True)
def test_the_closed_loop_repeats_an_experiments_run_and_a_restarted_robot_starts_over(
        explorer_node, experiment, paper):
    client, _ = explorer_node

    def drive(run: int, steps: int) -> tuple[dict, list[list[int]]]:
        out = subprocess.run([BAYESPROG, "robot", str(PAPER), "--ros", "--task", "T2",
                              "--steps", str(steps), "--seed", "7", "--run", str(run),
                              "--namespace", client.ns, "--json"], capture_output=True,
                             text=True, cwd=ROOT, timeout=120, env={**os.environ, **ROS_ENV})
        assert out.returncode == 0, out.stderr
        # the cells as the explorer took them from DDS: its path, started over at the reset
        client.spin(lambda: client.got["path"] and len(client.got["path"][-1].poses) == steps)
        poses = client.got["path"][-1].poses
        cells = [[int(round(p.pose.position.x / paper.cell - 0.5)),
                  int(round(p.pose.position.y / paper.cell - 0.5))] for p in poses]
        return json.loads(out.stdout), cells

    # a robot that stops halfway, then another that starts over as run 2 of the experiment
    first, _ = drive(0, 15)
    assert first["probes"] == 15
    summary, cells = drive(2, 40)
    stored = stored_run(experiment, "full", 2)
    flat = [int(np.ravel_multi_index(tuple(c), paper.shape)) for c in cells]
    assert flat == stored.cell.tolist()  # probe for probe, as DDS carried them
    assert summary["path"] == cells
    assert summary["gamma"] == pytest.approx(stored.gamma_m.iloc[-1], rel=1e-12)
    travelled = np.linalg.norm(np.diff(paper.centres[flat], axis=0), axis=1).sum()
    assert summary["path_length"] == pytest.approx(travelled)
    # and the start cell is run 2's of an experiment of seed 7 of any size
    assert flat[0] == int(np.ravel_multi_index(tuple(start_cells(paper.shape, 50, 7)[2]),
                                               paper.shape))


@pytest.mark.parametrize("explorer_node", [["--task", "T2", "--ablate", "P(U | O)"]],
                         indirect=True)
def test_the_closed_loop_repeats_an_ablated_run(explorer_node, experiment, paper):
    client, _ = explorer_node
    out = subprocess.run([BAYESPROG, "robot", str(PAPER), "--ros", "--task", "T2", "--steps",
                          "40", "--seed", "7", "--run", "1", "--namespace", client.ns, "--json"],
                         capture_output=True, text=True, cwd=ROOT, timeout=120,
                         env={**os.environ, **ROS_ENV})
    assert out.returncode == 0, out.stderr
    cells = json.loads(out.stdout)["path"]
    flat = [int(np.ravel_multi_index(tuple(c), paper.shape)) for c in cells]
    assert flat == stored_run(experiment, "without_U", 1).cell.tolist()
    assert flat != stored_run(experiment, "full", 1).cell.tolist()


def test_the_robot_prints_gamma_and_path_length(explorer_node, paper):
    client, _ = explorer_node
    out = subprocess.run([BAYESPROG, "robot", str(PAPER), "--ros", "--task", "T2", "--steps",
                          "12", "--namespace", client.ns], capture_output=True, text=True,
                         cwd=ROOT, timeout=120, env={**os.environ, **ROS_ENV})
    assert out.returncode == 0, out.stderr
    # seed 0, run 0 by default: that run of a simulation, decisions included
    sim = simulate(paper, "T2", "full", start_cells(paper.shape, 1, 0), np.arange(1), 0, 12)
    gamma = sim["gamma"][0, -1]
    assert f"Gamma (eq. 16) {gamma:.4f} m" in out.stdout
    travelled = np.linalg.norm(np.diff(paper.centres[sim["paths"][0]], axis=0), axis=1).sum()
    assert f"path length {travelled:.3f} m" in out.stdout


def test_a_robot_without_an_explorer_gives_up_after_its_timeout():
    out = subprocess.run([BAYESPROG, "robot", str(PAPER), "--ros", "--task", "T2",
                          "--namespace", "/nobody_here", "--timeout", "2"], capture_output=True,
                         text=True, cwd=ROOT, timeout=120, env={**os.environ, **ROS_ENV})
    assert out.returncode == 2
    assert "no explorer answers on /nobody_here/probe" in out.stderr
    assert "Traceback" not in out.stderr


# --- robustness --------------------------------------------------------------------------------


def test_two_explorers_in_two_namespaces_do_not_mix(paper):
    tag = random.SystemRandom().randrange(10**6)
    spaces = {f"/a{tag}": "T1", f"/b{tag}": "T2"}
    processes = {ns: start("explore", str(PAPER), "--ros", "--namespace", ns, "--task", task)
                 for ns, task in spaces.items()}
    clients = {ns: Client(ns, name=f"client_{ns[1]}") for ns in spaces}
    try:
        for client in clients.values():
            client.handshake()
        a, b = clients.values()
        line = probe((10, 12), "silicone")
        reply_a = a.ask(line)
        deadline = time.monotonic() + 1.0
        while time.monotonic() < deadline:
            b.executor.spin_once(timeout_sec=0.05)
        assert b.got["reply"] == []  # b heard nothing of a's probe
        reply_b = b.ask(line)
        assert reply_a == same_session([line], task="T1", preamble=a.preamble)[0]
        assert reply_b == same_session([line], task="T2", preamble=b.preamble)[0]
        assert reply_a["probed"]["task_material"] != reply_b["probed"]["task_material"]
        assert len(a.got["reply"]) == 1
    finally:
        for client in clients.values():
            client.close()
        for process in processes.values():
            assert stop(process)[0] == 0


@pytest.mark.parametrize("command", [["explore", str(PAPER), "--ros", "--task", "T2"],
                                     ["robot", str(PAPER), "--ros", "--task", "T2"]],
                         ids=["explore", "robot"])
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_node_stopped_while_it_starts_ends_cleanly(command, sig):
    process = start(*command, "--namespace", f"/w{random.SystemRandom().randrange(10**6)}")
    assert process.stderr is not None
    first = process.stderr.readline()  # said as it starts to load the scenario
    assert first.startswith(f"bayesprog_{command[0].replace('explore', 'explorer')}: loading")
    status, took, err = stop(process, sig)
    assert (status, "Traceback" in err) == (0, False), err
    assert took < 5


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_both_nodes_end_cleanly_on_a_signal(sig):
    namespace = f"/g{random.SystemRandom().randrange(10**6)}"
    explorer = start("explore", str(PAPER), "--ros", "--namespace", namespace, "--task", "T2")
    client = Client(namespace)
    try:
        client.spin(client.connected, timeout=60)
        robot = start("robot", str(PAPER), "--ros", "--task", "T2", "--steps", "100000",
                      "--namespace", namespace)
        client.spin(lambda: len(client.got["reply"]) > 20, timeout=60)  # mid-loop
        status, took, err = stop(robot, sig)
        assert (status, "Traceback" in err) == (0, False), err
        assert took < 5
        assert "probe(s) (interrupted)" in robot.printed
        status, took, err = stop(explorer, sig)
        assert (status, "Traceback" in err) == (0, False), err
        assert took < 5
    finally:
        client.close()
        for process in (explorer,):
            if process.poll() is None:
                process.kill()
    # no process of either node is left
    left = subprocess.run(["pgrep", "-f", namespace], capture_output=True, text=True)
    assert left.stdout.strip() == ""


# --- a volume of cells -------------------------------------------------------------------------


def test_in_a_volume_the_fields_are_point_clouds():
    volume = load_scenario(VOLUME)
    task = next(iter(volume.spec.tasks))
    namespace = f"/v{random.SystemRandom().randrange(10**6)}"
    explorer = start("explore", str(VOLUME), "--ros", "--namespace", namespace, "--task", task,
                     "--frame", "table")
    client = Client(namespace, volume=True)
    try:
        client.handshake()
        cell = [3, 4, 1]
        material = volume.materials[volume.material_map[tuple(cell)]]
        e, c = READINGS.get(material, (0.5, 0.1))
        reply = client.ask(json.dumps({"cell": cell, "texture": e, "compliance": c}))
    finally:
        client.close()
        stop(explorer)
    target = client.got["next_target"][-1]
    assert target.header.frame_id == "table"
    assert [target.point.x, target.point.y, target.point.z] == pytest.approx(
        [(i + 0.5) * volume.cell for i in reply["next"]])
    belief = client.got["belief"][-1]
    assert belief.header.frame_id == "table"
    names = [(f.name, f.offset, f.datatype) for f in belief.fields]
    assert names == [("x", 0, 7), ("y", 4, 7), ("z", 8, 7), ("intensity", 12, 7)]
    points = np.frombuffer(bytes(belief.data), np.float32).reshape(-1, 4)
    assert len(points) == belief.width == 1  # only the probed cell is known
    assert points[0, :3] == pytest.approx([(i + 0.5) * volume.cell for i in cell])
    assert points[0, 3] == round(100 * reply["probed"]["task_material"])
    inhibition = np.frombuffer(bytes(client.got["inhibition"][-1].data), np.float32)
    assert len(inhibition) // 4 == int(np.prod(volume.shape))  # known everywhere


# --- the documentation's bridge and RViz view --------------------------------------------------


def test_the_documented_bridge_turns_a_drivers_presses_into_probes(paper):
    """docs/examples/ros_bridge.py between the explorer and a driver (played here): the hand is
    sent to the start cell, each press becomes a probe, each next cell a goal."""
    from std_msgs.msg import Float64MultiArray

    namespace = f"/h{random.SystemRandom().randrange(10**6)}"
    start("explore", str(PAPER), "--ros", "--namespace", namespace, "--task", "T2")
    client = Client(namespace, name="driver")
    goals: list = []
    client.node.create_subscription(PointStamped, "/hand/goal", goals.append, 10)
    features = client.node.create_publisher(Float64MultiArray, "/hand/features", 10)
    try:
        client.handshake()
        bridge = subprocess.Popen([sys.executable, str(ROOT / "docs/examples/ros_bridge.py"),
                                   "--cell", str(paper.cell), "--start", "15", "9",
                                   "--namespace", namespace], cwd=ROOT,
                                  env={**os.environ, **ROS_ENV}, stderr=subprocess.PIPE,
                                  text=True)
        _STARTED.append(bridge)
        presses = 8

        def steps() -> list[dict]:
            replies = (json.loads(m.data) for m in client.got["reply"])
            return [r for r in replies if "next" in r]

        for k in range(presses):
            client.spin(lambda k=k: len(goals) > k and features.get_subscription_count() > 0,
                        timeout=60)
            goal = goals[k].point
            cell = (int(goal.x / paper.cell), int(goal.y / paper.cell))
            e, c = READINGS[paper.materials[paper.material_map[cell]]]
            features.publish(Float64MultiArray(data=[e, c]))
            while k == 0 and not steps():  # the bridge has just come up: until it hears us
                end = time.monotonic() + 2
                client.spin(lambda end=end: steps() or time.monotonic() > end)
                if not steps():
                    features.publish(Float64MultiArray(data=[e, c]))
        client.spin(lambda: len(steps()) == presses)
    finally:
        client.close()
    replies = [json.loads(m.data) for m in client.got["reply"]]
    first = next(i for i, r in enumerate(replies) if "next" in r)
    assert all(r.get("reset") for r in replies[:first])  # the bridge's start
    replies = replies[first:]
    assert [r["k"] for r in replies] == list(range(presses))
    assert replies[0]["probed"]["cell"] == [15, 9]
    # every goal after the first is the cell the explorer named
    for reply, goal in zip(replies, goals[1:], strict=False):
        assert [goal.point.x, goal.point.y] == pytest.approx(
            [(i + 0.5) * paper.cell for i in reply["next"]])
    assert stop(bridge)[0] == 0


def test_the_shipped_rviz_view_shows_the_contracts_topics():
    import yaml

    view = yaml.safe_load((ROOT / "runner" / "robot" / "ros" / "bayesprog.rviz").read_text())
    displays = {d["Topic"]["Value"]: d for d in view["Visualization Manager"]["Displays"]
                if "Topic" in d}
    assert view["Visualization Manager"]["Global Options"]["Fixed Frame"] == "workspace"
    kinds = {"belief": "Map", "posterior": "Map", "saliency": "Map", "uncertainty": "Map",
             "inhibition": "Map", "path": "Path", "shape": "MarkerArray",
             "next_target": "PointStamped"}
    for topic, kind in kinds.items():
        display = displays[f"/bayesprog/{topic}"]
        assert display["Class"] == f"rviz_default_plugins/{kind}"
        assert display["Topic"]["Reliability Policy"] == "Reliable"
        latched = topic not in ("next_target",)
        assert (display["Topic"]["Durability Policy"] == "Transient Local") == latched, topic
    shown = {t for t, d in displays.items() if d["Enabled"]}
    assert {"/bayesprog/belief", "/bayesprog/posterior", "/bayesprog/path",
            "/bayesprog/shape"} <= shown


@pytest.mark.parametrize("frame", ["", "w", "workspace", "table_top_frame"])
def test_a_growing_path_serializes_as_the_whole_message(frame):
    """The path is published from bytes made pose by pose; rclpy reads them back as the
    message built whole, whatever the frame's length (which shifts the poses' alignment)."""
    from builtin_interfaces.msg import Time
    from rclpy.serialization import deserialize_message, serialize_message

    from runner.robot.ros import messages

    grown, centres = messages.GrowingPath(), []
    rng = np.random.default_rng(3)
    for k in range(7):
        head = messages.header(frame, Time(sec=100 + k, nanosec=7 * k))
        centre = rng.random(2 + k % 2)
        grown.append(centre, head)
        centres.append((centre, head))
    head = messages.header(frame, Time(sec=999, nanosec=5))
    whole = PathMsg(header=head, poses=[messages.pose(c, h) for c, h in centres])
    data = grown.serialized(head)
    assert deserialize_message(data, PathMsg) == whole
    assert len(data) == len(serialize_message(whole))
    grown.clear()
    assert deserialize_message(grown.serialized(head), PathMsg) == PathMsg(header=head)


# --- the physics robot ------------------------------------------------------------------------


def test_the_physics_robot_drives_the_explorer_and_publishes_its_fingertip():
    """``robot --physics --ros`` against ``explore --ros``: the contract unchanged (the same
    path as the closed loop in one process, which shares its seeds), and after each probe the
    fingertip's pose, from the workspace frame to ``fingertip``."""
    from geometry_msgs.msg import TransformStamped

    from runner.robot.closed import closed_loop

    scenario_file = ROOT / "models" / "scenarios" / "paper_physics.yaml"
    namespace = f"/t{random.SystemRandom().randrange(10**6)}"
    explorer = start("explore", str(scenario_file), "--ros", "--namespace", namespace,
                     "--task", "T2")
    client = Client(namespace)
    poses: list = []
    client.node.create_subscription(TransformStamped, f"{namespace}/fingertip", poses.append,
                                    LATCHED)  # the last ten, even those sent before we matched
    try:
        client.spin(client.connected, timeout=60)
        robot = start("robot", str(scenario_file), "--physics", "--ros", "--json", "--task",
                      "T2", "--steps", "10", "--namespace", namespace)
        client.spin(lambda: robot.poll() is not None, timeout=120)
        out, err = robot.communicate()
        assert robot.returncode == 0, err
        # (a bound on a hang, like the waits above: the ten poses come as soon as DDS delivers)
        client.spin(lambda: len(poses) >= 10, timeout=60)
    finally:
        client.close()
        stop(explorer)
    outcome = json.loads(out)
    alone = closed_loop(load_scenario(scenario_file), "T2", 10)
    assert outcome["path"] == [p["cell"] for p in alone["probes"]]
    assert outcome["gamma"] == pytest.approx(alone["gamma_m"])
    assert [(p.header.frame_id, p.child_frame_id) for p in poses] == [("workspace", "fingertip")] * 10
    centres = [(np.array(c) + 0.5) * 0.01 for c in outcome["path"]]
    for pose, centre in zip(poses, centres, strict=True):  # where it pressed: near the centre
        at = np.array([pose.transform.translation.x, pose.transform.translation.y])
        assert np.linalg.norm(at - centre) < 0.005


def test_when_the_explorer_dies_the_robot_prints_what_it_did_and_exits_1(paper):
    namespace = f"/t{random.SystemRandom().randrange(10**6)}"
    explorer = start("explore", str(PAPER), "--ros", "--namespace", namespace, "--task", "T2")
    client = Client(namespace)
    try:
        client.spin(client.connected, timeout=60)
        # (the timeout also bounds how long the robot looks for the explorer at its start:
        # discovery on a loaded machine takes seconds)
        robot = start("robot", str(PAPER), "--ros", "--json", "--task", "T2", "--steps", "500",
                      "--timeout", "8", "--namespace", namespace)
        client.spin(lambda: len(client.got["reply"]) >= 6, timeout=60)
        explorer.kill()
        out, err = robot.communicate(timeout=60)
    finally:
        client.close()
    assert robot.returncode == 1
    assert "the explorer is gone" in err and "Traceback" not in err
    outcome = json.loads(out)
    assert 6 <= outcome["probes"] < 500 and len(outcome["path"]) == outcome["probes"]
    assert outcome["gamma"] > 0 and outcome["path_length"] > 0


# --- a lab's own readings over ROS 2 -----------------------------------------------------------

FINGERTIP = ROOT / "models" / "scenarios" / "fingertip.yaml"


def test_named_and_missing_readings_over_ros_are_answered_as_over_stdio_and_logged(tmp_path):
    """A lab's probe lines (its readings by name, some missing) on NS/probe get the replies
    stdio gives, and --log writes every probe."""
    namespace = f"/t{random.SystemRandom().randrange(10**6)}"
    log = tmp_path / "session.csv"
    process = start("explore", str(FINGERTIP), "--ros", "--namespace", namespace,
                    "--task", "follow_felt", "--log", str(log))
    client = Client(namespace)
    lines = [json.dumps({"cell": [2, 2], "readings": {"pdc": 31.0, "pac_rms": -0.6, "tdc": 0.9,
                                                      "electrode_var": 0.28, "slip": "stick"}}),
             json.dumps({"cell": [3, 2], "readings": {"pdc": 30.0, "tdc": None}}),
             json.dumps({"cell": [3, 3], "readings": {"tcd": 1.0}})]
    try:
        client.handshake()
        replies = [client.ask(line) if i < 2 else None for i, line in enumerate(lines)]
        n = len(client.got["reply"])
        client.publisher.publish(String(data=lines[2]))
        client.spin(lambda: len(client.got["reply"]) > n)
        replies[2] = json.loads(client.got["reply"][n].data)
    finally:
        client.close()
        status, _, err = stop(process)
    assert status == 0 and "Traceback" not in err, err
    session = Session(Explorer(load_scenario(FINGERTIP), "follow_felt"))
    expected = [session.answer(line + "\n") for line in [RESET] * client.preamble + lines]
    expected = expected[client.preamble:]
    assert replies[:2] == expected[:2]
    assert replies[1]["missing"] == ["pac_rms", "tdc", "electrode_var", "slip"]
    assert "did you mean 'tdc'" in replies[2]["error"]
    table = pd.read_csv(log)
    assert list(table["step"]) == [0, 1] and table["tdc"].isna().tolist() == [False, True]


def test_a_labs_driver_records_its_sensor_over_ros(tmp_path):
    namespace = f"/t{random.SystemRandom().randrange(10**6)}"
    out = tmp_path / "presses.csv"
    process = start("record", str(FINGERTIP), "--ros", "--namespace", namespace, "-o", str(out))
    client = Client(namespace, name="lab_driver")
    presses = [{"material": "steel", "readings": {"pdc": 35.0, "tdc": 3.1, "slip": "slip"}},
               {"cell": [0, 0], "readings": {"pdc": 30.0, "pac_rms": -0.7}},
               {"material": "stel", "readings": {"pdc": 1.0}}]
    replies = []
    try:
        client.spin(lambda: client.publisher.get_subscription_count() > 0
                    and client.node.count_publishers(f"{client.ns}/reply") > 0, timeout=60)
        for press in presses:  # each sent until answered: a reader may miss the first
            n = len(client.got["reply"])
            end = time.monotonic() + 30
            while len(client.got["reply"]) == n:
                assert time.monotonic() < end, "the recorder never answered"
                client.publisher.publish(String(data=json.dumps(press)))
                until = time.monotonic() + 0.5
                while len(client.got["reply"]) == n and time.monotonic() < until:
                    client.executor.spin_once(timeout_sec=0.02)
            replies.append(json.loads(client.got["reply"][n].data))
    finally:
        client.close()
        status, _, err = stop(process)
    assert status == 0 and "Traceback" not in err, err
    assert replies[0]["material"] == "steel" and replies[1]["material"] == "pine"
    assert "unknown material 'stel'" in replies[2]["error"]
    table = pd.read_csv(out)
    assert set(table["material"]) == {"steel", "pine"}  # a press repeated is recorded again
    assert list(table.columns)[:6] == ["material", "pdc", "pac_rms", "tdc", "electrode_var",
                                       "slip"]
    assert "press(es) recorded" in err


def test_the_robots_log_has_every_probe_and_the_explorers_answer(explorer_node, paper, tmp_path):
    """The explorer publishes a probe's next_target before its reply: the robot pairs each
    reply with its probe by step, the last one's included, whatever the order."""
    client, _ = explorer_node
    log = tmp_path / "robot.csv"
    out = subprocess.run([BAYESPROG, "robot", str(PAPER), "--ros", "--task", "T2", "--steps",
                          "12", "--namespace", client.ns, "--json", "--log", str(log)],
                         capture_output=True, text=True, cwd=ROOT, timeout=120,
                         env={**os.environ, **ROS_ENV})
    assert out.returncode == 0, out.stderr
    table = pd.read_csv(log)
    sim = simulate(paper, "T2", "full", start_cells(paper.shape, 1, 0), np.arange(1), 0, 12)
    assert list(table["step"]) == list(range(12))
    cells = np.ravel_multi_index((table["ix"], table["iy"]), paper.shape)
    assert cells.tolist() == sim["paths"][0].tolist()
    assert (table["next_ix"].iloc[:-1].to_numpy() == table["ix"].iloc[1:].to_numpy()).all()
    assert (table["total_ms"] > 0).all()
    assert json.loads(log.with_suffix(".json").read_text())["task"] == "T2"
