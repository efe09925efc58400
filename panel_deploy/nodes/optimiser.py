"""``optimiser`` node: the stiffness optimisation of Eq. (8) as a service.

A goal on the ``~/optimise`` action (``panel_deploy_interfaces/action/Optimise``)
searches on the model last received; progress is the goal's feedback and
goes to ``~/progress`` (``OptimiserProgress``, for recorders) too; a feasible
K is set on the ``target_node``'s ``stiffness`` (and ``damping_ratio`` when
searched) through its ``set_parameters`` service (a relative name is in this
node's namespace), then the result (YAML, as ``panel-deploy optimise`` writes
it) is the goal's result and goes to ``~/result``. Cancelling the goal stops
with the best K so far; a goal that cannot run is aborted with the reason.
"""

from __future__ import annotations

import math
import threading
import time

from panel_deploy_interfaces.action import Optimise
from rcl_interfaces.srv import SetParameters
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.parameter import Parameter

from .. import contract
from ..build import build_model
from ..errors import SceneError, shown
from ..scene_text import check_optimisation, optimisation_scene
from ..optimise import optimise
from ..optimise.io import dump_result, result_to_dict
from ..optimise.parallel import Cancelled
from . import messages, runtime

PARAMETERS = {
    "max_evaluations": (0, "simulation budget; 0: the scene's optimisation.max_evaluations",
                        (0, 1_000_000)),
    "method": ("", "local or global; empty: the scene's"),
    "workers": (1, "parallel evaluations in local processes (0: all cores, 1: in this process)",
                (0, 1024)),
    "dask_address": ("", "run the evaluations on this Dask scheduler; empty: locally"),
    "damping_ratio_bounds": (Parameter.Type.DOUBLE_ARRAY,
                             "[lower, upper] c/k, s, to search c/k too; unset or empty: the scene's"),
    "seed": (-1, "random seed; -1: the scene's", (-1, 2**32 - 1)),
    "target_node": ("dynamics", "node whose stiffness (and damping_ratio) a feasible result sets; "
                                "a relative name is in this node's namespace"),
}


class OptimiserNode(runtime.WorkerNode):
    def __init__(self, **kwargs):
        super().__init__("optimiser", **kwargs)
        runtime.declare(self, PARAMETERS, self._check)
        self.progress = runtime.publisher(self, contract.OPTIMISER_PROGRESS)
        self.result_pub = runtime.publisher(self, contract.OPTIMISER_RESULT)
        self.diagnostics = runtime.publisher(self, contract.DIAGNOSTICS)
        self._cancel_event = threading.Event()
        self.action_server(contract.OPTIMISE, self._optimise, self._cancel_event.set,
                           self.diagnostics)
        self._client_group = MutuallyExclusiveCallbackGroup()
        self._targets = {}  # set_parameters clients by service name

    def _check(self, changes):
        self._target_service(changes.get("target_node", self.get_parameter("target_node").value))
        if self.scene is not None:
            self._search_scene(changes)
        else:  # no model yet: the keys on their own, so that none is taken unchecked
            check_optimisation(**self._search_keys(changes))

    def _target_service(self, target: str) -> str:
        """The ``set_parameters`` service of ``target``, resolved in this node's namespace."""
        # Empty would resolve to /set_parameters, ~ to this node's own.
        if target and not target.endswith("/") and not target.startswith("~"):
            try:
                return self.resolve_service_name(f"{target}/set_parameters")
            except RuntimeError:  # rclpy's RCLError: a character or token a name cannot have
                pass
        raise SceneError("target_node", f"expected a node name such as dynamics or "
                                        f"/array1/dynamics, got {shown(target)}")

    def _search_keys(self, changes=None) -> dict:
        """The scene's ``optimisation`` keys these parameters (with ``changes``) set."""
        p = {**runtime.values(self, PARAMETERS), **(changes or {})}
        return dict(max_evaluations=p["max_evaluations"] or None, method=p["method"],
                    damping_ratio_bounds=p["damping_ratio_bounds"],
                    seed=None if p["seed"] < 0 else p["seed"])

    def _search_scene(self, changes=None):
        p = {**runtime.values(self, PARAMETERS), **(changes or {})}
        return optimisation_scene(self.scene, **self._search_keys(changes)), p

    def _optimise(self, goal_handle):
        scene, p = self._search_scene()
        model = build_model(scene)
        self._cancel_event.clear()
        self.get_logger().info(f"optimising {scene.name or scene.source} "
                               f"({scene.optimisation.method}, at most "
                               f"{scene.optimisation.max_evaluations} evaluations)")
        return self._run, (model, scene, p)

    def _run(self, goal_handle, model, scene, p):
        def report(progress):
            msg = messages.progress(progress, time.time())
            self.progress.publish(msg)
            goal_handle.publish_feedback(Optimise.Feedback(progress=msg))
        try:
            result = optimise(model, scene, workers=p["workers"],
                              dask_address=p["dask_address"] or None, progress=report,
                              stop=self._cancel_event.is_set)
        except Cancelled:
            return Optimise.Result(success=False, message="cancelled before the first "
                                                          "evaluation: no result")
        self.get_logger().info(result.message)
        success = result_to_dict(result)["success"]  # false too if a value came out non-finite
        if success:
            self._set_target(p["target_node"], result)
        text = dump_result(result, scene.name)
        # Last: a client that has the result knows the target has its K.
        self.result_pub.publish(messages.string(text))
        ratio = (float(result.c[0] / result.k[0]) if result.problem.damping_variable
                 else math.nan)
        return Optimise.Result(success=bool(success), message=result.message,
                               stiffness=[float(k) for k in result.k], damping_ratio=ratio,
                               result=text)

    def _set_target(self, target, result):
        values = [Parameter("stiffness", Parameter.Type.DOUBLE_ARRAY, [float(k) for k in result.k])]
        if result.problem.damping_variable:
            values.append(Parameter("damping_ratio", Parameter.Type.DOUBLE,
                                    float(result.c[0] / result.k[0])))
        service = self._target_service(target)
        if service not in self._targets:  # kept: destroying a client under a spinning executor blocks
            self._targets[service] = self.create_client(SetParameters, service,
                                                        callback_group=self._client_group)
        client = self._targets[service]
        if not client.wait_for_service(timeout_sec=5.0):
            return self.get_logger().error(f"{target}: no set_parameters service")
        done = threading.Event()
        future = client.call_async(SetParameters.Request(
            parameters=[v.to_parameter_msg() for v in values]))
        future.add_done_callback(lambda _: done.set())
        if not done.wait(10.0):
            return self.get_logger().error(f"{target}: set_parameters did not answer")
        refused = [r.reason for r in future.result().results if not r.successful]
        if refused:
            self.get_logger().error(f"{target} refused the result: {refused[0]}")

    def close(self):
        self._cancel_event.set()
        if self._worker is not None:
            self._worker.join(timeout=30.0)


def main(argv=None) -> int:
    return runtime.node_main(OptimiserNode, argv)
