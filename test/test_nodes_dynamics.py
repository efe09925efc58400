"""The dynamics node as its own process: streamed deployment, parameters, the Deploy action."""

import itertools
import json
import math
import time
from pathlib import Path

import numpy as np
import pytest
from action_msgs.msg import GoalStatus
from diagnostic_msgs.msg import DiagnosticArray
from rcl_interfaces.msg import ParameterType
from rcl_interfaces.srv import DescribeParameters, GetParameters, SetParameters
from rclpy.parameter import Parameter
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from visualization_msgs.msg import MarkerArray

from panel_deploy import contract
from panel_deploy.build import build_model
from panel_deploy.cli import main
from panel_deploy.dynamics import simulate
from panel_deploy.dynamics.report import hinge_states
from panel_deploy.configure import DynamicsParameters, configure
from panel_deploy.nodes import load, messages
from panel_deploy.scene import load_scene, resolve_scene
from panel_deploy.scene_text import scene_from_yaml
from ros_harness import Client, NodeProcess, wait_for

T_END, RATE = 0.5, 200.0


@pytest.fixture(scope="module")
def graph(compiled_nodes):
    model = NodeProcess("array_model", "scene:=paper_4x4")
    # An integer for a double, as ros2 param set and -p send whole numbers: taken as 200.0.
    dynamics = NodeProcess("dynamics", f"t_end:={T_END}", f"rate_hz:={int(RATE)}",
                           "real_time_factor:=0.0")
    client = Client("dynamics_test")
    yield client, model, dynamics
    client.close()
    for p in (model, dynamics):
        p.stop()


def set_params(client, *params):
    reply = client.call(SetParameters, "/dynamics/set_parameters",
                        SetParameters.Request(parameters=[p.to_parameter_msg() for p in params]))
    return reply.results


def deploy(client, node="/dynamics", **goal):
    """A Deploy goal to ``node``, started (sent again while the model has not reached it)."""
    return client.start_goal(contract.DEPLOY, node, **goal)


def deploy_and_collect(client):
    states = client.listen(JointState, "/joint_states", messages.qos(contract.STREAM))
    diagnostics = client.listen(DiagnosticArray, "/diagnostics")
    clocks = client.listen(Clock, "/clock")
    panels = client.listen(MarkerArray, "/panel_deploy/panels")
    wait_for(lambda: client.node.count_publishers("/joint_states") >= 1, what="the dynamics node")
    for box in (states, diagnostics, clocks, panels):
        box.clear()
    goal = deploy(client, wait_for_subscribers=1)
    result = goal.result()
    assert result.success and goal.status == GoalStatus.STATUS_SUCCEEDED, result.message
    wait_for(lambda: any(s.name == "/dynamics" for d in diagnostics for s in d.status),
             timeout=60, what="the outcome on /diagnostics")
    return states, diagnostics, clocks, panels, goal


def test_deploy_streams_the_core_trajectory(graph):
    client, *_ = graph
    states, diagnostics, clocks, panels, goal = deploy_and_collect(client)
    wait_for(lambda: len(states) >= round(T_END * RATE) + 1, what="every sample")
    scene, model = configure(load_scene(resolve_scene("paper_4x4")),
                             DynamicsParameters(t_end=T_END, rate_hz=RATE))
    reference = simulate(model, scene.simulation)
    names, theta, omega, torque = hinge_states(model, reference)
    assert len(states) == round(T_END * RATE) + 1
    assert all(list(s.name) == names for s in states)
    last = states[-1]
    assert messages.seconds(last.header.stamp) == pytest.approx(T_END, abs=1e-9)
    assert np.abs(np.array(last.position) - theta[-1]).max() <= 1e-9
    assert np.abs(np.array(last.velocity) - omega[-1]).max() <= 1e-9
    assert np.abs(np.array(last.effort) - torque[-1]).max() <= 1e-9
    stamps = [messages.seconds(s.header.stamp) for s in states]
    assert np.all(np.diff(stamps) > 0)
    assert len(clocks) == len(states)
    box = panels[-1].markers[0]
    assert box.header.frame_id == "world" and len(panels[-1].markers) == model.n_bodies
    assert (box.scale.x, box.scale.y, box.scale.z) == tuple(model.bodies[0].size)
    assert messages.seconds(box.header.stamp) == pytest.approx(T_END, abs=1e-9)  # the last sample
    centres = np.array([[m.pose.position.x, m.pose.position.y, m.pose.position.z]
                        for m in panels[-1].markers])
    assert np.abs(centres - reference.position[-1]).max() <= 1e-9
    status = [s for d in diagnostics for s in d.status if s.name == "/dynamics"][-1]
    values = {kv.key: kv.value for kv in status.values}
    assert values["success"] == "True" and float(values["energy_balance_error"]) < 0.05
    result = goal.result()
    assert result.samples == len(states) and result.t_end == pytest.approx(T_END)
    assert json.loads(result.summary)["energy_balance_error"] == float(values["energy_balance_error"])
    assert goal.feedback and goal.feedback[-1].samples <= len(states)
    assert goal.feedback[0].subscribers >= 1  # this client's joint_states subscription


