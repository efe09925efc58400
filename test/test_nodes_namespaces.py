"""Two arrays side by side, each graph in a namespace of its own (separate node
processes): every node hears only its own array, and each verdict is its own."""

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from rosgraph_msgs.msg import Clock
from panel_deploy_interfaces.msg import CollisionEvent
from rcl_interfaces.srv import GetParameters
from ros_harness import Client, NodeProcess, wait_for

from panel_deploy import contract
from panel_deploy.nodes import messages

T_END = 0.6
#: /array1 deploys the paper's uniform design, which collides at 0.416 s;
#: /array2 the same with c/k = 0.19 s, which deploys without a collision
#: (scene comments, docs/findings.md). A model or joint state crossing over
#: would change a verdict or make a monitor refuse messages.
ARRAYS = {"/array1": [], "/array2": ["damping_ratio:=0.19"]}


@pytest.fixture(scope="module")
def arrays(compiled_nodes):
    procs = []
    for ns, extra in ARRAYS.items():
        procs += [NodeProcess("array_model", "scene:=paper_4x4", namespace=ns),
                  NodeProcess("dynamics", f"t_end:={T_END}", "real_time_factor:=0.0", *extra,
                              namespace=ns),
                  # Sim time from its own array's clock: /clock is remapped to <ns>/clock.
                  NodeProcess("collision_monitor", "use_sim_time:=true", "max_lag:=0.0", namespace=ns,
                              remaps=[contract.CLOCK_REMAP])]
    client = Client("namespaces_test")
    diagnostics = client.listen(DiagnosticArray, "/diagnostics")
    events = {ns: client.listen(CollisionEvent, f"{ns}/panel_deploy/collision_events")
              for ns in ARRAYS}
    for ns in ARRAYS:
        client.listen(Clock, f"{ns}/clock", messages.qos(contract.STREAM))
    client.listen(Clock, "/clock", messages.qos(contract.STREAM))
    yield client, diagnostics, events
    client.close()
    for p in procs:
        code, seconds, err = p.stop()
        assert code == 0 and "Traceback" not in err, err


def statuses(diagnostics, name):
    return [s for d in list(diagnostics) for s in d.status if s.name == name]




def test_each_array_has_its_own_topics_and_verdict(arrays):
    client, diagnostics, events = arrays
    for ns in ARRAYS:  # each monitor has its model when its first verdict comes
        wait_for(lambda: statuses(diagnostics, f"{ns}/collision_monitor"), timeout=60,
                 what=f"{ns}/collision_monitor")
        wait_for(lambda: client.node.count_publishers(f"{ns}/joint_states") == 1
                 and client.node.count_subscribers(f"{ns}/joint_states") == 1,
                 what=f"{ns}'s dynamics and monitor on joint_states")
    topics = {name for name, _ in client.node.get_topic_names_and_types()}
    for topic in ("joint_states", "robot_description", "panel_deploy/model",
                  "panel_deploy/collision_events", "panel_deploy/collision_markers"):
        assert {f"{ns}/{topic}" for ns in ARRAYS} <= topics and f"/{topic}" not in topics, topic
    # The graph seen from here is not the dynamics node's match with its monitor:
    # samples sent before that match are lost to the monitor, so the goal waits for it.
    goals = {ns: client.start_goal(contract.DEPLOY, f"{ns}/dynamics", wait_for_subscribers=1)
             for ns in ARRAYS}
    for ns, goal in goals.items():
        assert goal.result().success, goal.result().message
    outcome = {}
    for ns in ARRAYS:
        wait_for(lambda: statuses(diagnostics, f"{ns}/dynamics"), timeout=120,
                 what=f"the outcome of {ns}/dynamics")
        outcome[ns] = messages.values(statuses(diagnostics, f"{ns}/dynamics")[-1])
        assert int(outcome[ns]["samples"]) == round(T_END * 200) + 1

    def verdict(ns):
        """The monitor's last verdict once it has checked every sample its dynamics node sent."""
        done = [s for s in statuses(diagnostics, f"{ns}/collision_monitor")
                if messages.values(s).get("samples") == outcome[ns]["samples"]]
        return done[-1] if done else None
    for ns in ARRAYS:
        def left(ns=ns):
            last = statuses(diagnostics, f"{ns}/collision_monitor")[-1]
            return (f"{ns}'s verdict on all {outcome[ns]['samples']} samples (the last: "
                    f"{last.message!r}, {messages.values(last)})")
        wait_for(lambda: verdict(ns) is not None, timeout=60, what=left)
    first, second = verdict("/array1"), verdict("/array2")
    assert first.level == messages.ERROR and "r1c2+r1c3" in first.message, first.message
    assert 0.41 <= float(messages.values(first)["first_collision_t"]) <= 0.42
    assert second.level == messages.OK and second.message == "no collision", second.message
    assert events["/array1"] and not events["/array2"]
    assert {e.header.frame_id for e in events["/array1"]} == {"world"}
    assert events["/array1"][0].body_a == "r1c2+r1c3"
    # Each array's own sim time, never the other's: no clock goes back, none on /clock.
    for ns in ARRAYS:
        stamps = [messages.seconds(c.clock) for c in client.received[f"{ns}/clock"]]
        assert stamps and stamps[-1] == pytest.approx(T_END), (ns, stamps[-3:])
        back = np.flatnonzero(np.diff(stamps) <= 0)
        assert not back.size, (ns, len(stamps), [stamps[j - 1:j + 3] for j in back[:3]])
    assert client.received["/clock"] == []
    # With use_sim_time and the stream over (its clock stopped), verdicts go on.
    count = len(statuses(diagnostics, "/array1/collision_monitor"))
    wait_for(lambda: len(statuses(diagnostics, "/array1/collision_monitor")) > count + 2,
             what="verdicts after the sim clock stopped")
    # A stream of the other array would have been refused (stamps going back, a WARN each).
    for ns in ARRAYS:
        assert not [s for s in statuses(diagnostics, f"{ns}/collision_monitor")
                    if s.level == messages.WARN]


def test_each_dynamics_node_kept_its_own_parameters(arrays):
    client, *_ = arrays
    ratios = {ns: client.call(GetParameters, f"{ns}/dynamics/get_parameters",
                              GetParameters.Request(names=["damping_ratio"])).values[0].double_value
              for ns in ARRAYS}
    assert ratios == {"/array1": -1.0, "/array2": 0.19}
