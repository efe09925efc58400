"""Every ROS message the nodes send or read, built from and parsed into core values.

The one ROS-facing module of message building: nodes call these and never
fill message fields themselves. Times are simulated seconds; frames follow
the URDF (``world`` is the ground panel's flat frame).
"""

from __future__ import annotations

import array
import json
from importlib import import_module

import numpy as np
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Point, Pose, Quaternion, Vector3
from panel_deploy_interfaces.msg import CollisionEvent, MonitorVerdict, OptimiserProgress
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from scipy.spatial.transform import Rotation
from sensor_msgs.msg import JointState
from std_msgs.msg import ColorRGBA, String
from visualization_msgs.msg import Marker, MarkerArray

from .. import contract
from ..contract import HIT_COLOUR
from ..errors import TrajectoryError, shown

FRAME = contract.WORLD
OK, WARN, ERROR = DiagnosticStatus.OK, DiagnosticStatus.WARN, DiagnosticStatus.ERROR


def message_class(typename: str):
    """The rclpy message class of a ROS 2 type name (``sensor_msgs/msg/JointState``)."""
    package, kind, name = typename.split("/")
    return getattr(import_module(f"{package}.{kind}"), name)


def qos(q: contract.QoS) -> QoSProfile:
    """rclpy's QoSProfile of a contract QoS."""
    return QoSProfile(depth=q.depth, history=HistoryPolicy.KEEP_LAST,
                      reliability=ReliabilityPolicy[q.reliability.upper()],
                      durability=DurabilityPolicy[q.durability.upper()])


def stamp(t: float) -> Time:
    """``builtin_interfaces/Time`` of ``t`` s (>= 0)."""
    ns = round(t * 1e9)
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def seconds(time: Time) -> float:
    return time.sec + time.nanosec * 1e-9


def string(text: str) -> String:
    return String(data=text)


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


def read_joint_state(msg: JointState, names) -> tuple:
    """``(t, name, position, velocity)`` of a JointState whose joints are among ``names``.

    ``t`` is the stamp in s; ``velocity`` is None when the message has none.
    Which joints it must carry is the stream check's to say (any set the
    loop closure completes).

    Raises
    ------
    TrajectoryError
        Unknown or repeated names, array lengths that do not match ``name``,
        or values that are not finite; the message says which field.
    """
    n = len(msg.name)
    if len(set(msg.name)) != n:
        raise TrajectoryError("name: a joint is named twice")
    unknown = sorted(set(msg.name) - set(names))
    if unknown:
        raise TrajectoryError(f"name: unknown joint {shown(unknown[0])}")
    if len(msg.position) != n:
        raise TrajectoryError(f"position: {len(msg.position)} values for {n} names")
    if len(msg.velocity) not in (0, n):
        raise TrajectoryError(f"velocity: {len(msg.velocity)} values for {n} names")
    position = np.asarray(msg.position, dtype=float)
    velocity = np.asarray(msg.velocity, dtype=float) if len(msg.velocity) else None
    for field, values in (("position", position), ("velocity", velocity)):
        if values is not None and not np.all(np.isfinite(values)):
            raise TrajectoryError(f"{field}: not finite ({values[~np.isfinite(values)][0]})")
    return seconds(msg.header.stamp), list(msg.name), position, velocity


def _pose(rotation, position) -> Pose:
    x, y, z, w = Rotation.from_matrix(rotation).as_quat()
    return Pose(position=Point(x=float(position[0]), y=float(position[1]), z=float(position[2])),
                orientation=Quaternion(x=float(x), y=float(y), z=float(z), w=float(w)))


def _box(model, body, rotation, position, t, ns, colour, frame=FRAME) -> Marker:
    m = Marker()
    m.header.frame_id = frame
    m.header.stamp = stamp(t)
    m.ns, m.id, m.type, m.action = ns, int(body), Marker.CUBE, Marker.ADD
    m.pose = _pose(rotation[body], position[body])
    sx, sy, sz = model.bodies[body].size
    m.scale = Vector3(x=float(sx), y=float(sy), z=float(sz))
    m.color = ColorRGBA(r=colour[0], g=colour[1], b=colour[2], a=colour[3])
    m.text = model.bodies[body].name
    return m


