"""``panel-deploy run``: the whole graph in one process, end to end, as a user runs it."""

import json
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from ros_harness import Client, NodeProcess

from rclpy.task import Future

from panel_deploy import contract
from panel_deploy.collision import CollisionSettings, check_trajectory
from panel_deploy.dynamics import simulate
from panel_deploy.configure import DynamicsParameters, configure
from panel_deploy.nodes import load
from panel_deploy.scene import load_scene, resolve_scene

CLI = str(Path(sys.executable).parent / "panel-deploy")


def test_run_paper_scene_matches_simulate(compiled_nodes):
    proc = subprocess.run([CLI, "run", "paper_4x4", "--real-time-factor", "0", "--json",
                           "--set", "simulation.t_end=0.6"],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 1, proc.stderr  # the paper's uniform k collides
    summary = json.loads(proc.stdout)
    scene, model = configure(load_scene(resolve_scene("paper_4x4"), ["simulation.t_end=0.6"]),
                             DynamicsParameters(rate_hz=200.0))
    report = check_trajectory(model, simulate(model, scene.simulation),
                              CollisionSettings.from_scene(scene))
    first = summary["collision"]["first_collision"]
    assert first["pair"] == list(report.first_collision.names)
    assert abs(first["t"] - report.first_collision.t) <= 0.005
    assert "t = " in proc.stderr and "collision" in proc.stderr


def test_run_finds_an_impact_the_panel_contact_absorbed(compiled_nodes):
    """Every pair of the paper scene in contact: two pairs come down on each
    other at 0.2836 s and the contact holds them within the tolerance, which joint states
    cannot show; the monitor checks the dynamics node's contact onsets and
    reports the impact simulate reports."""
    sets = ["contact.panels=true", "simulation.t_end=0.3"]
    proc = subprocess.run([CLI, "run", "paper_4x4", "--real-time-factor", "0", "--json",
                           *(a for x in sets for a in ("--set", x))],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 1, proc.stderr
    scene, model = configure(load_scene(resolve_scene("paper_4x4"), sets),
                             DynamicsParameters(rate_hz=200.0))
    report = check_trajectory(model, simulate(model, scene.simulation),
                              CollisionSettings.from_scene(scene))
    assert report.first_collision.impact
    first = json.loads(proc.stdout)["collision"]["first_collision"]
    assert first["pair"] == list(report.first_collision.names)
    assert first["t"] == pytest.approx(report.first_collision.t, abs=1e-12)
    assert first["v"] == pytest.approx(report.first_collision.normal_speed, rel=1e-12)


def _drive_separate_nodes(ns, patch=lambda driver: None):
    """run's driver (patched by ``patch``) driving the nodes in processes of their own."""
    procs = [NodeProcess("array_model", "scene:=paper_4x4", namespace=ns),
             NodeProcess("dynamics", "t_end:=0.6", "real_time_factor:=0.0", namespace=ns),
             NodeProcess("collision_monitor", "max_lag:=0.0", namespace=ns)]
    client = Client("driver_test")
    driver = load("graph").Driver(threading.Event(), context=client.context, namespace=ns)
    patch(driver)
    client.executor.add_node(driver)
    try:
        driver.drive(optimise=False)
    finally:
        client.executor.remove_node(driver)
        driver.destroy_node()
        client.close()
        for p in procs:
            p.stop()
    s = driver.summary
    first = s["collision"]["first_collision"]
    assert driver.exit_code == 1 and s["t_end"] == pytest.approx(0.6)
    assert first["pair"] == ["r1c2+r1c3", "r2c2+r2c3"] and 0.41 <= first["t"] <= 0.42
    assert s["collision"]["samples_checked"] == 121 and s["collision"]["d"] == pytest.approx(0.0454, abs=1e-3)


def test_the_driver_drives_nodes_in_processes_of_their_own(compiled_nodes):
    """run's driver knows the nodes by their topics and services only."""
    _drive_separate_nodes("/separate")


def test_a_goal_whose_answer_is_lost_is_followed_by_its_id(compiled_nodes, monkeypatch):
    """A goal the server runs although its answer never reaches the driver (as
    under load, while discovery is under way) is asked for by its id: the
    request reaches the server only 1.5 s after it was sent, so the first asks
    are answered UNKNOWN, and the deployment is followed to its end (one
    deployment: the monitor checked its 121 samples)."""
    graph = load("graph")
    monkeypatch.setattr(graph, "ACCEPT_WAIT", 0.5)
    sent = []

    def lose_answers(driver):
        client = driver.actions[contract.DEPLOY]
        send = client.send_goal_async

        def late(*args, **kwargs):
            sent.append(threading.Timer(1.5, send, args, kwargs))
            sent[-1].start()
            return Future()  # never answered
        monkeypatch.setattr(client, "send_goal_async", late)
    _drive_separate_nodes("/lost", lose_answers)
    assert sent and all(not timer.is_alive() for timer in sent)


def test_run_optimise_then_deploys_flat_without_collision(compiled_nodes):
    proc = subprocess.run([CLI, "run", "paper_4x4", "--optimise", "--real-time-factor", "0",
                           "--set", "optimisation.damping_ratio_bounds=[0.043,0.3]",
                           "--set", "optimisation.max_evaluations=12",
                           "--set", "optimisation.method=local"],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert proc.stdout.startswith("ok:") and "no collision" in proc.stdout
    assert "optimise" in proc.stderr


def test_run_interrupted_prints_what_was_computed(compiled_nodes):
    proc = subprocess.Popen([CLI, "run", "paper_4x4"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    line = ""
    while "t = " not in line and time.monotonic() < deadline:  # the deployment is under way
        line = proc.stderr.readline()
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=30)
    assert proc.returncode == 130 and "Traceback" not in err, err
    assert "simulated to" in out and "interrupted" in err


def test_bad_scene_is_one_line_before_any_node_starts():
    proc = subprocess.run([CLI, "run", "paper_4x4", "--set", "simulation.rtol=-1"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert proc.stderr.strip().startswith("panel-deploy: error:") and "simulation.rtol" in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1


def test_run_in_a_namespace(compiled_nodes):
    proc = subprocess.run([CLI, "run", "paper_4x4", "--namespace", "array7", "--real-time-factor",
                           "0", "--json", "--set", "simulation.t_end=0.3"],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 1, proc.stderr  # never flat by 0.3 s
    assert "[array7.array_model]" in proc.stderr  # rclpy's logger name of /array7/array_model
    summary = json.loads(proc.stdout)
    assert summary["t_end"] == pytest.approx(0.3) and summary["collision"]["samples_checked"] == 61


@pytest.mark.parametrize("flag, value", [("--rate", "0"), ("--real-time-factor", "-1"),
                                         ("--namespace", "two words")])
def test_bad_flags_are_one_line(flag, value):
    proc = subprocess.run([CLI, "run", "paper_4x4", flag, value], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 2 and proc.stderr.startswith(f"panel-deploy: error: {flag}")
