"""The optimiser node as its own process: background search, progress, result, target set, cancel."""

import pytest
import yaml
from action_msgs.msg import GoalStatus
from panel_deploy_interfaces.msg import OptimiserProgress
from rcl_interfaces.srv import DescribeParameters, GetParameters, SetParameters
from rclpy.parameter import Parameter
from std_msgs.msg import String

from panel_deploy import contract
from panel_deploy.nodes import messages
from ros_harness import Client, NodeProcess, wait_for

# c/k searched too (the paper's lubricant): feasible K within a few evaluations.
LUBRICANT = [0.043, 0.3]


@pytest.fixture(scope="module")
def graph(compiled_nodes):
    procs = [NodeProcess("array_model", "scene:=paper_4x4"), NodeProcess("dynamics"),
             NodeProcess("optimiser", "max_evaluations:=12", "method:=local",
                         f"damping_ratio_bounds:=[{LUBRICANT[0]},{LUBRICANT[1]}]")]
    client = Client("optimiser_test")
    progress = client.listen(OptimiserProgress, "/optimiser/progress")
    results = client.listen(String, "/optimiser/result", messages.qos(contract.LATCHED))
    yield client, progress, results
    client.close()
    for p in procs:
        code, seconds, err = p.stop()
        assert code == 0 and "Traceback" not in err, err


def optimise(client):
    """An Optimise goal, started (sent again while the model has not come)."""
    return client.start_goal(contract.OPTIMISE, "/optimiser")


def stiffness(client):
    """The dynamics node's (stiffness, damping_ratio); stiffness [] while unset."""
    def get(name):
        return client.call(GetParameters, "/dynamics/get_parameters",
                           GetParameters.Request(names=[name])).values
    k = get("stiffness")
    return (list(k[0].double_array_value) if k else []), get("damping_ratio")[0].double_value


def test_optimise_reports_progress_and_sets_the_target(graph):
    client, progress, results = graph
    before = stiffness(client)
    goal = optimise(client)
    second = client.send_goal(contract.OPTIMISE, "/optimiser")
    assert "running" in second.result(timeout=10).message
    assert second.status == GoalStatus.STATUS_ABORTED
    answer = goal.result(timeout=120)
    assert answer.success and goal.status == GoalStatus.STATUS_SUCCEEDED, answer.message
    wait_for(lambda: results, timeout=10, what="the result topic")
    result = yaml.safe_load(results[-1].data)
    assert result == yaml.safe_load(answer.result) and result["success"], result["message"]
    assert progress and progress[-1].evaluations >= progress[0].evaluations >= 1
    assert goal.feedback[-1].progress.evaluations == progress[-1].evaluations
    assert answer.damping_ratio == pytest.approx(result["hinges"][next(iter(result["hinges"]))]["c"]
                                                 / result["hinges"][next(iter(result["hinges"]))]["k"])
    k = [result["hinges"][name]["k"] for name in result["hinges"]]
    wait_for(lambda: stiffness(client) != before, what="the dynamics node's stiffness to change")
    after, ratio = stiffness(client)
    assert after == pytest.approx(k)  # per hinge, in model order
    assert LUBRICANT[0] <= ratio <= LUBRICANT[1]


def test_cancel_stops_with_the_best_so_far(graph):
    client, progress, results = graph
    set_reply = client.call(SetParameters, "/optimiser/set_parameters", SetParameters.Request(
        parameters=[Parameter("max_evaluations", value=400).to_parameter_msg(),
                    Parameter("damping_ratio_bounds", Parameter.Type.DOUBLE_ARRAY, [])
                    .to_parameter_msg()]))
    assert all(r.successful for r in set_reply.results)
    results.clear()
    progress.clear()
    goal = optimise(client)
    wait_for(lambda: progress, timeout=60, what="progress")
    goal.cancel()
    answer = goal.result(timeout=60)
    assert goal.status == GoalStatus.STATUS_CANCELED
    result = yaml.safe_load(answer.result)
    assert result["status"] == 3 and result["nfev"] < 400


def test_invalid_parameters_are_rejected(graph):
    client, *_ = graph
    for param, reason in ((Parameter("max_evaluations", value=-4), "max_evaluations"),
                          (Parameter("method", value="annealing"), "method"),
                          (Parameter("workers", value=-2), "workers"),
                          (Parameter("seed", value=-2), "seed"),
                          (Parameter("target_node", value=""), "target_node"),
                          (Parameter("target_node", value="two words"), "target_node"),
                          (Parameter("damping_ratio_bounds", Parameter.Type.DOUBLE_ARRAY, [0.3, 0.1]),
                           "damping_ratio_bounds")):
        result, = client.call(SetParameters, "/optimiser/set_parameters",
                              SetParameters.Request(parameters=[param.to_parameter_msg()])).results
        assert not result.successful and reason in result.reason, result.reason


def test_integer_ranges_are_in_the_descriptors(graph):
    client, *_ = graph
    described = client.call(DescribeParameters, "/optimiser/describe_parameters",
                            DescribeParameters.Request(names=["max_evaluations", "workers", "seed"]))
    assert {d.name: (d.integer_range[0].from_value, d.integer_range[0].to_value)
            for d in described.descriptors} == {"max_evaluations": (0, 1_000_000),
                                                "workers": (0, 1024), "seed": (-1, 2**32 - 1)}


@pytest.mark.parametrize("param", ["workers:=-2", "target_node:=''", "max_evaluations:=-1"])
def test_bad_values_at_start_are_one_line_and_exit_2(param):
    proc = NodeProcess("optimiser", param)
    _, err = proc.proc.communicate(timeout=60)
    lines = err.strip().splitlines()
    assert proc.proc.returncode == 2 and len(lines) == 1, err
    assert lines[0].startswith("panel-deploy: error:") and param.split(":=")[0] in lines[0], err


def test_target_node_resolves_in_the_optimisers_namespace():
    from panel_deploy.nodes.optimiser import OptimiserNode
    client = Client("optimiser_namespace_test")
    node = OptimiserNode(context=client.context, namespace="/array2")
    try:
        assert node._target_service("dynamics") == "/array2/dynamics/set_parameters"
        assert node._target_service("left/dynamics") == "/array2/left/dynamics/set_parameters"
        assert node._target_service("/array1/dynamics") == "/array1/dynamics/set_parameters"
    finally:
        node.destroy_node()
        client.close()
