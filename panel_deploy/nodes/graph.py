"""``panel-deploy run``: the four nodes in one process on one executor, driven
through their topics and services only, like any ROS client (the driver
would drive the same nodes in processes of their own).

Real rclpy: ``ros2 topic echo /joint_states`` from another shell sees them.
"""

from __future__ import annotations

import json
import sys
import tempfile
import threading
import time
from pathlib import Path

import rclpy
import yaml
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.validate_namespace import validate_namespace
from std_srvs.srv import Trigger

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


class Driver(Node):
    """The client side of ``run``: calls the services, follows the topics,
    shows progress on stderr and builds the summary from what they carry."""

    def __init__(self, interrupt, recorder=None, **kwargs):
        super().__init__("panel_deploy_run", **kwargs)
        self.interrupt, self.recorder = interrupt, recorder
        self.group = ReentrantCallbackGroup()
        # The nodes are this node's neighbours: their names resolve in its namespace.
        self.dynamics, self.monitor = (self.resolve_topic_name(n)
                                       for n in (contract.DEPLOY.node, contract.RESET.node))
        self._triggers = {}
        self.outcome = None   # values of the dynamics node's outcome status
        self.verdict = None   # values of the monitor's last verdict
        self.events = []      # values of this deployment's collision events
        self.result = None    # the optimiser's result (parsed YAML)
        self.search_failed = None
        self.deploying = False
        self.shown = -1.0
        self.exit_code = 1
        self.summary = None
        for topic, callback in ((contract.DIAGNOSTICS, self._on_diagnostics),
                                (contract.COLLISION_EVENTS, self._on_events),
                                (contract.OPTIMISER_PROGRESS, self._on_progress),
                                (contract.OPTIMISER_RESULT, self._on_result),
                                (contract.PANELS, self._on_panels)):
            runtime.subscription(self, topic, callback, callback_group=self.group)

    def call(self, service: contract.Service, retry: str = "no model yet") -> str:
        """Call a Trigger ``service``; again while it refuses with ``retry`` (up to TIMEOUT)."""
        service = service.path
        if service not in self._triggers:
            self._triggers[service] = self.create_client(Trigger, service, callback_group=self.group)
        client = self._triggers[service]
        if not client.wait_for_service(timeout_sec=TIMEOUT):
            raise RuntimeError(f"{service}: no such service")
        end = time.monotonic() + TIMEOUT
        while True:
            done = threading.Event()
            future = client.call_async(Trigger.Request())
            future.add_done_callback(lambda _: done.set())
            if not done.wait(TIMEOUT):
                raise RuntimeError(f"{service}: no answer")
            reply = future.result()
            if reply.success:
                return reply.message
            if retry not in reply.message or time.monotonic() > end:
                raise RuntimeError(f"{service}: {reply.message}")
            time.sleep(0.05)

    def _on_diagnostics(self, msg):
        for s in msg.status:
            if s.name == self.dynamics:
                self.outcome = {"level": s.level, "message": s.message, **messages.values(s)}
            elif s.name == self.monitor:
                self.verdict = messages.values(s)

    def _on_events(self, msg):
        for s in msg.status:
            self.events.append(messages.values(s))
            print(f"  collision: {s.message}", file=sys.stderr, flush=True)

    def _on_progress(self, msg):
        for s in msg.status:
            if s.level == messages.ERROR:
                self.search_failed = s.message
                continue
            v = messages.values(s)
            print(f"  optimise {s.message:>8}: {v['evaluations']} evaluations, best f "
                  f"{float(v['best_f']):+.5f}, feasible {v['feasible']}, "
                  f"{float(v['elapsed']):.1f} s", file=sys.stderr, flush=True)

    def _on_result(self, msg):
        self.result = yaml.safe_load(msg.data)

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

    def _wait(self, condition, what, timeout=TIMEOUT, interruptible=True) -> bool:
        """Until ``condition()``; KeyboardInterrupt on an interrupt (if
        ``interruptible``), RuntimeError after ``timeout`` s (else False)."""
        end = time.monotonic() + timeout
        while not condition():
            if interruptible and self.interrupt.is_set():
                raise KeyboardInterrupt
            if time.monotonic() > end:
                if interruptible:
                    raise RuntimeError(f"timed out waiting for {what}")
                return False
            time.sleep(0.02)
        return True

    def drive(self, optimise: bool) -> None:
        # The monitor says it has the model with its first verdict; the
        # dynamics node and the optimiser refuse requests until theirs came.
        self._wait(lambda: self.verdict is not None, "the model to reach the collision monitor")
        if optimise:
            print(self.call(contract.OPTIMISE), file=sys.stderr, flush=True)
            # The result is published once the optimiser has set its K on the dynamics node.
            self._wait(lambda: self.result is not None or self.search_failed, "the optimiser",
                       timeout=1e9)
            if self.result is None or not self.result["success"]:
                what = self.result["message"] if self.result else self.search_failed
                print(f"optimise: {what}; deploying with the scene's stiffness",
                      file=sys.stderr, flush=True)
        # A sample sent before the monitor's subscription is known to the
        # dynamics node is lost to it: in processes of their own, discovery takes a while.
        self._wait(self._monitor_listens, "the collision monitor on joint_states")
        self.events.clear()
        self.deploying = True
        print(self.call(contract.DEPLOY), file=sys.stderr, flush=True)
        self._wait(lambda: self.outcome is not None, "the deployment", timeout=1e9)
        self._finish()

    def _monitor_listens(self) -> bool:
        topic = self.resolve_topic_name(contract.JOINT_STATES.name)
        return any(f"{i.node_namespace.rstrip('/')}/{i.node_name}" == self.monitor
                   for i in self.get_subscriptions_info_by_topic(topic))

    def stop_deployment(self) -> None:
        """After an interrupt: stop a running deployment and summarise what was computed."""
        if not self.deploying:
            return
        try:
            self.call(contract.STOP, retry="")
        except RuntimeError:
            pass  # none running: it has just ended
        try:
            if self._wait(lambda: self.outcome is not None, "", TIMEOUT, interruptible=False):
                self._finish(interruptible=False)
        except RuntimeError as e:  # interrupted anyway: say why there is no summary
            print(f"panel-deploy: {e}", file=sys.stderr)

    def _finish(self, interruptible=True) -> None:
        if "summary" not in self.outcome:  # the deployment failed (an ERROR status)
            raise RuntimeError(self.outcome["message"])
        published = self.outcome["samples"]
        self._wait(lambda: (self.verdict or {}).get("samples", 0) >= published,
                   "the collision monitor", interruptible=interruptible)
        self.summarise()
        if self.recorder is not None:
            got = self.recorder.received
            self._wait(lambda: (got[contract.JOINT_STATES.name] >= published
                                and got[contract.DIAGNOSTICS.name] >= 1),
                       "the recorder", interruptible=interruptible)
            time.sleep(0.2)  # the monitor's last events and verdict, published just now
            self.recorder.close(self.summary)

    def summarise(self) -> None:
        """The deployment's summary (the outcome's) with the monitor's verdict
        and events as its collision part; sets the exit code."""
        s = self.outcome["summary"]
        v = self.verdict
        pair = v.get("first_collision_pair")
        first = None if not pair else {"t": v["first_collision_t"], "pair": pair,
                                       "v": v["approach_speed"]}
        s["collision"] = {
            "collided": first is not None, "first_collision": first,
            "colliding_pairs": [{key: e[key] for key in ("pair", "t", "approach_speed", "distance")}
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
                 CollisionMonitorNode(**ns), OptimiserNode(**ns))
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
