"""``simulate --record``: the paper deployment read back by four independent decoders.

- the ``mcap`` library's reader: header, summary, statistics, chunk and
  metadata indexes, CRCs;
- ``rosbags``: rosbag2's reader on the file alone and its own CDR decoder:
  every message decodes and equals what the simulation computed;
- ``rclpy.serialization.deserialize_message``: the real ROS type support;
- rerun's MCAP importer (``rerun mcap convert``): Boxes3D from the URDF,
  Transform3D for every panel frame, scalars for the joint states.
"""

import io
import json
import math
import shutil
import subprocess
import sys
from contextlib import redirect_stdout
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from panel_deploy.build import build_model
from panel_deploy.cli import main
from panel_deploy.dynamics.report import hinge_states
from panel_deploy.export.urdf import link_poses, model_urdf
from panel_deploy.scene_text import scene_from_yaml
from panel_deploy.record import messages as m
from panel_deploy.pipeline import simulate_scene
from panel_deploy.scene import load_scene, resolve_scene

PER_SAMPLE = ("/clock", "/joint_states", "/panel_deploy/panels", "/tf")
#: Latched topics, as ROS users expect them (a late subscriber gets the last message).
LATCHED = ("/robot_description", "/panel_deploy/model", "/tf_static", "/dynamics/scene", "/collision_monitor/verdict",
           "/optimiser/result")
#: What simulate --record has no source for: no optimiser runs, no panel contact in the paper's model.
NOT_SIMULATED = ("/optimiser/progress", "/optimiser/result", "/dynamics/contact_onsets")


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """The paper deployment recorded, and the same deployment simulated without recording."""
    path = tmp_path_factory.mktemp("rec") / "paper.mcap"
    out = io.StringIO()
    with redirect_stdout(out):
        assert main(["simulate", "paper_4x4", "--record", str(path), "--json"]) == 0
    scene = load_scene(resolve_scene("paper_4x4"))
    model, result, report = simulate_scene(scene)
    return path, json.loads(out.getvalue()), scene, model, result, report


def test_the_recorded_run_is_the_plain_run(recorded):
    path, summary, scene, model, result, report = recorded
    first = summary["collision"]["first_collision"]
    assert first["t"] == report.first_collision.t and first["pair"] == list(report.first_collision.names)
    assert summary["collision"]["v"] == report.v and summary["collision"]["d"] == report.d
    assert summary["time_to_flat"] is not None and summary["t_end"] == result.t[-1]


def test_mcap_reader_summary_counts_and_chunks(recorded):
    from mcap.reader import make_reader

    path, _, scene, model, result, report = recorded
    expected = {topic: (len(result.t) if topic in PER_SAMPLE else 0 if topic in NOT_SIMULATED
                        else len(report.events) if topic == "/panel_deploy/collision_events" else 1)
                for topic in m.TOPICS}
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        header, summary = reader.get_header(), reader.get_summary()
        assert header.profile == "ros2"
        topics = {c.topic: c for c in summary.channels.values()}
        assert sorted(topics) == sorted(m.TOPICS)
        counts = summary.statistics.channel_message_counts
        for topic, channel in topics.items():
            schema = summary.schemas[channel.schema_id]
            assert (schema.name, schema.encoding, channel.message_encoding) == \
                   (m.TOPICS[topic][0], "ros2msg", "cdr")
            assert channel.metadata["topic_type_hash"] == m.type_hash(schema.name)
            qos = yaml.safe_load(channel.metadata["offered_qos_profiles"])[0]
            assert qos["durability"] == ("transient_local" if topic in LATCHED else "volatile")
            assert qos["depth"] == (5000 if topic in ("/joint_states", "/clock", "/dynamics/contact_onsets") else
                                    1 if topic in LATCHED else 100)
            assert counts.get(channel.id, 0) == expected[topic], topic
        assert summary.statistics.message_count == sum(expected.values())
        assert summary.statistics.message_end_time == round(result.t[-1] * 1e9)
        chunks = summary.chunk_indexes
        assert len(chunks) >= 8 and all(c.compression == "zstd" for c in chunks)
        # chunks close every 0.25 s of simulated time: what a killed process loses
        assert max(c.message_end_time - c.message_start_time for c in chunks) < 0.25e9
        assert sum(1 for _ in reader.iter_messages()) == summary.statistics.message_count
        meta = {r.name: r.metadata for r in reader.iter_metadata()}
    assert {"scene", "model", "integrator", "run", "outcome", "rosbag2"} <= set(meta)
    outcome = {k: json.loads(v) for k, v in meta["outcome"].items() if k != "message"}
    assert outcome["first_collision_pair"] == ["r1c2+r1c3", "r2c2+r2c3"]
    assert outcome["time_to_flat"] == 1.645 and outcome["collided"] is True
    integrator = {k: json.loads(v) for k, v in meta["integrator"].items() if k != "method"}
    assert integrator["rtol"] == scene.simulation.rtol and integrator["rate_hz"] == 200.0
    assert json.loads(meta["model"]["stiffness"]) == [h.k for h in model.hinges]
    assert json.loads(meta["model"]["damping"]) == [h.c for h in model.hinges]
    assert json.loads(meta["model"]["air_density"]) == 0.0  # the paper's model: no air
    assert json.loads(meta["model"]["stop_ramp"]) == 0.0  # and the paper's joint stops
    assert json.loads(meta["model"]["panel_contacts"]) == len(model.contact_pairs) == 0  # no panel contact
    assert json.loads(meta["model"]["friction"]) == 0.0
    assert json.loads(meta["model"]["contact_pressure"]) is False
    assert yaml.safe_load(meta["scene"]["yaml"])["name"] == "paper_4x4"
    assert meta["run"]["version"] and meta["run"]["wall_time"]
    bag = yaml.safe_load(meta["rosbag2"]["serialized_metadata"])
    assert bag["version"] == 9 and bag["storage_identifier"] == "mcap"
    assert {t["topic_metadata"]["name"]: t["message_count"] for t in bag["topics_with_message_count"]} \
        == expected


