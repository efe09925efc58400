"""``panel-deploy run``: the four nodes in one process on one executor, driven
through their topics and actions only, like any ROS client (the driver
would drive the same nodes in processes of their own).

Real rclpy: ``ros2 topic echo /joint_states`` from another shell sees them.
"""

from __future__ import annotations

import json
import sys
import tempfile
import threading
import time
import uuid
from pathlib import Path

import rclpy
from action_msgs.msg import GoalStatus
from rclpy.action import ActionClient
from rclpy.action.client import ClientGoalHandle
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.validate_namespace import validate_namespace
from unique_identifier_msgs.msg import UUID

from .. import contract
from ..errors import SceneError, shown
from ..scene_text import scene_yaml
from ..summary import deployment_text
from . import messages, runtime
from .array_model import ArrayModelNode
from .collision_monitor import CollisionMonitorNode
from .dynamics import DynamicsNode
from .optimiser import OptimiserNode
from .recorder import RecorderNode

#: Seconds to wait for a service, for the model to reach every node, or for
#: the monitor to catch up.
TIMEOUT = 30.0
#: Seconds to wait for a goal's acceptance before asking for the goal by its id.
ACCEPT_WAIT = 5.0


class Driver(Node):
    """The client side of ``run``: sends the optimise and deploy goals, follows
    the topics, shows progress on stderr and builds the summary from what the
    goals' results and the monitor's verdict carry."""

    def __init__(self, interrupt, recorder=None, **kwargs):
        super().__init__("panel_deploy_run", **kwargs)
        self.interrupt, self.recorder = interrupt, recorder
        self.group = ReentrantCallbackGroup()
        self.verdict = None   # values of the monitor's last verdict
        self.events = []      # this deployment's collision events
        self.goal = None      # the running goal's handle
        self.shown = -1.0
        self.exit_code = 1
        self.summary = None
        for topic, callback in ((contract.VERDICT, self._on_verdict),
                                (contract.COLLISION_EVENTS, self._on_event),
                                (contract.PANELS, self._on_panels)):
            runtime.subscription(self, topic, callback, callback_group=self.group)
        self.actions = {a: ActionClient(self, messages.message_class(a.type), a.path,
                                        callback_group=self.group)
                        for a in contract.ACTIONS}

    def run_goal(self, action: contract.Service, feedback=None, **goal):
        """Send a goal to ``action`` and wait for its result; again while it is
        aborted because the model has not reached the node yet (up to TIMEOUT)."""
        client = self.actions[action]
        if not client.wait_for_server(timeout_sec=TIMEOUT):
            raise RuntimeError(f"{action.path}: no such action server")
        end = time.monotonic() + TIMEOUT
        while True:
            self.goal = self._send(action, goal, feedback)
            if not self.goal.accepted:
                raise RuntimeError(f"{action.path}: goal rejected")
            result = self._future(self.goal.get_result_async(), timeout=1e9).result().result
            if result.success or "no model" not in result.message or time.monotonic() > end:
                return result
            time.sleep(0.05)

    def _send(self, action: contract.Service, goal: dict, feedback) -> ClientGoalHandle:
        """Send ``action`` a goal of fields ``goal``; its handle once the
        server has it.

        While discovery is under way (a node process of its own, a loaded
        machine) the server can receive a goal and run it, yet its answer be
        lost: Fast DDS waits 100 ms for the client's response reader to match,
        then drops the answer. After ACCEPT_WAIT s without one, the goal is
        asked for by its id: the get-result service answers UNKNOWN at once for
        a goal the server has not got yet (asked again, up to TIMEOUT) and
        answers with the result for one it has, so a goal that runs is
        followed, never sent twice.
        """
        client, action_type = self.actions[action], messages.message_class(action.type)
        goal_id = UUID(uuid=list(uuid.uuid4().bytes))
        sent = client.send_goal_async(action_type.Goal(**goal), feedback_callback=feedback,
                                      goal_uuid=goal_id)
        if self._wait(sent.done, "an answer", ACCEPT_WAIT, required=False):
            return sent.result()
        self.goal = ClientGoalHandle(client, goal_id,
                                     action_type.Impl.SendGoalService.Response(accepted=True))
        end = time.monotonic() + TIMEOUT
        while not sent.done():
            asked = self.goal.get_result_async()
            self._wait(lambda: sent.done() or asked.done(), "the goal's result", 1e9)
            if asked.done() and asked.result().status != GoalStatus.STATUS_UNKNOWN:
                return self.goal
            if time.monotonic() > end:
                raise RuntimeError(f"timed out waiting for an answer from {action.path}")
            time.sleep(0.1)
        return sent.result()

    def _future(self, future, timeout=TIMEOUT):
        done = threading.Event()
        future.add_done_callback(lambda _: done.set())
        self._wait(done.is_set, "an answer", timeout)
        return future

    def _on_verdict(self, msg):
        self.verdict = contract.verdict_values(msg)

    def _on_event(self, msg):
        self.events.append(msg)
        print(f"  collision: {contract.event_text(msg.body_a, msg.body_b, msg.t)}",
              file=sys.stderr, flush=True)

    @staticmethod
    def _on_progress(feedback):
        p = feedback.feedback.progress
        print(f"  optimise {p.phase:>8}: {p.evaluations} evaluations, best f "
              f"{p.best_f:+.5f}, feasible {p.feasible}, {p.elapsed:.1f} s",
              file=sys.stderr, flush=True)

    def _on_panels(self, msg):
        """A line every 0.1 s of simulated time (the panels come at a display rate)."""
        if not msg.markers:
            return
        t = messages.seconds(msg.markers[0].header.stamp)
        if t - self.shown < 0.1:
            return
        self.shown = t
        d = (self.verdict or {}).get("d")
        print(f"  t = {t:6.3f} s  smallest distance d = "
              f"{'-' if d is None else f'{d * 1e3:.2f} mm'}  "
              f"collisions {len(self.events)}", file=sys.stderr, flush=True)

    def _wait(self, condition, what, timeout=TIMEOUT, interruptible=True,
              required=True) -> bool:
        """Until ``condition()``; KeyboardInterrupt on an interrupt (if
        ``interruptible``); after ``timeout`` s RuntimeError (if ``required``,
        else False)."""
        end = time.monotonic() + timeout
        while not condition():
            if interruptible and self.interrupt.is_set():
                raise KeyboardInterrupt
            if time.monotonic() > end:
                if required:
                    raise RuntimeError(f"timed out waiting for {what}")
                return False
            time.sleep(0.02)
        return True

    def drive(self, optimise: bool) -> None:
        # The monitor says it has the model with its first verdict; the
        # dynamics node and the optimiser abort goals until theirs came.
        self._wait(lambda: self.verdict is not None, "the model to reach the collision monitor")
        if optimise:
            result = self.run_goal(contract.OPTIMISE, self._on_progress)
            if not result.success:
                print(f"optimise: {result.message}; deploying with the scene's stiffness",
                      file=sys.stderr, flush=True)
        self.events.clear()
        # A sample sent before the monitor's (and the recorder's) subscription is
        # matched is lost to it: in processes of their own, discovery takes a while.
        result = self.run_goal(contract.DEPLOY,
                               wait_for_subscribers=1 + (self.recorder is not None))
        self.goal = None
        self._finish(result)

    def stop_deployment(self) -> None:
        """After an interrupt: cancel a running goal; summarise what was computed."""
        goal, self.goal = self.goal, None
        if goal is None:
            return
        done = threading.Event()
        goal.cancel_goal_async()
        future = goal.get_result_async()
        future.add_done_callback(lambda _: done.set())
        if not done.wait(TIMEOUT):
            print("panel-deploy: the goal did not end after its cancel", file=sys.stderr)
            return
        result = future.result().result
        if hasattr(result, "summary"):  # a Deploy goal: what was computed is summarised
            try:
                self._finish(result, interruptible=False)
            except RuntimeError as e:  # interrupted anyway: say why there is no summary
                print(f"panel-deploy: {e}", file=sys.stderr)

    def _finish(self, result, interruptible=True) -> None:
        if not result.summary:  # the deployment did not run or failed with an error
            raise RuntimeError(result.message)
        published = result.samples
        self._wait(lambda: self._checked(published), "the collision monitor",
                   interruptible=interruptible, required=interruptible)
        self.summarise(json.loads(result.summary))
        if self.recorder is not None:
            got = self.recorder.received
            self._wait(lambda: (got[contract.JOINT_STATES.name] >= published
                                and got[contract.DIAGNOSTICS.name] >= 1),
                       "the recorder", interruptible=interruptible, required=interruptible)
            time.sleep(0.2)  # the monitor's last events and verdict, published just now
            self.recorder.close(self.summary)

    def _checked(self, published: int) -> bool:
        """The monitor has checked the ``published`` samples, and for a model with
        panel contact their intervals' contact onsets."""
        v = self.verdict or {}
        return v.get("samples", 0) >= published and (v.get("onsets") is None
                                                     or v["onsets"] >= published - 1)

    def summarise(self, s: dict) -> None:
        """The deployment's summary ``s`` (the Deploy result's) with the monitor's
        verdict and events as its collision part; sets the exit code."""
        v = self.verdict
        pair = v.get("first_collision_pair")
        first = None if not pair else {"t": v["first_collision_t"], "pair": pair,
                                       "v": v["approach_speed"]}
        s["collision"] = {
            "collided": first is not None, "first_collision": first,
            "colliding_pairs": [{"pair": [e.body_a, e.body_b], "t": e.t,
                                 "approach_speed": e.approach_speed, "distance": e.distance}
                                for e in self.events],
            "v": first["v"] if first else 0.0, "d": v.get("d"), "d_time": v.get("d_time"),
            "d_pair": v.get("d_pair"), "samples_checked": v["samples"]}
        flat = s["time_to_flat"]
        collided_before_flat = first is not None and (flat is None or first["t"] <= flat)
        self.exit_code = 0 if s["success"] and flat is not None and not collided_before_flat else 1
        self.summary = s


