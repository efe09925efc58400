"""``collision_monitor`` node: the streaming collision check of ``/joint_states``.

Fed by the simulator or by a real array's encoders. Per deployment it
publishes each collision as it begins (``/panel_deploy/collision_events``,
one status per event, and the pair highlighted on
``/panel_deploy/collision_markers``) and its verdict on ``/diagnostics``
(OK, or ERROR after a collision; twice a second and at every event).
A malformed message gets a WARN and is skipped.
"""

from __future__ import annotations

import math

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from visualization_msgs.msg import MarkerArray

from ..build import build_model
from ..collision import CollisionSettings
from ..errors import PanelDeployError, SceneError, shown
from ..kinematics import forward_kinematics
from ..live import StreamCheck, scene_from_yaml
from . import messages, runtime

PARAMETERS = {
    "tolerance": (-1.0, "interference depth that counts as a collision, m; negative: the scene's"),
    "refine": (True, "also check between samples (Hermite motion), so no collision is missed"),
}
STATUS = "panel_deploy/collision_monitor"


class CollisionMonitorNode(Node):
    def __init__(self, **kwargs):
        super().__init__("collision_monitor", **kwargs)
        runtime.declare(self, PARAMETERS)
        runtime.validator(self, lambda changes: self._collision(changes))
        self.add_post_set_parameters_callback(self._apply)
        self.diagnostics = self.create_publisher(DiagnosticArray, "/diagnostics", messages.EVENTS)
        self.events = self.create_publisher(DiagnosticArray, "/panel_deploy/collision_events",
                                            messages.EVENTS)
        self.markers = self.create_publisher(MarkerArray, "/panel_deploy/collision_markers",
                                             messages.EVENTS)
        self.create_subscription(String, "/panel_deploy/model", self._on_model, messages.LATCHED)
        self.create_subscription(JointState, "/joint_states", self._on_joint_state, messages.STREAM)
        runtime.trigger_service(self, "~/reset", self._reset)
        self.create_timer(0.5, self._publish_verdict)
        self.scene = None
        self.stream = None  # StreamCheck of the current model

    def _collision(self, changes=None) -> CollisionSettings:
        p = {**runtime.values(self, PARAMETERS), **(changes or {})}
        section = self.scene.collision if self.scene is not None else CollisionSettings()
        tolerance = section.tolerance if p["tolerance"] < 0 else p["tolerance"]
        if not math.isfinite(tolerance):
            raise SceneError("tolerance", f"expected a finite number, got {shown(tolerance)}")
        return CollisionSettings.from_scene(section, tolerance=tolerance, refine=p["refine"],
                                            margin=max(CollisionSettings.margin, tolerance))

    def _apply(self, params):
        if self.stream is not None:  # from the next deployment on
            self.stream.collision = self._collision()

    def _on_model(self, msg):
        try:
            self.scene = scene_from_yaml(msg.data)
            self.stream = StreamCheck(build_model(self.scene), self._collision())
        except PanelDeployError as e:
            self._warn(f"ignored a model: {e}")

    def _on_joint_state(self, msg):
        if self.stream is None:
            return self._warn("joint state skipped: no model yet on /panel_deploy/model")
        try:
            t, theta, omega = messages.read_joint_state(msg, self.stream.names, self.stream.required)
            found = self.stream.update(t, theta, omega)
        except PanelDeployError as e:
            return self._warn(f"joint state skipped: {e}")
        if found:
            R, p = forward_kinematics(self.stream.model, theta)
            self.events.publish(messages.diagnostics(
                t, *(messages.event_status(e) for e in found)))
            self.markers.publish(messages.collision_markers(self.stream.model, found[0], R, p))
            self._publish_verdict()

    def _warn(self, text):
        self.get_logger().warning(text)
        self.diagnostics.publish(messages.diagnostics(
            self.get_clock().now().nanoseconds * 1e-9, messages.status(STATUS, messages.WARN, text)))

    def _publish_verdict(self):
        if self.stream is None:
            return
        level, text, values = self.stream.verdict()
        self.diagnostics.publish(messages.diagnostics(
            values.get("t") or 0.0, messages.status(STATUS, level, text, values)))

    def _reset(self, request, response):
        if self.stream is None:
            response.success, response.message = False, "no model yet"
            return response
        self.stream.reset()
        response.success, response.message = True, "the next joint state starts a new deployment"
        return response


def main(argv=None) -> int:
    return runtime.node_main(CollisionMonitorNode, argv)
