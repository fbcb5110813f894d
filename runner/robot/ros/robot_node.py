"""``bayesprog robot SCENARIO --ros``: a simulated robot, the ROS 2 node ``bayesprog_robot``.

It probes its start cell with the scenario's sensor, publishes the reading on ``probe`` (one
JSON line, as ``explore --stdio`` reads it), and on each ``next_target`` probes that cell and
publishes again, for N probes. With ``--physics`` its readings come from the simulated
fingertip (:mod:`runner.world.physics`) and it publishes the fingertip's pose after each probe
(``fingertip``, a ``geometry_msgs/TransformStamped`` from the workspace frame to
``fingertip``). With ``--seed S --run R`` its start cell and readings are run
R's of an experiment of seed S, and it asks the explorer to decide as in that run
(``{"reset": {"seed": S, "run": R}}``), so the closed loop repeats that run's path.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from geometry_msgs.msg import PointStamped, TransformStamped
from rclpy.node import Node
from std_msgs.msg import String

from runner.experiments.log import SessionLog
from runner.experiments.loop import make_sensor, reading_seed, start_cell
from runner.experiments.metrics import BorderDistance, moves
from runner.robot.ros.explorer_node import LATCHED, PROBES, STREAM
from runner.robot.secret import KEY as SECRET_KEY
from runner.robot.secret import REFUSED
from runner.robot.session import probe_line
from runner.world.physics import ProbeSpec
from runner.world.readings import Readings, shown
from runner.world.scenario import Scenario


@dataclass
class RobotOptions:
    task: str
    steps: int = 100
    #: the robot is run ``run`` of an experiment of ``seed``: start cell, readings, decisions
    seed: int = 0
    run: int = 0
    #: seconds to wait for the explorer to appear, and for each of its answers
    timeout: float = 60.0
    #: the simulated fingertip's probes (MuJoCo) instead of the scenario's sensor
    physics: ProbeSpec | None = None
    #: the frame the fingertip's pose is given in
    frame: str = "workspace"
    #: where every probe and its answer are written, when asked (``--log``)
    log: SessionLog | None = None
    #: the explorer's secret, sent with every line (``--secret FILE``)
    secret: str | None = None


@dataclass
class Outcome:
    """How the session ended: ``error`` None when every probe was answered."""

    cells: list[int] = field(default_factory=list)
    error: str | None = None
    #: the error is that no explorer was found (the user's to fix: start one)
    no_explorer: bool = False


#: how long a physics robot that is done waits for a viewer of its fingertip's poses, and how
#: long it then leaves them to be delivered (seconds)
POSE_LINGER = 2.0
POSE_DELIVERY = 0.3


class RobotNode(Node):
    """A simulated robot on ``scenario``; :meth:`advance` drives it from a spin loop."""

    def __init__(self, scenario: Scenario, options: RobotOptions, namespace: str = "/bayesprog",
                 **node_options: Any):
        super().__init__("bayesprog_robot", namespace=namespace, **node_options)
        self.scenario, self.options = scenario, options
        seed, run = options.seed, options.run
        self.sensor = make_sensor(scenario, [reading_seed(seed, run)], options.physics)
        # the fingertip's pose, where a TF broadcaster would put it: frame ``fingertip`` in
        # the workspace frame (tf2's messages are not among the extra's wheels)
        # transient-local, as the explorer's path: a late viewer gets the last ten poses
        self.fingertip = (self.create_publisher(TransformStamped, "fingertip", LATCHED)
                          if options.physics is not None else None)
        self.start = start_cell(scenario.shape, seed, run)
        self.gamma = BorderDistance(scenario.centres, scenario.border(options.task), 1)
        self.outcome = Outcome()
        self.probe = self.create_publisher(String, "probe", PROBES)
        self.create_subscription(PointStamped, "next_target", self.on_next_target, STREAM)
        self.create_subscription(String, "reply", self.on_reply, STREAM)
        self._reset_sent: float | None = None
        #: our probes not answered yet, by step: the cell, its readings and when it was sent
        self._pending: dict[int, tuple[list[int], Readings, float]] = {}
        self._ready = False  # the explorer answered the reset
        self._refusals = 0  # replies that refused a line for its secret (anyone's)
        self._waiting_since = time.monotonic()
        self._created = time.monotonic()
        self.done = False
        self._done_at: float | None = None
        self._matched_at: float | None = None

    # the loop ---------------------------------------------------------------------------------
    def settled(self) -> bool:
        """Done, and the fingertip's last poses given the time to reach a viewer that matched
        late (transient-local keeps them only while this node lives): at most
        :data:`POSE_LINGER` seconds, :data:`POSE_DELIVERY` once a viewer is there."""
        if not self.done:
            return False
        now = time.monotonic()
        if self._done_at is None:
            self._done_at = now
        if self.options.log is not None and self._pending and \
                now - self._done_at < POSE_LINGER:
            return False  # the last probes' answers, for the log (the explorer sends them last)
        if self.fingertip is None:
            return True
        if self.fingertip.get_subscription_count() > 0:
            if self._matched_at is None:
                self._matched_at = now
            return now - self._matched_at >= POSE_DELIVERY
        return now - self._done_at >= POSE_LINGER

    def reset_line(self) -> dict:
        """A new session that decides as the robot's run of an experiment does."""
        return {"reset": {"seed": self.options.seed, "run": self.options.run}}

    def advance(self) -> None:
        """Called between spins: find the explorer, reset it, watch the time."""
        now = time.monotonic()
        if self.done:
            return
        if not self._ready:
            found = (self.probe.get_subscription_count() > 0
                     and self.count_publishers("next_target") > 0
                     and self.count_publishers("reply") > 0)
            if not found:
                if now - self._created > self.options.timeout:
                    self.fail(f"no explorer answers on {self.probe.topic_name} after "
                              f"{self.options.timeout:g} s: start bayesprog explore SCENARIO "
                              "--ros first (same namespace and ROS_DOMAIN_ID)")
                    self.outcome.no_explorer = True
                return
            if self._reset_sent is None or now - self._reset_sent > 1.0:
                self.send(self.reset_line())  # again each second until it is answered
                self._reset_sent = now
            if now - self._created > self.options.timeout:
                self.fail(f"the explorer on {self.probe.topic_name} does not answer its reset "
                          f"after {self.options.timeout:g} s" + self.refusals_seen())
            return
        if now - self._waiting_since > self.options.timeout:
            if len(self.outcome.cells) >= self.options.steps:
                self.done = True  # every probe was sent; the last one's answer is not needed
                return
            self.fail(f"the explorer is gone: no next_target after {self.options.timeout:g} s "
                      f"(after probe {len(self.outcome.cells)}); the outcome above is what was "
                      "done until then")

    def on_reply(self, msg: String) -> None:
        """The explorer's answers, read for our reset and for a refusal of our probe; replies
        to lines of anyone else in the namespace are none of the robot's business."""
        try:
            reply = json.loads(msg.data)
        except ValueError:
            return
        if not isinstance(reply, dict):
            return
        if reply.get("refused") == REFUSED:
            # a line without the explorer's secret: a stranger's (ours carry it), or all of
            # ours if our secret is not the explorer's (then our reset is never answered)
            self._refusals += 1
            return
        k = reply.get("k")
        if isinstance(k, int) and not isinstance(k, bool) and k in self._pending:
            # the answer to one of our probes (its next_target may have come first)
            self.write_log(reply, *self._pending.pop(k))
            return
        if self.done:
            return
        if not self._ready:
            if reply.get("reset") is True and reply.get("seed") == self.options.seed \
                    and reply.get("run") == self.options.run:
                self._ready = True
                self.probe_cell(self.start)
            return
        if "error" in reply and self._pending:
            self.fail(f"the explorer refused a probe: {reply['error']}")

    def on_next_target(self, msg: PointStamped) -> None:
        if not self._ready or self.done:
            return
        if len(self.outcome.cells) >= self.options.steps:
            self.done = True  # the explorer has taken the last probe
            return
        p = msg.point
        centre = np.array([p.x, p.y, p.z][:self.scenario.dims])
        cell = np.floor(centre / self.scenario.cell).astype(int)
        if np.any(cell < 0) or np.any(cell >= np.asarray(self.scenario.shape)):
            self.fail(f"next_target {centre.tolist()} m lies outside the grid")
            return
        self.probe_cell(cell)

    def probe_cell(self, cell: np.ndarray) -> None:
        flat = int(np.ravel_multi_index(tuple(int(i) for i in cell), self.scenario.shape))
        readings = self.sensor.probe(np.array([flat]))
        self.publish_fingertip()
        self.gamma.probe(np.array([flat]))
        self.outcome.cells.append(flat)
        k = len(self.outcome.cells) - 1
        # the step it answers: a late or repeated message is refused, never taken as another
        self.send(probe_line([int(i) for i in cell], readings, k=k,
                             perception=self.scenario.readings))
        self._waiting_since = time.monotonic()
        self._pending[k] = ([int(i) for i in cell], readings, self._waiting_since)

    def write_log(self, reply: dict, cell: list[int], readings: Readings, sent: float) -> None:
        """A probe of ours and the explorer's answer as a row of the log (the explorer's own
        phases are its to time: here only the round trip)."""
        log = self.options.log
        if log is None:
            return
        perception = self.scenario.readings
        if log.columns is None:
            log.start(perception, self.scenario.dims, {
                "scenario": str(self.scenario.path.resolve()), "task": self.options.task,
                "seed": self.options.seed, "run": self.options.run, "ablate": []})
        flat = int(np.ravel_multi_index(tuple(cell), self.scenario.shape))
        truth = self.scenario.materials[int(self.scenario.material_map.ravel()[flat])]
        probed = reply.get("probed", {})
        log.write(int(reply["k"]), cell, [(i + 0.5) * self.scenario.cell for i in cell],
                  shown(perception, readings), list(reply.get("missing", [])),
                  [reply["warning"]] if "warning" in reply else [], truth,
                  str(probed.get("material", "")), float(probed.get("probability", np.nan)),
                  reply.get("next"), {}, time.monotonic() - sent)

    def publish_fingertip(self) -> None:
        """Where the fingertip pressed last (its positioning error included), on the surface."""
        probes = getattr(self.sensor, "last", [])
        if self.fingertip is None or not probes:
            return
        pose = TransformStamped()
        pose.header.stamp = self.get_clock().now().to_msg()
        pose.header.frame_id = self.options.frame
        pose.child_frame_id = "fingertip"
        x, y = probes[-1].at
        pose.transform.translation.x, pose.transform.translation.y = float(x), float(y)
        pose.transform.rotation.w = 1.0
        self.fingertip.publish(pose)

    def send(self, line: dict) -> None:
        if self.options.secret is not None:
            line = {**line, SECRET_KEY: self.options.secret}
        self.probe.publish(String(data=json.dumps(line)))

    def refusals_seen(self) -> str:
        """What the replies refused for their secret say of the explorer, for a message."""
        if not self._refusals:
            return ""
        if self.options.secret is None:
            return (f" (it refused {self._refusals} line(s) without its secret: it was started "
                    "with --secret FILE; give the robot --secret FILE too)")
        return (f" (it refused {self._refusals} line(s) for their secret: is --secret the file "
                "the explorer was started with?)")

    def fail(self, why: str) -> None:
        self.outcome.error = why
        self.done = True

    # what it prints at the end ----------------------------------------------------------------
    def summary(self) -> dict:
        """The run's Gamma (eq. 16, metres, and per border cell in mm) and path length."""
        cells = np.asarray(self.outcome.cells, dtype=np.int64)
        border = int(self.scenario.border(self.options.task).sum())
        gamma = float(self.gamma.gamma()[0]) if len(cells) else float("nan")
        length = float(moves(cells[None], self.scenario.centres).sum()) if len(cells) else 0.0
        shape = self.scenario.shape
        path = [[int(i) for i in np.unravel_index(c, shape)] for c in cells]
        return {"probes": len(cells), "gamma": gamma, "border_cells": border,
                "gamma_per_border_cell_mm": 1000 * gamma / max(border, 1),
                "path_length": length, "path": path}