def collision_markers(model, event, rotation, position, stamp_s: float,
                      frame: str = FRAME) -> MarkerArray:
    """The colliding pair in red at the instant of the event, and the contact point,
    in ``frame``, stamped ``stamp_s`` (s, the stream's clock)."""
    boxes = [_box(model, b, rotation, position, stamp_s, "collision", HIT_COLOUR, frame)
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


def clear_markers(frame: str = FRAME) -> MarkerArray:
    """DELETEALL: every marker of the topic's publisher off the display."""
    m = Marker()
    m.header.frame_id = frame
    m.action = Marker.DELETEALL
    return MarkerArray(markers=[m])


def status(name: str, level: int, message: str, values: dict | None = None,
           hardware_id: str = "panel_array") -> DiagnosticStatus:
    """A DiagnosticStatus; ``level`` OK, WARN, ERROR or 0, 1, 2; ``values``
    become key-values (None as empty string)."""
    return DiagnosticStatus(level=level if isinstance(level, bytes) else bytes([level]),
                            name=name, message=message, hardware_id=hardware_id,
                            values=[KeyValue(key=str(k), value=contract.status_value(v))
                                    for k, v in (values or {}).items()])


def values(status: DiagnosticStatus) -> dict:
    """A status's key-values as Python values (:func:`~panel_deploy.contract.parse_values`)."""
    return contract.parse_values({kv.key: kv.value for kv in status.values})


def diagnostics(t: float, *statuses) -> DiagnosticArray:
    msg = DiagnosticArray(status=list(statuses))
    msg.header.stamp = stamp(t)
    return msg


def collision_event(event, origin: float = 0.0, frame: str = FRAME) -> CollisionEvent:
    """The ``CollisionEvent`` of ``event``: stamped ``origin`` + t (s, the
    stream's clock), its point in ``frame`` (:func:`~panel_deploy.contract.event_message`)."""
    fields = contract.event_message(event)
    x, y, z = fields.pop("point")
    msg = CollisionEvent(point=Point(x=x, y=y, z=z), **fields)
    msg.header.stamp, msg.header.frame_id = stamp(origin + event.t), frame
    return msg


def verdict(level: int, text: str, values: dict, stamp_s: float) -> MonitorVerdict:
    """The ``MonitorVerdict`` of a verdict's key-values, stamped ``stamp_s`` (s)."""
    msg = MonitorVerdict(**contract.verdict_message(level, text, values))
    msg.header.stamp = stamp(stamp_s)
    return msg


def progress(p, wall_s: float) -> OptimiserProgress:
    """The ``OptimiserProgress`` of a search's progress report (optimise.search.Progress)."""
    msg = OptimiserProgress(phase=p.phase, evaluations=p.nfev, best_f=float(p.best_f),
                            feasible=bool(not p.collision and p.reached_flat),
                            elapsed=float(p.elapsed))
    msg.header.stamp = stamp(wall_s)
    return msg


def deploy_result(summary: dict, samples: int):
    """The Deploy action's result of a deployment summary
    (:func:`panel_deploy.summary.deployment_summary`) and the samples published."""
    from panel_deploy_interfaces.action import Deploy

    def number(key):  # None (never flat, not computed) as NaN
        return float("nan") if summary[key] is None else float(summary[key])

    return Deploy.Result(
        success=bool(summary["success"]), status=int(summary["status"]),
        message=summary["message"], samples=samples, nsteps=int(summary["nsteps"]),
        summary=json.dumps(summary),
        **{k: number(k) for k in ("t_end", "time_to_flat", "energy_balance_error",
                                  "max_constraint_gap", "wall_time")})
