"""/tf and /tf_static of the dynamics node (separate processes): two arrays side by
side in /array1 and /array2, each with its own ``frame_prefix``; the link frames of
every sample agree with the model's forward kinematics, resolved as tf2 would, and
the messages are ROS 2 Jazzy's tf2_msgs/TFMessage on the wire."""

import numpy as np
import pytest

tf2_msgs = pytest.importorskip(
    "tf2_msgs.msg", reason="tf2_msgs has no wheel: pip install ./vendor/interfaces (README)")

from rcl_interfaces.srv import SetParameters  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rosbags.typesys import Stores, get_typestore  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

from panel_deploy import contract  # noqa: E402
from panel_deploy.build import build_model  # noqa: E402
from panel_deploy.export.urdf import link_poses  # noqa: E402
from panel_deploy.kinematics import forward_kinematics  # noqa: E402
from panel_deploy.nodes import messages  # noqa: E402
from panel_deploy.scene import load_scene, resolve_scene  # noqa: E402
from ros_harness import Client, NodeProcess, wait_for  # noqa: E402

TFMessage = tf2_msgs.TFMessage
T_END, RATE = 0.3, 200.0
SAMPLES = round(T_END * RATE) + 1
#: Namespace -> frame_prefix and extra parameters: the second array is damped, so
#: frames crossing over from the other array would not match its joint states.
ARRAYS = {"/array1": ("array1/", []), "/array2": ("array2/", ["damping_ratio:=0.19"])}


@pytest.fixture(scope="module")
def run(compiled_nodes):
    """Both arrays deployed once: per namespace its joint states, /tf and
    /tf_static messages (by frame prefix), and every /tf as CDR bytes."""
    procs = []
    for ns, (prefix, extra) in ARRAYS.items():
        procs += [NodeProcess("array_model", "scene:=paper_4x4", namespace=ns),
                  NodeProcess("dynamics", f"t_end:={T_END}", f"rate_hz:={RATE}",
                              "real_time_factor:=0.0", f"frame_prefix:={prefix}", *extra,
                              namespace=ns)]
    client = Client("tf_test")
    try:
        yield client, *_deploy_both(client)
    finally:
        client.close()
        for p in procs:
            p.stop()


def _deploy_both(client):
    states = {ns: client.listen(JointState, f"{ns}/joint_states", messages.qos(contract.STREAM)) for ns in ARRAYS}
    tf = client.listen(TFMessage, "/tf", messages.qos(contract.EVENTS))
    static = client.listen(TFMessage, "/tf_static", messages.qos(contract.LATCHED))
    raw = []
    client.node.create_subscription(TFMessage, "/tf", raw.append, messages.qos(contract.EVENTS), raw=True)
    wait_for(lambda: client.node.count_publishers("/tf") >= len(ARRAYS), what="the /tf publishers")
    for ns in ARRAYS:
        client.start_goal(contract.DEPLOY, f"{ns}/dynamics", wait_for_subscribers=1)

    def prefixed(box, prefix):
        return [m for m in list(box) if m.transforms[0].header.frame_id.startswith(prefix)]
    wait_for(lambda: all(len(states[ns]) >= SAMPLES and len(prefixed(tf, p)) >= SAMPLES
                         and prefixed(static, p) for ns, (p, _) in ARRAYS.items()),
             timeout=180, what="every sample of both arrays on joint_states and /tf, and /tf_static")
    return {ns: (states[ns], prefixed(tf, p), prefixed(static, p))
            for ns, (p, _) in ARRAYS.items()}, raw


def resolve(static, tf, prefix):
    """Every frame's (R, p) in ``prefix``world, chaining /tf_static and /tf as tf2 does."""
    edges = {}
    for t in [*static.transforms, *tf.transforms]:
        r, x = t.transform.rotation, t.transform.translation
        q = np.array([r.x, r.y, r.z, r.w])
        assert abs(np.linalg.norm(q) - 1.0) <= 1e-12
        edges.setdefault(t.header.frame_id, []).append((t.child_frame_id, _matrix(q),
                                                        np.array([x.x, x.y, x.z])))
    poses = {prefix + "world": (np.eye(3), np.zeros(3))}
    todo = [prefix + "world"]
    while todo:
        parent = todo.pop()
        R, p = poses[parent]
        for child, R_rel, p_rel in edges.get(parent, []):
            assert child not in poses, f"{child} has two parents"
            poses[child] = (R @ R_rel, p + R @ p_rel)
            todo.append(child)
    return poses


