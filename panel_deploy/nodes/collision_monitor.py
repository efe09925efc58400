"""``collision_monitor`` node: the streaming collision check of ``joint_states``.

Fed by the simulator or by a real array's encoders (core:
:class:`~panel_deploy.collision.StreamCheck`, which states how stamps, gaps
and hinges the stream lacks are handled; ``noise`` makes the check
noise-aware as :mod:`panel_deploy.collision.monitor` says). Per deployment it
publishes each collision as it begins (``panel_deploy/collision_events``,
one ``CollisionEvent`` per event, and the pair highlighted on
``panel_deploy/collision_markers``, cleared when a deployment starts) and its
verdict, as a ``MonitorVerdict`` on ``~/verdict`` (latched) and as a status on
``/diagnostics`` for diagnostics tools (OK; WARN when messages were refused or the
stream had gaps, or when its coverage is lost: joint states that cannot
arrive (a publisher of incompatible QoS), joint states all refused (another
robot's names, a hinge the loop closure cannot complete), a deployment's
stream stalled before the array is flat, or fewer samples checked than the
dynamics node says it sent, or for a model with panel contact, sample intervals
whose contact onsets did not come; every verdict carries that coverage (``measured``
and ``solved`` hinges, ``expected`` samples, ``onsets``, ``since_last_sample`` s); ERROR
after a collision; four times a second and at the first
event). A malformed message is skipped and counted; WARNs about it come at
most once a second per kind, saying how many were held back.

Above its capacity (a joint state that waited over ``max_lag`` s since the
middleware received it) the monitor skips the late samples and checks the
newest, but never skips a span longer than the scene's sample interval (5 ms
for the paper's scene): collisions in a skipped span are still found between
the checked samples, ``d`` becomes an upper bound, and the verdict (WARN) and
its ``skipped`` count say so (:meth:`~panel_deploy.collision.StreamCheck.skip`).
"""

from __future__ import annotations

import math
import re
import threading
import time
from collections import deque

import numpy as np

from rclpy.clock import Clock as RosClock, ClockType
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.node import Node

from .. import contract
from ..build import build_model
from ..collision import CollisionSettings, StreamCheck
from ..errors import PanelDeployError, SceneError, shown
from ..kinematics import forward_kinematics
from ..timing import Throttle
from ..scene_text import scene_from_yaml
from . import messages, runtime

PARAMETERS = {
    "tolerance": (-1.0, "interference depth that counts as a collision, m; negative: the scene's "
                        "collision.tolerance", (-1.0, 0.02)),
    "refine": (True, "also check between samples (Hermite motion), so no collision is missed"),
    "noise": (-1.0, "standard deviation of the measured angles, rad (encoders); negative: the "
                    "scene's collision.noise", (-1.0, 0.1)),
    "speed_interval": (-1.0, "spacing of Eq. 7's distances, s; 0: the stream's own samples; "
                             "negative: the scene's collision.speed_interval", (-1.0, 10.0)),
    "stamps": ("", "header: a joint state's time is its header.stamp; receipt: the time it "
                   "arrived (drivers that leave stamps unfilled); empty: the scene's "
                   "collision.stamps"),
    "max_lag": (0.02, "s a joint state may wait in the queue: above it the monitor is behind "
                      "and skips it, checking the newest (the verdict counts them); 0: check "
                      "every one however late", (0.0, 10.0)),
    runtime.FRAME_PREFIX: ("", runtime.FRAME_PREFIX_DOC),
}
#: s between verdicts on /diagnostics.
VERDICT_PERIOD = 0.25
#: Joint states read in one turn of the executor at most.
DRAIN = 500
#: A deployment's stream is stalled after this many wall seconds without a joint
#: state (or this many typical intervals, when longer) before the array is flat.
STALL_S = 0.5
STALL_INTERVALS = 20.0
#: What the worker's queue holds: a joint state, a contact onset, the driver's sample count.
_JOINT_STATE, _ONSET, _EXPECTED = "joint state", "onset", "expected"
#: The scene's collision keys a parameter overrides when it holds no "the scene's" value.
_OVERRIDES = {"tolerance": lambda v: v >= 0, "noise": lambda v: v >= 0,
              "speed_interval": lambda v: v >= 0, "stamps": bool, "refine": lambda v: True,
              runtime.FRAME_PREFIX: lambda v: False, "max_lag": lambda v: False}


