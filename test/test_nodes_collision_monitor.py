"""The collision_monitor node as its own process, fed joint states by the test like encoders."""

import math

import pytest
from diagnostic_msgs.msg import DiagnosticArray
from panel_deploy_interfaces.msg import CollisionEvent, MonitorVerdict
from hostile import alias_bomb
from rcl_interfaces.srv import SetParameters
from rclpy.parameter import Parameter
from ros_harness import Client, NodeProcess, wait_for
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from visualization_msgs.msg import Marker, MarkerArray

from panel_deploy import contract
from panel_deploy.collision import CollisionSettings, check_trajectory
from panel_deploy.dynamics import simulate
from panel_deploy.dynamics.report import hinge_states
from panel_deploy.configure import DynamicsParameters, configure
from panel_deploy.nodes import messages
from panel_deploy.scene import load_scene, resolve_scene

STATUS = "/collision_monitor"  # the node's full name


@pytest.fixture(scope="module")
def deployment():
    scene, model = configure(load_scene(resolve_scene("paper_4x4")),
                             DynamicsParameters(t_end=0.6, rate_hz=200.0))
    result = simulate(model, scene.simulation)
    report = check_trajectory(model, result, CollisionSettings.from_scene(scene))
    return model, result, report


@pytest.fixture(scope="module")
def graph(compiled_nodes):
    model = NodeProcess("array_model", "scene:=paper_4x4")
    monitor = NodeProcess("collision_monitor", "max_lag:=0.0")  # every sample checked
    client = Client("monitor_test")
    publisher = client.node.create_publisher(JointState, "/joint_states", messages.qos(contract.STREAM))
    events = client.listen(CollisionEvent, "/panel_deploy/collision_events")
    verdicts = client.listen(MonitorVerdict, "/collision_monitor/verdict", messages.qos(contract.LATCHED))
    diagnostics = client.listen(DiagnosticArray, "/diagnostics")
    markers = client.listen(MarkerArray, "/panel_deploy/collision_markers")
    wait_for(lambda: publisher.get_subscription_count() >= 1, timeout=60, what="the monitor")
    # The monitor warns about joint states until the model has reached it.
    wait_for(lambda: any(s.name == STATUS and s.message in ("waiting for joint states", "no collision")
                         for d in diagnostics for s in d.status), timeout=60, what="the model")
    yield client, publisher, events, diagnostics, markers, verdicts
    client.close()
    for p in (model, monitor):
        code, seconds, err = p.stop()
        assert code == 0 and "Traceback" not in err, err


def feed(publisher, model, result, rows):
    names, theta, omega, torque = hinge_states(model, result)
    for j in rows:
        publisher.publish(messages.joint_state(names, result.t[j], theta[j], omega[j], torque[j]))


def wait_checked(diagnostics, samples):
    """Until a verdict says the monitor has checked ``samples`` samples of this deployment."""
    wait_for(lambda: any({kv.key: kv.value for kv in s.values}.get("samples") == str(samples)
                         for s in statuses(diagnostics)), what=f"{samples} samples checked")


def statuses(diagnostics, level=None):
    return [s for d in diagnostics for s in d.status
            if s.name == STATUS and (level is None or s.level == level)]


