"""The ROS contract of panel_deploy, in one place and without rclpy.

Every topic, service and action the node suite offers, with its type, QoS,
publisher and stamp convention; the status names on ``/diagnostics``; the
fields of a collision event, a monitor verdict and a deployment outcome, with
the parsers that turn their key-value text on ``/diagnostics`` back into
numbers. Our own message and action definitions are in ``interfaces/`` (the
ROS interface package ``panel_deploy_interfaces``, which
``vendor/interfaces`` builds at install; :func:`definitions` gives their text
to readers without ROS). The nodes create their
publishers, subscriptions and services from these values, the recorder
records every topic listed here with the QoS given here, and the readers,
replay and the tests read them from here (``test_contract`` fails when a
topic name or a QoS appears anywhere else in the package).

Names: a topic name without a leading ``/`` is relative and resolves in the
graph's namespace (``joint_states`` is ``/array7/joint_states`` for a graph
run with ``--namespace array7``); a leading ``/`` marks a global topic, as
ROS's own ``/diagnostics``, ``/tf`` and ``/tf_static`` are. The simulated
clock is relative (``/array7/clock``), so two arrays do not interleave time. A
recording keeps the resolved (namespaced) names.

:mod:`.cdr` builds the messages a deployment sends at every sample (and
``/tf_static``) as the bytes the dynamics node publishes and recordings store.

Frames: ``world`` is the ground frame (the flat array frame of the ground
panel); every body's link frame is named after the body (``r1c2+r1c3``). The
dynamics node's ``frame_prefix`` parameter puts a prefix before every frame.

Times: every stamp of a simulated deployment is simulated time in s since
release (``/clock`` carries the same). A monitor's verdict is stamped with
the stream's time of its last sample.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

#: The ground frame's name (URDF root link, /tf_static parent, marker frame).
WORLD = "world"

STRING = "std_msgs/msg/String"
JOINT_STATE = "sensor_msgs/msg/JointState"
MARKER_ARRAY = "visualization_msgs/msg/MarkerArray"
DIAGNOSTIC_ARRAY = "diagnostic_msgs/msg/DiagnosticArray"
CLOCK = "rosgraph_msgs/msg/Clock"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"
TRIGGER = "std_srvs/srv/Trigger"
#: Our interface package (panel_deploy/contract/interfaces).
INTERFACES = "panel_deploy_interfaces"
COLLISION_EVENT = f"{INTERFACES}/msg/CollisionEvent"
CONTACT_ONSET = f"{INTERFACES}/msg/ContactOnset"
MONITOR_VERDICT = f"{INTERFACES}/msg/MonitorVerdict"
OPTIMISER_PROGRESS_MSG = f"{INTERFACES}/msg/OptimiserProgress"
DEPLOY_ACTION = f"{INTERFACES}/action/Deploy"
OPTIMISE_ACTION = f"{INTERFACES}/action/Optimise"
#: The folder of the interface package: package.xml, CMakeLists.txt, msg/, action/.
INTERFACES_DIR = Path(__file__).resolve().parent / "interfaces"


def definitions() -> dict:
    """``{type name: .msg text}`` of every message of our interface package."""
    return {f"{INTERFACES}/msg/{path.stem}": path.read_text()
            for path in sorted((INTERFACES_DIR / "msg").glob("*.msg"))}


@dataclass(frozen=True)
class QoS:
    """A publisher's quality of service: reliable, keep last ``depth``,
    ``durability`` "volatile" or "transient_local" (latched)."""

    depth: int
    durability: str = "volatile"
    reliability: str = "reliable"


#: Latched: a late subscriber still gets the last message.
LATCHED = QoS(1, "transient_local")
#: Deep enough for a whole deployment computed faster than real time (2 s at
#: 1 kHz plus room), so that no subscriber misses a sample.
STREAM = QoS(5000)
#: Everything else; /tf as tf2's own (reliable, volatile, 100 deep).
EVENTS = QoS(100)


@dataclass(frozen=True)
class Topic:
    """One topic of the node suite.

    Attributes
    ----------
    name : str
        Relative (resolved in the graph's namespace) or global (leading ``/``).
    type : str
        ROS 2 type name, e.g. ``sensor_msgs/msg/JointState``.
    qos : QoS
        What its publisher offers and its subscribers ask for.
    publisher : str
        The node that publishes it.
    stamped : bool
        Its messages carry a stamp in simulated (stream) time, which a
        recording takes as their log time.
    """

    name: str
    type: str
    qos: QoS
    publisher: str
    stamped: bool = False


ROBOT_DESCRIPTION = Topic("robot_description", STRING, LATCHED, "array_model")
MODEL = Topic("panel_deploy/model", STRING, LATCHED, "array_model")
#: The scene of the current deployment exactly as it runs: the model's scene
#: with every override (dynamics parameters, an optimiser's K and c/k) applied.
DEPLOYED_SCENE = Topic("dynamics/scene", STRING, LATCHED, "dynamics")
JOINT_STATES = Topic("joint_states", JOINT_STATE, STREAM, "dynamics", stamped=True)
PANELS = Topic("panel_deploy/panels", MARKER_ARRAY, EVENTS, "dynamics", stamped=True)
#: Relative, so that arrays side by side keep their own simulated time
#: (``/array1/clock``); in the root namespace it is ROS's ``/clock``. Nodes that
#: take their time from it under a namespace need the remap :data:`CLOCK_REMAP`.
CLOCK_TOPIC = Topic("clock", CLOCK, STREAM, "dynamics", stamped=True)
#: ``--ros-args -r /clock:=clock``: rclpy's time source (use_sim_time) reads
#: ``/clock``; this makes it the array's own clock in the node's namespace.
CLOCK_REMAP = ("/clock", "clock")
#: Published only for a model with panel contact: one per joint state, same stamp.
CONTACT_ONSETS = Topic("dynamics/contact_onsets", CONTACT_ONSET, STREAM, "dynamics", stamped=True)
TF = Topic("/tf", TF_MESSAGE, EVENTS, "dynamics", stamped=True)
TF_STATIC = Topic("/tf_static", TF_MESSAGE, LATCHED, "dynamics")
DIAGNOSTICS = Topic("/diagnostics", DIAGNOSTIC_ARRAY, EVENTS, "dynamics, collision_monitor, optimiser",
                    stamped=True)
COLLISION_EVENTS = Topic("panel_deploy/collision_events", COLLISION_EVENT, EVENTS,
                         "collision_monitor", stamped=True)
#: The monitor's verdict with its coverage; latched, so a late subscriber has the last.
VERDICT = Topic("collision_monitor/verdict", MONITOR_VERDICT, LATCHED, "collision_monitor",
                stamped=True)
COLLISION_MARKERS = Topic("panel_deploy/collision_markers", MARKER_ARRAY, EVENTS,
                          "collision_monitor", stamped=True)
OPTIMISER_PROGRESS = Topic("optimiser/progress", OPTIMISER_PROGRESS_MSG, EVENTS, "optimiser")
OPTIMISER_RESULT = Topic("optimiser/result", STRING, LATCHED, "optimiser")

#: Every topic, in the order a recording lists its channels.
TOPICS = (ROBOT_DESCRIPTION, MODEL, DEPLOYED_SCENE, JOINT_STATES, CONTACT_ONSETS, PANELS, DIAGNOSTICS,
          COLLISION_EVENTS, VERDICT, COLLISION_MARKERS, OPTIMISER_PROGRESS, OPTIMISER_RESULT, CLOCK_TOPIC,
          TF, TF_STATIC)


@dataclass(frozen=True)
class Service:
    """A service or an action of ``type``: ``node``/``name``, relative to the graph's namespace."""

    node: str
    name: str
    type: str = TRIGGER

    @property
    def path(self) -> str:
        """The service's name relative to the namespace (``dynamics/deploy``)."""
        return f"{self.node}/{self.name}"


RELOAD = Service("array_model", "reload")
RESET = Service("collision_monitor", "reset")
SERVICES = (RELOAD, RESET)

#: Long-running goals with feedback and cancel (``node``/``name``, relative).
DEPLOY = Service("dynamics", "deploy", DEPLOY_ACTION)
OPTIMISE = Service("optimiser", "optimise", OPTIMISE_ACTION)
ACTIONS = (DEPLOY, OPTIMISE)
#: s the dynamics node waits for a Deploy goal's ``wait_for_subscribers`` at most.
SUBSCRIBER_WAIT = 30.0

#: Node names of the suite.
NODES = ("array_model", "dynamics", "collision_monitor", "optimiser")


def nanoseconds(t: float) -> int:
    """``t`` seconds as integer nanoseconds (stamps and MCAP log times)."""
    return round(t * 1e9)


def resolve(name: str, namespace: str = "") -> str:
    """The absolute name of topic ``name`` in ``namespace`` (``""`` or ``/``: the root)."""
    if name.startswith("/"):
        return name
    ns = namespace.strip("/")
    return f"/{ns}/{name}" if ns else f"/{name}"


def namespace_of(resolved: str, topic: Topic) -> str | None:
    """The namespace in which ``topic`` resolves to ``resolved`` ("" for the
    root), or None when it does not."""
    if topic.name.startswith("/"):
        return "" if resolved == topic.name else None
    suffix = "/" + topic.name
    if not resolved.endswith(suffix):
        return None
    return resolved[:-len(suffix)]


def topic_of(resolved: str):
    """``(topic, namespace)`` of a resolved topic name (``/array7/joint_states``),
    or None for a topic the contract does not list."""
    for topic in TOPICS:
        ns = namespace_of(resolved, topic)
        if ns is not None:
            return topic, ns
    return None


def status_name(namespace: str, node: str) -> str:
    """The name of ``node``'s statuses on /diagnostics: its full name
    (``/array7/dynamics``), so that arrays side by side tell theirs apart."""
    return resolve(node, namespace)


OK, WARN, ERROR = 0, 1, 2
PANEL_COLOUR = (0.25, 0.45, 0.85, 1.0)
HIT_COLOUR = (0.95, 0.15, 0.1, 1.0)


def status_value(v) -> str:
    """A diagnostic key-value's text: floats by ``repr``, sequences comma-separated,
    None as the empty string."""
    if v is None:
        return ""
    if isinstance(v, float):
        return "nan" if math.isnan(v) else repr(v)
    if isinstance(v, (list, tuple)):
        return ",".join(map(str, v))
    return str(v)


def _nan(v) -> float:
    """A message's float field: None (no value) as NaN."""
    return math.nan if v is None else float(v)


def event_message(event) -> dict:
    """The fields of the ``CollisionEvent`` message of a collision ``event``
    (:class:`panel_deploy.collision.CollisionEvent`) but its header, whose stamp
    is the event's time in the stream's clock (the deployment's first stamp + t):
    the pair, t (s since the first sample checked), the approach speed of
    Eq. (7) (the normal speed where Eq. 7 has none; m/s), the distance (m),
    contact time (s), sample and contact point (m)."""
    speed = event.approach_speed if math.isfinite(event.approach_speed) else event.normal_speed
    return {"body_a": event.names[0], "body_b": event.names[1], "t": float(event.t),
            "approach_speed": float(speed), "normal_speed": _nan(event.normal_speed),
            "distance": float(event.distance), "contact_time": _nan(event.contact_time),
            "sample": -1 if event.sample is None else int(event.sample),
            "point": [float(x) for x in event.point]}


def event_text(body_a: str, body_b: str, t: float) -> str:
    """One line saying a collision happened (logs, the event's verdict)."""
    return f"collision between {body_a} and {body_b} at t = {t:.4f} s"


def onset_fields(message) -> tuple:
    """``(body_a, body_b, t, speed, point, normal)`` of a ``ContactOnset``
    message (rclpy's or rosbags'), as :meth:`~panel_deploy.collision.StreamCheck.onset` takes them."""
    p, n = message.point, message.normal
    return (message.body_a, message.body_b, float(message.t), float(message.speed),
            (p.x, p.y, p.z), (n.x, n.y, n.z))


#: MonitorVerdict's float, count and name-list fields (besides level and message).
_VERDICT_FLOATS = ("origin", "t", "since_last_sample", "largest_gap", "d", "d_time",
                   "distance_now", "first_collision_t", "approach_speed")
_VERDICT_COUNTS = ("deployment", "samples", "refused", "skipped", "gaps")
#: MonitorVerdict's counts that may be unknown or not apply (-1 in the message).
_VERDICT_OPTIONAL = ("expected", "onsets")
_VERDICT_NAMES = ("measured", "solved", "d_pair", "first_collision_pair")


def verdict_message(level: int, text: str, values: dict) -> dict:
    """The fields of a ``MonitorVerdict`` message but its header, from a
    verdict's key-values (those of ``/diagnostics``): NaN, 0, -1 or an empty
    list where a value is missing (-1: ``expected`` unknown, ``onsets`` not
    checked: a model without panel contact)."""
    out = {"level": int(level), "message": text}
    out.update({k: _nan(values.get(k)) for k in _VERDICT_FLOATS})
    out.update({k: int(values.get(k) or 0) for k in _VERDICT_COUNTS})
    out.update({k: [str(x) for x in values.get(k) or ()] for k in _VERDICT_NAMES})
    out.update({k: -1 if values.get(k) is None else int(values[k]) for k in _VERDICT_OPTIONAL})
    return out


def verdict_values(message) -> dict:
    """A ``MonitorVerdict`` message (rclpy's or rosbags') as the key-values of
    the same verdict on ``/diagnostics``: None where the message holds NaN,
    -1 or an empty pair."""
    out = {"level": int(message.level), "message": message.message}
    for k in _VERDICT_FLOATS:
        v = float(getattr(message, k))
        out[k] = None if math.isnan(v) else v
    out.update({k: int(getattr(message, k)) for k in _VERDICT_COUNTS})
    out.update({k: list(getattr(message, k)) for k in _VERDICT_NAMES})
    for k in ("d_pair", "first_collision_pair"):
        out[k] = out[k] or None
    out.update({k: None if getattr(message, k) < 0 else int(getattr(message, k))
                for k in _VERDICT_OPTIONAL})
    return out


#: Keys of the dynamics node's outcome status (besides ``summary`` and ``samples``).
OUTCOME_KEYS = ("success", "status", "message", "time_to_flat", "t_end", "energy_balance_error",
                "max_constraint_gap", "wall_time", "nsteps")


def outcome_level(summary: dict) -> int:
    """OK when the run reached t_end and flat, WARN when it reached t_end only, else ERROR."""
    if summary["success"]:
        return OK if summary["time_to_flat"] is not None else WARN
    return ERROR


def outcome_values(summary: dict, samples: int) -> dict:
    """The key-values of the dynamics node's outcome status: the scalars of a
    :func:`~panel_deploy.summary.deployment_summary`, ``samples`` (how many
    joint states were published, so a client knows when a monitor has
    checked them all) and the whole summary as JSON."""
    values = {k: summary[k] for k in OUTCOME_KEYS}
    values["samples"] = samples
    values["summary"] = json.dumps(summary)
    return values


def _number(text: str):
    return None if text in ("", "None") else float(text)


def _integer(text: str):
    return None if text in ("", "None") else int(text)


def _pair(text: str):
    return text.split(",") if text else None


#: How each key-value of an event, a verdict or an outcome reads back.
_PARSERS = {"t": float, "approach_speed": float, "deployment": _integer, "onsets": _integer, "origin": _number, "samples": _integer, "d": _number,
            "d_pair": _pair, "d_time": _number, "distance_now": _number, "refused": _integer,
            "gaps": _integer, "skipped": _integer, "largest_gap": _number, "solved": lambda s: s.split(",") if s else [],
            "measured": lambda s: s.split(",") if s else [], "expected": _integer,
            "since_last_sample": _number,
            "first_collision_pair": _pair, "first_collision_t": _number,
            "success": lambda s: s == "True", "status": _integer, "time_to_flat": _number,
            "t_end": _number, "energy_balance_error": _number, "max_constraint_gap": _number,
            "wall_time": _number, "nsteps": _integer, "publish_wall_time": _number,
            "summary": json.loads, "evaluations": _integer, "best_f": float,
            "feasible": lambda s: s == "True", "elapsed": float}


def parse_values(values: dict) -> dict:
    """Key-values of a verdict or an outcome on ``/diagnostics`` (``{key: text}``) as
    Python values: numbers, lists, None for an empty value; unknown keys stay text."""
    return {k: (_PARSERS[k](v) if k in _PARSERS else v) for k, v in values.items()}