def _rosbags_messages(path):
    from rosbags.rosbag2 import Reader

    out = {}
    with Reader(path) as reader:
        assert reader.message_count == sum(c.msgcount for c in reader.connections)
        for connection, timestamp, raw in reader.messages():
            msg = m.TYPESTORE.deserialize_cdr(raw, connection.msgtype)
            out.setdefault(connection.topic, []).append((timestamp, msg))
    return out


def test_rosbags_decodes_every_message_and_it_is_what_was_computed(recorded):
    path, _, scene, model, result, report = recorded
    got = _rosbags_messages(path)
    names, theta, omega, torque = hinge_states(model, result)
    s = len(result.t)
    stamps = [round(t * 1e9) for t in result.t]
    js = got["/joint_states"]
    assert [ts for ts, _ in js] == stamps
    assert all(list(msg.name) == names for _, msg in js)
    assert np.array_equal(np.array([msg.position for _, msg in js]), theta)
    assert np.array_equal(np.array([msg.velocity for _, msg in js]), omega)
    assert np.array_equal(np.array([msg.effort for _, msg in js]), torque)
    assert [msg.clock.sec * 10**9 + msg.clock.nanosec for _, msg in got["/clock"]] == stamps
    for j in (0, s // 2, s - 1):
        markers = got["/panel_deploy/panels"][j][1].markers
        assert np.allclose([[x.scale.x, x.scale.y, x.scale.z] for x in markers],
                           [b.size for b in model.bodies], rtol=0, atol=0)
        assert np.array_equal([[x.pose.position.x, x.pose.position.y, x.pose.position.z]
                               for x in markers], result.position[j])
        q = [[x.pose.orientation.x, x.pose.orientation.y, x.pose.orientation.z,
              x.pose.orientation.w] for x in markers]
        assert np.allclose(Rotation.from_quat(q).as_matrix(), result.rotation[j], atol=1e-14)
        R, p = link_poses(model, result.rotation[j], result.position[j])
        frames = {b.name: i for i, b in enumerate(model.bodies)}
        for t in got["/tf"][j][1].transforms:
            a, b = frames[t.header.frame_id], frames[t.child_frame_id]
            assert np.allclose([t.transform.translation.x, t.transform.translation.y,
                                t.transform.translation.z], R[a].T @ (p[b] - p[a]), atol=1e-14)
    assert len(got["/tf"][0][1].transforms) == model.n_bodies - 1
    assert got["/robot_description"][0][1].data == model_urdf(model)
    rebuilt = build_model(scene_from_yaml(got["/panel_deploy/model"][0][1].data))
    assert [h.k for h in rebuilt.hinges] == [h.k for h in model.hinges]
    assert np.allclose([h.c for h in rebuilt.hinges], [h.c for h in model.hinges], rtol=1e-12)
    static = got["/tf_static"][0][1].transforms[0]
    assert (static.header.frame_id, static.child_frame_id) == ("world", model.bodies[model.ground].name)
    events = got["/panel_deploy/collision_events"]
    first = report.first_collision
    assert [t for t, _ in events] == [stamps[first.sample]] * len(report.events)
    event = events[0][1]
    assert [event.body_a, event.body_b] == list(first.names) and event.sample == first.sample
    assert event.t == first.t and event.approach_speed == first.approach_speed
    assert event.header.frame_id == "world" and np.array_equal(
        [event.point.x, event.point.y, event.point.z], first.point)
    (t_verdict, verdict), = got["/collision_monitor/verdict"]
    assert t_verdict == stamps[-1] and verdict.level == m.ERROR
    assert list(verdict.first_collision_pair) == list(first.names) and verdict.d == report.d
    (t_end, diagnostics), = got["/diagnostics"]
    assert t_end == stamps[-1]
    outcome = {st.name: st for st in diagnostics.status}
    assert outcome["/dynamics"].level == m.OK
    assert outcome["/collision_monitor"].level == m.ERROR


def test_rclpy_deserializes_every_message_to_the_same_content(recorded):
    """The real ROS 2 type support (every type but tf2_msgs, which is not pip-installable)."""
    pytest.importorskip("rclpy")
    from diagnostic_msgs.msg import DiagnosticArray
    from mcap.reader import make_reader
    from rclpy.serialization import deserialize_message
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import JointState
    from std_msgs.msg import String
    from visualization_msgs.msg import MarkerArray

    from panel_deploy_interfaces.msg import CollisionEvent, MonitorVerdict

    types = {m.STRING: String, m.JOINT_STATE: JointState, m.MARKER_ARRAY: MarkerArray,
             m.DIAGNOSTIC_ARRAY: DiagnosticArray, m.CLOCK: Clock,
             m.COLLISION_EVENT: CollisionEvent, m.MONITOR_VERDICT: MonitorVerdict}
    path = recorded[0]
    decoded = 0
    with open(path, "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages():
            if schema.name not in types:
                continue
            ours = m.deserialize(message.data, schema.name)
            theirs = deserialize_message(message.data, types[schema.name])
            _same(ours, theirs)
            decoded += 1
    # 3 strings, markers of the collision, /diagnostics, the verdict and the events
    assert decoded == 3 * len(recorded[4].t) + 6 + len(recorded[5].events)


def _same(ours, theirs):
    """Field-by-field equality of a rosbags message and an rclpy message."""
    for name in theirs.get_fields_and_field_types():
        a, b = getattr(ours, name), getattr(theirs, name)
        if hasattr(b, "get_fields_and_field_types"):
            _same(a, b)
        elif isinstance(b, list) and b and hasattr(b[0], "get_fields_and_field_types"):
            assert len(a) == len(b)
            for x, y in zip(a, b):
                _same(x, y)
        elif isinstance(b, bytes):  # byte fields: rclpy bytes, rosbags int
            assert (a if isinstance(a, (bytes, bytearray)) else bytes([a])) == b
        else:
            a, b = np.asarray(a), np.asarray(b)
            assert np.array_equal(a, b, equal_nan=a.dtype.kind == "f"), name


def _rerun():
    exe = Path(sys.executable).parent / "rerun"
    return str(exe) if exe.exists() else shutil.which("rerun")


def test_rerun_importer_shows_the_urdf_boxes_moved_by_tf(recorded, tmp_path):
    """What ``rerun FILE.mcap`` shows without our code: URDF boxes, /tf frames, joint scalars."""
    from rerun.chunk import RrdReader

    path, _, scene, model, result, _ = recorded
    rrd = tmp_path / "x.rrd"
    subprocess.run([_rerun(), "mcap", "convert", str(path), "-o", str(rrd)], check=True,
                   capture_output=True, timeout=300)
    first, frames, children, scalars = {}, set(), set(), 0  # first: (entity, component) -> value
    for chunk in RrdReader(rrd).stream():
        batch = chunk.to_record_batch()
        for column in ("Boxes3D:half_sizes", "CoordinateFrame:frame"):
            if column in batch.schema.names:
                values = [x for x in batch.column(column).to_pylist() if x]
                if values:
                    first.setdefault((chunk.entity_path, column), values[0][0])
        if "Transform3D:child_frame" in batch.schema.names:
            children.update(x[0] for x in batch.column("Transform3D:child_frame").to_pylist() if x)
            frames.update(x[0] for x in batch.column("Transform3D:parent_frame").to_pylist() if x)
        if chunk.entity_path == "/joint_states/position" and "Scalars:scalars" in batch.schema.names:
            scalars += sum(1 for x in batch.column("Scalars:scalars").to_pylist() if x)
    boxes = {first[(e, "CoordinateFrame:frame")]: np.array(half) * 2
             for (e, c), half in first.items()
             if c == "Boxes3D:half_sizes" and "visual" in e and (e, "CoordinateFrame:frame") in first}
    names = [b.name for b in model.bodies]
    assert sorted(boxes) == sorted(names)
    for b in model.bodies:  # float32 in rerun
        assert np.allclose(boxes[b.name], b.size, rtol=1e-6)
    assert children == set(names) and "world" in frames
    assert scalars == len(result.t)


def test_collide_on_the_recording_reports_the_simulated_collision(recorded, capsys):
    path, _, scene, model, result, report = recorded
    assert main(["collide", str(path), "--json"]) == 0
    got = json.loads(capsys.readouterr().out)
    assert got["first_collision"]["t"] == report.first_collision.t
    assert got["first_collision"]["pair"] == list(report.first_collision.names)
    assert math.isclose(got["v"], report.v, rel_tol=1e-12)
    assert math.isclose(got["d"], report.d, rel_tol=1e-12)


def test_a_recording_with_panel_contact_carries_its_onsets(tmp_path, capsys):
    """Every pair of the paper scene in contact: r1c2+r1c3 comes down on r2c4
    and r4c1 on r4c4 at 0.2836 s, impacts the contact holds within the
    tolerance (test_contacts).
    The recording has each sample's onset on dynamics/contact_onsets (rosbags
    reads them), and ``collide`` on it finds the impact the simulation's
    check found, with a verdict that says nothing is missing."""
    from panel_deploy.collision import check_trajectory

    sets = ["--set", "contact.panels=true", "--set", "simulation.t_end=0.3", "--set",
            "simulation.samples=61"]
    path = tmp_path / "contact.mcap"
    assert main(["simulate", "paper_4x4", *sets, "--record", str(path), "--json"]) == 0
    first = json.loads(capsys.readouterr().out)["collision"]["first_collision"]
    scene = load_scene(resolve_scene("paper_4x4"), [a for a in sets if a != "--set"])
    model, result, report = simulate_scene(scene)
    assert report.first_collision.impact and first["t"] == report.first_collision.t
    assert report.first_collision.t == check_trajectory(model, result).first_collision.t
    onsets = _rosbags_messages(path)["/dynamics/contact_onsets"]
    assert [t for t, _ in onsets] == [round(t * 1e9) for t in result.t]
    fastest = max((msg for _, msg in onsets), key=lambda msg: msg.speed)
    assert [fastest.body_a, fastest.body_b] == list(report.first_collision.names)
    assert fastest.t == report.first_collision.t
    assert main(["collide", str(path), "--json"]) == 0
    got = json.loads(capsys.readouterr().out)
    assert got["first_collision"]["t"] == report.first_collision.t
    assert got["first_collision"]["pair"] == list(report.first_collision.names)
    assert got["verdict"] == {"level": 2, "message": got["verdict"]["message"]}
    assert "onsets" not in got["verdict"]["message"], got["verdict"]


@pytest.mark.parametrize("search", [[], ["--set", "optimisation.damping_ratio_bounds=[0.043,0.3]"]])
def test_optimise_record_deploys_the_result_file(tmp_path, search):
    """``optimise --record`` records the deployment of the K and c it wrote to --out
    (with a searched c/k, the recording's scene carries it as hinges.damping_ratio)."""
    out, mcap = tmp_path / "k.yaml", tmp_path / "best.mcap"
    code = main(["optimise", "paper_4x4", "--max-evaluations", "4", "--workers", "1", "--quiet",
                 "--out", str(out), "--record", str(mcap), *search])
    assert code in (0, 1)
    hinges = yaml.safe_load(out.read_text())["hinges"]
    from panel_deploy.record import open_recording
    recording = open_recording(mcap)
    model = json.loads(recording.metadata["model"]["stiffness"]), \
        json.loads(recording.metadata["model"]["damping"])
    names = json.loads(recording.metadata["model"]["hinges"])
    assert model[0] == [hinges[n]["k"] for n in names]
    assert np.allclose(model[1], [hinges[n]["c"] for n in names], rtol=1e-12, atol=0)
    ratio = hinges[names[0]]["c"] / hinges[names[0]]["k"]
    assert recording.scene().hinges.damping_ratio == pytest.approx(ratio, rel=1e-12)
    rebuilt = build_model(recording.scene())
    assert [h.k for h in rebuilt.hinges] == model[0]
    assert recording.count("/joint_states") == 401
