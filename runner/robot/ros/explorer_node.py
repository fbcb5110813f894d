"""``bayesprog explore SCENARIO --ros``: the explorer as the ROS 2 node ``bayesprog_explorer``.

Every ``probe`` line (``std_msgs/String``) is answered by a :class:`runner.robot.session.Session`,
as ``explore --stdio`` answers it, on ``reply``; after a probe the node publishes the next cell
(``next_target``), then the belief, pi_tar's posterior, the cues, the path and the registered
shape. The topics, types and QoS are the contract of ``docs/robot.md``.
"""

from __future__ import annotations

import json
import sys
import time
import traceback
from typing import Any

import numpy as np
from geometry_msgs.msg import PointStamped
from nav_msgs.msg import OccupancyGrid, Path
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import PointCloud2
from std_msgs.msg import String
from visualization_msgs.msg import MarkerArray

from runner.attention.shape import rotation
from runner.robot.ros import messages
from runner.robot.session import Session

#: replies and the next cell: reliable, for whoever listens now
STREAM = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                    reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
#: probes: reliable, with room for a burst of lines sent faster than they are answered
PROBES = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000,
                    reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
#: the grids, the path and the shape: kept for a viewer that starts late, as a map server does
LATCHED = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10,
                     reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)

#: the fields published over the grid after every probe, by topic
FIELDS = ("belief", "posterior", "saliency", "uncertainty", "inhibition")


class ExplorerNode(Node):
    """Answers probes for one exploration; ``frame`` names the workspace's frame."""

    def __init__(self, session: Session, namespace: str = "/bayesprog", frame: str = "workspace",
                 **node_options: Any):
        super().__init__("bayesprog_explorer", namespace=namespace, **node_options)
        self.session = session
        self.frame = frame
        scenario = session.explorer.scenario
        self.shape, self.cell, self.centres = scenario.shape, scenario.cell, scenario.centres
        field_type = OccupancyGrid if len(self.shape) == 2 else PointCloud2
        self.reply = self.create_publisher(String, "reply", STREAM)
        self.next_target = self.create_publisher(PointStamped, "next_target", STREAM)
        self.fields = {name: self.create_publisher(field_type, name, LATCHED) for name in FIELDS}
        self.path = self.create_publisher(Path, "path", LATCHED)
        self.shape_markers = self.create_publisher(MarkerArray, "shape", LATCHED)
        self.probes = self.create_subscription(String, "probe", self.on_probe, PROBES)
        self._senders = 0  # publishers on probe when a listener was last awaited
        self._path = messages.GrowingPath()
        self.answered = 0
        self.publish_cleared()

    def header(self) -> messages.Header:
        return messages.header(self.frame, self.get_clock().now().to_msg())

    def on_probe(self, msg: String) -> None:
        line = msg.data if msg.data.endswith("\n") else msg.data + "\n"
        try:
            reply = self.session.answer(line)
        except Exception as exc:  # a fault of ours: answered, logged, and the node goes on
            traceback.print_exc(file=sys.stderr)
            reply = {"error": f"line {self.session.line_no}: internal error: {exc!r}"}
        if reply is None:
            return
        stepped = self.session.stepped
        self.await_listener()
        head = self.header()
        if stepped:
            self.next_target.publish(messages.point_stamped(self.centre(reply["next"]), head))
        self.reply.publish(String(data=json.dumps(reply)))
        try:
            if stepped:
                self.answered += 1
                self.publish_state(reply, head)
            elif "reset" in reply:
                self.publish_cleared()
        except Exception:  # a fault of ours in what RViz shows: logged, and the node goes on
            traceback.print_exc(file=sys.stderr)

    def await_listener(self, most: float = 1.0) -> None:
        """A probe can arrive before this node has matched its sender's subscriptions (each
        side discovers the other on its own): when a new sender has appeared and nobody is
        matched yet on ``reply`` or on ``next_target``, wait up to ``most`` seconds for both,
        so the answer is not sent into the void. Once per new sender: a sender that listens to
        neither pays it once."""
        senders = self.probes.get_publisher_count()
        if senders == self._senders:
            return
        self._senders = senders
        end = time.monotonic() + most
        while ((self.reply.get_subscription_count() == 0
                or self.next_target.get_subscription_count() == 0) and time.monotonic() < end):
            time.sleep(0.005)

    def centre(self, cell: list[int]) -> np.ndarray:
        return (np.asarray(cell, float) + 0.5) * self.cell

    # what RViz shows --------------------------------------------------------------------------
    def publish_state(self, reply: dict, head: messages.Header) -> None:
        e = self.session.explorer
        d = e.decision
        posterior = e.target_probabilities[0]
        values = {"belief": messages.percent(e.belief()[0]),
                  "posterior": messages.percent(posterior, float(np.max(posterior))),
                  "saliency": messages.percent(d.saliency[0]),
                  "uncertainty": messages.percent(d.uncertainty[0]),
                  "inhibition": messages.percent(d.inhibition[0])}
        for name, publisher in self.fields.items():
            publisher.publish(messages.field(values[name], self.shape, self.cell, self.centres,
                                             head))
        self._path.append(self.centre(reply["probed"]["cell"]), head)
        self.path.publish(self._path.serialized(head))
        self.shape_markers.publish(self.markers(reply["shape"]["posterior"], head))

    def publish_cleared(self) -> None:
        """Nothing probed yet: unknown grids, an empty path, no shape."""
        head = self.header()
        unknown = np.full(len(self.centres), -1, np.int8)
        for publisher in self.fields.values():
            publisher.publish(messages.field(unknown, self.shape, self.cell, self.centres, head))
        self._path.clear()
        self.path.publish(self._path.serialized(head))
        self.shape_markers.publish(messages.clear_markers(head))

    def markers(self, posterior: dict[str, float] | None, head: messages.Header) -> MarkerArray:
        """The most probable template as registered, while the shape cue is in force."""
        e = self.session.explorer
        if posterior is None or e.registration is None:
            return messages.clear_markers(head)
        name = max(posterior, key=lambda n: posterior[n])
        t = list(e.shape_names).index(name)
        reg = e.registration
        if len(self.shape) == 2:
            outline = e.outlines[t] @ rotation(reg.angle[0, t]).T + reg.shift[0, t]
            return messages.shape_markers(outline, name, posterior[name], self.cell, head,
                                          closed=True)
        return messages.shape_markers(reg.points[0, t], name, posterior[name], self.cell, head,
                                      closed=False)

