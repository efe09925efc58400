"""Every ROS message the nodes send or read, built from and parsed into core values.

The one ROS-facing module of message building: nodes call these and never
fill message fields themselves. Times are simulated seconds; frames follow
the URDF (``world`` is the ground panel's flat frame).
"""

from __future__ import annotations

import array

import numpy as np
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Point, Pose, Quaternion, Vector3
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rosgraph_msgs.msg import Clock
from scipy.spatial.transform import Rotation
from sensor_msgs.msg import JointState
from std_msgs.msg import ColorRGBA, String
from visualization_msgs.msg import Marker, MarkerArray

from ..errors import TrajectoryError, shown
from ..record.messages import EVENT_STATUS, PANEL_COLOUR, event_fields, status_value

#: Latched topics (/robot_description, /panel_deploy/model, results): a late
#: subscriber still gets the last message.
LATCHED = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST,
                     reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
#: /joint_states and /clock: reliable and deep enough for a whole deployment
#: computed faster than real time (2 s at 1 kHz), so no subscriber misses a sample.
STREAM = QoSProfile(depth=5000, history=HistoryPolicy.KEEP_LAST,
                    reliability=ReliabilityPolicy.RELIABLE)
#: Everything else.
EVENTS = QoSProfile(depth=100, history=HistoryPolicy.KEEP_LAST,
                    reliability=ReliabilityPolicy.RELIABLE)

FRAME = "world"
OK, WARN, ERROR = DiagnosticStatus.OK, DiagnosticStatus.WARN, DiagnosticStatus.ERROR
HIT_COLOUR = (0.95, 0.15, 0.1, 1.0)


def stamp(t: float) -> Time:
    """``builtin_interfaces/Time`` of ``t`` s (>= 0)."""
    ns = round(t * 1e9)
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def seconds(time: Time) -> float:
    return time.sec + time.nanosec * 1e-9


def string(text: str) -> String:
    return String(data=text)


def clock(t: float) -> Clock:
    return Clock(clock=stamp(t))


def joint_state(names, t, theta, omega, torque) -> JointState:
    """Every hinge: position theta (rad), velocity omega (rad/s), effort torque (N m)."""
    msg = JointState()
    msg.header.stamp = stamp(t)
    msg.name = list(names)
    # array.array('d') is taken as it is; a list is checked element by element.
    msg.position = _doubles(theta)
    msg.velocity = _doubles(omega)
    msg.effort = _doubles(torque)
    return msg


def _doubles(values) -> array.array:
    return array.array("d", np.ascontiguousarray(values, dtype=float).tobytes())


def read_joint_state(msg: JointState, names, required) -> tuple:
    """``(t, theta, omega)`` of a JointState for the hinges ``required`` (names, in order).

    ``names`` are all hinges the model knows (a stream may carry the cut
    hinge too); ``omega`` is None when the message has no velocities.

    Raises
    ------
    TrajectoryError
        Unknown or missing names, array lengths that do not match ``name``,
        or values that are not finite; the message says which field.
    """
    n = len(msg.name)
    if len(set(msg.name)) != n:
        raise TrajectoryError("name: a joint is named twice")
    unknown = sorted(set(msg.name) - set(names))
    if unknown:
        raise TrajectoryError(f"name: unknown joint {shown(unknown[0])}")
    missing = [h for h in required if h not in msg.name]
    if missing:
        raise TrajectoryError(f"name: missing joint {shown(missing[0])}")
    if len(msg.position) != n:
        raise TrajectoryError(f"position: {len(msg.position)} values for {n} names")
    if len(msg.velocity) not in (0, n):
        raise TrajectoryError(f"velocity: {len(msg.velocity)} values for {n} names")
    index = [list(msg.name).index(h) for h in required]
    theta = np.asarray(msg.position, dtype=float)[index]
    omega = np.asarray(msg.velocity, dtype=float)[index] if len(msg.velocity) else None
    t = seconds(msg.header.stamp)
    for field, values in (("position", theta), ("velocity", omega)):
        if values is not None and not np.all(np.isfinite(values)):
            raise TrajectoryError(f"{field}: not finite ({values[~np.isfinite(values)][0]})")
    return t, theta, omega


