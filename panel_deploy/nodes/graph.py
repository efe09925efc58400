"""``panel-deploy run``: the four nodes in one process on one executor, driven
through their own services and topics like any ROS client would.

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
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node
from rclpy.parameter import Parameter
from std_srvs.srv import Trigger

from ..live import scene_yaml
from ..record.deployment import outcome_record
from ..summary import deployment_summary, deployment_text
from . import messages, runtime
from .array_model import ArrayModelNode
from .collision_monitor import CollisionMonitorNode
from .dynamics import DynamicsNode
from .optimiser import OptimiserNode
from .recorder import RecorderNode

#: Seconds to wait for a service or for the model to reach every node.
TIMEOUT = 30.0


class Driver(Node):
    """The client side of ``run``: calls the services, shows progress on stderr."""

    def __init__(self, graph, stop, recorder=None):
        super().__init__("panel_deploy_run")
        self.graph, self.stop, self.recorder = graph, stop, recorder
        self.group = ReentrantCallbackGroup()
        self.create_subscription(DiagnosticArray, "/panel_deploy/collision_events",
                                 self._on_events, messages.EVENTS, callback_group=self.group)
        self.create_subscription(DiagnosticArray, "/optimiser/progress", self._on_progress,
                                 messages.EVENTS, callback_group=self.group)
        self.exit_code = 1
        self.summary = None

    def call(self, service: str) -> str:
        client = self.create_client(Trigger, service, callback_group=self.group)
        if not client.wait_for_service(timeout_sec=TIMEOUT):
            raise RuntimeError(f"{service}: no such service")
        done = threading.Event()
        future = client.call_async(Trigger.Request())
        future.add_done_callback(lambda _: done.set())
        if not done.wait(TIMEOUT):
            raise RuntimeError(f"{service}: no answer")
        reply = future.result()
        if not reply.success:
            raise RuntimeError(f"{service}: {reply.message}")
        return reply.message

    def _on_events(self, msg):
        for s in msg.status:
            print(f"  collision: {s.message}", file=sys.stderr, flush=True)

    def _on_progress(self, msg):
        for s in msg.status:
            v = {kv.key: kv.value for kv in s.values}
            print(f"  optimise {s.message:>8}: {v.get('evaluations')} evaluations, best f "
                  f"{float(v.get('best_f', 'nan')):+.5f}, feasible {v.get('feasible')}, "
                  f"{float(v.get('elapsed', 0)):.1f} s", file=sys.stderr, flush=True)

    def _wait(self, condition, what, timeout=TIMEOUT) -> None:
        end = time.monotonic() + timeout
        while not condition():
            if self.stop.is_set():
                raise KeyboardInterrupt
            if time.monotonic() > end:
                raise RuntimeError(f"timed out waiting for {what}")
            time.sleep(0.02)

    def drive(self, optimise: bool) -> None:
        model_node, dynamics, monitor, optimiser = self.graph
        self._wait(lambda: dynamics.scene is not None and monitor.stream is not None
                   and optimiser.scene is not None, "the model on /panel_deploy/model")
        if optimise:
            print(self.call("/optimiser/optimise"), file=sys.stderr, flush=True)
            self._wait(lambda: not optimiser.running, "the optimiser", timeout=1e9)
            if optimiser.result is None or not optimiser.result.success:
                what = optimiser.result.message if optimiser.result else "the search failed"
                print(f"optimise: {what}; deploying with the scene's stiffness",
                      file=sys.stderr, flush=True)
        print(self.call("/dynamics/deploy"), file=sys.stderr, flush=True)
        shown = -1.0
        while dynamics.running:
            shown = self._show_progress(dynamics, monitor, shown)
            time.sleep(0.1)
        published = len(dynamics.deployment.result.t)
        self._wait(lambda: monitor.stream.check is not None
                   and monitor.stream.check.checked >= published, "the collision monitor")
        self.summarise()
        if self.recorder is not None:
            got = self.recorder.received
            self._wait(lambda: got["/joint_states"] >= published and got["/diagnostics"] >= 1,
                       "the recorder")
            time.sleep(0.2)  # the monitor's last events and verdict, published just now
            self.recorder.close(outcome_record(self.summary, monitor.stream.check.report()))

    def summarise(self) -> None:
        """The summary of what the deployment and the monitor have computed so far."""
        _, dynamics, monitor, _ = self.graph
        deployment = dynamics.deployment
        if deployment is None or deployment.result is None:
            return
        check = monitor.stream.check if monitor.stream is not None else None
        report = check.report() if check is not None else None
        s = deployment_summary(deployment.model, deployment.result, report,
                               flat_tolerance=deployment.settings.flat_tolerance)
        first = report.first_collision if report is not None else None
        flat = s["time_to_flat"]
        collided_before_flat = first is not None and (flat is None or first.t <= flat)
        self.exit_code = 0 if s["success"] and flat is not None and not collided_before_flat else 1
        self.summary = s

    @staticmethod
    def _show_progress(dynamics, monitor, shown) -> float:
        """A line every 0.1 s of simulated time; returns the time last shown."""
        stream = monitor.stream
        if stream is None or stream.check is None or not dynamics.deployment.blocks:
            return shown
        t = float(dynamics.deployment.blocks[-1].t[-1])
        if t - shown < 0.1:
            return shown
        d = stream.check.d
        print(f"  t = {t:6.3f} s  smallest distance d = "
              f"{'-' if d == float('inf') else f'{d * 1e3:.2f} mm'}  "
              f"collisions {len(stream.check.monitor.events)}", file=sys.stderr, flush=True)
        return t


def run_graph(scene, *, optimise: bool = False, real_time_factor: float = 1.0,
              rate_hz: float = 200.0, as_json: bool = False, record=None) -> int:
    """Start the graph on ``scene`` (a validated Scene, overrides included),
    optimise (optionally), deploy, print the summary; return the exit code.

    With ``record`` (a path), the graph's topics go to that MCAP file
    (:mod:`.recorder`).

    0 when the deployment reaches flat without a collision before it, 1
    otherwise, 130 when interrupted (the summary of what was computed is
    still printed).
    """
    with tempfile.TemporaryDirectory(prefix="panel_deploy_run_") as folder:
        # The array_model node reads a scene file: this one has the overrides applied.
        path = Path(folder) / f"{scene.name or 'scene'}.yaml"
        path.write_text(scene_yaml(scene))
        return _run(str(path), optimise, real_time_factor, rate_hz, as_json, record)


def _run(scene_file, optimise, real_time_factor, rate_hz, as_json, record) -> int:
    stop = runtime.start([])
    try:
        recorder = RecorderNode(record) if record else None
        graph = (ArrayModelNode(parameter_overrides=[Parameter("scene", value=scene_file)]),
                 DynamicsNode(parameter_overrides=[
                     Parameter("real_time_factor", value=float(real_time_factor)),
                     Parameter("rate_hz", value=float(rate_hz))]),
                 CollisionMonitorNode(), OptimiserNode())
        driver = Driver(graph, stop, recorder)
        failure = []

        def drive():
            try:
                driver.drive(optimise)
            except KeyboardInterrupt:
                driver.summarise()
                interrupted.set()
            except RuntimeError as e:
                failure.append(str(e))
            finally:
                stop.set()

        interrupted = threading.Event()
        worker = threading.Thread(target=drive, daemon=True)
        worker.start()
        runtime.spin([*graph, driver] + ([recorder] if recorder else []), stop)
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
