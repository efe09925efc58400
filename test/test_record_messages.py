"""panel_deploy.record.messages and contract.cdr: message contents, CDR bytes, schemas and type hashes.

The fast per-sample encoder is checked byte for byte against rosbags'
serializer; both are decoded by rclpy's own type support (the real ROS
deserializer) and by the schema text we write (mcap-ros2-support, the
parser Foxglove's web decoder mirrors).
"""

import json
import math
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from panel_deploy import contract, frames
from panel_deploy.frames import quaternions
from panel_deploy.build import build_model
from panel_deploy.model import hinge_order
from panel_deploy.export.urdf import link_poses
from panel_deploy.kinematics import forward_kinematics
from panel_deploy.dynamics.deployment import Sample
from panel_deploy.record import messages as m
from panel_deploy.contract.cdr import SampleEncoder
from panel_deploy.scene import load_scene, resolve_scene


# Reference builders: the per-sample messages and /tf_static as rosbags messages, built
# field by field from the same values, for the byte-for-byte check of contract.cdr.
_T = m._T


def clock(t: float):
    return _T[m.CLOCK](clock=m.stamp(t))


def panel_markers(model, rotation, position, t: float):
    """Every panel as a CUBE of its true size (thickness included), frame ``world``;
    ``rotation`` (nb, 3, 3) and ``position`` (nb, 3, m) are the body (centroid) poses."""
    return _T[m.MARKER_ARRAY](markers=[
        m._marker(t, "panels", b, body.size, q, position[b], m.PANEL_COLOUR, body.name)
        for b, (body, q) in enumerate(zip(model.bodies, m._quaternions(rotation)))])


def _transform(t, parent, child, q, p):
    return _T["geometry_msgs/msg/TransformStamped"](
        header=m._header(t, parent), child_frame_id=child,
        transform=_T["geometry_msgs/msg/Transform"](translation=m._vector(p), rotation=q))


def tf_message(model, rotation, position, t: float):
    """``/tf`` at one sample (:func:`tree_transforms`)."""
    a, b, R_rel, p_rel = frames.tree_transforms(model, rotation, position)
    return _T[m.TF_MESSAGE](transforms=[
        _transform(t, model.bodies[i].name, model.bodies[j].name, q, d)
        for i, j, q, d in zip(a, b, m._quaternions(R_rel), p_rel)])


def tf_static(model, t: float = 0.0):
    """``/tf_static``: ``world`` -> the ground body's link (:func:`ground_transform`)."""
    R, p = frames.ground_transform(model)
    return _T[m.TF_MESSAGE](transforms=[_transform(t, m.WORLD, model.bodies[model.ground].name,
                                                 m._quaternions(R[None])[0], p)])




@pytest.fixture(scope="module")
def model():
    return build_model(load_scene(resolve_scene("paper_4x4")))


@pytest.fixture(scope="module")
def names(model):
    return [model.hinges[h].name for h in hinge_order(model)]


def _samples(model, names, count=12, seed=0):
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(count):
        R, p = forward_kinematics(model, rng.uniform(0, np.pi, model.n_coords))
        theta, omega, torque = rng.normal(size=(3, len(names)))
        out.append(Sample(float(rng.uniform(0, 5)), theta, omega, torque, R, p))
    return out


def test_quaternions_match_scipy_up_to_sign():
    R = Rotation.random(500, random_state=3).as_matrix()
    R = np.concatenate([R, np.eye(3)[None], Rotation.from_rotvec([[np.pi, 0, 0]]).as_matrix()])
    q = quaternions(R)
    assert np.all(q[:, 3] >= 0) and np.allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-15)
    assert np.allclose(Rotation.from_quat(q).as_matrix(), R, atol=1e-14)


