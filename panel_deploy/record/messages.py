"""The ROS 2 messages of a recording, built without rclpy as ``rosbags`` dataclasses.

Same topics, types and contents as the node suite (``panel_deploy/nodes``):
times are simulated seconds, frames follow the URDF of
:func:`panel_deploy.export.urdf.model_urdf` (``world`` is the flat array
frame; one link per body, named ``Body.name``). Types come from the rosbags
ROS 2 Jazzy type store (``tf2_msgs`` included, which is not pip-installable);
:func:`serialize` turns a message into its CDR bytes, as ROS 2 sends them.
"""

from __future__ import annotations

import math
import struct

import numpy as np
from rosbags.typesys import Stores, get_typestore

from ..export.urdf import WORLD, link_poses

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
_T = TYPESTORE.types

STRING = "std_msgs/msg/String"
JOINT_STATE = "sensor_msgs/msg/JointState"
MARKER_ARRAY = "visualization_msgs/msg/MarkerArray"
DIAGNOSTIC_ARRAY = "diagnostic_msgs/msg/DiagnosticArray"
CLOCK = "rosgraph_msgs/msg/Clock"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"

#: QoS the node suite offers: latched (transient local, depth 1), the joint
#: state stream (depth 5000) and everything else (depth 100); all reliable.
LATCHED, STREAM, EVENTS = ("transient_local", 1), ("volatile", 5000), ("volatile", 100)

#: Every topic a recording carries: type and the QoS (durability, depth) its publisher offers.
TOPICS = {
    "/robot_description": (STRING, LATCHED),
    "/panel_deploy/model": (STRING, LATCHED),
    "/joint_states": (JOINT_STATE, STREAM),
    "/panel_deploy/panels": (MARKER_ARRAY, EVENTS),
    "/diagnostics": (DIAGNOSTIC_ARRAY, EVENTS),
    "/panel_deploy/collision_events": (DIAGNOSTIC_ARRAY, EVENTS),
    "/clock": (CLOCK, EVENTS),
    "/tf": (TF_MESSAGE, EVENTS),
    "/tf_static": (TF_MESSAGE, LATCHED),
}

OK, WARN, ERROR = 0, 1, 2
#: Status names of the node suite's ``dynamics`` and ``collision_monitor``, as the
#: nodes name theirs (their full names) in the root namespace.
DYNAMICS_STATUS = "/dynamics"
MONITOR_STATUS = "/collision_monitor"
EVENT_STATUS = MONITOR_STATUS + "/event"
PANEL_COLOUR = (0.25, 0.45, 0.85, 1.0)


def serialize(message) -> bytes:
    """CDR bytes (little endian, with the encapsulation header) of a rosbags message."""
    return bytes(TYPESTORE.serialize_cdr(message, message.__msgtype__, little_endian=True))


def _decode(data, typename: str):
    """``(message, end)``: the rosbags message in CDR bytes ``data`` and the
    byte offset where it ends (encapsulation header included)."""
    data = memoryview(data)
    if len(data) < 4 or bytes(data[:2]) not in (b"\x00\x00", b"\x00\x01"):
        raise ValueError("not CDR (no CDR encapsulation header)")
    msgdef = TYPESTORE.get_msgdef(typename)
    decode = msgdef.deserialize_cdr_le if data[1] else msgdef.deserialize_cdr_be
    try:
        message, end = decode(data[4:], 0, msgdef.cls, TYPESTORE)
    except (struct.error, UnicodeDecodeError, ValueError, IndexError) as e:
        raise ValueError(f"not a {typename} ({e})") from None
    return message, 4 + end


def deserialize(data, typename: str):
    """The rosbags message of CDR bytes ``data`` of type ``typename``.

    Bytes after the end of the message are ignored: rclpy's serializer
    (whose bytes ``ros2 bag record`` stores) leaves stray padding after some
    messages, e.g. a JointState with an empty float64 array, which the
    strict ``deserialize_cdr`` of rosbags rejects as a size mismatch.

    Raises
    ------
    ValueError
        Not CDR, or the bytes end before the message does.
    """
    return _decode(data, typename)[0]


def trim(data, typename: str) -> bytes:
    """CDR bytes of type ``typename`` without what follows the message (see
    :func:`deserialize`), so that strict decoders accept them too; for bytes
    received from rclpy before they are recorded."""
    return bytes(memoryview(data)[:_decode(data, typename)[1]])


def msgdef(typename: str) -> str:
    """The ``ros2msg`` schema text of ``typename``: its definition, then every
    type it uses after a ``MSG:`` separator line (the MCAP ROS 2 profile)."""
    return TYPESTORE.generate_msgdef(typename, ros_version=2)[0]


def type_hash(typename: str) -> str:
    """The ROS 2 type hash (``RIHS01_...``) that rosbag2 stores as ``topic_type_hash``."""
    return TYPESTORE.hash_rihs01(typename)


