"""``dynamics`` node: deploys the array from the stowed state and streams it.

``~/deploy`` answers at once and starts a deployment of the model last
received on ``panel_deploy/model`` with the current parameters; samples go
out on ``joint_states`` and ``/clock`` as they are computed, ``rate_hz`` per
simulated second, paced by ``real_time_factor``, stamped with simulated
time; ``panel_deploy/panels`` follows at a display rate. The outcome ends on
``/diagnostics`` (its summary, as ``panel-deploy simulate --json`` prints it,
included), or an ERROR saying why the deployment failed; the node deploys again.

``/tf`` carries every sample's link frames (each tree joint's child link in its
parent's, as robot_state_publisher would send them, which cannot hold the
loop) and ``/tf_static`` the ground's, so that RViz and Foxglove show the array
live; frames are ``frame_prefix`` + the URDF's link names (and ``world``).
tf2_msgs has no wheel on PyPI: without ``pip install ./vendor/tf2_msgs`` the
node says so once and publishes no /tf.
"""

from __future__ import annotations

import math
import time
from dataclasses import fields

from rclpy.parameter import Parameter

from .. import contract
from ..contract.cdr import SampleEncoder
from ..errors import PanelDeployError
from ..dynamics.deployment import Deployment
from ..configure import DynamicsParameters, configure
from ..timing import Pacer
from ..scene_text import scene_yaml
from ..summary import deployment_summary
from . import messages, runtime

_DOC = {
    "stiffness": "k, N m/rad: one per stiffness group or one per hinge; unset or empty: the scene's",
    "damping_ratio": "c/k of every hinge, s; negative: the scene's",
    "method": "integrator (RK23, RK45, DOP853, Radau, BDF, LSODA, dopri5, ros34pw2, compiled); empty: the scene's",
    "rtol": "relative tolerance of the integrator; 0: the scene's",
    "closure": "loop closure: penalty or exact; empty: the scene's",
    "t_end": "simulated end time, s; 0: the scene's",
    "rate_hz": "samples published per simulated second",
    "real_time_factor": "simulated seconds per wall second; 0: as fast as computed",
}
#: The node's own parameter, beside DynamicsParameters'.
FRAME_PREFIX = runtime.FRAME_PREFIX
#: Ranges ``ros2 param describe`` shows; the rest of each check is DynamicsParameters'.
_RANGE = {"rtol": (0.0, 1.0), "t_end": (0.0, 600.0), "rate_hz": (1e-3, 1e6),
          "real_time_factor": (0.0, math.inf)}
PARAMETERS = {f.name: (Parameter.Type.DOUBLE_ARRAY if f.name == "stiffness" else f.default,
                       _DOC[f.name], *([_RANGE[f.name]] if f.name in _RANGE else []))
              for f in fields(DynamicsParameters)}
PARAMETERS[FRAME_PREFIX] = ("", runtime.FRAME_PREFIX_DOC)
#: /panel_deploy/panels per wall second at most (and always the last sample).
PANEL_RATE = 30.0


class DynamicsNode(runtime.WorkerNode):
    def __init__(self, **kwargs):
        super().__init__("dynamics", **kwargs)
        runtime.declare(self, PARAMETERS, self._check)
        self.joint_states = runtime.publisher(self, contract.JOINT_STATES)
        self.panels = runtime.publisher(self, contract.PANELS)
        self.clock = runtime.publisher(self, contract.CLOCK_TOPIC)
        self.diagnostics = runtime.publisher(self, contract.DIAGNOSTICS)
        self.deployed = runtime.publisher(self, contract.DEPLOYED_SCENE)
        # Absolute, as tf2's own: a namespaced array keeps its frames apart by frame_prefix.
        if messages.TFMessage is None:
            self.tf = self.tf_static = None
            self.get_logger().warning("tf2_msgs is not installed: no /tf or /tf_static "
                                      "(pip install ./vendor/tf2_msgs, see the README)")
        else:
            self.tf = runtime.publisher(self, contract.TF)
            self.tf_static = runtime.publisher(self, contract.TF_STATIC)
        runtime.trigger_service(self, contract.DEPLOY, self._deploy)
        runtime.trigger_service(self, contract.STOP, self._stop)
        self.deployment = None  # the current or last Deployment

    def parameters(self, changes=None) -> DynamicsParameters:
        current = runtime.values(self, PARAMETERS)
        current.update(changes or {})
        del current[FRAME_PREFIX]
        current["stiffness"] = tuple(float(k) for k in current["stiffness"])
        return DynamicsParameters(**current)

    def _check(self, changes):
        runtime.check_frame_prefix(changes)
        params = self.parameters(changes)
        if self.scene is not None:  # counts and values the scene must accept
            configure(self.scene, params)

    def _deploy(self, request, response):
        if self.busy(response, "a deployment", contract.STOP):
            return response
        try:
            params = self.parameters()
            scene, model = configure(self.scene, params)
        except PanelDeployError as e:
            response.success, response.message = False, str(e)
            return response
        self.deployment = Deployment(model, scene.simulation)
        # What runs, overrides included, before its first sample: recorders and audits need it.
        self.deployed.publish(messages.string(scene_yaml(scene, model)))
        prefix = self.get_parameter(FRAME_PREFIX).value
        self.start_job("the deployment", self.diagnostics, self._run, self.deployment, scene, params,
                       prefix)
        response.success = True
        # It does not wait for subscribers: say how many will see it from the first sample.
        response.message = (f"deploying {scene.name or scene.source} to {scene.simulation.t_end:g} s "
                            f"({scene.simulation.samples} samples, "
                            f"{self.joint_states.get_subscription_count()} joint_states "
                            f"subscribers)")
        return response

    def _run(self, deployment, scene, params, prefix=""):
        model = deployment.model
        pacer = Pacer(params.real_time_factor, deployment.stopping)
        # The contract's own bytes, as recordings store them: published as they are.
        encoder = SampleEncoder(model, prefix)
        shown = -math.inf
        if self.tf_static is not None:
            self.tf_static.publish(encoder.tf_static())
        start = time.monotonic()
        for s in deployment:
            pacer.wait(s.t)
            (clock, joint_state, panels, tf), = encoder.encode([s])
            self.clock.publish(clock)
            self.joint_states.publish(joint_state)
            if self.tf is not None:
                self.tf.publish(tf)
            # Markers are for eyes: a display rate is enough.
            now = time.monotonic()
            if now - shown >= 1.0 / PANEL_RATE or s.t >= deployment.settings.t_end:
                self.panels.publish(panels)
                shown = now
        published = time.monotonic() - start
        result = deployment.result
        s = deployment_summary(model, result, flat_tolerance=scene.simulation.flat_tolerance)
        values = contract.outcome_values(s, len(result.t))
        values["publish_wall_time"] = published  # s from the first block to the last message
        self.diagnostics.publish(messages.diagnostics(float(result.t[-1]), messages.status(
            self.get_fully_qualified_name(), contract.outcome_level(s), s["message"], values)))

    def _stop(self, request, response):
        if not self.running:
            response.success, response.message = False, "no deployment is running"
            return response
        self.deployment.stop()
        response.success, response.message = True, "stopping at the end of the current block"
        return response

    def close(self):
        if self.running:
            self.deployment.stop()
            self._worker.join(timeout=5.0)


def main(argv=None) -> int:
    return runtime.node_main(DynamicsNode, argv)