def test_deploy_waits_for_the_subscribers_it_is_asked_for(graph):
    """Nobody else listens: asked for 5 subscribers, the goal ends without a sample."""
    client, *_ = graph
    states = client.listen(JointState, "/joint_states", messages.qos(contract.STREAM))
    wait_for(lambda: client.node.count_publishers("/joint_states") >= 1, what="the dynamics node")
    states.clear()
    goal = client.send_goal(contract.DEPLOY, "/dynamics", wait_for_subscribers=5)
    time.sleep(1.0)
    assert not goal.done() and not goal.feedback  # waiting (the model came: tests above ran)
    goal.cancel()
    result = goal.result(timeout=10)
    assert goal.status == GoalStatus.STATUS_CANCELED and not result.success
    assert "subscribers" in result.message and states == []


def test_second_goal_is_aborted_and_cancel_stops_the_first(graph):
    client, *_ = graph
    assert all(r.successful for r in set_params(client, Parameter("real_time_factor", value=1.0),
                                                Parameter("t_end", value=2.0)))
    try:
        first = deploy(client)
        assert not first.done()
        second = client.send_goal(contract.DEPLOY, "/dynamics")
        assert "running" in second.result(timeout=10).message
        assert second.status == GoalStatus.STATUS_ABORTED
        first.cancel()
        result = first.result(timeout=10)
        assert first.status == GoalStatus.STATUS_CANCELED
        assert result.status == 1 and result.message.startswith("stopped at t = ")
        assert 0 < result.samples < 401 and json.loads(result.summary)["t_end"] < 2.0
    finally:
        set_params(client, Parameter("real_time_factor", value=0.0), Parameter("t_end", value=T_END))


@pytest.mark.parametrize("param, reason", [
    (Parameter("stiffness", Parameter.Type.DOUBLE_ARRAY, [-0.1] * 12), "stiffness"),
    (Parameter("stiffness", Parameter.Type.DOUBLE_ARRAY, [0.1, 0.1]), "stiffness: expected"),
    (Parameter("rate_hz", value=-5.0), "rate_hz"),
    (Parameter("method", value="Euler"), "method"),
    (Parameter("closure", value="glue"), "closure"),
    # issue 26: the scene schema's limits, as on the command line
    # (the descriptor's range, which is the schema's limit, refuses it before our check)
    (Parameter("t_end", value=4000.0), "t_end out of range Min: 0.0, Max: 600.0"),
    (Parameter("rate_hz", value=1e5), "rate_hz: 100000 Hz over 0.5 s gives 50001 samples: expected an integer <= 50000"),
])
def test_invalid_parameters_are_rejected_with_a_reason(graph, param, reason):
    client, *_ = graph
    deploy_and_collect(client)  # the node has the model: counts are checked against it
    result, = set_params(client, param)
    assert not result.successful and reason in result.reason


def test_stiffness_per_group_is_accepted_and_read_back(graph):
    client, *_ = graph
    scene = load_scene(resolve_scene("paper_4x4"))
    from panel_deploy.build import build_model
    groups = build_model(scene).hinge_groups
    k = [0.05 + 0.01 * g for g in range(len(groups))]
    result, = set_params(client, Parameter("stiffness", Parameter.Type.DOUBLE_ARRAY, k))
    assert result.successful, result.reason
    reply = client.call(GetParameters, "/dynamics/get_parameters",
                        GetParameters.Request(names=["stiffness"]))
    assert list(reply.values[0].double_array_value) == k


