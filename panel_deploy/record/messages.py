"""The ROS 2 messages of a recording, built without rclpy as ``rosbags`` dataclasses.

Same topics, types and contents as the node suite (``panel_deploy/nodes``):
times are simulated seconds, frames follow the URDF of
:func:`panel_deploy.export.urdf.model_urdf` (``world`` is the flat array
frame; one link per body, named ``Body.name``). Types come from the rosbags
ROS 2 Jazzy type store (``tf2_msgs`` included, which is not pip-installable)
and our own ``panel_deploy_interfaces`` messages, registered from their .msg
text (:func:`panel_deploy.contract.definitions`);
:func:`serialize` turns a message into its CDR bytes, as ROS 2 sends them.
"""

from __future__ import annotations

import struct

import numpy as np
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from .. import contract
from ..contract import nanoseconds
# The contract's type names and levels, here too for readers of recordings (m.JOINT_STATE).
from ..contract import (CLOCK, COLLISION_EVENT, CONTACT_ONSET, DIAGNOSTIC_ARRAY,  # noqa: F401
                        ERROR, JOINT_STATE, MARKER_ARRAY, MONITOR_VERDICT, HIT_COLOUR, OK,
                        PANEL_COLOUR, STRING, TF_MESSAGE, WARN, WORLD)
from ..frames import quaternions

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
for _name, _text in contract.definitions().items():
    TYPESTORE.register(get_types_from_msg(_text, _name))
_T = TYPESTORE.types

#: The recorded topics, by resolved name in the root namespace: (type, QoS).
TOPICS = {contract.resolve(t.name): (t.type, t.qos) for t in contract.TOPICS}


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


#: Field defaults of the Jazzy definitions our messages use, which rosbags'
#: generated text leaves out: ``geometry_msgs/Quaternion`` is the only type
#: among them with defaults (checked against the .msg files of the Jazzy wheels).
_DEFAULTS = {"geometry_msgs/Quaternion": {"x": "0", "y": "0", "z": "0", "w": "1"}}


def msgdef(typename: str) -> str:
    """The ``ros2msg`` schema text of ``typename``: its definition, then every
    type it uses after a ``MSG:`` separator line (the MCAP ROS 2 profile),
    field defaults included (``float64 w 1`` of a Quaternion)."""
    text = TYPESTORE.generate_msgdef(typename, ros_version=2)[0]
    lines, current = [], "/".join(typename.split("/")[::2])
    for line in text.split("\n"):
        if line.startswith("MSG: "):
            current = line[len("MSG: "):]
        parts = line.split()
        default = _DEFAULTS.get(current, {}).get(parts[1]) if len(parts) == 2 else None
        lines.append(f"{line} {default}" if default is not None else line)
    return "\n".join(lines)


def type_hash(typename: str) -> str:
    """The ROS 2 type hash (``RIHS01_...``) that rosbag2 stores as ``topic_type_hash``."""
    return TYPESTORE.hash_rihs01(typename)


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


def joint_state(names, t: float, theta, omega, torque):
    """Every hinge: position theta (rad), velocity omega (rad/s), effort torque (N m)."""
    return _T[JOINT_STATE](header=_header(t), name=list(names),
                           position=np.ascontiguousarray(theta, dtype=np.float64),
                           velocity=np.ascontiguousarray(omega, dtype=np.float64),
                           effort=np.ascontiguousarray(torque, dtype=np.float64))


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


def _marker(t, ns, index, size, q, p, colour, text="", kind=1):
    """A Marker in ``world``: ``kind`` 1 CUBE, 2 SPHERE; action ADD."""
    return _T["visualization_msgs/msg/Marker"](
        header=_header(t, WORLD), ns=ns, id=int(index), type=kind, action=0,
        pose=_T["geometry_msgs/msg/Pose"](position=_vector(p, "Point"), orientation=q),
        scale=_vector(size), color=_T["std_msgs/msg/ColorRGBA"](*map(float, colour)),
        lifetime=_FOREVER, frame_locked=False, points=[], colors=[], texture_resource="",
        texture=_NO_IMAGE, uv_coordinates=[], text=text, mesh_resource="", mesh_file=_NO_MESH,
        mesh_use_embedded_materials=False)


def collision_markers(model, event, rotation, position):
    """The colliding pair of ``event`` in red at the instant of the event, and
    its contact point (a yellow 10 mm sphere), as the collision monitor sends them."""
    q = _quaternions(rotation)
    unit = _T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0)
    return _T[MARKER_ARRAY](markers=[
        *(_marker(event.t, "collision", b, model.bodies[b].size, q[b], position[b], HIT_COLOUR,
                  model.bodies[b].name) for b in event.bodies),
        _marker(event.t, "collision_point", 0, (0.01, 0.01, 0.01), unit, event.point,
                (1.0, 1.0, 0.0, 1.0), kind=2)])


def status(name: str, level: int, message: str, values: dict | None = None,
           hardware_id: str = "panel_array"):
    """A ``diagnostic_msgs/DiagnosticStatus``; ``values`` become key-values
    (None as the empty string, floats by ``repr``, sequences comma-separated)."""
    kv = _T["diagnostic_msgs/msg/KeyValue"]
    return _T["diagnostic_msgs/msg/DiagnosticStatus"](
        level=level, name=name, message=message,
        hardware_id=hardware_id,
        values=[kv(key=str(k), value=contract.status_value(v))
                for k, v in (values or {}).items()])


def diagnostics(t: float, *statuses):
    return _T[DIAGNOSTIC_ARRAY](header=_header(t), status=list(statuses))


def collision_event(event, origin: float = 0.0, frame: str = WORLD):
    """The ``CollisionEvent`` of ``event`` as the collision monitor sends it:
    stamped ``origin`` + t (s), its point in ``frame``."""
    fields = contract.event_message(event)
    point = _vector(fields.pop("point"), "Point")
    return _T[COLLISION_EVENT](header=_header(origin + event.t, frame), point=point, **fields)


def verdict(level: int, text: str, values: dict, stamp_s: float):
    """The monitor's ``MonitorVerdict`` of a verdict's key-values, stamped ``stamp_s`` (s)."""
    return _T[MONITOR_VERDICT](header=_header(stamp_s),
                               **contract.verdict_message(level, text, values))


def outcome_status(name: str, summary: dict, samples: int):
    """The ``dynamics`` node's end-of-run status (named ``name``) from a deployment
    summary (:func:`panel_deploy.summary.deployment_summary`)."""
    return status(name, contract.outcome_level(summary), summary["message"],
                  contract.outcome_values(summary, samples))
