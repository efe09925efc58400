"""ROS 2 nodes: thin rclpy adapters between messages and the panel_deploy core.

All rclpy imports live under this package. The executables below are what
``ros2 run panel_deploy <node>`` starts; without rclpy they say in one line
how to install it and exit with code 2.
"""

from __future__ import annotations

import importlib
import sys

from ..errors import PanelDeployError

INSTALL_HINT = ('rclpy is not installed: python -m pip install "panel_deploy[ros]" '
                '(or source a ROS 2 Jazzy installation)')
INTERFACES_HINT = ("panel_deploy_interfaces is not installed: python -m pip install "
                   "./vendor/interfaces (from the repository; see the README), or build "
                   "panel_deploy/contract/interfaces with colcon")


class MissingROSError(PanelDeployError, ImportError):
    """A ROS command was run where rclpy cannot be imported."""


def load(module: str):
    """Import ``panel_deploy.nodes.<module>``, or raise :class:`MissingROSError`."""
    try:
        return importlib.import_module(f"{__name__}.{module}")
    except ImportError as e:
        if e.name and e.name.split(".")[0] in ("rclpy", "rcl_interfaces", "std_msgs", "std_srvs",
                                               "sensor_msgs", "diagnostic_msgs", "geometry_msgs",
                                               "visualization_msgs", "rosgraph_msgs",
                                               "builtin_interfaces"):
            raise MissingROSError(f"{INSTALL_HINT} ({e.name} not found)") from None
        if e.name and e.name.split(".")[0] == "panel_deploy_interfaces":
            raise MissingROSError(INTERFACES_HINT) from None
        raise


def _executable(module: str):
    def main(argv=None) -> int:
        try:
            node_module = load(module)
        except MissingROSError as e:
            print(f"{module}: error: {e}", file=sys.stderr)
            return 2
        return node_module.main(argv)
    main.__name__ = f"{module}_main"
    main.__doc__ = f"The ``{module}`` node executable."
    return main


array_model = _executable("array_model")
dynamics = _executable("dynamics")
collision_monitor = _executable("collision_monitor")
optimiser = _executable("optimiser")
