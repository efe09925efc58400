"""The recorder of ``panel-deploy run --record``: every topic of the contract to
one MCAP file through :class:`~panel_deploy.record.writer.DeploymentWriter`,
the path ``simulate --record`` takes too (see there what it writes).

Messages are recorded as received (CDR bytes) under their resolved names,
so a graph in a namespace keeps it. ``/tf`` and ``/tf_static`` are written
by the writer from the deployed model, as robot_state_publisher would: the
dynamics node's own are global and need tf2_msgs (no wheel; vendor/interfaces
builds it), and a recording needs neither.
"""

from __future__ import annotations

from pathlib import Path

from rclpy.node import Node

from .. import contract
from ..errors import PanelDeployError, TrajectoryError
from ..record.writer import DeploymentWriter
from . import runtime

#: What the recorder subscribes to: every contract topic but those the writer makes.
SUBSCRIBED = tuple(t for t in contract.TOPICS if t not in (contract.TF, contract.TF_STATIC))


class RecorderNode(Node):
    def __init__(self, path, **kwargs):
        super().__init__("panel_deploy_recorder", **kwargs)
        self.recording = DeploymentWriter(Path(path), self.get_namespace())
        #: Why the recording stopped (the file could not be written), or None.
        self.failed = None
        #: Messages received per topic (contract name), written or not.
        self.received = {topic.name: 0 for topic in SUBSCRIBED}
        for topic in SUBSCRIBED:
            runtime.subscription(self, topic, self._writer(topic), raw=True)

    def _writer(self, topic):
        def write(data):
            self.received[topic.name] += 1  # the run waits for the recorder, file or not
            if self.failed is not None:
                return
            try:
                self.recording.receive(topic, data)
            except TrajectoryError as e:  # disk full: the run goes on, reported at its end
                self.failed = str(e)
                self.get_logger().error(f"recording stopped: {e}")
            except PanelDeployError as e:
                self.get_logger().warning(f"recorded {topic.name}, but not as a model: {e}")
        return write

    def close(self, summary: dict | None = None):
        """Write the ``outcome`` record of ``summary`` (if given) and the file's summary."""
        try:
            self.recording.close(summary)
        except TrajectoryError as e:
            self.failed = str(e)
