"""The node suite's speed on the paper scene (not a test: prints medians and ratios).

    python bench/bench_nodes.py [--repeats R]

1. ``dynamics`` at real_time_factor 0 (its own process, the way ``ros2 run``
   starts it): wall time from ``~/deploy`` to the last of the 401
   ``/joint_states`` received by a client in this process, against the core
   ``simulate`` of the same run here, side by side (goal: at most 1.5x).
2. ``collision_monitor``: time the node spends per JointState (parse + the
   streaming check), median and p99 over a whole 2 s deployment sampled at
   1 kHz, and the rate that keeps up (1 / mean); then the same stream sent
   to the node process at 1 kHz of wall time, and how long after the last
   message its verdict has caught up (goal: 1 kHz, an encoder's rate).
3. Latency from the JointState that reveals the first collision (published
   at 200 Hz real time) to its event on ``/panel_deploy/collision_events``.

DDS stays on this machine (see test/ros_env.py).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "test"))
import ros_env  # noqa: E402

ros_env.isolate()

import numpy as np  # noqa: E402
from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from panel_deploy_interfaces.msg import CollisionEvent  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

from panel_deploy import contract  # noqa: E402
from panel_deploy.dynamics import simulate  # noqa: E402
from panel_deploy.dynamics.report import hinge_states  # noqa: E402
from panel_deploy.configure import DynamicsParameters, configure  # noqa: E402
from panel_deploy.nodes import messages  # noqa: E402
from panel_deploy.nodes.collision_monitor import VERDICT_PERIOD  # noqa: E402
from panel_deploy.scene import load_scene, resolve_scene  # noqa: E402
from ros_harness import Client, NodeProcess, checked_samples, wait_for  # noqa: E402


def paper(rate_hz, t_end=None):
    return configure(load_scene(resolve_scene("paper_4x4")),
                     DynamicsParameters(rate_hz=rate_hz, t_end=t_end or 0.0))


def dynamics_throughput(client, repeats):
    scene, model = paper(200.0)
    core = []
    for _ in range(repeats):
        start = time.perf_counter()
        simulate(model, scene.simulation)
        core.append(time.perf_counter() - start)
    states = client.listen(JointState, "/joint_states", messages.qos(contract.STREAM))
    diagnostics = client.listen(DiagnosticArray, "/diagnostics")
    received, published = [], []
    for _ in range(repeats):
        states.clear()
        diagnostics.clear()
        start = time.perf_counter()
        client.send_goal(contract.DEPLOY, "/dynamics")
        wait_for(lambda: len(states) >= scene.simulation.samples, timeout=120, what="the run")
        received.append(time.perf_counter() - start)
        wait_for(lambda: diagnostics, what="the outcome")
        values = {kv.key: kv.value for kv in diagnostics[-1].status[0].values}
        published.append(float(values["publish_wall_time"]))
    t_end = scene.simulation.t_end
    c, p, r = np.median(core), np.median(published), np.median(received)
    print(f"dynamics, paper scene {t_end:g} s at 200 Hz, median of {repeats}:")
    print(f"  core simulate                  {c:7.3f} s  {t_end / c:6.2f} simulated s per wall s")
    print(f"  node, first block to last publish {p:7.3f} s  {t_end / p:6.2f}  ratio {p / c:5.2f}x "
          f"(goal <= 1.5x)")
    print(f"  deploy call to last JointState received here {r:7.3f} s  {t_end / r:6.2f}  "
          f"ratio {r / c:5.2f}x (service, DDS, and this client on the same 2 cores)")


def monitor_cost(rate_hz=1000.0):
    from panel_deploy.nodes.collision_monitor import CollisionMonitorNode
    import rclpy
    scene, model = paper(rate_hz)
    result = simulate(model, scene.simulation)
    names, theta, omega, torque = hinge_states(model, result)
    msgs = [messages.joint_state(names, result.t[j], theta[j], omega[j], torque[j])
            for j in range(len(result.t))]
    context = rclpy.Context()
    rclpy.init(context=context)
    # A name of its own: the node process of the live part below owns "collision_monitor".
    node = CollisionMonitorNode(context=context,
                                cli_args=["--ros-args", "-r", "__node:=collision_monitor_bench"])
    try:
        node._on_model(messages.string(open(resolve_scene("paper_4x4")).read()))
        times = np.empty(len(msgs))
        for j, msg in enumerate(msgs):  # what the node does per sample: read it, check it
            start = time.perf_counter()
            sample = messages.read_joint_state(msg, node.stream.names)
            node._check(node.stream, *sample)
            times[j] = time.perf_counter() - start
    finally:
        node.close()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
    print(f"collision_monitor, paper scene 2 s at {rate_hz:g} Hz ({len(msgs)} JointStates, "
          f"refine on), time per message to read and check it:")
    print(f"  median {np.median(times) * 1e3:.3f} ms  p99 {np.percentile(times, 99) * 1e3:.3f} ms  "
          f"max {times.max() * 1e3:.1f} ms  mean {times.mean() * 1e3:.3f} ms "
          f"-> keeps up with {1 / times.mean():.0f} Hz on average")
    return msgs


def monitor_live(client, msgs, rate_hz=1000.0):
    publisher = client.node.create_publisher(JointState, "/joint_states", messages.qos(contract.STREAM))
    diagnostics = client.listen(DiagnosticArray, "/diagnostics")
    wait_for(lambda: publisher.get_subscription_count() >= 1, what="the monitor")
    client.trigger("/collision_monitor/reset")
    start = time.perf_counter()
    for j, msg in enumerate(msgs):
        ahead = start + j / rate_hz - time.perf_counter()
        if ahead > 0.002:  # sleep in steps the scheduler can keep: the rate holds on average
            time.sleep(ahead)
        publisher.publish(msg)
    sent = time.perf_counter()
    # Until every sample is checked, or nothing moved for 10 s (then say how many were).
    checked, _ = checked_samples(diagnostics, len(msgs), idle=10.0)
    lag = time.perf_counter() - sent
    print(f"  live, node process fed at {rate_hz:g} Hz for {sent - start:.2f} s: {checked} of "
          f"{len(msgs)} samples checked, the last {lag:.2f} s after the last message "
          f"(verdicts go out every {VERDICT_PERIOD:g} s)")


def event_latency(client):
    scene, model = paper(200.0, t_end=0.6)
    result = simulate(model, scene.simulation)
    names, theta, omega, torque = hinge_states(model, result)
    publisher = client.node.create_publisher(JointState, "/joint_states", messages.qos(contract.STREAM))
    events = client.listen(CollisionEvent, "/panel_deploy/collision_events")
    client.trigger("/collision_monitor/reset")
    events.clear()
    sent, arrived = {}, []
    client.node.create_subscription(CollisionEvent, "/panel_deploy/collision_events",
                                    lambda _: arrived.append(time.perf_counter()), messages.qos(contract.EVENTS))
    start = time.perf_counter()
    for j in range(len(result.t)):
        # Sleep, not spin: a busy loop here would take a core from the monitor.
        time.sleep(max(0.0, start + result.t[j] - time.perf_counter()))
        sent[j] = time.perf_counter()
        publisher.publish(messages.joint_state(names, result.t[j], theta[j], omega[j], torque[j]))
    wait_for(lambda: events and arrived, what="the event")
    sample = events[0].sample
    print(f"latency from the JointState that reveals the first collision (sample {sample}, "
          f"200 Hz real time) to its event: {(arrived[0] - sent[sample]) * 1e3:.1f} ms "
          f"(resolution: one 5 ms sample period)")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    # The monitor starts after the dynamics figures: on 2 cores it would take CPU from them.
    procs = [NodeProcess("array_model", "scene:=paper_4x4"),
             NodeProcess("dynamics", "real_time_factor:=0.0")]
    client = Client("bench_nodes")
    try:
        client.start_goal(contract.DEPLOY, "/dynamics").result()  # the model has reached it
        dynamics_throughput(client, args.repeats)
        procs[1].stop()
        procs.append(NodeProcess("collision_monitor", "max_lag:=0.0"))  # checks every sample
        msgs = monitor_cost()
        monitor_live(client, msgs)
        event_latency(client)
    finally:
        client.close()
        for p in procs:
            p.stop()


if __name__ == "__main__":
    main()