def _matrix(q):
    x, y, z, w = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


@pytest.mark.parametrize("ns", ARRAYS)
def test_tf_is_the_forward_kinematics_of_every_sample(run, ns):
    _, arrays, _ = run
    states, tf, static = arrays[ns]
    prefix = ARRAYS[ns][0]
    model = build_model(load_scene(resolve_scene("paper_4x4")))
    links = [prefix + b.name for b in model.bodies]
    (ground,) = static[-1].transforms
    assert (ground.header.frame_id, ground.child_frame_id) == (prefix + "world",
                                                                links[model.ground])
    by_stamp = {(s.header.stamp.sec, s.header.stamp.nanosec): s for s in states}
    assert len(tf) == SAMPLES and len(by_stamp) == SAMPLES
    worst = 0.0
    for message in tf:
        (stamp,) = {(t.header.stamp.sec, t.header.stamp.nanosec) for t in message.transforms}
        state = by_stamp[stamp]  # one /tf per joint_states sample, same stamp
        position = dict(zip(state.name, state.position))
        theta = [position[model.hinges[h].name] for h in model.joints]
        R, p = link_poses(model, *forward_kinematics(model, theta))
        assert len(message.transforms) == len(model.joints)
        poses = resolve(static[-1], message, prefix)
        assert sorted(poses) == sorted([prefix + "world", *links])  # one tree: every link
        for b, name in enumerate(links):
            R_tf, p_tf = poses[name]
            worst = max(worst, np.abs(p_tf - p[b]).max())
            assert np.abs(R_tf - R[b]).max() <= 1e-9, name
    assert worst <= 1e-9
    assert messages.seconds(tf[-1].transforms[0].header.stamp) == pytest.approx(T_END, abs=1e-9)


def test_tf_is_jazzy_tf2_msgs_on_the_wire(run):
    """Type name, type hash and CDR are ROS 2 Jazzy's: rosbags' Jazzy type store (an
    independent implementation) hashes the type the same and reads every message."""
    client, arrays, raw = run
    store = get_typestore(Stores.ROS2_JAZZY)
    infos = client.node.get_publishers_info_by_topic("/tf")
    assert len(infos) == len(ARRAYS)
    for info in infos:
        assert info.topic_type == "tf2_msgs/msg/TFMessage"
        assert str(info.topic_type_hash) == store.hash_rihs01("tf2_msgs/msg/TFMessage")

    def key(transforms):
        t = transforms[-1]
        return (t.header.frame_id, t.header.stamp.sec, t.header.stamp.nanosec, t.child_frame_id)
    decoded = {key(m.transforms): m for m in
               (store.deserialize_cdr(data, "tf2_msgs/msg/TFMessage") for data in list(raw))}
    ours = {key(m.transforms): m for _, tf, _ in arrays.values() for m in tf}
    assert len(ours) == len(ARRAYS) * SAMPLES
    # The raw subscription is one of its own: it may still lack the last sample or so.
    assert set(decoded) <= set(ours) and len(decoded) >= SAMPLES
    for k, theirs in decoded.items():
        message = ours[k]
        for a, b in zip(message.transforms, theirs.transforms, strict=True):
            assert (a.header.frame_id, a.child_frame_id) == (b.header.frame_id, b.child_frame_id)
            x, y = a.transform, b.transform
            assert (x.translation.x, x.translation.y, x.translation.z, x.rotation.x, x.rotation.y,
                    x.rotation.z, x.rotation.w) == (y.translation.x, y.translation.y,
                                                    y.translation.z, y.rotation.x, y.rotation.y,
                                                    y.rotation.z, y.rotation.w)


@pytest.mark.parametrize("value, ok", [("array9/", True), ("", True), ("/array1/", False),
                                       ("array 1/", False)])
def test_frame_prefix_is_checked_when_set(run, value, ok):
    client, *_ = run
    reply = client.call(SetParameters, "/array1/dynamics/set_parameters", SetParameters.Request(
        parameters=[Parameter("frame_prefix", value=value).to_parameter_msg()]))
    result = reply.results[0]
    assert result.successful == ok, result.reason
    assert ok or "frame_prefix" in result.reason
