"""Recordings that are not ours or not whole: clear one-line errors (exit 2), or a note and what there is.

Also ``collide`` on a real array's recording: encoder joint states as
``ros2 bag record`` stores them (rclpy's serializer, rosbag2's MCAP layout
written by rosbags), without velocities, stamped with wall-clock time.
"""

import json
import os
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from hostile import file_size_limit, mcap_with_chunk

from panel_deploy.cli import main
from panel_deploy.record import messages as m
from panel_deploy.record import open_recording
from panel_deploy.record.writer import Recorder
from panel_deploy.pipeline import simulate_scene
from panel_deploy.scene import load_scene, resolve_scene

CLI = str(Path(sys.executable).parent / "panel-deploy")


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    path = tmp_path_factory.mktemp("errors") / "paper.mcap"
    assert main(["simulate", "paper_4x4", "--t-end", "0.6", "--record", str(path)]) == 0
    return path


def _one_line_error(capsys, path, *words):
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"panel-deploy: error: {path}: ") and "\n" not in err, err
    for w in words:
        assert w in err, err
    return err


@pytest.mark.parametrize("command", [["collide"], ["replay", "--save", "x.rrd"]])
def test_empty_file(tmp_path, capsys, command):
    path = tmp_path / "empty.mcap"
    path.write_bytes(b"")
    assert main([command[0], str(path), *command[1:]]) == 2
    _one_line_error(capsys, path, "empty file")


def test_not_mcap(tmp_path, capsys):
    path = tmp_path / "notes.mcap"
    path.write_text("a text file\n")
    assert main(["collide", str(path)]) == 2
    _one_line_error(capsys, path, "not an MCAP file")


def test_missing_file(tmp_path, capsys):
    path = tmp_path / "nowhere.mcap"
    assert main(["collide", str(path)]) == 2
    _one_line_error(capsys, path, "cannot read")


