"""Keep DDS on this machine: localhost discovery, a domain of this process's own,
and the repository's Fast DDS profile (UDPv4 on 127.0.0.1 plus shared memory).

Call :func:`isolate` before rclpy starts; node processes started afterwards
inherit the environment.
"""

import os
from pathlib import Path

PROFILE = Path(__file__).resolve().parent.parent / "config" / "fastdds_loopback.xml"


def isolate(domain: int | None = None) -> None:
    """``domain``, else ``PANEL_DEPLOY_TEST_DOMAIN`` (two runs at once, as CI's two
    Pythons, name theirs), else one from this process's id; each pytest-xdist
    worker of a run (``-n``) then takes a domain of its own, 53 further on
    (coprime to the 230 domains used, so up to 230 workers never share one)."""
    if domain is None:
        domain = int(os.environ.get("PANEL_DEPLOY_TEST_DOMAIN") or 1 + os.getpid() % 100)
        worker = os.environ.get("PYTEST_XDIST_WORKER", "gw0")
        domain = 1 + (domain - 1 + 53 * int(worker.removeprefix("gw") or 0)) % 230
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    os.environ.pop("ROS_LOCALHOST_ONLY", None)
    os.environ["ROS_DOMAIN_ID"] = str(domain)
    os.environ["FASTRTPS_DEFAULT_PROFILES_FILE"] = str(PROFILE)
    os.environ.setdefault("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")