def test_encoder_bytes_equal_rosbags_serializer(model, names):
    samples = _samples(model, names)
    encoder = SampleEncoder(model)
    assert encoder.names == names
    for s, (time, joint_state, panels, tf) in zip(samples, encoder.encode(samples)):
        assert time == m.serialize(clock(s.t))
        assert joint_state == m.serialize(m.joint_state(names, s.t, s.theta, s.omega, s.torque))
        assert panels == m.serialize(panel_markers(model, s.rotation, s.position, s.t))
        assert tf == m.serialize(tf_message(model, s.rotation, s.position, s.t))
        assert tf == encoder.tf(s.rotation, s.position, s.t)
    assert encoder.tf_static() == m.serialize(tf_static(model))
    prefixed = SampleEncoder(model, "array1/")
    assert prefixed.tf_static() != encoder.tf_static()
    static = m.deserialize(prefixed.tf_static(), m.TF_MESSAGE).transforms[0]
    assert (static.header.frame_id, static.child_frame_id) == ("array1/world", "array1/r1c2+r1c3")


def test_contact_onset_bytes_equal_rosbags_serializer():
    """Every contact pair's onset, no onset, the pair's names in order and a prefixed frame."""
    model = build_model(load_scene(resolve_scene("paper_4x4"), ["contact.panels=true"]))
    rng = np.random.default_rng(5)
    encoder = SampleEncoder(model, "array1/")
    for k in (*range(len(model.contact_pairs)), -1, 3):  # 3 again: its layout reused
        onset = np.array([rng.uniform(0, 1), rng.uniform(0, 4), k, *rng.normal(size=6)])
        a, b = ((model.bodies[i].name for i in model.contact_pairs[k]) if k >= 0 else ("", ""))
        t = float(rng.uniform(0, 2))
        expected = _T[m.CONTACT_ONSET](
            header=m._header(t, "array1/world"), body_a=a, body_b=b, t=float(onset[0]),
            speed=float(onset[1]), point=m._vector(onset[3:6], "Point"), normal=m._vector(onset[6:9]))
        data = encoder.onset(t, onset)
        assert data == m.serialize(expected)
        fields = contract.onset_fields(m.deserialize(data, m.CONTACT_ONSET))
        assert fields[:2] == (a, b) and fields[2:4] == (onset[0], onset[1])
        assert fields[4] + fields[5] == tuple(onset[3:])


def test_tf_composes_to_the_link_poses(model, names):
    s = _samples(model, names, count=1, seed=4)[0]
    R, p = link_poses(model, s.rotation, s.position)
    tf = tf_message(model, s.rotation, s.position, s.t)
    names_of = [b.name for b in model.bodies]
    static = tf_static(model).transforms[0]
    assert static.header.frame_id == "world" and static.child_frame_id == names_of[model.ground]
    world = {"world": (np.eye(3), np.zeros(3))}
    world[static.child_frame_id] = (np.eye(3), _xyz(static.transform.translation))
    pending = list(tf.transforms)
    while pending:  # parents come first in coordinate order, but do not rely on it
        t = pending.pop(0)
        if t.header.frame_id not in world:
            pending.append(t)
            continue
        Rp, pp = world[t.header.frame_id]
        q = t.transform.rotation
        Rc = Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix()
        world[t.child_frame_id] = (Rp @ Rc, pp + Rp @ _xyz(t.transform.translation))
    assert sorted(world) == sorted(["world", *names_of])
    for b, name in enumerate(names_of):
        assert np.allclose(world[name][0], R[b], atol=1e-12)
        assert np.allclose(world[name][1], p[b], atol=1e-12)


def _xyz(v):
    return np.array([v.x, v.y, v.z])


def test_panel_markers_are_cubes_of_the_true_size(model):
    R, p = forward_kinematics(model, model.theta_stowed)
    markers = panel_markers(model, R, p, 0.25).markers
    assert len(markers) == model.n_bodies
    for b, marker in enumerate(markers):
        assert marker.type == 1 and marker.header.frame_id == "world"  # CUBE
        assert np.allclose([marker.scale.x, marker.scale.y, marker.scale.z], model.bodies[b].size)
        assert np.allclose(_xyz(marker.pose.position), p[b])
        assert marker.text == model.bodies[b].name


