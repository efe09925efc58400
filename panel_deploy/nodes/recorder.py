"""The recorder of ``panel-deploy run --record``: the live graph's topics to MCAP,
as ``ros2 bag record`` of them would store them, plus ``/tf``.

Messages are written as received (CDR bytes, rclpy's stray padding
trimmed), with log time = simulated time: a JointState's stamp, a Clock's
value, and for everything else the last simulated time seen (0 before the
deployment starts). The recorder writes ``/tf`` itself, from each
JointState and the model, with ``/tf_static``, as robot_state_publisher
would: the dynamics node's own /tf (the same transforms) needs tf2_msgs,
which has no wheel (vendor/tf2_msgs builds it), and a recording needs none.
"""

from __future__ import annotations

from pathlib import Path

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from visualization_msgs.msg import MarkerArray

from ..build import build_model
from ..errors import PanelDeployError, TrajectoryError
from ..kinematics import forward_kinematics
from ..live import scene_from_yaml
from ..record import messages as recorded
from ..record.writer import Recorder, run_metadata
from . import messages

#: Topic subscribed -> (rclpy type, QoS) of what the graph publishes and the
#: recorder keeps. Relative as the nodes' own, so that a recorder in a
#: namespace records its array's; the file names each topic absolute without
#: the namespace (:func:`recorded_name`), as its readers expect.
TOPICS = {
    "robot_description": (String, messages.LATCHED),
    "panel_deploy/model": (String, messages.LATCHED),
    "joint_states": (JointState, messages.STREAM),
    "panel_deploy/panels": (MarkerArray, messages.EVENTS),
    "/diagnostics": (DiagnosticArray, messages.EVENTS),
    "panel_deploy/collision_events": (DiagnosticArray, messages.EVENTS),
    "/clock": (Clock, messages.STREAM),
}


def recorded_name(topic: str) -> str:
    return "/" + topic.lstrip("/")


class RecorderNode(Node):
    def __init__(self, path, **kwargs):
        super().__init__("panel_deploy_recorder", **kwargs)
        self.recorder = Recorder(Path(path))
        self.recorder.metadata("run", run_metadata())
        for topic, (typename, _) in recorded.TOPICS.items():  # every topic, even one left empty
            self.recorder.channel(topic, typename)
        self.model = None
        #: Why the recording stopped (the file could not be written), or None.
        self.failed = None
        self.now = 0  # ns of simulated time
        self.received = {recorded_name(topic): 0 for topic in TOPICS}
        for topic, (msg_type, qos) in TOPICS.items():
            self.create_subscription(msg_type, topic, self._writer(recorded_name(topic)), qos,
                                     raw=True)

    def _writer(self, topic):
        typename = recorded.TOPICS[topic][0]

        def write(data):
            self.received[topic] += 1  # the run waits for the recorder, file or not
            if self.failed is not None:
                return
            try:
                record(data)
            except TrajectoryError as e:  # disk full: the run goes on, reported at its end
                self.failed = str(e)
                self.get_logger().error(f"recording stopped: {e}")

        def record(data):
            data = recorded.trim(data, typename)
            if topic in ("/joint_states", "/clock"):
                message = recorded.deserialize(data, typename)
                stamp = message.header.stamp if topic == "/joint_states" else message.clock
                self.now = stamp.sec * 1_000_000_000 + stamp.nanosec
                if topic == "/joint_states":
                    self._tf(message)
            elif topic == "/panel_deploy/model":
                self._model(recorded.deserialize(data, typename).data)
            self.recorder.write(topic, typename, data, self.now)
        return write

    def _model(self, text):
        try:
            scene = scene_from_yaml(text)
            self.model = build_model(scene)
        except PanelDeployError as e:
            self.get_logger().warning(f"recording without /tf: {e}")
            return
        self.recorder.metadata("scene", {"name": scene.name or "", "yaml": text})
        self.recorder.write("/tf_static", recorded.TF_MESSAGE, recorded.tf_static(self.model),
                            self.now)

    def _tf(self, joint_state):
        if self.model is None:
            return
        index = {name: i for i, name in enumerate(joint_state.name)}
        try:
            theta = [joint_state.position[index[self.model.hinges[h].name]]
                     for h in self.model.joints]
        except KeyError:
            return  # not this model's joint states: recorded, but no /tf for them
        R, p = forward_kinematics(self.model, theta)
        self.recorder.write("/tf", recorded.TF_MESSAGE,
                            recorded.tf_message(self.model, R, p, self.now * 1e-9), self.now)

    def close(self, outcome: dict | None = None):
        """Write the ``outcome`` metadata record (if given) and the file's summary."""
        if self.recorder.closed:
            return
        try:
            if outcome is not None:
                self.recorder.metadata("outcome", outcome)
            self.recorder.close()
        except TrajectoryError as e:
            self.failed = str(e)
