"""Start the four panel_deploy nodes with config/params.yaml.

    ros2 launch panel_deploy panel_deploy.launch.py scene:=paper_4x4 real_time_factor:=1.0

Arguments: scene, rate_hz, real_time_factor, use_sim_time, namespace, frame_prefix. Then
``ros2 action send_goal /dynamics/deploy panel_deploy_interfaces/action/Deploy
"{wait_for_subscribers: 1}" --feedback`` deploys the array;
with ``namespace:=array1`` every topic, service and action but /diagnostics,
/tf and /tf_static is under /array1, so that several arrays run side by side
(``frame_prefix:=array1/`` keeps their frames apart on the global /tf); the
clock too, /array1/clock, which the nodes read as /clock (a remap) with
``use_sim_time:=true``.
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue

from panel_deploy import contract

NODES = ("array_model", "dynamics", "collision_monitor", "optimiser")


def generate_launch_description():
    params = os.path.join(get_package_share_directory("panel_deploy"), "config", "params.yaml")
    arguments = [
        DeclareLaunchArgument("scene", default_value="paper_4x4",
                              description="scene file or shipped scene name"),
        DeclareLaunchArgument("rate_hz", default_value="200.0",
                              description="joint states per simulated second"),
        DeclareLaunchArgument("real_time_factor", default_value="1.0",
                              description="simulated seconds per wall second (0: as fast as computed)"),
        DeclareLaunchArgument("use_sim_time", default_value="false",
                              description="nodes take their time from /clock"),
        DeclareLaunchArgument("namespace", default_value="",
                              description="namespace of the four nodes (one per array)"),
        DeclareLaunchArgument("frame_prefix", default_value="",
                              description="prefix of the /tf frames and the markers (e.g. "
                                          "array1/ with namespace:=array1: /tf is global)"),
    ]
    sim_time = ParameterValue(LaunchConfiguration("use_sim_time"), value_type=bool)
    overrides = {
        "array_model": {"scene": LaunchConfiguration("scene")},
        "dynamics": {"rate_hz": ParameterValue(LaunchConfiguration("rate_hz"), value_type=float),
                     "real_time_factor": ParameterValue(LaunchConfiguration("real_time_factor"),
                                                        value_type=float),
                     "frame_prefix": LaunchConfiguration("frame_prefix")},
        "collision_monitor": {"frame_prefix": LaunchConfiguration("frame_prefix")},
    }
    # The array's own simulated clock: /clock resolves in the namespace (/array1/clock).
    nodes = [Node(package="panel_deploy", executable=name, name=name, output="screen",
                  namespace=LaunchConfiguration("namespace"), remappings=[contract.CLOCK_REMAP],
                  parameters=[params, {"use_sim_time": sim_time, **overrides.get(name, {})}])
             for name in NODES]
    return LaunchDescription(arguments + nodes)