def run_graph(scene, *, optimise: bool = False, real_time_factor: float = 1.0,
              rate_hz: float = 200.0, as_json: bool = False, record=None,
              namespace: str = "") -> int:
    """Start the graph on ``scene`` (a validated Scene, overrides included),
    optimise (optionally), deploy, print the summary; return the exit code.

    With ``record`` (a path), the graph's topics go to that MCAP file
    (:mod:`.recorder`). ``namespace`` puts every node under it.

    0 when the deployment reaches flat without a collision before it, 1
    otherwise, 130 when interrupted (the summary of what was computed is
    still printed).

    Raises
    ------
    SceneError
        ``namespace`` is not a valid ROS namespace.
    """
    namespace = "/" + namespace.strip("/") if namespace.strip("/") else ""
    try:
        validate_namespace(namespace or "/")
    except Exception as e:  # rclpy's message is three lines with a caret
        reason = str(e).splitlines()[0].removeprefix("Invalid namespace: ").rstrip(":")
        raise SceneError("--namespace", f"{reason}, got {shown(namespace)}") from None
    with tempfile.TemporaryDirectory(prefix="panel_deploy_run_") as folder:
        # The array_model node reads a scene file: this one has the overrides applied.
        path = Path(folder) / f"{scene.name or 'scene'}.yaml"
        path.write_text(scene_yaml(scene))
        return _run(str(path), optimise, real_time_factor, rate_hz, as_json, record, namespace)


