"""panel_deploy.contract is the one owner of the ROS contract: no other module names a
topic, a service or a QoS; the live nodes publish exactly the contract's topics with its
QoS, and recordings carry the same QoS."""

import ast
from pathlib import Path

import pytest
import yaml

from panel_deploy import contract

PACKAGE = Path(__file__).resolve().parent.parent / "panel_deploy"


def _names():
    """Every spelling of a contract name: relative, absolute, and a node's private ``~/x``."""
    names = set()
    for topic in contract.TOPICS:
        names |= {topic.name, contract.resolve(topic.name)}
        node, _, rest = topic.name.partition("/")
        if node in contract.NODES:
            names.add("~/" + rest)
    for service in contract.SERVICES + contract.ACTIONS:
        names |= {service.path, "/" + service.path, "~/" + service.name}
    return names


def test_no_module_but_the_contract_names_a_topic_a_service_or_a_qos():
    names = _names()
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        if path.parent.name == "contract":
            continue
        tree = ast.parse(path.read_text(), str(path))
        exported = {id(c) for n in ast.walk(tree) if isinstance(n, ast.Assign)
                    and any(getattr(t, "id", "") == "__all__" for t in n.targets)
                    for c in ast.walk(n.value)}  # function names, not topics
        for node in ast.walk(tree):
            if id(node) in exported:
                continue
            if isinstance(node, ast.Constant) and isinstance(node.value, str) and node.value in names:
                found.append(f"{path.relative_to(PACKAGE)}:{node.lineno}: {node.value!r}")
            if isinstance(node, ast.Call) and getattr(node.func, "id", getattr(node.func, "attr", "")) \
                    == "QoSProfile" and path.name != "messages.py":
                found.append(f"{path.relative_to(PACKAGE)}:{node.lineno}: QoSProfile(...)")
            if isinstance(node, ast.Call) and getattr(node.func, "attr", "") in (
                    "create_publisher", "create_subscription", "create_service") \
                    and path.name != "runtime.py":
                found.append(f"{path.relative_to(PACKAGE)}:{node.lineno}: {node.func.attr} "
                             "outside nodes/runtime.py")
    assert found == []


def test_the_scan_would_see_a_topic_name():
    assert "joint_states" in _names() and "/diagnostics" in _names()
    assert "~/deploy" in _names() and "dynamics/deploy" in _names()


def test_names_resolve_in_a_namespace():
    assert contract.resolve("joint_states", "array7") == "/array7/joint_states"
    assert contract.resolve("joint_states", "/a/b/") == "/a/b/joint_states"
    assert contract.resolve("/clock", "array7") == "/clock"
    assert contract.topic_of("/array7/joint_states") == (contract.JOINT_STATES, "/array7")
    assert contract.topic_of("/panel_deploy/model") == (contract.MODEL, "")
    assert contract.topic_of("/elsewhere") is None


def test_typed_values_read_back():
    v = contract.parse_values({"t": "0.416", "d_pair": "a,b", "d": "", "samples": "401",
                               "success": "True", "summary": '{"x": 1}', "other": "text"})
    assert v == {"t": 0.416, "d_pair": ["a", "b"], "d": None, "samples": 401, "success": True,
                 "summary": {"x": 1}, "other": "text"}
    assert contract.status_value(None) == "" and contract.status_value(0.1) == "0.1"


@pytest.fixture
def graph():
    rclpy = pytest.importorskip("rclpy")
    from panel_deploy.nodes.array_model import ArrayModelNode
    from panel_deploy.nodes.collision_monitor import CollisionMonitorNode
    from panel_deploy.nodes.dynamics import DynamicsNode
    from panel_deploy.nodes.optimiser import OptimiserNode

    context = rclpy.Context()
    rclpy.init(context=context)
    nodes = [cls(context=context) for cls in (ArrayModelNode, DynamicsNode,
                                              CollisionMonitorNode, OptimiserNode)]
    yield nodes
    for node in nodes:
        node.destroy_node()
    rclpy.shutdown(context=context)


def test_live_nodes_publish_the_contract_with_its_qos(graph):
    expected = {contract.resolve(t.name): t for t in contract.TOPICS}
    seen = {}
    for node in graph:
        for name, types in node.get_publisher_names_and_types_by_node(node.get_name(), "/"):
            if name in ("/rosout", "/parameter_events") or "/_action/" in name:
                continue  # every rclpy node's own, and the actions' (checked below)
            assert name in expected, f"{node.get_name()} publishes {name}, not in the contract"
            assert types == [expected[name].type]
            seen[name] = node.get_name()
    assert set(seen) == set(expected)
    for node in graph:
        for publisher in node.publishers:
            name = publisher.topic_name
            if name in ("/rosout", "/parameter_events") or "/_action/" in name:
                continue
            qos, topic = publisher.qos_profile, expected[name]
            assert qos.depth == topic.qos.depth, name
            assert qos.durability.name.lower() == topic.qos.durability, name
            assert qos.reliability.name.lower() == topic.qos.reliability, name
    for node, services in ((graph[0], [contract.RELOAD]), (graph[2], [contract.RESET])):
        offered = {name for name, _ in node.get_service_names_and_types_by_node(node.get_name(), "/")}
        assert {"/" + s.path for s in services} <= offered
    from rclpy.action import get_action_server_names_and_types_by_node

    for node, action in ((graph[1], contract.DEPLOY), (graph[3], contract.OPTIMISE)):
        offered = dict(get_action_server_names_and_types_by_node(node, node.get_name(), "/"))
        assert offered == {"/" + action.path: [action.type]}