def test_first_event_names_the_pair_simulate_finds(graph, deployment):
    client, publisher, events, diagnostics, markers, verdicts = graph
    model, result, report = deployment
    events.clear()
    feed(publisher, model, result, range(len(result.t)))
    wait_for(lambda: events, what="a collision event")
    first = events[0]
    assert (first.body_a, first.body_b) == report.first_collision.names
    dt = result.t[1] - result.t[0]
    assert abs(first.t - report.first_collision.t) <= dt
    assert messages.seconds(first.header.stamp) == pytest.approx(first.t)  # stamps from 0 here
    assert first.approach_speed == pytest.approx(report.v, rel=1e-6)
    # The first markers that show a pair (a new deployment first clears the last one's).
    hits = lambda: [a for a in markers if any(m.ns == "collision" for m in a.markers)]  # noqa: E731
    wait_for(hits, what="the collision markers")
    assert {m.text for m in hits()[0].markers if m.ns == "collision"} == set(report.first_collision.names)
    wait_for(lambda: statuses(diagnostics, messages.ERROR), what="an ERROR verdict")
    wait_checked(diagnostics, len(result.t))
    # The typed verdict says what the /diagnostics one says.
    wait_for(lambda: verdicts and verdicts[-1].samples == len(result.t), what="the typed verdict")
    typed = contract.verdict_values(verdicts[-1])
    assert typed["level"] == MonitorVerdict.ERROR
    assert typed["first_collision_pair"] == list(report.first_collision.names)
    assert typed["d"] == pytest.approx(report.d) and typed["expected"] is None
    assert len(typed["measured"]) == len(model.hinges) and typed["solved"] == []


BAD = {
    "unknown name": lambda m: m.name.__setitem__(0, "no_such_hinge"),
    # A hinge on no loop: the loop closure cannot stand in for it.
    "missing name": lambda m: [x.pop(m.name.index("r2c2-r3c2"))
                               for x in (m.position, m.velocity, m.effort, m.name)],
    "wrong length": lambda m: m.position.pop(),
    "NaN": lambda m: m.position.__setitem__(1, math.nan),
    "stamp out of order": lambda m: setattr(m.header, "stamp", messages.stamp(0.05)),
}