class CollisionMonitorNode(Node):
    def __init__(self, **kwargs):
        super().__init__("collision_monitor", **kwargs)
        self.scene = None
        self.stream = None  # StreamCheck of the current model
        #: Name of every status this node sends, so that arrays in namespaces tell theirs apart.
        self.status_name = self.get_fully_qualified_name()
        runtime.declare(self, PARAMETERS, self._collision)
        self.add_post_set_parameters_callback(self._apply)
        self.diagnostics = runtime.publisher(self, contract.DIAGNOSTICS)
        self.events = runtime.publisher(self, contract.COLLISION_EVENTS)
        self.verdicts = runtime.publisher(self, contract.VERDICT)
        self.markers = runtime.publisher(self, contract.COLLISION_MARKERS)
        runtime.subscription(self, contract.MODEL, self._on_model)
        # Impacts the panel contact absorbed, which joint states cannot show.
        self._onsets = runtime.subscription(self, contract.CONTACT_ONSETS, self._on_onset)
        self._joint_states = runtime.subscription(
            self, contract.JOINT_STATES, self._on_joint_state,
            event_callbacks=SubscriptionEventCallbacks(incompatible_qos=self._on_incompatible_qos))
        # The simulated driver's outcome says how many samples a deployment had.
        runtime.subscription(self, contract.DIAGNOSTICS, self._on_diagnostics)
        self._dynamics = contract.status_name(self.get_namespace(), contract.DEPLOY.node)
        self._expected = None      # samples of the current deployment, when its driver says
        self._arrived = None       # monotonic s of the last joint state checked
        self._started = None       # monotonic s of the current deployment's first one
        self._onset_arrived = None  # monotonic s of its last contact onset checked
        self._qos_fault = None     # why joint states cannot arrive at all
        runtime.trigger_service(self, contract.RESET, self._reset)
        self._throttle = Throttle()
        # Joint states are read as they come and checked by a worker thread of
        # their own, so that the check never holds up the executor and the
        # worker always sees the newest sample that has come (the skip rule).
        self._lock = threading.RLock()     # the stream check and its verdict
        self._queued = threading.Condition()
        self._pending = deque()            # read, not yet checked
        self._closing = False
        self._apply()
        # Wall time, whatever use_sim_time says: a stream that stops (and its /clock
        # with it) must still get the verdict that says so.
        self.create_timer(VERDICT_PERIOD, self._publish_verdict,
                          clock=RosClock(clock_type=ClockType.STEADY_TIME))
        self._worker = threading.Thread(target=self._check_loop, daemon=True)
        self._worker.start()

    def _collision(self, changes=None) -> tuple:
        """``(settings, receipt)``: the scene's collision settings with the
        parameters that override them, and whether stamps are arrival times."""
        runtime.check_frame_prefix(changes or {})
        p = {**runtime.values(self, PARAMETERS), **(changes or {})}
        given = {k: v for k, v in p.items() if _OVERRIDES[k](v)}
        if given.get("stamps", "header") not in ("header", "receipt"):
            raise SceneError("stamps", f"expected header or receipt (or empty for the scene's), "
                                       f"got {shown(given['stamps'])}")
        if not math.isfinite(given.get("tolerance", 0.0)):
            raise SceneError("tolerance", f"expected a finite number, got {shown(given['tolerance'])}")
        scene = self.scene if self.scene is not None else CollisionSettings()
        if "tolerance" in given:
            given["margin"] = max(CollisionSettings.margin, given["tolerance"])
        try:
            settings = CollisionSettings.from_scene(scene, **given)
            return settings, settings.stamps == "receipt"
        except SceneError as e:  # named as the node's parameter, not the scene key
            raise SceneError(e.path.removeprefix("collision."), e.reason) from None

    def _apply(self, params=None):
        """The stamps rule at once; the rest from the next deployment."""
        collision, self._receipt = self._collision()
        self._max_lag = self.get_parameter("max_lag").value
        with self._lock:
            if self.stream is not None:
                self.stream.collision = collision

    def _on_model(self, msg):
        try:
            scene = scene_from_yaml(msg.data)
            self.scene = scene
            collision, self._receipt = self._collision()
            stream = StreamCheck(build_model(scene), collision)
            with self._lock:
                self.stream = stream
                # Checked samples never further apart than those simulate checks.
                self._skip_span = scene.simulation.t_end / (scene.simulation.samples - 1)
        except PanelDeployError as e:
            self._warn("model", f"ignored a model: {e}")
            return
        self._publish_verdict()  # at once: clients learn that the model has reached the monitor

    def _on_joint_state(self, msg, info):
        self._read(msg, info)
        # Then take what else has come straight from the subscription (rclpy's own
        # take, as its executor does): a round of the executor per message costs
        # about 200 us, which capped the monitor near 2,400 joint states a second.
        # At most DRAIN at a time, so that timers and services still get their turn.
        sub = self._joint_states
        for _ in range(DRAIN):
            with sub.handle:
                taken = sub.handle.take_message(sub.msg_type, sub.raw)
            if taken is None:
                return
            self._read(*taken)

    def _read(self, msg, info):
        stream = self.stream
        if stream is None:
            return self._warn("no model", "joint state skipped: no model yet on panel_deploy/model")
        try:
            t, names, position, velocity = messages.read_joint_state(msg, stream.names)
        except PanelDeployError as e:
            return self._refuse(stream, e)
        if self._receipt:  # when it left the driver, else when it arrived: not when handled
            t = (info["source_timestamp"] or info["received_timestamp"]) * 1e-9
        self._queue(_JOINT_STATE, (stream, t, names, position, velocity,
                                   info["received_timestamp"]))

    def _on_onset(self, msg):
        stream = self.stream
        if stream is not None:
            self._queue(_ONSET, (stream, messages.seconds(msg.header.stamp),
                                 contract.onset_fields(msg)))

    def _queue(self, kind, item):
        """Hand ``item`` to the worker, in arrival order with the others."""
        with self._queued:
            self._pending.append((kind, item))
            self._queued.notify()

    def _refuse(self, stream, e, onset=False):
        with self._lock:
            stream.refuse(str(e).split(":", 1)[0][:40], onset)
            # One kind per fault, whatever its values (names, numbers): a flood is throttled.
            kind = re.sub(r"'[^']*'|\d+(\.\d*)?(e[-+]?\d+)?", "#", str(e))[:80]
            self._warn(kind, f"{'contact onset' if onset else 'joint state'} skipped: {e}")

    def _check_loop(self):
        """The worker: every joint state read so far, in order; above capacity
        (one that waited over ``max_lag`` s since the middleware received it,
        and a newer one has come) skipped and counted, so the newest is always
        checked, and never more than the scene's sample interval of them in a row (:meth:`~panel_deploy.collision.StreamCheck.skip`)."""
        while True:
            with self._queued:
                while not self._pending and not self._closing:
                    self._queued.wait()
                if self._closing:
                    return
                batch = list(self._pending)
                self._pending.clear()
            with self._lock:
                newest = max((i for i, (kind, _) in enumerate(batch) if kind == _JOINT_STATE),
                             default=-1)
                for i, (kind, item) in enumerate(batch):
                    if kind == _EXPECTED:  # the driver's sample count, in its place
                        self._expected = item
                        continue
                    if item[0] is not self.stream:
                        continue  # read against a model that has since been replaced
                    if kind == _ONSET:
                        self._check_onset(*item)
                        continue
                    stream, t, *sample, received = item
                    late = (self._max_lag > 0 and received and i < newest
                            and (time.time_ns() - received) * 1e-9 > self._max_lag)
                    if not (late and stream.skip(t, self._skip_span)):
                        self._check(stream, t, *sample)

    def _check(self, stream, t, names, position, velocity):
        try:
            theta, omega = stream.coordinates(names, position, velocity)
            deployments = stream.deployments
            found = stream.update(t, theta, omega)
        except PanelDeployError as e:
            return self._refuse(stream, e)
        self._arrived, self._qos_fault = time.monotonic(), None
        if stream.deployments != deployments:
            self._clear_markers()
            self._expected = self._onset_arrived = None
            self._started = self._arrived
        if stream.last_gap is not None:
            self._warn("gap", f"gap of {stream.last_gap * 1e3:.1f} ms in joint_states before "
                              f"t = {t - stream.origin:.4f} s (typical interval "
                              f"{stream.typical_interval * 1e3:.2f} ms): collisions in it are "
                              f"located on interpolated motion")
        self._publish_events(stream, found, theta, t)

    def _check_onset(self, stream, stamp, fields):
        try:
            found = stream.onset(stamp, *fields)
        except PanelDeployError as e:
            return self._refuse(stream, e, onset=True)
        self._onset_arrived = time.monotonic()
        self._publish_events(stream, found, stream.last_theta, stream.last_stamp)

    def _publish_events(self, stream, found, theta, t):
        """The collision events one message revealed, the first one's pair
        highlighted on the array at ``theta`` (rad) and time ``t`` (s)."""
        if found:
            first = found[0] is stream.check.first_events[0]
            R, p = forward_kinematics(stream.model, theta)
            for e in found:
                self.events.publish(messages.collision_event(e, stream.origin, self._frame()))
            self.markers.publish(messages.collision_markers(
                stream.model, found[0], R, p, t, self._frame()))
            if first:  # the verdict turns ERROR now; later events leave it so (timer only)
                self._publish_verdict()

    def close(self):
        """Stop the worker (the executor still spins: see runtime.spin)."""
        with self._queued:
            self._closing = True
            self._queued.notify()
        self._worker.join(timeout=5.0)

    def _warn(self, kind, text):
        """A WARN on the log and /diagnostics, at most one a second of each kind."""
        held = self._throttle(kind)
        if held is None:
            return
        if held:
            text += f" ({held} more like it held back)"
        self.get_logger().warning(text)
        # Stamped in the stream's clock, as the verdicts: a recording logs it where it happened.
        stamp = self.stream.last_stamp if self.stream is not None else None
        self.diagnostics.publish(messages.diagnostics(
            stamp or 0.0, messages.status(self.status_name, messages.WARN, text)))

    def _on_diagnostics(self, msg):
        for s in msg.status:
            if s.name == self._dynamics and self.stream is not None:
                samples = messages.values(s).get("samples")
                if samples is not None:
                    # Queued behind the joint states read before it: the worker takes it
                    # after them, so a deployment it has yet to start cannot clear it.
                    self._queue(_EXPECTED, samples)

    def _on_incompatible_qos(self, event):
        policy = getattr(event.last_policy_kind, "name", str(event.last_policy_kind))
        self._qos_fault = (f"a joint_states publisher offers QoS this monitor cannot take "
                           f"({policy.removeprefix('RMW_QOS_POLICY_').lower()}: it needs "
                           f"{contract.JOINT_STATES.qos.reliability}): none of its messages arrive")
        self.get_logger().warning(self._qos_fault)
        self._publish_verdict()

    def _publish_verdict(self):
        with self._lock:
            if self.stream is not None:
                self._send_verdict()

    def _send_verdict(self):
        level, text, values = self.stream.verdict(self._onsets_in_flight())
        coverage = self._coverage()
        if coverage is not None and level < 2:
            level, text = 1, (f"{text}; {coverage}" if level == 1 else coverage)
        values.update(expected=self._expected, since_last_sample=(
            None if self._arrived is None else time.monotonic() - self._arrived))
        stamp = values["origin"] + values["t"] if "t" in values else 0.0
        self.verdicts.publish(messages.verdict(level, text, values, stamp))
        self.diagnostics.publish(messages.diagnostics(
            stamp, messages.status(self.status_name, level, text, values,
                                   hardware_id=self.get_namespace().strip("/") or "panel_array")))

    def _onsets_in_flight(self) -> bool:
        """Contact onsets may still be coming: a driver publishes them, and one
        came (or the deployment started) less than STALL_S s ago."""
        last = self._onset_arrived or self._started
        return (self._onsets.get_publisher_count() > 0 and last is not None
                and time.monotonic() - last < STALL_S)

    def _coverage(self) -> str | None:
        """Why the last verdict covers less than it should, or None: joint states that
        cannot arrive, a driver's samples not all checked, or a deployment whose stream
        stopped before the array was flat."""
        if self._qos_fault is not None:
            return self._qos_fault
        stream = self.stream
        if stream.check is None or self._arrived is None:
            return None
        silent = time.monotonic() - self._arrived
        if silent < max(STALL_S, STALL_INTERVALS * (stream.typical_interval or 0.0)):
            return None
        checked = stream.check.checked
        if self._expected is not None:  # skipped ones are accounted for (and said) by the verdict
            return None if checked + stream.skipped >= self._expected else (
                f"checked {checked} (skipped {stream.skipped}) of the {self._expected} joint "
                f"states the deployment sent")
        flat = self.scene.simulation.flat_tolerance
        if stream.last_theta is not None and np.abs(stream.last_theta).max() <= flat:
            return None  # deployed: a stream that stops now has ended
        return (f"stream stalled: no joint state for {silent:.1f} s since t = "
                f"{stream.last_stamp - stream.origin:.4f} s, the array not flat")

    def _frame(self) -> str:
        """The ground frame the markers are drawn in: ``frame_prefix`` + ``world``."""
        return self.get_parameter(runtime.FRAME_PREFIX).value + contract.WORLD

    def _clear_markers(self):
        """Take the last deployment's collision markers off displays."""
        self.markers.publish(messages.clear_markers(self._frame()))

    def _reset(self, request, response):
        if self.stream is None:
            response.success, response.message = False, "no model yet"
            return response
        with self._queued:  # read before the reset: not the next deployment's
            self._pending.clear()
        with self._lock:
            self.stream.reset()
        self._qos_fault = self._expected = self._arrived = self._started = None
        self._onset_arrived = None
        self._clear_markers()
        response.success, response.message = True, "the next joint state starts a new deployment"
        return response


def main(argv=None) -> int:
    return runtime.node_main(CollisionMonitorNode, argv)
