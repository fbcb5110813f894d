"""Secured mode: the nodes under DDS Security (SROS2), ``--secure KEYSTORE``.

``--secure KEYSTORE`` sets what ROS 2 reads for it, as a ROS 2 installation's
``ros2 run ... --ros-args --enclave E`` under ``ROS_SECURITY_*`` does: the keystore
(``ROS_SECURITY_KEYSTORE``), security on and enforced (``ROS_SECURITY_ENABLE=true``,
``ROS_SECURITY_STRATEGY=Enforce``), and the node's enclave (the explorer's and the recorder's
``/bayesprog/explorer``, the robot's ``/bayesprog/driver``; ``ROS_SECURITY_ENCLAVE_OVERRIDE``
names another). The keystore is :func:`runner.robot.keystore.create_keystore`'s (``bayesprog
keystore create``) or ``ros2 security``'s. The same variables set by hand, without the flag,
start the nodes secured too.

The middleware does the rest, or says it cannot: the Fast DDS of the ``bayesprog[ros]`` wheels is
built without the DDS Security plugins, and refuses to start a secured participant; that is
said in one line (:func:`refusal`), with what to use instead.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

from bayesprog import BayesprogError

#: the enclave each node runs in by default, by its part in the exchange
EXPLORER_ENCLAVE = "/bayesprog/explorer"
DRIVER_ENCLAVE = "/bayesprog/driver"

#: what Fast DDS says when it was built without its security plugins
NO_PLUGINS = "doesn't have the security libraries"


def enabled() -> bool:
    """Whether ROS 2 will start the nodes' participants with DDS Security (as rcl reads it)."""
    return os.environ.get("ROS_SECURITY_ENABLE") == "true"


def secure(keystore: Path, enclave: str) -> list[str]:
    """Turn DDS Security on, enforced, with ``keystore``; rclpy's arguments that put the node in
    ``enclave`` (unless ``ROS_SECURITY_ENCLAVE_OVERRIDE`` names another). The enclave's files
    are checked first, so that a wrong folder is said in one line."""
    enclave = os.environ.get("ROS_SECURITY_ENCLAVE_OVERRIDE") or enclave
    if not (keystore / "enclaves" / "governance.p7s").is_file():
        raise BayesprogError(f"--secure: {keystore} is not a keystore (no "
                             f"enclaves/governance.p7s): make one with bayesprog keystore "
                             f"create {keystore} --enclaves {EXPLORER_ENCLAVE} {DRIVER_ENCLAVE}")
    folder = keystore / "enclaves" / enclave.strip("/")
    lacking = [name for name in ("cert.pem", "key.pem", "permissions.p7s", "governance.p7s",
                                 "identity_ca.cert.pem", "permissions_ca.cert.pem")
               if not (folder / name).is_file()]
    if lacking:
        raise BayesprogError(f"--secure: {keystore} has no enclave {enclave} (lacking "
                             f"{', '.join(lacking)} in {folder}): add it with bayesprog "
                             f"keystore create {keystore} --enclaves {enclave}")
    os.environ.update({"ROS_SECURITY_KEYSTORE": str(keystore.resolve()),
                       "ROS_SECURITY_ENABLE": "true", "ROS_SECURITY_STRATEGY": "Enforce"})
    return ["--ros-args", "--enclave", enclave]


def refusal(exc: Exception) -> BayesprogError:
    """The middleware's refusal to start a secured node, as one line that says why and what
    to do."""
    said = "; ".join(line.strip() for line in re.sub(r", at \S+:\d+", "", str(exc)).splitlines()
                     if line.strip())
    if NO_PLUGINS in said:
        return BayesprogError(
            f"--secure: the middleware cannot run DDS Security: {said}. The Fast DDS of the "
            "bayesprog[ros] wheels is built without its security plugins: run the nodes with a "
            "ROS 2 installation whose Fast DDS has them, or use --secret FILE instead (see "
            "docs/robot.md, \"Security\")")
    return BayesprogError(f"--secure: the middleware refused the secured node: {said}")
