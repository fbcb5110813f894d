"""The explorer as a ROS 2 node, and a simulated robot node to drive it.

``bayesprog explore SCENARIO --ros`` runs :class:`runner.robot.ros.explorer_node.ExplorerNode`
(node ``bayesprog_explorer``, namespace ``/bayesprog``): it answers every ``probe`` line as
``explore --stdio`` does (:class:`runner.robot.session.Session`) and publishes the next cell, the
belief, pi_tar's posterior, the cues, the path and the registered shape for RViz.
``bayesprog robot SCENARIO --ros`` runs :class:`runner.robot.ros.robot_node.RobotNode`, a robot
whose probes are drawn from the scenario's sensor. ``docs/robot.md`` gives the contract.

rclpy and the message packages are an extra (``pip install "bayesprog[ros]"``); nothing here
imports them before a node is started, and :func:`require` says how to install them.
"""

from __future__ import annotations

import os

from bayesprog import BayesprogError

#: The messages the nodes use, by ROS 2 package.
PACKAGES = ("rclpy", "std_msgs", "geometry_msgs", "nav_msgs", "visualization_msgs",
            "sensor_msgs")


def require() -> None:
    """Import rclpy and the messages, or say in one line how to install them; check the
    domain the nodes would use."""
    import importlib

    for name in PACKAGES:
        try:
            importlib.import_module(name if name == "rclpy" else f"{name}.msg")
        except (ImportError, OSError):
            raise BayesprogError(f"--ros needs ROS 2's Python client ({name} is not installed): "
                                 'install it with pip install "bayesprog[ros]"') from None
    _check_domain()


def _check_domain() -> None:
    """ROS_DOMAIN_ID, when set, must name a domain DDS can map to ports (0 to 232)."""
    value = os.environ.get("ROS_DOMAIN_ID", "").strip()
    if value and not (value.isascii() and value.isdigit() and int(value) <= 232):
        raise BayesprogError(f"ROS_DOMAIN_ID={value!r}: expected an integer from 0 to 232 "
                             "(0 to 101 is safe on Linux)")