def test_the_installed_package_holds_the_interface_definitions():
    """Package data: recordings embed these schemas, readers register them."""
    assert set(contract.definitions()) == {contract.COLLISION_EVENT, contract.CONTACT_ONSET,
                                           contract.MONITOR_VERDICT, contract.OPTIMISER_PROGRESS_MSG}
    assert {p.name for p in (contract.INTERFACES_DIR / "action").iterdir()} == {
        "Deploy.action", "Optimise.action"}
    assert (contract.INTERFACES_DIR / "package.xml").is_file()


def test_message_fields_come_from_the_verdict_values_and_back():
    values = {"deployment": 1, "origin": 2.5, "t": 0.4, "samples": 81, "d": None,
              "d_pair": [], "measured": ["a", "b"], "solved": [], "expected": None,
              "first_collision_pair": ["p", "q"], "first_collision_t": 0.416,
              "approach_speed": 4.2, "refused": 3}
    fields = contract.verdict_message(2, "collision", values)
    assert fields["expected"] == -1 and fields["skipped"] == 0
    from types import SimpleNamespace
    back = contract.verdict_values(SimpleNamespace(**fields))
    assert back["d"] is None and back["d_pair"] is None and back["expected"] is None
    assert back["first_collision_pair"] == ["p", "q"] and back["samples"] == 81
    assert back["origin"] == 2.5 and back["refused"] == 3 and back["level"] == 2


def test_a_recording_offers_each_topic_with_the_live_qos(tmp_path):
    from panel_deploy.record.reader import open_recording
    from panel_deploy.cli import main

    path = tmp_path / "r.mcap"
    assert main(["simulate", "paper_4x4", "--t-end", "0.05", "--record", str(path)]) == 0
    from mcap.reader import make_reader
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    channels = summary.channels.values()
    schemas = {s.name: s.data.decode() for s in summary.schemas.values()}
    # the Jazzy definitions with their defaults (a Quaternion is w 1 unless set)
    for name in ("tf2_msgs/msg/TFMessage", "visualization_msgs/msg/MarkerArray"):
        quaternion = schemas[name].split("MSG: geometry_msgs/Quaternion\n")[1].split("\n=")[0]
        assert quaternion.split("\n")[:4] == ["float64 x 0", "float64 y 0", "float64 z 0",
                                              "float64 w 1"], name
    qos = {c.topic: yaml.safe_load(c.metadata["offered_qos_profiles"])[0] for c in channels}
    assert set(qos) == {contract.resolve(t.name) for t in contract.TOPICS}
    for topic in contract.TOPICS:
        got = qos[contract.resolve(topic.name)]
        assert (got["depth"], got["durability"], got["reliability"]) == \
               (topic.qos.depth, topic.qos.durability, topic.qos.reliability)
    assert qos["/clock"]["depth"] == 5000  # as the dynamics node publishes it
    assert open_recording(path).namespace == ""


def test_get_parameters_answers_for_every_parameter_of_every_node(graph):
    """``ros2 param dump`` and rqt_reconfigure ask for all parameters at once: an unset
    one would empty the whole answer."""
    import threading

    from rcl_interfaces.srv import GetParameters, ListParameters
    from rclpy.executors import MultiThreadedExecutor
    from rclpy.node import Node

    context = graph[0].context
    client = Node("parameter_client", context=context)
    executor = MultiThreadedExecutor(context=context)
    for node in (*graph, client):
        executor.add_node(node)
    spinning = threading.Thread(target=executor.spin, daemon=True)
    spinning.start()

    def call(srv, service, request):
        c = client.create_client(srv, service)
        assert c.wait_for_service(timeout_sec=20), service
        done = threading.Event()
        future = c.call_async(request)
        future.add_done_callback(lambda _: done.set())
        assert done.wait(20), service
        return future.result()

    try:
        for node in graph:
            name = node.get_fully_qualified_name()
            names = call(ListParameters, f"{name}/list_parameters",
                         ListParameters.Request()).result.names
            assert "stiffness" in names or node.get_name() != "dynamics"
            answer = call(GetParameters, f"{name}/get_parameters",
                          GetParameters.Request(names=list(names)))
            assert len(answer.values) == len(names), name
            assert all(v.type != 0 for v in answer.values), name  # 0: PARAMETER_NOT_SET
    finally:
        executor.shutdown()
