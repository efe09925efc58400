"""A recording says exactly what ran: ``panel-deploy simulate RECORDING.mcap`` re-simulates
the deployment of ``simulate --record``, ``run --record`` and ``run --optimise --record``
to the recorded joint states (rosbags reads them; the re-run's columns come by name)."""

import io
import json
import subprocess
import sys
from contextlib import redirect_stdout
from pathlib import Path

import numpy as np
import pytest
import yaml
from rosbags.rosbag2 import Reader

from readers import typestore_of
from panel_deploy.cli import main

CLI = str(Path(sys.executable).parent / "panel-deploy")
#: rad: the re-run is the same integration with the same settings; this is far
#: below what the integrator's own tolerance would allow (the scene's rtol).
SAME = 1e-9


def recorded(path, namespace=""):
    """``{topic: [message]}`` of a recording, and its joint states as (names, t, position)."""
    out = {}
    with Reader(path) as reader:
        store = typestore_of(reader)
        for connection, _, raw in reader.messages():
            out.setdefault(connection.topic, []).append(
                store.deserialize_cdr(raw, connection.msgtype))
    js = out[f"{namespace}/joint_states"]
    t = np.array([m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for m in js])
    return out, list(js[0].name), t, np.array([m.position for m in js])


def rerun(recording, tmp_path, *args):
    """``simulate RECORDING --out``: the summary and the trajectory's columns by joint name."""
    npz = tmp_path / "rerun.npz"
    out = io.StringIO()
    with redirect_stdout(out):
        code = main(["simulate", str(recording), "--json", "--out", str(npz), *args])
    with np.load(npz) as z:
        columns = {str(n): z["theta"][:, i] for i, n in enumerate(z["joint_names"])}
        columns.update({str(n): z["cut_theta"][:, i] for i, n in enumerate(z["cut_hinge_names"])})
        t = z["t"].copy()
    return code, json.loads(out.getvalue()), t, columns


def assert_same_motion(recording, tmp_path, namespace=""):
    _, names, t, position = recorded(recording, namespace)
    code, summary, t2, columns = rerun(recording, tmp_path)
    assert np.allclose(t2, t, rtol=0, atol=1e-9)
    for i, name in enumerate(names):
        assert np.abs(columns[name] - position[:, i]).max() <= SAME, name
    return code, summary


def test_simulate_record_re_simulates_to_its_joint_states(tmp_path):
    path = tmp_path / "sim.mcap"
    first = io.StringIO()
    with redirect_stdout(first):
        assert main(["simulate", "paper_4x4", "--t-end", "0.5", "--set",
                     "hinges.overrides={r1c1-r2c1: 0.2, r3c1-r4c1: 0.05}", "--set",
                     "hinges.damping_ratio=0.1", "--record", str(path), "--json"]) == 0
    out, *_ = recorded(path)
    scene = yaml.safe_load(out["/dynamics/scene"][0].data)
    assert scene["hinges"]["overrides"]["r1c1-r2c1"] == 0.2 and scene["hinges"]["damping_ratio"] == 0.1
    code, summary = assert_same_motion(path, tmp_path)
    assert code == 0
    before = json.loads(first.getvalue())["collision"]
    assert {k: v for k, v in summary["collision"].items() if k != "wall_time"} == \
        {k: v for k, v in before.items() if k != "wall_time"}


def test_a_damping_that_does_not_follow_k_is_recorded_exactly(tmp_path):
    """An optimum whose c/k differs between hinges: the recorded scene carries each c."""
    from panel_deploy.build import build_model
    from panel_deploy.record.deployment import record_deployment
    from panel_deploy.scene import load_scene, resolve_scene

    scene = load_scene(resolve_scene("paper_4x4"), ["simulation.t_end=0.3"])
    model = build_model(scene)
    c = np.linspace(0.002, 0.02, len(model.hinges))
    path = tmp_path / "c.mcap"
    record_deployment(path, scene, model.with_stiffness(model.stiffness, c))
    out, *_ = recorded(path)
    assert yaml.safe_load(out["/dynamics/scene"][0].data)["hinges"]["damping_overrides"] == \
        {h.name: float(x) for h, x in zip(model.hinges, c)}
    assert_same_motion(path, tmp_path)


def _run(tmp_path, name, *args):
    path = tmp_path / name
    proc = subprocess.run([CLI, "run", "paper_4x4", "--real-time-factor", "0", "--record",
                           str(path), *args], capture_output=True, text=True, timeout=600)
    return proc, path


def test_run_record_re_simulates_to_its_joint_states(tmp_path, compiled_nodes):
    proc, path = _run(tmp_path, "run.mcap", "--set", "simulation.t_end=0.6", "--rate", "400")
    assert proc.returncode == 1, proc.stderr  # the uniform design collides
    code, summary = assert_same_motion(path, tmp_path)
    assert summary["collision"]["collided"] and code == 0


def test_run_optimise_record_re_simulates_the_optimised_design(tmp_path, compiled_nodes):
    proc, path = _run(tmp_path, "opt.mcap", "--optimise",
                      "--set", "optimisation.damping_ratio_bounds=[0.043,0.3]",
                      "--set", "optimisation.max_evaluations=12")
    assert proc.returncode == 0, proc.stderr  # deploys flat without a collision
    out, *_ = recorded(path)
    result = yaml.safe_load(out["/optimiser/result"][-1].data)
    deployed = yaml.safe_load(out["/dynamics/scene"][-1].data)
    hinge = next(iter(result["hinges"].values()))
    assert deployed["hinges"]["damping_ratio"] == pytest.approx(hinge["c"] / hinge["k"], rel=1e-9)
    assert deployed["hinges"]["overrides"] == pytest.approx(
        {name: h["k"] for name, h in result["hinges"].items()}, rel=1e-12)
    assert deployed["hinges"]["damping_ratio"] != 0.043  # not the scene's: what the optimiser set
    assert out["/optimiser/progress"]
    code, summary = assert_same_motion(path, tmp_path)
    assert code == 0 and not summary["collision"]["collided"] and summary["time_to_flat"]


def test_a_namespaced_run_keeps_its_names_and_is_read_back(tmp_path, compiled_nodes, capsys):
    proc, path = _run(tmp_path, "ns.mcap", "--namespace", "array7", "--set", "simulation.t_end=0.5")
    assert proc.returncode == 1, proc.stderr
    out, *_ = recorded(path, "/array7")
    assert {"/array7/joint_states", "/array7/panel_deploy/model", "/array7/dynamics/scene",
            "/diagnostics", "/array7/clock"} <= set(out)
    assert "/joint_states" not in out
    assert main(["collide", str(path), "--json"]) == 0  # the one array in the file
    first = json.loads(capsys.readouterr().out)["first_collision"]
    assert first["pair"] == ["r1c2+r1c3", "r2c2+r2c3"] and round(first["t"], 3) == 0.416
    assert main(["collide", str(path), "--namespace", "array8"]) == 2
    assert "no joint states in namespace '/array8'" in capsys.readouterr().err
    assert_same_motion(path, tmp_path, "/array7")
