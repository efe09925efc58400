"""Test-wide set-up: DDS traffic of every test that starts rclpy stays on this machine.

Done before rclpy is imported anywhere (conftest is imported first) and
inherited by the node processes the tests start; see ros_env.
"""

import ros_env

ros_env.isolate()