def _run(scene_file, optimise, real_time_factor, rate_hz, as_json, record, namespace) -> int:
    interrupt = runtime.start([])
    done = threading.Event()  # the executor spins until the driver is done
    try:
        ns = {"namespace": namespace}
        recorder = RecorderNode(record, **ns) if record else None
        graph = (ArrayModelNode(parameter_overrides=[Parameter("scene", value=scene_file)], **ns),
                 DynamicsNode(parameter_overrides=[
                     Parameter("real_time_factor", value=float(real_time_factor)),
                     Parameter("rate_hz", value=float(rate_hz))], **ns),
                 # A simulated stream has no deadline: every sample is checked.
                 CollisionMonitorNode(parameter_overrides=[Parameter("max_lag", value=0.0)], **ns),
                 OptimiserNode(**ns))
        driver = Driver(interrupt, recorder, **ns)
        failure = []
        interrupted = threading.Event()

        def drive():
            try:
                driver.drive(optimise)
            except KeyboardInterrupt:
                interrupted.set()
                driver.stop_deployment()
            except Exception as e:  # a RuntimeError says why; anything else is a bug, in one line too
                failure.append(str(e) if isinstance(e, RuntimeError) else f"{type(e).__name__}: {e}")
            finally:
                done.set()

        worker = threading.Thread(target=drive, daemon=True)
        worker.start()
        runtime.spin([*graph, driver] + ([recorder] if recorder else []), done)
        worker.join(timeout=10.0)
    finally:
        rclpy.try_shutdown()
    if failure:
        print(f"panel-deploy: error: {failure[0]}", file=sys.stderr)
        return 1
    if driver.summary is not None:
        print(json.dumps(driver.summary) if as_json else deployment_text(driver.summary))
    if recorder is not None and recorder.failed is not None:
        print(f"panel-deploy: error: {recorder.failed}", file=sys.stderr)
        return 2
    if interrupted.is_set() or driver.summary is None:
        print("panel-deploy: interrupted", file=sys.stderr)
        return 130
    return driver.exit_code
