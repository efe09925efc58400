"""``array_model`` node: publishes the array's URDF and resolved scene (latched).

Parameters ``scene`` (file or shipped name) and ``stiffness_file`` (an
optimisation result, or empty) are checked when set; ``~/reload`` re-reads
them and republishes, or refuses with the reason and keeps the old model.
"""

from __future__ import annotations

from rclpy.node import Node

from .. import contract
from ..errors import PanelDeployError
from ..export.urdf import model_urdf
from ..configure import load_array
from . import messages, runtime

PARAMETERS = {
    "scene": ("paper_4x4", "scene YAML file, or the name of a scene shipped in config/scenes"),
    "stiffness_file": ("", "optimisation result whose k per hinge replaces the scene's; empty: none"),
}


class ArrayModelNode(Node):
    def __init__(self, **kwargs):
        super().__init__("array_model", **kwargs)
        runtime.declare(self, PARAMETERS, self._check)
        self.description = runtime.publisher(self, contract.ROBOT_DESCRIPTION)
        self.model_pub = runtime.publisher(self, contract.MODEL)
        runtime.trigger_service(self, contract.RELOAD, self._reload)
        self.scene, self.model, text = load_array(**runtime.values(self, PARAMETERS))
        self._publish(text)

    def _check(self, changes):
        load_array(**{**runtime.values(self, PARAMETERS), **changes})

    def _publish(self, text):
        self.description.publish(messages.string(model_urdf(self.model)))
        self.model_pub.publish(messages.string(text))
        self.get_logger().info(f"published {self.scene.name or self.scene.source}: "
                               f"{self.model.n_bodies} bodies, {len(self.model.hinges)} hinges")

    def _reload(self, request, response):
        try:
            self.scene, self.model, text = load_array(**runtime.values(self, PARAMETERS))
        except PanelDeployError as e:
            response.success, response.message = False, f"kept the old model: {e}"
            return response
        self._publish(text)
        response.success, response.message = True, f"published {self.scene.name or self.scene.source}"
        return response


def main(argv=None) -> int:
    return runtime.node_main(ArrayModelNode, argv)