def test_corrupt_chunk(recording, tmp_path, capsys):
    data = bytearray(recording.read_bytes())
    data[len(data) // 2: len(data) // 2 + 64] = bytes(64)  # zeros in the middle of a chunk
    path = tmp_path / "corrupt.mcap"
    path.write_bytes(bytes(data))
    assert main(["collide", str(path)]) == 2
    _one_line_error(capsys, path, "corrupt")


@pytest.mark.parametrize("compression", ["zstd", "lz4"])
@pytest.mark.parametrize("declared, zeros, expected", [
    (1 << 30, 1 << 30, "to 1 above 33554432 bytes"),  # 1 GiB of zeros: 33 kB (zstd), 4.4 MB (lz4)
    (1000, 1 << 24, "declares 1000 bytes uncompressed but holds more"),  # the frame is not trusted
    (1000, 10, "declares 1000 bytes uncompressed but holds 10"),
])
def test_chunk_sizes_are_checked_before_inflating(tmp_path, capsys, declared, zeros, expected,
                                                  compression):
    if compression == "lz4":
        pytest.importorskip("lz4")
    path = tmp_path / "bomb.mcap"
    path.write_bytes(mcap_with_chunk(declared, zeros, compression))
    start = time.perf_counter()
    assert main(["collide", str(path), "--scene", "paper_4x4"]) == 2
    assert time.perf_counter() - start < 5
    _one_line_error(capsys, path, "corrupt chunk record at byte 36", expected)


def test_truncated_file_is_read_up_to_its_end_and_says_so(recording, tmp_path, capsys):
    path = tmp_path / "cut.mcap"
    path.write_bytes(recording.read_bytes()[:len(recording.read_bytes()) * 2 // 3])
    assert main(["collide", str(path)]) == 0
    out = capsys.readouterr()
    assert "is truncated" in out.err and "read up to t = " in out.err
    assert "samples up to t = " in out.out or "first collision" in out.out
    assert main(["replay", str(path), "--save", str(tmp_path / "cut.rrd")]) == 0
    assert "is truncated" in capsys.readouterr().err


def test_mcap_without_our_topics(tmp_path, capsys):
    path = tmp_path / "chatter.mcap"
    with Recorder(path) as rec:
        rec.write("/chatter", m.STRING, m.string("hello"), 0)
    assert main(["collide", str(path), "--scene", "paper_4x4"]) == 2
    _one_line_error(capsys, path, "no /joint_states", "/chatter")


def test_joint_states_without_a_scene(tmp_path, capsys):
    path = tmp_path / "bare.mcap"
    with Recorder(path) as rec:
        rec.write("/joint_states", m.JOINT_STATE, m.joint_state(["a"], 0.0, [0.0], [0.0], [0.0]), 0)
    assert main(["collide", str(path)]) == 2
    _one_line_error(capsys, path, "no /panel_deploy/model", "--scene")


def test_joint_names_that_are_not_the_scenes_hinges(tmp_path, capsys):
    path = tmp_path / "other_robot.mcap"
    with Recorder(path) as rec:
        for j in range(3):
            rec.write("/joint_states", m.JOINT_STATE,
                      m.joint_state(["shoulder", "elbow"], j * 0.01, [0.1, 0.2], [0, 0], [0, 0]), j)
    assert main(["collide", str(path), "--scene", "paper_4x4"]) == 2
    _one_line_error(capsys, path, "not the hinges of scene paper_4x4", "'shoulder'")


def test_topic_of_another_type(tmp_path, capsys):
    path = tmp_path / "strings.mcap"
    with Recorder(path) as rec:
        rec.write("/joint_states", m.STRING, m.string("r1c1-r1c2: 0.3"), 0)
    assert main(["collide", str(path), "--scene", "paper_4x4"]) == 2
    _one_line_error(capsys, path, "/joint_states is std_msgs/msg/String")


@pytest.mark.parametrize("command", [["collide"], ["replay", "--save", "x.rrd"]])
def test_non_finite_joint_state_names_message_and_joint(tmp_path, capsys, command):
    path = tmp_path / "nan.mcap"
    with Recorder(path) as rec:
        for j in range(3):
            position = [0.1, float("nan") if j == 2 else 0.2]
            rec.write("/joint_states", m.JOINT_STATE,
                      m.joint_state(["a", "b"], j * 0.01, position, [0, 0], [0, 0]), j)
    assert main([command[0], str(path), *command[1:], "--scene", "paper_4x4"]) == 2
    _one_line_error(capsys, path, "/joint_states message 2: position of b is nan (not finite)")


def test_optimise_record_needs_out(capsys):
    assert main(["optimise", "paper_4x4", "--record", "x.mcap"]) == 2
    assert "--record: needs --out" in capsys.readouterr().err


def test_collide_on_an_encoder_recording_from_ros2_bag_record(tmp_path, capsys):
    """Encoders: tree hinges only, in another order, positions only, epoch stamps; bytes
    from rclpy's serializer (stray padding included) in a rosbag2 MCAP written by rosbags."""
    pytest.importorskip("rclpy")
    from rclpy.serialization import serialize_message
    from rosbags.rosbag2 import StoragePlugin, Writer
    from sensor_msgs.msg import JointState

    scene = load_scene(resolve_scene("paper_4x4"))
    scene = scene.replace(simulation=replace(scene.simulation, t_end=0.6, samples=121))
    model, result, report = simulate_scene(scene)
    names = [model.hinges[h].name for h in model.joints][::-1]
    theta = result.theta[:, ::-1]
    epoch = 1_763_900_000.0
    bag = tmp_path / "encoders"
    with Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection("/joint_states", m.JOINT_STATE, typestore=m.TYPESTORE)
        for t, angles in zip(result.t, theta):
            msg = JointState(name=names, position=[float(a) for a in angles])
            ns = round((epoch + t) * 1e9)
            msg.header.stamp.sec, msg.header.stamp.nanosec = ns // 10**9, ns % 10**9
            writer.write(conn, ns, serialize_message(msg))
    (mcap_file,) = bag.glob("*.mcap")
    assert main(["collide", str(mcap_file), "--scene", "paper_4x4", "--json"]) == 0
    captured = capsys.readouterr()
    got = json.loads(captured.out)
    assert "counted from the first /joint_states stamp" in captured.err
    assert got["first_collision"]["pair"] == list(report.first_collision.names)
    assert abs(got["first_collision"]["t"] - report.first_collision.t) <= 0.005 + 1e-6


# --- issue 26: a recording replaces its target whole, or not at all ---

@pytest.mark.parametrize("target, limit", [("/dev/full", None), ("old.mcap", 30_000),
                                           ("new.mcap", 30_000)])
def test_a_recording_that_cannot_be_written_is_one_line_and_leaves_the_target(
        tmp_path, target, limit):
    old = tmp_path / "old.mcap"
    old.write_bytes(b"the previous recording")
    proc = subprocess.run([CLI, "simulate", "paper_4x4", "--t-end", "0.5", "--record", target],
                          capture_output=True, text=True, timeout=300, cwd=tmp_path,
                          preexec_fn=file_size_limit(limit))
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
    reason = "File too large" if limit else "No space left on device"
    assert lines[-1].startswith(f"panel-deploy: error: {target}: cannot write the recording "
                                f"({reason})"), lines
    assert [line for line in lines if "error" in line] == lines[-1:]  # the rest: compile note
    assert lines[-1].endswith("old.mcap is unchanged") == (target == "old.mcap"), lines[-1]
    assert old.read_bytes() == b"the previous recording"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["old.mcap"]  # no partial file left


def test_two_recorders_of_one_file_leave_one_whole_recording(tmp_path):
    path = tmp_path / "both.mcap"
    first, second = Recorder(path), Recorder(path)
    assert {Path(first.partial).parent, Path(second.partial).parent} == {tmp_path}
    for j in range(50):  # interleaved, as two processes would
        first.write("/chatter", m.STRING, m.string(f"first {j}"), j)
        second.write("/chatter", m.STRING, m.string(f"second {j}"), j)
        if j % 10 == 9:
            first.flush()
            second.flush()
    assert not path.exists()  # nothing at the target before a recording is whole
    second.close()
    first.close()
    recording = open_recording(path)
    assert recording.truncated is None
    assert [msg.data for _, msg in recording.messages("/chatter")] == [f"first {j}" for j in range(50)]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["both.mcap"]


def test_a_namespaced_ros2_bag_record_is_read_by_namespace(tmp_path, capsys):
    """``ros2 bag record`` of two graphs (/array1, /array2): collide and replay need
    --namespace to choose one, and then read that array's joint states."""
    from rosbags.rosbag2 import StoragePlugin, Writer

    scene = load_scene(resolve_scene("paper_4x4"))
    scene = scene.replace(simulation=replace(scene.simulation, t_end=0.6, samples=121))
    model, result, report = simulate_scene(scene)
    names = [model.hinges[h].name for h in model.joints]
    bag = tmp_path / "two"
    with Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conns = {ns: writer.add_connection(f"/{ns}/joint_states", m.JOINT_STATE,
                                           typestore=m.TYPESTORE) for ns in ("array1", "array2")}
        for t, angles in zip(result.t, result.theta):
            for ns, conn in conns.items():
                still = angles if ns == "array1" else model.theta_stowed  # array2 never moves
                msg = m.joint_state(names, t, still, np.zeros(0), np.zeros(0))
                writer.write(conn, round(t * 1e9), m.serialize(msg))
    (mcap_file,) = bag.glob("*.mcap")
    assert main(["collide", str(mcap_file), "--scene", "paper_4x4"]) == 2
    err = capsys.readouterr().err
    assert "joint states of several arrays (/array1, /array2): choose one with --namespace" in err
    assert main(["collide", str(mcap_file), "--scene", "paper_4x4", "--namespace", "array1",
                 "--json"]) == 0
    got = json.loads(capsys.readouterr().out)
    assert got["first_collision"]["pair"] == list(report.first_collision.names)
    assert main(["collide", str(mcap_file), "--scene", "paper_4x4", "--namespace", "/array2",
                 "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["collided"] is False
    png = tmp_path / "a1.png"
    assert main(["replay", str(mcap_file), "--scene", "paper_4x4", "--namespace", "array1",
                 "--png", str(png), "--at", "0,0.3"]) == 0
    assert png.stat().st_size > 10_000


# What a careful user's foreign recordings hold (issue 32): refused only where the data
# that matter are wrong.

def _encoder_stream(path, *, order=None, repeat=1, effort=None, extra=None):
    """The paper deployment's tree joint states (0.6 s, 200 Hz) written to ``path`` by
    our writer: in file ``order`` (log times as stamps), each message ``repeat`` times,
    an ``effort`` row, and ``extra(recorder)`` called first."""
    scene = load_scene(resolve_scene("paper_4x4"))
    scene = scene.replace(simulation=replace(scene.simulation, t_end=0.6, samples=121))
    model, result, report = simulate_scene(scene)
    names = [model.hinges[h].name for h in model.joints]
    rows = list(range(len(result.t))) if order is None else order(len(result.t))
    with Recorder(path) as rec:
        if extra is not None:
            extra(rec)
        for j in rows:
            msg = m.joint_state(names, result.t[j], result.theta[j], result.omega[j],
                                np.zeros(len(names)) if effort is None else effort)
            for _ in range(repeat):
                rec.write("/joint_states", m.JOINT_STATE, msg, round(result.t[j] * 1e9))
    return report


def _collided(capsys, path):
    assert main(["collide", str(path), "--scene", "paper_4x4", "--json"]) == 0, \
        capsys.readouterr().err
    return json.loads(capsys.readouterr().out)["first_collision"]


@pytest.mark.parametrize("case", ["out of file order", "each twice", "inf effort",
                                  "40 MB on another topic"])
def test_recordings_with_harmless_oddities_are_read(tmp_path, capsys, case):
    path = tmp_path / "odd.mcap"
    kwargs = {"out of file order": {"order": lambda n: list(range(n))[::-1]},
              "each twice": {"repeat": 2},
              "inf effort": {"effort": np.full(11, np.inf)},
              "40 MB on another topic": {"extra": lambda rec: rec.write(
                  "/camera/raw", m.STRING, m.string(np.random.default_rng(0).bytes(30 << 20)
                                                    .hex()[:40 << 20]), 0)}}[case]
    report = _encoder_stream(path, **kwargs)
    first = _collided(capsys, path)
    assert first["pair"] == list(report.first_collision.names)
    assert abs(first["t"] - report.first_collision.t) <= 0.005 + 1e-6


def test_an_unknown_chunk_compression_is_named(tmp_path, capsys):
    from hostile import mcap_with_chunk
    data = mcap_with_chunk(1000, 1000, "zstd").replace(b"\x04\x00\x00\x00zstd", b"\x04\x00\x00\x00zzz1")
    path = tmp_path / "brotli.mcap"
    path.write_bytes(data)
    assert main(["collide", str(path), "--scene", "paper_4x4"]) == 2
    _one_line_error(capsys, path, "compression 'zzz1' is none of the MCAP specification's")


def test_a_run_a_recording_cannot_represent_is_refused_before_writing(tmp_path, capsys):
    path = tmp_path / "tiny.mcap"
    assert main(["simulate", "paper_4x4", "--set", "simulation.t_end=1e-9", "--record",
                 str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--record: samples 2.5e-12 s apart" in err[0], err
    assert not path.exists() and list(tmp_path.iterdir()) == []


def test_a_cut_recording_and_a_wrong_flag_are_one_line(recording, tmp_path, capsys):
    data = recording.read_bytes()
    cut = tmp_path / "killed.abcdefgh.part.mcap"
    cut.write_bytes(data[:len(data) // 2])
    assert main(["replay", str(cut), "--png", str(tmp_path / "p.png"), "--at", "19.5"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--at: 19.5 s is outside the recording" in err[0], err
    assert main(["replay", str(cut), "--png", str(tmp_path / "p.png"), "--at", "0.1"]) == 0
    assert "is truncated" in capsys.readouterr().err  # the note, once the work is done


def test_a_recording_cut_before_its_scene_says_it_was_cut(tmp_path, capsys):
    """Joint states in the chunks that closed, the scene in the one the kill cut."""
    path = tmp_path / "early.part.mcap"
    with Recorder(path, chunk_span=0.01) as rec:
        for j in range(5):
            rec.write("/joint_states", m.JOINT_STATE,
                      m.joint_state(["a"], j * 0.01, [0.0], [0.0], [0.0]), j * 10_000_000)
        rec.flush()
        first = os.path.getsize(rec.partial)
        rec.write("/panel_deploy/model", m.STRING, m.string("name: x\n" * 1000), 60_000_000)
        rec.flush()
    data = path.read_bytes()
    path.write_bytes(data[:first + 20])  # inside the scene's chunk
    assert main(["collide", str(path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no /panel_deploy/model in this recording (the file was cut short" \
        in err[0] and "--scene" in err[0], err


@pytest.mark.parametrize("kind", ["folder", "db3"])
@pytest.mark.parametrize("command", ["collide", "replay"])
def test_rosbag2_bags_are_named_with_what_to_do(tmp_path, capsys, kind, command):
    if kind == "folder":
        path = tmp_path / "bag"
        path.mkdir()
        (path / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
    else:
        path = tmp_path / "bag_0.db3"
        path.write_bytes(b"SQLite format 3\x00" + bytes(100))
    args = [command, str(path)] + (["--png", str(tmp_path / "p.png")] if command == "replay" else [])
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "ros2 bag convert" in err[0], err


def test_receipt_timing_never_reports_a_collision_the_data_cannot_support(tmp_path, capsys):
    """Arrivals of a loaded machine (1.06 ms apart typically, bursts up to 86 ms late)
    for joint states stamped every 5 ms, timed by arrival (collision.stamps: receipt,
    the log time of ``ros2 bag record``): the one collision the angles show, none earlier."""
    scene = load_scene(resolve_scene("paper_4x4"))
    scene = scene.replace(simulation=replace(scene.simulation, t_end=0.6, samples=121))
    model, result, report = simulate_scene(scene)
    names = [model.hinges[h].name for h in model.joints]
    rng = np.random.default_rng(32)
    gaps = rng.exponential(1.06e-3, len(result.t))
    gaps[rng.random(len(result.t)) < 0.05] = 0.086  # a burst held back
    arrival = np.cumsum(gaps)
    path = tmp_path / "receipt.mcap"
    with Recorder(path) as rec:
        for j, t in enumerate(result.t):
            rec.write("/joint_states", m.JOINT_STATE,
                      m.joint_state(names, 0.0, result.theta[j], np.zeros(0), np.zeros(0)),
                      round(arrival[j] * 1e9))  # unfilled stamps: 0
    assert main(["collide", str(path), "--scene", "paper_4x4", "--json",
                 "--set", "collision.stamps=receipt"]) == 0
    got = json.loads(capsys.readouterr().out)
    first = got["first_collision"]
    # The same as the samples alone show with their true times: the first sample whose
    # angles interfere (the refined truth is between it and the one before), at its arrival.
    from panel_deploy.collision import CollisionSettings, check_trajectory
    at_samples = check_trajectory(model, result, CollisionSettings(refine=False)).first_collision
    j = int(np.argmin(np.abs(result.t - at_samples.t)))
    assert result.t[j - 1] < report.first_collision.t <= result.t[j] == at_samples.t
    assert first["pair"] == list(at_samples.names)
    assert first["t"] == pytest.approx(arrival[j] - arrival[0], abs=1e-9)
    assert not [e for e in got["colliding_pairs"] if e["t"] < first["t"]]
