"""``panel-deploy run --record``: the live graph's topics in MCAP, read back by independent readers."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hostile import file_size_limit
from rclpy.serialization import deserialize_message
from rosbags.rosbag2 import Reader
from scipy.spatial.transform import Rotation
from sensor_msgs.msg import JointState

from readers import typestore_of
from panel_deploy.collision import CollisionSettings, check_trajectory
from panel_deploy.dynamics import simulate
from panel_deploy.dynamics.report import hinge_states
from panel_deploy.export.urdf import link_poses
from panel_deploy.configure import DynamicsParameters, configure
from panel_deploy.scene import load_scene, resolve_scene

CLI = str(Path(sys.executable).parent / "panel-deploy")
T_END = 0.6


@pytest.fixture(scope="module")
def recording(tmp_path_factory, compiled_nodes):
    path = tmp_path_factory.mktemp("run") / "run.mcap"
    proc = subprocess.run([CLI, "run", "paper_4x4", "--real-time-factor", "0", "--record", str(path),
                           "--set", f"simulation.t_end={T_END}"],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 1, proc.stderr  # the paper's uniform k collides
    scene, model = configure(load_scene(resolve_scene("paper_4x4"), [f"simulation.t_end={T_END}"]),
                             DynamicsParameters(rate_hz=200.0))
    return path, model, simulate(model, scene.simulation)


def read(path):
    out = {}
    with Reader(path) as reader:
        store = typestore_of(reader)
        for connection, timestamp, raw in reader.messages():
            out.setdefault(connection.topic, []).append(
                (timestamp, raw, store.deserialize_cdr(raw, connection.msgtype)))
    return out


def test_rosbags_reads_every_topic_and_the_joint_states_are_the_core_run(recording):
    path, model, result = recording
    got = read(path)
    assert {t: len(v) for t, v in got.items() if t in ("/robot_description", "/panel_deploy/model",
                                                          "/tf_static")} == dict.fromkeys(
        ("/robot_description", "/panel_deploy/model", "/tf_static"), 1)
    names, theta, omega, torque = hinge_states(model, result)
    js = got["/joint_states"]
    assert len(js) == len(got["/clock"]) == len(got["/tf"]) == len(result.t)
    assert [ts for ts, _, _ in js] == [round(t * 1e9) for t in result.t]  # log time = simulated
    assert np.abs(np.array([m.position for _, _, m in js]) - theta).max() <= 1e-9
    assert np.abs(np.array([m.effort for _, _, m in js]) - torque).max() <= 1e-9
    assert got["/panel_deploy/collision_events"] and got["/diagnostics"]
    j = len(result.t) - 1
    R, p = link_poses(model, result.rotation[j], result.position[j])
    frames = {b.name: i for i, b in enumerate(model.bodies)}
    for t in got["/tf"][j][2].transforms:  # child in parent frame, as robot_state_publisher
        a, b = frames[t.header.frame_id], frames[t.child_frame_id]
        q = t.transform.rotation
        R_rel = Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix()
        assert np.allclose(R_rel, R[a].T @ R[b], atol=1e-9)
        d = t.transform.translation
        assert np.allclose([d.x, d.y, d.z], R[a].T @ (p[b] - p[a]), atol=1e-9)


def test_rclpy_decodes_the_recorded_joint_states(recording):
    path, model, result = recording
    for _, raw, msg in read(path)["/joint_states"][::50]:
        ours = deserialize_message(raw, JointState)
        assert list(ours.name) == list(msg.name) and list(ours.position) == list(msg.position)


def test_collide_reads_the_recording_and_agrees(recording):
    path, model, result = recording
    proc = subprocess.run([CLI, "collide", str(path), "--json"], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode in (0, 1), proc.stderr
    scene = load_scene(resolve_scene("paper_4x4"))
    report = check_trajectory(model, result, CollisionSettings.from_scene(scene))
    first = json.loads(proc.stdout)["first_collision"]
    assert first["pair"] == list(report.first_collision.names)
    assert abs(first["t"] - report.first_collision.t) <= 1e-6


@pytest.mark.parametrize("target", ["{tmp}/no/x.mcap", "/dev/full"])
def test_unwritable_record_path_is_one_line(tmp_path, target):
    target = target.format(tmp=tmp_path)
    proc = subprocess.run([CLI, "run", "paper_4x4", "--record", target],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1 and target in proc.stderr


def test_a_recording_that_fills_the_disk_stops_and_the_run_goes_on(tmp_path, compiled_nodes):
    (tmp_path / "x.mcap").write_bytes(b"the previous recording")
    proc = subprocess.run([CLI, "run", "paper_4x4", "--real-time-factor", "0", "--json", "--record",
                           "x.mcap", "--set", f"simulation.t_end={T_END}"], cwd=tmp_path,
                          preexec_fn=file_size_limit(50_000),  # outgrown mid-run
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
    # the run's answer is kept (last line: Fast DDS complains on stdout that the limit
    # also stops its shared-memory segments)
    assert json.loads(proc.stdout.strip().splitlines()[-1])["collision"]["first_collision"]
    assert proc.stderr.strip().splitlines()[-1] == ("panel-deploy: error: x.mcap: cannot write the "
                                                    "recording (File too large); x.mcap is "
                                                    "unchanged")
    assert (tmp_path / "x.mcap").read_bytes() == b"the previous recording"
    assert [p.name for p in tmp_path.iterdir()] == ["x.mcap"]
