"""Test-wide set-up: DDS traffic of every test that starts rclpy stays on this machine.

Set before rclpy is imported anywhere (conftest is imported first), and
inherited by the node processes the tests start: discovery on localhost
only, a domain of this run's own, and the repository's Fast DDS profile
(UDPv4 bound to 127.0.0.1 plus shared memory, built-in transports off).
"""

import os
from pathlib import Path

PROFILE = Path(__file__).resolve().parent.parent / "config" / "fastdds_loopback.xml"

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.pop("ROS_LOCALHOST_ONLY", None)
os.environ["ROS_DOMAIN_ID"] = str(1 + os.getpid() % 100)
os.environ["FASTRTPS_DEFAULT_PROFILES_FILE"] = str(PROFILE)
os.environ.setdefault("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")
