"""A bridge between a robot hand's driver and ``bayesprog explore --ros`` (docs/robot.md).

It assumes a driver that
  * takes a fingertip goal on ``/hand/goal`` (geometry_msgs/PointStamped, in the workspace's
    frame, metres), moves there and presses, and
  * publishes what the press felt on ``/hand/features`` (std_msgs/Float64MultiArray:
    [texture, compliance], on the scale pi_per was written or learned for).

Put your driver's topics and types in their place. The bridge sends the hand to the start cell,
once the explorer has answered its reset, and from then on turns every press into one probe
line for the explorer and every ``next_target`` into a goal for the hand:

    python docs/examples/ros_bridge.py --cell 0.01 --start 5 7 [--namespace /bayesprog]
        [--frame workspace]
"""

from __future__ import annotations

import argparse
import json
import math

import rclpy
import rclpy.executors
from geometry_msgs.msg import PointStamped
from rclpy.node import Node
from std_msgs.msg import Float64MultiArray, String


class Bridge(Node):
    def __init__(self, cell: float, start: list[int], namespace: str, frame: str):
        super().__init__("hand_bridge")
        self.cell_size, self.frame = cell, frame
        self.cell = start  # the cell the hand is sent to, and presses next
        self.dims = len(start)  # 2 on a surface of cells, 3 in a volume
        self.goal = self.create_publisher(PointStamped, "/hand/goal", 10)
        self.probe = self.create_publisher(String, f"{namespace}/probe", 10)
        self.create_subscription(Float64MultiArray, "/hand/features", self.on_features, 10)
        self.create_subscription(PointStamped, f"{namespace}/next_target", self.on_target, 10)
        self.create_subscription(String, f"{namespace}/reply", self.on_reply, 10)
        self.started, self.waiting = False, False
        self.timer = self.create_timer(0.5, self.reset)

    def reset(self) -> None:
        """Start a new exploration: sent each half second until the explorer answers (a message
        sent before the explorer has matched this node is not delivered)."""
        if self.goal.get_subscription_count() > 0:  # the driver listens
            self.probe.publish(String(data=json.dumps({"reset": {}})))
        elif not self.waiting:
            self.waiting = True
            self.get_logger().info("waiting for a driver to subscribe to /hand/goal")

    def on_reply(self, msg: String) -> None:
        reply = json.loads(msg.data)
        if "error" in reply:  # e.g. a reading that is not a number: press the same cell again
            self.get_logger().error(f"the explorer refused a probe: {reply['error']}")
            if self.started:
                self.send_goal()
        elif reply.get("reset") and not self.started:  # the first goal: the start cell
            self.started = True
            self.timer.cancel()
            self.send_goal()

    def send_goal(self) -> None:
        goal = PointStamped()
        goal.header.frame_id = self.frame
        goal.header.stamp = self.get_clock().now().to_msg()
        centre = [(i + 0.5) * self.cell_size for i in self.cell] + [0.0]
        goal.point.x, goal.point.y, goal.point.z = centre[:3]
        self.goal.publish(goal)

    def on_features(self, msg: Float64MultiArray) -> None:
        texture, compliance = msg.data[0], msg.data[1]
        self.probe.publish(String(data=json.dumps(
            {"cell": self.cell, "texture": texture, "compliance": compliance})))

    def on_target(self, msg: PointStamped) -> None:
        p = msg.point
        self.cell = [math.floor(v / self.cell_size) for v in (p.x, p.y, p.z)[:self.dims]]
        self.send_goal()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cell", type=float, required=True, help="cell size, metres")
    parser.add_argument("--start", type=int, nargs="+", required=True, help="ix iy [iz]")
    parser.add_argument("--namespace", default="/bayesprog")
    parser.add_argument("--frame", default="workspace", help="the explorer's --frame")
    args = parser.parse_args()
    rclpy.init()
    node = Bridge(args.cell, args.start, args.namespace.rstrip("/"), args.frame)
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, rclpy.executors.ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