def nanoseconds(t: float) -> int:
    """``t`` seconds as integer nanoseconds (the MCAP log time and ROS stamp resolution)."""
    return round(t * 1e9)


def stamp(t: float):
    """``builtin_interfaces/Time`` of ``t`` s (>= 0)."""
    ns = nanoseconds(t)
    return _T["builtin_interfaces/msg/Time"](sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def seconds(time) -> float:
    """Seconds of a ``builtin_interfaces/Time``."""
    return time.sec + time.nanosec * 1e-9


def _header(t: float, frame: str = ""):
    return _T["std_msgs/msg/Header"](stamp=stamp(t), frame_id=frame)


def string(text: str):
    return _T[STRING](data=text)


def clock(t: float):
    return _T[CLOCK](clock=stamp(t))


def joint_state(names, t: float, theta, omega, torque):
    """Every hinge: position theta (rad), velocity omega (rad/s), effort torque (N m)."""
    return _T[JOINT_STATE](header=_header(t), name=list(names),
                           position=np.asarray(theta, dtype=np.float64),
                           velocity=np.asarray(omega, dtype=np.float64),
                           effort=np.asarray(torque, dtype=np.float64))


def quaternions(R) -> np.ndarray:
    """Unit quaternions (x, y, z, w) of rotation matrices ``R`` (k, 3, 3), w >= 0.

    Shepperd's method: each quaternion is computed from its largest
    component, so there is no division by a small number.
    """
    R = np.asarray(R, dtype=float)
    m00, m11, m22 = R[:, 0, 0], R[:, 1, 1], R[:, 2, 2]
    # 4 x^2, 4 y^2, 4 z^2, 4 w^2
    d = np.stack([1 + m00 - m11 - m22, 1 - m00 + m11 - m22, 1 - m00 - m11 + m22,
                  1 + m00 + m11 + m22], axis=1)
    big = np.argmax(d, axis=1)
    s = 2 * np.sqrt(d[np.arange(len(R)), big])  # 4 times the largest component
    yz, xz, xy = R[:, 1, 2] + R[:, 2, 1], R[:, 0, 2] + R[:, 2, 0], R[:, 0, 1] + R[:, 1, 0]
    wx, wy, wz = R[:, 2, 1] - R[:, 1, 2], R[:, 0, 2] - R[:, 2, 0], R[:, 1, 0] - R[:, 0, 1]
    quarter = s * s / 4
    # Row j: 4 * the largest component times (x, y, z, w), if component j is the largest.
    candidates = np.array([[quarter, xy, xz, wx], [xy, quarter, yz, wy],
                           [xz, yz, quarter, wz], [wx, wy, wz, quarter]])  # (4, 4, k)
    q = candidates[big, :, np.arange(len(R))] / s[:, None]
    return q * np.where(q[:, 3:] < 0, -1.0, 1.0)


def _quaternions(R):
    """``geometry_msgs/Quaternion`` of every rotation matrix in ``R`` (k, 3, 3)."""
    q = _T["geometry_msgs/msg/Quaternion"]
    return [q(x=x, y=y, z=z, w=w) for x, y, z, w in quaternions(R).tolist()]


def _vector(v, kind="Vector3"):
    return _T[f"geometry_msgs/msg/{kind}"](x=float(v[0]), y=float(v[1]), z=float(v[2]))


_NO_IMAGE = _T["sensor_msgs/msg/CompressedImage"](
    header=_T["std_msgs/msg/Header"](stamp=_T["builtin_interfaces/msg/Time"](sec=0, nanosec=0),
                                     frame_id=""),
    format="", data=np.zeros(0, dtype=np.uint8))
_NO_MESH = _T["visualization_msgs/msg/MeshFile"](filename="", data=np.zeros(0, dtype=np.uint8))
_FOREVER = _T["builtin_interfaces/msg/Duration"](sec=0, nanosec=0)


def _marker(t, ns, index, body, q, p, colour):
    return _T["visualization_msgs/msg/Marker"](
        header=_header(t, WORLD), ns=ns, id=int(index), type=1, action=0,  # CUBE, ADD
        pose=_T["geometry_msgs/msg/Pose"](position=_vector(p, "Point"), orientation=q),
        scale=_vector(body.size), color=_T["std_msgs/msg/ColorRGBA"](*map(float, colour)),
        lifetime=_FOREVER, frame_locked=False, points=[], colors=[], texture_resource="",
        texture=_NO_IMAGE, uv_coordinates=[], text=body.name, mesh_resource="", mesh_file=_NO_MESH,
        mesh_use_embedded_materials=False)


def panel_markers(model, rotation, position, t: float):
    """Every panel as a CUBE of its true size (thickness included), frame ``world``;
    ``rotation`` (nb, 3, 3) and ``position`` (nb, 3, m) are the body (centroid) poses."""
    return _T[MARKER_ARRAY](markers=[
        _marker(t, "panels", b, body, q, position[b], PANEL_COLOUR)
        for b, (body, q) in enumerate(zip(model.bodies, _quaternions(rotation)))])


def _transform(t, parent, child, q, p):
    return _T["geometry_msgs/msg/TransformStamped"](
        header=_header(t, parent), child_frame_id=child,
        transform=_T["geometry_msgs/msg/Transform"](translation=_vector(p), rotation=q))


def tree_transforms(model, rotation, position):
    """Every tree joint's child link in its parent link's frame, as
    robot_state_publisher would broadcast them (frames = URDF link names).

    ``rotation`` (nb, 3, 3) and ``position`` (nb, 3, m) are the body (centroid)
    poses in ``world``. Returns ``(parent, child, R, p)``: body indices (k,),
    rotations (k, 3, 3) and translations (k, 3, m), in ``model.joints`` order.
    The recordings' ``/tf`` and the dynamics node's are made of these.
    """
    R, p = link_poses(model, rotation, position)
    pairs = [(model.hinges[h].body_a, model.hinges[h].body_b) for h in model.joints]
    a, b = np.array(pairs).T
    R_rel = np.einsum("kji,kjl->kil", R[a], R[b])           # R_a^T R_b
    p_rel = np.einsum("kji,kj->ki", R[a], p[b] - p[a])      # R_a^T (p_b - p_a)
    return a, b, R_rel, p_rel


def ground_transform(model):
    """``world`` -> the ground body's link (the URDF's fixed joint): ``(R, p)``."""
    g = model.ground
    R, p = link_poses(model, np.eye(3)[None].repeat(model.n_bodies, 0),
                      np.array([b.flat_position for b in model.bodies]))
    return R[g], p[g]


def tf_message(model, rotation, position, t: float):
    """``/tf`` at one sample (:func:`tree_transforms`)."""
    a, b, R_rel, p_rel = tree_transforms(model, rotation, position)
    return _T[TF_MESSAGE](transforms=[
        _transform(t, model.bodies[i].name, model.bodies[j].name, q, d)
        for i, j, q, d in zip(a, b, _quaternions(R_rel), p_rel)])


def tf_static(model, t: float = 0.0):
    """``/tf_static``: ``world`` -> the ground body's link (:func:`ground_transform`)."""
    R, p = ground_transform(model)
    return _T[TF_MESSAGE](transforms=[_transform(t, WORLD, model.bodies[model.ground].name,
                                                 _quaternions(R[None])[0], p)])


def status_value(v) -> str:
    """A diagnostic key-value's text: floats by ``repr``, sequences comma-separated."""
    if isinstance(v, float):
        return "nan" if math.isnan(v) else repr(v)
    if isinstance(v, (list, tuple)):
        return ",".join(map(str, v))
    return str(v)


def status(name: str, level: int, message: str, values: dict | None = None,
           hardware_id: str = "panel_array"):
    """A ``diagnostic_msgs/DiagnosticStatus``; ``values`` become key-values
    (None as the empty string, floats by ``repr``, sequences comma-separated)."""
    kv = _T["diagnostic_msgs/msg/KeyValue"]
    return _T["diagnostic_msgs/msg/DiagnosticStatus"](
        level=level, name=name, message=message,
        hardware_id=hardware_id,
        values=[kv(key=str(k), value="" if v is None else status_value(v))
                for k, v in (values or {}).items()])


def diagnostics(t: float, *statuses):
    return _T[DIAGNOSTIC_ARRAY](header=_header(t), status=list(statuses))


def event_fields(event) -> tuple:
    """Message and key-values of one collision event's status: pair, time (s),
    approach speed of Eq. (7) (m/s), distance (m); the nodes send the same."""
    speed = event.approach_speed if math.isfinite(event.approach_speed) else event.normal_speed
    return (f"collision between {event.names[0]} and {event.names[1]} at t = {event.t:.4f} s",
            {"pair": list(event.names), "t": event.t, "approach_speed": speed,
             "normal_speed": event.normal_speed, "distance": event.distance,
             "contact_time": event.contact_time, "sample": event.sample,
             "point": [float(x) for x in event.point]})


def event_status(event):
    """One collision event's DiagnosticStatus (:func:`event_fields`)."""
    return status(EVENT_STATUS, ERROR, *event_fields(event))


def outcome_status(summary: dict):
    """The ``dynamics`` node's end-of-run status from a deployment summary
    (:func:`panel_deploy.summary.deployment_summary`)."""
    s = summary
    level = OK if s["success"] and s["time_to_flat"] is not None else (WARN if s["success"] else ERROR)
    values = {k: s[k] for k in ("success", "status", "message", "time_to_flat", "t_end",
                                "energy_balance_error", "max_constraint_gap", "wall_time", "nsteps")}
    return status(DYNAMICS_STATUS, level, s["message"], values)