@pytest.mark.parametrize("topic", sorted(m.TOPICS))
def test_type_hash_is_the_jazzy_interface_hash(topic):
    """rosbag2 stores the RIHS01 hash; it must equal the installed Jazzy interfaces' own."""
    typename = m.TOPICS[topic][0]
    found = list(Path(sys.prefix).glob(f"share/{typename}.json"))
    if not found:
        pytest.skip(f"{typename}.json not installed (tf2_msgs is not pip-installable)")
    hashes = json.loads(found[0].read_text())["type_hashes"]
    expected = next(h["hash_string"] for h in hashes if h["type_name"] == typename)
    assert m.type_hash(typename) == expected


@pytest.mark.parametrize("typename", sorted({t for t, _ in m.TOPICS.values()}))
def test_schema_text_decodes_our_bytes(model, names, typename):
    """mcap-ros2-support builds its decoder from the schema text alone, as Foxglove does."""
    from mcap.records import Schema
    from mcap_ros2.decoder import DecoderFactory

    s = _samples(model, names, count=1, seed=1)[0]
    built = {m.STRING: m.string("<robot/>"), m.JOINT_STATE: m.joint_state(names, s.t, s.theta, s.omega, s.torque),
             m.MARKER_ARRAY: panel_markers(model, s.rotation, s.position, s.t),
             m.DIAGNOSTIC_ARRAY: m.diagnostics(s.t, m.status("x", m.WARN, "text", {"a": 1.5, "b": None})),
             m.CLOCK: clock(s.t), m.TF_MESSAGE: tf_message(model, s.rotation, s.position, s.t),
             m.COLLISION_EVENT: m.collision_event(EVENT, origin=2.0),
             m.MONITOR_VERDICT: m.verdict(2, "collision", VERDICT, 2.416),
             contract.OPTIMISER_PROGRESS_MSG: m.TYPESTORE.types[contract.OPTIMISER_PROGRESS_MSG](
                 header=m._header(3.0), phase="local 1", evaluations=7, best_f=-0.5,
                 feasible=True, elapsed=3.0),
             m.CONTACT_ONSET: _T[m.CONTACT_ONSET](
                 header=m._header(0.285), body_a="r4c1", body_b="r4c4", t=0.2841, speed=0.094,
                 point=m._vector((0.1, 0.2, 0.0), "Point"), normal=m._vector((0.0, 0.0, 1.0)))}
    schema = Schema(id=1, name=typename, encoding="ros2msg", data=m.msgdef(typename).encode())
    decoded = DecoderFactory().decoder_for("cdr", schema)(m.serialize(built[typename]))
    if typename == m.JOINT_STATE:
        assert list(decoded.name) == names and np.allclose(decoded.position, s.theta)
    elif typename == m.TF_MESSAGE:
        assert len(decoded.transforms) == model.n_coords
    elif typename == m.MARKER_ARRAY:
        assert [x.text for x in decoded.markers] == [b.name for b in model.bodies]
    elif typename == m.CONTACT_ONSET:
        assert (decoded.body_a, decoded.body_b, decoded.t, decoded.speed) == ("r4c1", "r4c4", 0.2841, 0.094)
        assert decoded.header.stamp.nanosec == 285_000_000 and decoded.normal.z == 1.0
    elif typename == m.COLLISION_EVENT:
        assert (decoded.body_a, decoded.body_b, decoded.t) == ("a", "b", 0.416)
        assert decoded.header.stamp.sec == 2 and decoded.point.y == 0.16
        assert math.isnan(decoded.contact_time) and decoded.sample == 84
    elif typename == m.MONITOR_VERDICT:
        assert decoded.level == 2 and list(decoded.first_collision_pair) == ["a", "b"]
        assert decoded.expected == -1 and math.isnan(decoded.d) and decoded.samples == 84


#: A collision event and a verdict as the core makes them (fields of
#: panel_deploy.collision's CollisionEvent and of StreamCheck.verdict()).
EVENT = SimpleNamespace(names=("a", "b"), t=0.416, approach_speed=4.2, normal_speed=4.0,
                        distance=-1e-4, contact_time=None, sample=84, point=(0.0, 0.16, 0.0025))