def get_params(client, *names):
    return client.call(GetParameters, "/dynamics/get_parameters",
                       GetParameters.Request(names=list(names))).values


def test_integers_for_doubles_are_set_as_doubles(graph):
    client, *_ = graph
    assert get_params(client, "rate_hz")[0].double_value == RATE  # given as an integer at start
    try:
        results = set_params(client, Parameter("rate_hz", value=500),
                             Parameter("stiffness", Parameter.Type.INTEGER_ARRAY, [0] * 12))
        assert all(r.successful for r in results), [r.reason for r in results]
        rate, k = get_params(client, "rate_hz", "stiffness")
        assert (rate.type, rate.double_value) == (ParameterType.PARAMETER_DOUBLE, 500.0)
        assert k.type == ParameterType.PARAMETER_DOUBLE_ARRAY and list(k.double_array_value) == [0.0] * 12
        refused, = set_params(client, Parameter("rate_hz", value=-5))
        assert not refused.successful and "rate_hz" in refused.reason
    finally:
        set_params(client, Parameter("rate_hz", value=RATE),
                   Parameter("stiffness", Parameter.Type.DOUBLE_ARRAY, []))


def test_ranges_are_in_the_descriptors(graph):
    client, *_ = graph
    names = ["rtol", "t_end", "rate_hz", "real_time_factor"]
    described = client.call(DescribeParameters, "/dynamics/describe_parameters",
                            DescribeParameters.Request(names=names)).descriptors
    ranges = {d.name: (d.floating_point_range[0].from_value, d.floating_point_range[0].to_value)
              for d in described}
    assert ranges == {"rtol": (0.0, 1.0), "t_end": (0.0, 600.0), "rate_hz": (1e-3, 1e6),
                      "real_time_factor": (0.0, math.inf)}


@pytest.mark.parametrize("given, name", [
    ({"params_file": "rate_hz: -5.0"}, "rate_hz"),
    ({"params_file": "t_end: 1000.0"}, "t_end"),
    ({"params_file": "stiffness: [0.1, -0.1]"}, "stiffness"),
    ({"param": "rate_hz:=fast"}, "rate_hz"),
    ({"param": "closure:=glue"}, "closure"),
], ids=["negative rate", "t_end out of range", "negative k", "text for a number", "bad closure"])
def test_bad_values_at_start_are_one_line_and_exit_2(tmp_path, given, name):
    params = []
    path = None
    if "params_file" in given:  # as a user writes it, for the node in any namespace
        path = tmp_path / "params.yaml"
        path.write_text("/**/dynamics:\n  ros__parameters:\n    " + given["params_file"] + "\n")
    else:
        params.append(given["param"])
    proc = NodeProcess("dynamics", *params, params_file=path)
    _, err = proc.proc.communicate(timeout=60)
    lines = err.strip().splitlines()
    assert proc.proc.returncode == 2 and len(lines) == 1, err
    assert lines[0].startswith("panel-deploy: error:") and name in lines[0], err


def test_a_failing_deployment_is_an_error_status_and_the_node_deploys_again(monkeypatch,
                                                                            compiled_nodes):
    """The node in this process, its deployment made to fail after three samples."""
    node_module = load("dynamics")  # panel_deploy.nodes.dynamics is the executable

    class Failing(node_module.Deployment):
        def __iter__(self):
            yield from itertools.islice(super().__iter__(), 3)
            raise RuntimeError("the integrator blew up")

    monkeypatch.setattr(node_module, "Deployment", Failing)
    model = NodeProcess("array_model", "scene:=paper_4x4", namespace="/guarded")
    client = Client("dynamics_guard_test")
    node = node_module.DynamicsNode(context=client.context, namespace="/guarded",
                                    parameter_overrides=[Parameter("t_end", value=0.1),
                                                         Parameter("real_time_factor", value=0.0)])
    client.executor.add_node(node)
    diagnostics = client.listen(DiagnosticArray, "/diagnostics")
    outcomes = lambda: [s for d in list(diagnostics) for s in d.status  # noqa: E731
                        if s.name == "/guarded/dynamics"]
    try:
        goal = deploy(client, "/guarded/dynamics")
        result = goal.result()
        assert goal.status == GoalStatus.STATUS_ABORTED and not result.success
        assert result.message == "~/deploy failed: RuntimeError: the integrator blew up"
        wait_for(outcomes, what="the failure on /diagnostics")
        failed, = outcomes()
        assert failed.level == messages.ERROR
        assert failed.message == result.message
        monkeypatch.undo()
        wait_for(lambda: not node.running, what="the failed worker to end")
        assert client.send_goal(contract.DEPLOY, "/guarded/dynamics").result().success
        wait_for(lambda: len(outcomes()) == 2, what="the second outcome")
        values = messages.values(outcomes()[-1])
        assert values["success"] is True and values["samples"] == 21
    finally:
        client.executor.remove_node(node)
        node.destroy_node()
        client.close()
        model.stop()


