"""``bayesprog record SCENARIO --ros -o FILE.csv``: the recorder as the ROS 2 node
``bayesprog_recorder``. Every ``probe`` line (``std_msgs/String``, the JSON of
:mod:`runner.robot.recording`) is recorded and answered on ``reply``, as ``record --stdio``
answers it: a lab's driver records its sensor on the topics it explores on."""

from __future__ import annotations

import json
import sys
import traceback
from typing import Any

from rclpy.node import Node
from std_msgs.msg import String

from runner.robot.recording import Recorder
from runner.robot.ros.explorer_node import PROBES, STREAM


class RecorderNode(Node):
    """Records the presses sent on ``probe``."""

    def __init__(self, recorder: Recorder, namespace: str = "/bayesprog", **node_options: Any):
        super().__init__("bayesprog_recorder", namespace=namespace, **node_options)
        self.recorder = recorder
        self.reply = self.create_publisher(String, "reply", STREAM)
        self.create_subscription(String, "probe", self.on_probe, PROBES)

    def on_probe(self, msg: String) -> None:
        try:
            reply = self.recorder.answer(msg.data)
        except Exception as exc:  # a fault of ours: answered, logged, and the node goes on
            traceback.print_exc(file=sys.stderr)
            reply = {"error": f"line {self.recorder.line_no}: internal error: {exc!r}"}
        if reply is not None:
            self.reply.publish(String(data=json.dumps(reply)))
