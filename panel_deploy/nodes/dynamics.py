"""``dynamics`` node: deploys the array from the stowed state and streams it.

A goal on the ``~/deploy`` action (``panel_deploy_interfaces/action/Deploy``)
deploys the model last received on ``panel_deploy/model`` with the current
parameters, after waiting (at most 30 s) for the goal's number of
``joint_states`` subscribers; samples go out on ``joint_states`` and
``/clock`` as they are computed, ``rate_hz`` per simulated second, paced by
``real_time_factor``, stamped with simulated time (for a model with panel
contact each with its interval's fastest contact onset on
``dynamics/contact_onsets``, which joint states cannot show); ``panel_deploy/panels``
follows at a display rate, the feedback ten times a second. The outcome is
the goal's result (its summary, as ``panel-deploy simulate --json`` prints
it, included) and a status on ``/diagnostics``; a goal that cannot run (one
running already, no model, parameters the model refuses) is aborted with the
reason. Cancelling the goal stops the deployment at the end of the current
block; the result then holds what was computed.

``/tf`` carries every sample's link frames (each tree joint's child link in its
parent's, as robot_state_publisher would send them, which cannot hold the
loop) and ``/tf_static`` the ground's, so that RViz and Foxglove show the array
live; frames are ``frame_prefix`` + the URDF's link names (and ``world``).
"""

from __future__ import annotations

import math
import time
from dataclasses import fields

from panel_deploy_interfaces.action import Deploy
from rclpy.parameter import Parameter

from .. import contract
from ..contract.cdr import SampleEncoder
from ..dynamics.deployment import Deployment
from ..configure import DynamicsParameters, configure
from ..timing import Pacer
from ..scene_text import scene_yaml
from ..summary import deployment_summary
from . import messages, runtime

_DOC = {
    "stiffness": "k, N m/rad: one per stiffness group or one per hinge; unset or empty: the scene's",
    "damping_ratio": "c/k of every hinge, s; negative: the scene's",
    "method": "integrator (RK23, RK45, DOP853, Radau, BDF, LSODA, dopri5, tsit5, ros34pw2, compiled); "
              "empty: the scene's",
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
#: Deploy feedback per wall second at most.
FEEDBACK_RATE = 10.0


class DynamicsNode(runtime.WorkerNode):
    def __init__(self, **kwargs):
        super().__init__("dynamics", **kwargs)
        runtime.declare(self, PARAMETERS, self._check)
        self.joint_states = runtime.publisher(self, contract.JOINT_STATES)
        self.onsets = runtime.publisher(self, contract.CONTACT_ONSETS)
        self.panels = runtime.publisher(self, contract.PANELS)
        self.clock = runtime.publisher(self, contract.CLOCK_TOPIC)
        self.diagnostics = runtime.publisher(self, contract.DIAGNOSTICS)
        self.deployed = runtime.publisher(self, contract.DEPLOYED_SCENE)
        # Absolute, as tf2's own: a namespaced array keeps its frames apart by frame_prefix.
        self.tf = runtime.publisher(self, contract.TF)
        self.tf_static = runtime.publisher(self, contract.TF_STATIC)
        self.action_server(contract.DEPLOY, self._deploy, self._stop, self.diagnostics)
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

    def _deploy(self, goal_handle):
        params = self.parameters()
        scene, model = configure(self.scene, params)
        self.deployment = Deployment(model, scene.simulation)
        # What runs, overrides included, before its first sample: recorders and audits need it.
        self.deployed.publish(messages.string(scene_yaml(scene, model)))
        prefix = self.get_parameter(FRAME_PREFIX).value
        self.get_logger().info(f"deploying {scene.name or scene.source} to "
                               f"{scene.simulation.t_end:g} s ({scene.simulation.samples} samples)")
        return self._run, (self.deployment, scene, params, prefix)

    def _subscribers(self, wanted: int, deployment) -> int:
        """joint_states subscribers, once ``wanted`` are there (at most
        SUBSCRIBER_WAIT s; a stop ends the wait)."""
        end = time.monotonic() + contract.SUBSCRIBER_WAIT
        while (self.joint_states.get_subscription_count() < wanted and time.monotonic() < end
               and not deployment.stopping.is_set()):
            time.sleep(0.01)
        return self.joint_states.get_subscription_count()

    def _run(self, goal_handle, deployment, scene, params, prefix=""):
        wanted = goal_handle.request.wait_for_subscribers
        subscribers = self._subscribers(wanted, deployment)
        if subscribers < wanted:
            why = ("cancelled" if deployment.stopping.is_set()
                   else f"after {contract.SUBSCRIBER_WAIT:g} s")
            return Deploy.Result(success=False, status=-1, message=(
                f"only {subscribers} of the {wanted} joint_states subscribers asked for, "
                f"{why}: not deployed"))
        model = deployment.model
        pacer = Pacer(params.real_time_factor, deployment.stopping)
        # The contract's own bytes, as recordings store them: published as they are.
        encoder = SampleEncoder(model, prefix)
        contact = bool(model.contact_pairs)  # no panel contact: no onsets to send
        shown = told = -math.inf
        samples = 0
        self.tf_static.publish(encoder.tf_static())
        start = time.monotonic()
        for s in deployment:
            pacer.wait(s.t)
            (clock, joint_state, panels, tf), = encoder.encode([s])
            self.clock.publish(clock)
            self.joint_states.publish(joint_state)
            if contact:
                self.onsets.publish(encoder.onset(s.t, s.onset))
            samples += 1
            self.tf.publish(tf)
            # Markers and feedback are for eyes and progress bars: a display rate is enough.
            now = time.monotonic()
            if now - shown >= 1.0 / PANEL_RATE or s.t >= deployment.settings.t_end:
                self.panels.publish(panels)
                shown = now
            if now - told >= 1.0 / FEEDBACK_RATE:
                goal_handle.publish_feedback(Deploy.Feedback(t=float(s.t), samples=samples,
                                                             subscribers=subscribers))
                told = now
        published = time.monotonic() - start
        result = deployment.result
        s = deployment_summary(model, result, flat_tolerance=scene.simulation.flat_tolerance)
        values = contract.outcome_values(s, len(result.t))
        values["publish_wall_time"] = published  # s from the first block to the last message
        self.diagnostics.publish(messages.diagnostics(float(result.t[-1]), messages.status(
            self.get_fully_qualified_name(), contract.outcome_level(s), s["message"], values)))
        return messages.deploy_result(s, len(result.t))

    def _stop(self):
        if self.deployment is not None:
            self.deployment.stop()

    def close(self):
        if self.running:
            self.deployment.stop()
            self._worker.join(timeout=5.0)


def main(argv=None) -> int:
    return runtime.node_main(DynamicsNode, argv)