def test_malformed_joint_states_warn_and_the_verdict_stays_right(graph, deployment):
    client, publisher, events, diagnostics, markers, _ = graph
    model, result, report = deployment
    names, theta, omega, torque = hinge_states(model, result)
    n = len(result.t)
    events.clear()
    feed(publisher, model, result, range(n // 2))
    wait_checked(diagnostics, n // 2)
    diagnostics.clear()
    j = n // 2
    for spoil in BAD.values():
        msg = messages.joint_state(names, result.t[j], theta[j], omega[j], torque[j])
        msg.name, msg.position, msg.velocity, msg.effort = (list(msg.name), list(msg.position),
                                                           list(msg.velocity), list(msg.effort))
        spoil(msg)
        publisher.publish(msg)
    needles = ("unknown joint", "missing joint", "values for", "not finite", "header.stamp")

    def warns():
        return [s.message for s in statuses(diagnostics, messages.WARN)]
    # Wait for each WARN by what it says, not by their count: under load a "stream
    # stalled" WARN (no valid sample while the bad ones are refused) can come first.
    wait_for(lambda: all(any(needle in w for w in warns()) for needle in needles),
             what=lambda: f"a WARN for each of {needles}, got {warns()}")
    feed(publisher, model, result, range(j, n))
    wait_for(lambda: events, what="the collision after the bad messages")
    wait_checked(diagnostics, n)  # done with this deployment: the next test starts clean
    # The earliest: under load the last deployment's later events (it goes on checking
    # after its first collision) can arrive after the clear above.
    first = min(events, key=lambda e: e.t)
    assert (first.body_a, first.body_b) == report.first_collision.names
    assert abs(first.t - report.first_collision.t) <= result.t[1] - result.t[0]


def test_reset_starts_a_new_deployment(graph, deployment):
    client, publisher, events, diagnostics, markers, _ = graph
    model, result, report = deployment
    markers.clear()
    assert client.trigger("/collision_monitor/reset").success
    # The last collision's markers go off displays (under load, markers the last
    # deployment's later events sent can arrive after the clear above).
    wait_for(lambda: any([m.action for m in a.markers] == [Marker.DELETEALL] for a in markers),
             what="the markers cleared")
    diagnostics.clear()
    feed(publisher, model, result, range(20))  # before the collision: OK again
    wait_checked(diagnostics, 20)
    # The first verdict on the 20 samples: half a second after the feed stops a
    # later one rightly says the stream stalled (a full suite's load once let the
    # wait above see that one first).
    at_20 = [s for s in statuses(diagnostics) if {kv.key: kv.value for kv in s.values}
             .get("samples") == "20"]
    first = at_20[0]
    assert first.level == messages.OK and first.message == "no collision", \
        [(s.level, s.message) for s in at_20]


def test_an_alias_bomb_on_the_model_topic_is_ignored_at_once(graph, deployment):
    # one such message from anyone on the graph took down collision_monitor and dynamics
    client, publisher, events, diagnostics, markers, _ = graph
    model, result, report = deployment
    with client.publisher(String, "/panel_deploy/model", messages.qos(contract.LATCHED)) as bomb:
        diagnostics.clear()
        bomb.publish(String(data=alias_bomb(key="array")))
        wait_for(lambda: any("ignored a model" in s.message and "aliases expand it beyond" in s.message
                             for s in statuses(diagnostics, messages.WARN)), timeout=10,
                 what="the monitor's warning")
    assert client.trigger("/collision_monitor/reset").success  # the model it had is kept
    diagnostics.clear()
    feed(publisher, model, result, range(20))
    wait_checked(diagnostics, 20)


@pytest.mark.parametrize("param, reason", [
    (Parameter("tolerance", value=float("inf")), "tolerance"),
    (Parameter("tolerance", value=float("nan")), "tolerance"),
])
def test_invalid_tolerance_is_rejected(graph, param, reason):
    client = graph[0]
    result, = client.call(SetParameters, "/collision_monitor/set_parameters",
                          SetParameters.Request(parameters=[param.to_parameter_msg()])).results
    assert not result.successful and reason in result.reason


def test_a_model_with_panel_contact_is_ok_only_with_its_contact_onsets(graph):
    """Joint states cannot show an impact the panel contact absorbed: from a
    driver without dynamics/contact_onsets (encoders) the clean verdict is
    WARN at once, saying so; with each interval's onset it is OK."""
    from panel_deploy.contract.cdr import SampleEncoder
    from panel_deploy.scene_text import scene_yaml
    from panel_deploy_interfaces.msg import ContactOnset

    client, publisher, events, diagnostics, markers, verdicts = graph
    scene, model = configure(load_scene(resolve_scene("paper_4x4"), ["contact.panels=true"]),
                             DynamicsParameters(t_end=0.1, rate_hz=200.0))
    result = simulate(model, scene.simulation)
    latched = messages.qos(contract.LATCHED)
    with client.publisher(String, "/panel_deploy/model", latched) as source:
        verdicts.clear()
        source.publish(String(data=scene_yaml(scene)))
        # A new model starts afresh: its first verdict waits for joint states.
        wait_for(lambda: verdicts and verdicts[-1].message == "waiting for joint states",
                 what="the contact model")
        feed(publisher, model, result, range(len(result.t)))
        wait_for(lambda: verdicts and verdicts[-1].samples == len(result.t), what="the samples checked")
        assert verdicts[-1].level == MonitorVerdict.WARN and verdicts[-1].onsets == 0
        assert "no contact onsets came: an impact the contact absorbs" in verdicts[-1].message

        with client.publisher(ContactOnset, "/dynamics/contact_onsets", messages.qos(contract.STREAM)) as onsets:
            wait_for(lambda: onsets.get_subscription_count() >= 1, what="the monitor's onset subscription")
            assert client.trigger("/collision_monitor/reset").success
            encoder = SampleEncoder(model)
            names, theta, omega, torque = hinge_states(model, result)
            for j in range(len(result.t)):
                publisher.publish(messages.joint_state(names, result.t[j], theta[j], omega[j], torque[j]))
                onsets.publish(encoder.onset(result.t[j], result.contact_onsets[j]))
            wait_for(lambda: verdicts and verdicts[-1].onsets == len(result.t) - 1, what="the onsets checked")
            wait_for(lambda: verdicts[-1].level == MonitorVerdict.OK, timeout=5,
                     what=lambda: f"an OK verdict, got {verdicts[-1].message}")
            assert verdicts[-1].samples == len(result.t) and verdicts[-1].message == "no collision"