VERDICT = {"deployment": 1, "origin": 2.0, "t": 0.416, "samples": 84, "d": None,
           "measured": ["r1c1-r1c2"], "solved": [], "first_collision_pair": ["a", "b"],
           "first_collision_t": 0.416, "approach_speed": 4.2}


def test_rclpy_deserializes_what_we_encode(model, names):
    """The real ROS type support decodes every type it has (tf2_msgs is not pip-installable)."""
    pytest.importorskip("rclpy")
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.serialization import deserialize_message
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import JointState
    from visualization_msgs.msg import MarkerArray

    s = _samples(model, names, count=1, seed=2)[0]
    clock, joint_state, panels, _ = SampleEncoder(model).encode([s])[0]
    js = deserialize_message(joint_state, JointState)
    assert list(js.name) == names and np.array_equal(js.position, s.theta)
    assert np.array_equal(js.velocity, s.omega) and np.array_equal(js.effort, s.torque)
    assert js.header.stamp.sec * 10**9 + js.header.stamp.nanosec == m.nanoseconds(s.t)
    markers = deserialize_message(panels, MarkerArray).markers
    assert [x.text for x in markers] == [b.name for b in model.bodies]
    assert np.allclose([[x.pose.position.x, x.pose.position.y, x.pose.position.z] for x in markers],
                       s.position, atol=0)
    assert deserialize_message(clock, Clock).clock.nanosec == m.nanoseconds(s.t) % 10**9
    diag = deserialize_message(m.serialize(m.diagnostics(1.5, m.status("n", m.ERROR, "msg", {"k": 2.0}))),
                               DiagnosticArray)
    assert diag.status[0].level == b"\x02" and diag.status[0].values[0].value == "2.0"
    from panel_deploy_interfaces.msg import CollisionEvent, MonitorVerdict

    event = deserialize_message(m.serialize(m.collision_event(EVENT, origin=2.0)), CollisionEvent)
    assert (event.body_a, event.body_b, event.sample, event.point.z) == ("a", "b", 84, 0.0025)
    assert event.header.stamp.sec == 2 and event.header.stamp.nanosec == 416_000_000
    verdict = deserialize_message(m.serialize(m.verdict(2, "c", VERDICT, 2.416)), MonitorVerdict)
    assert verdict.level == MonitorVerdict.ERROR and list(verdict.measured) == ["r1c1-r1c2"]
    assert contract.verdict_values(verdict)["first_collision_t"] == 0.416


def test_rclpy_bytes_with_stray_padding_decode_and_trim():
    """rclpy's bytes for a JointState with empty float64 arrays end in stray padding,
    which rosbags' strict decoder rejects; ours ignores it and ``trim`` cuts it off."""
    pytest.importorskip("rclpy")
    from rclpy.serialization import serialize_message
    from rosbags.serde import SerdeError
    from sensor_msgs.msg import JointState

    msg = JointState(name=["r1c1-r1c2", "r1c1-r2c1"], position=[0.5, 1.5])
    msg.header.stamp.sec, msg.header.stamp.nanosec = 3, 250
    data = serialize_message(msg)
    with pytest.raises(SerdeError):
        m.TYPESTORE.deserialize_cdr(data, m.JOINT_STATE)
    ours = m.deserialize(data, m.JOINT_STATE)
    trimmed = m.trim(data, m.JOINT_STATE)
    strict = m.TYPESTORE.deserialize_cdr(trimmed, m.JOINT_STATE)
    for decoded in (ours, strict):
        assert decoded.name == msg.name and list(decoded.position) == [0.5, 1.5]
        assert len(decoded.velocity) == len(decoded.effort) == 0
        assert m.seconds(decoded.header.stamp) == 3 + 250e-9
    with pytest.raises(ValueError, match="not CDR"):
        m.deserialize(b"text", m.JOINT_STATE)