def test_sigint_mid_deployment_stops_it_and_ends_cleanly(compiled_nodes):
    """The worker is stopped and joined while the executor still spins: the
    outcome of what was computed goes out, and the process ends at once."""
    model = NodeProcess("array_model", "scene:=paper_4x4", namespace="/interrupted")
    dynamics = NodeProcess("dynamics", "t_end:=2.0", "real_time_factor:=1.0",
                           namespace="/interrupted")
    client = Client("dynamics_interrupt_test")
    diagnostics = client.listen(DiagnosticArray, "/diagnostics")
    states = client.listen(JointState, "/interrupted/joint_states", messages.qos(contract.STREAM))
    try:
        goal = deploy(client, "/interrupted/dynamics")
        assert not goal.done()
        wait_for(lambda: len(states) > 20, what="the deployment under way")
        code, seconds, err = dynamics.stop()
        assert code == 0 and seconds < 3.0 and "Traceback" not in err, (code, seconds, err)
        wait_for(lambda: any(s.name == "/interrupted/dynamics" for d in list(diagnostics)
                             for s in d.status), timeout=5, what="the outcome")
        outcome, = [s for d in diagnostics for s in d.status if s.name == "/interrupted/dynamics"]
        assert outcome.message.startswith("stopped at t = "), outcome.message
        assert int(messages.values(outcome)["samples"]) < 401
    finally:
        client.close()
        model.stop()
        dynamics.stop()


def test_a_calibrated_scene_deploys_as_written(compiled_nodes, tmp_path):
    """What ``panel-deploy calibrate`` writes is a scene file array_model takes: the
    dynamics node deploys its fitted k and c/k (a 2-evaluation fit: the values differ
    from the scene's, which is what is checked, not the fit)."""
    path = tmp_path / "calibrated.yaml"
    bag = str(Path(__file__).resolve().parent.parent / "bags" / "paper_4x4_uniform.mcap")
    main(["calibrate", bag, "--until", "0.3", "--max-evaluations", "2", "--quiet",
          "--out", str(path)])  # exit 1: the budget ran out, the best fit is written
    calibrated = build_model(load_scene(path))
    nominal = build_model(load_scene(resolve_scene("paper_4x4")))
    assert [h.k for h in calibrated.hinges] != [h.k for h in nominal.hinges]
    model = NodeProcess("array_model", f"scene:={path}", namespace="/calibrated")
    dynamics = NodeProcess("dynamics", "t_end:=0.05", "real_time_factor:=0.0",
                           namespace="/calibrated")
    client = Client("calibrated_test")
    scenes = client.listen(String, "/calibrated/dynamics/scene", messages.qos(contract.LATCHED))
    try:
        goal = client.start_goal(contract.DEPLOY, "/calibrated/dynamics")
        assert goal.result().success, goal.result().message
        wait_for(lambda: scenes, what="the deployed scene")
        deployed = build_model(scene_from_yaml(scenes[-1].data))
        assert [h.k for h in deployed.hinges] == pytest.approx([h.k for h in calibrated.hinges])
        assert [h.c for h in deployed.hinges] == pytest.approx([h.c for h in calibrated.hinges])
    finally:
        client.close()
        model.stop()
        dynamics.stop()