def _pose(rotation, position) -> Pose:
    x, y, z, w = Rotation.from_matrix(rotation).as_quat()
    return Pose(position=Point(x=float(position[0]), y=float(position[1]), z=float(position[2])),
                orientation=Quaternion(x=float(x), y=float(y), z=float(z), w=float(w)))


def _box(model, body, rotation, position, t, ns, colour) -> Marker:
    m = Marker()
    m.header.frame_id = FRAME
    m.header.stamp = stamp(t)
    m.ns, m.id, m.type, m.action = ns, int(body), Marker.CUBE, Marker.ADD
    m.pose = _pose(rotation[body], position[body])
    sx, sy, sz = model.bodies[body].size
    m.scale = Vector3(x=float(sx), y=float(sy), z=float(sz))
    m.color = ColorRGBA(r=colour[0], g=colour[1], b=colour[2], a=colour[3])
    m.text = model.bodies[body].name
    return m


def panel_markers(model, rotation, position, t) -> MarkerArray:
    """Every panel as a box of its true size (thickness included), frame ``world``."""
    return MarkerArray(markers=[_box(model, b, rotation, position, t, "panels", PANEL_COLOUR)
                                for b in range(model.n_bodies)])


def move_markers(markers: MarkerArray, rotation, position, t) -> MarkerArray:
    """``markers`` of :func:`panel_markers`, moved in place to new poses at ``t``.

    Filling a message costs far more than changing it (rclpy checks every
    field on construction): a stream moves one array instead.
    """
    quaternions = Rotation.from_matrix(rotation).as_quat()
    time = stamp(t)
    for m, q, p in zip(markers.markers, quaternions.tolist(), position.tolist()):
        m.header.stamp = time
        o, x = m.pose.orientation, m.pose.position
        o.x, o.y, o.z, o.w = q
        x.x, x.y, x.z = p
    return markers


def collision_markers(model, event, rotation, position) -> MarkerArray:
    """The colliding pair in red at the instant of the event, and the contact point."""
    boxes = [_box(model, b, rotation, position, event.t, "collision", HIT_COLOUR)
             for b in event.bodies]
    point = Marker()
    point.header = boxes[0].header
    point.ns, point.id, point.type, point.action = "collision_point", 0, Marker.SPHERE, Marker.ADD
    point.pose.position = Point(x=float(event.point[0]), y=float(event.point[1]),
                                z=float(event.point[2]))
    point.pose.orientation.w = 1.0
    point.scale = Vector3(x=0.01, y=0.01, z=0.01)
    point.color = ColorRGBA(r=1.0, g=1.0, b=0.0, a=1.0)
    return MarkerArray(markers=boxes + [point])


def status(name: str, level: int, message: str, values: dict | None = None,
           hardware_id: str = "panel_array") -> DiagnosticStatus:
    """A DiagnosticStatus; ``level`` OK, WARN, ERROR or 0, 1, 2; ``values``
    become key-values (None as empty string)."""
    return DiagnosticStatus(level=level if isinstance(level, bytes) else bytes([level]),
                            name=name, message=message, hardware_id=hardware_id,
                            values=[KeyValue(key=str(k), value="" if v is None else status_value(v))
                                    for k, v in (values or {}).items()])


def diagnostics(t: float, *statuses) -> DiagnosticArray:
    msg = DiagnosticArray(status=list(statuses))
    msg.header.stamp = stamp(t)
    return msg


def event_status(event) -> DiagnosticStatus:
    """One collision event's status, as recordings carry it (``event_fields``)."""
    return status(EVENT_STATUS, ERROR, *event_fields(event))
