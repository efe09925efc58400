"""The collision_monitor node as a test stand sees it: event latency and sustained rate.

    python bench/bench_monitor_latency.py [--repeats N] [--rates 1000,2000,10000]

The node runs as its own process (with array_model); this process publishes the paper's
uniform deployment (it collides at 0.416 s) as JointStates paced in real time at each
rate, with every hinge ("full") or without the loop hinge r2c1-r3c1 ("partial": solved
from the loop closure), and measures

under two rules: ``all`` (``max_lag`` 0: every sample checked however late) and ``skip``
(the default ``max_lag``, 20 ms: late samples skipped, the newest checked, never more
than the scene's 5 ms sample interval skipped in a row), and measures

- latency: from publishing the sample that reveals the first collision (the event's
  ``sample``; with ``skip``, the first checked sample after the collision) to receiving
  its event on ``panel_deploy/collision_events``; median, 99th percentile and largest;
- sustained rate: samples the monitor accounted for (checked + skipped) per second of
  stream, and how long after the last message the last one was; what it checked and
  skipped of those sent.

Wall clock on 2 shared cores: medians and ratios within one run, never targets in tests.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "test"))

import ros_env  # noqa: E402

ros_env.isolate()  # DDS stays on this machine (before rclpy starts)

from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from rcl_interfaces.srv import SetParameters  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from panel_deploy_interfaces.msg import CollisionEvent  # noqa: E402
from ros_harness import Client, NodeProcess, checked_samples, wait_for  # noqa: E402
from sensor_msgs.msg import JointState  # noqa: E402

from panel_deploy import contract  # noqa: E402
from panel_deploy.configure import DynamicsParameters, configure  # noqa: E402
from panel_deploy.dynamics import simulate  # noqa: E402
from panel_deploy.dynamics.report import hinge_states  # noqa: E402
from panel_deploy.nodes import messages  # noqa: E402
from panel_deploy.nodes.collision_monitor import PARAMETERS  # noqa: E402
from panel_deploy.scene import load_scene, resolve_scene  # noqa: E402

T_END = 0.6
LEFT_OUT = "r2c1-r3c1"
#: The collision monitor's default max_lag (s), as its parameter declares it.
MAX_LAG = PARAMETERS["max_lag"][0]


def set_max_lag(client, value):
    result, = client.call(SetParameters, "/collision_monitor/set_parameters", SetParameters.Request(
        parameters=[Parameter("max_lag", value=float(value)).to_parameter_msg()])).results
    assert result.successful, result.reason


def stream(rate_hz, partial):
    """The JointStates of the paper deployment at ``rate_hz`` (every hinge, or all but LEFT_OUT)."""
    scene, model = configure(load_scene(resolve_scene("paper_4x4")),
                             DynamicsParameters(t_end=T_END, rate_hz=rate_hz))
    result = simulate(model, scene.simulation)
    names, theta, omega, torque = hinge_states(model, result)
    keep = [i for i, n in enumerate(names) if not (partial and n == LEFT_OUT)]
    return result.t, [messages.joint_state([names[i] for i in keep], result.t[j], theta[j, keep],
                                           omega[j, keep], torque[j, keep])
                      for j in range(len(result.t))]


def once(client, publisher, events, diagnostics, t, msgs):
    """One paced run: (latency s or None, (checked, skipped), s from the last message
    to the last accounted for)."""
    assert client.trigger("/collision_monitor/reset").success
    events.clear()
    diagnostics.clear()
    sent = np.zeros(len(msgs))
    start = time.perf_counter()
    for j, msg in enumerate(msgs):
        ahead = start + t[j] - time.perf_counter()
        if ahead > 0.001:  # sleep, not spin: a busy loop would take a core from the monitor
            time.sleep(ahead)
        sent[j] = time.perf_counter()
        publisher.publish(msg)
    last_sent = time.perf_counter()
    accounted = checked_samples(diagnostics, len(msgs))
    done = time.perf_counter() - last_sent
    latency = None
    if events and client.arrivals:
        # the sample that revealed it, counted in the stream (events count checked ones)
        revealed = int(np.searchsorted(t, events[0].t)) if events[0].sample >= 0 else 0
        latency = client.arrivals[0] - sent[min(revealed, len(sent) - 1)]
    return latency, accounted, done


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--rates", default="1000,2000,10000")
    args = p.parse_args(argv)
    procs = [NodeProcess("array_model", "scene:=paper_4x4"), NodeProcess("collision_monitor")]
    client = Client("bench_monitor_latency")
    client.arrivals = []
    try:
        publisher = client.node.create_publisher(JointState, "/joint_states",
                                                 messages.qos(contract.STREAM))
        diagnostics = client.listen(DiagnosticArray, "/diagnostics")
        events = client.listen(CollisionEvent, "/panel_deploy/collision_events")
        client.node.create_subscription(
            CollisionEvent, "/panel_deploy/collision_events",
            lambda _: client.arrivals.append(time.perf_counter()), messages.qos(contract.EVENTS))
        wait_for(lambda: publisher.get_subscription_count() >= 1, timeout=60, what="the monitor")
        wait_for(lambda: diagnostics, timeout=60, what="the model at the monitor")
        print(f"paper deployment to {T_END} s (first collision at 0.416 s), paced in real time; "
              f"{args.repeats} runs each; latency median / 99th percentile / largest")
        print(f"{'rate':>7} {'sensing':>8} {'rule':>5} {'latency':>24} "
              f"{'checked':>8} {'skipped':>8} {'of':>6} {'rate kept':>10} {'last after':>11}")
        for rate in (float(r) for r in args.rates.split(",")):
            for partial in (False, True):
                t, msgs = stream(rate, partial)
                for rule, max_lag in (("all", 0.0), ("skip", MAX_LAG)):
                    set_max_lag(client, max_lag)
                    runs = []
                    for _ in range(args.repeats):
                        client.arrivals.clear()
                        runs.append(once(client, publisher, events, diagnostics, t, msgs))
                    lat = np.array([r[0] for r in runs if r[0] is not None]) * 1e3
                    checked = int(np.median([r[1][0] for r in runs]))
                    skipped = int(np.median([r[1][1] for r in runs]))
                    after = float(np.median([r[2] for r in runs]))
                    kept = (checked + skipped) / (T_END + after)
                    latency = (f"{np.median(lat):.1f} / {np.percentile(lat, 99):.1f} / "
                               f"{lat.max():.0f} ms" if len(lat) else "no event")
                    print(f"{rate:7.0f} {'partial' if partial else 'full':>8} {rule:>5} "
                          f"{latency:>24} {checked:>8} {skipped:>8} {len(msgs):>6} "
                          f"{kept:8.0f}/s {after:9.2f} s"
                          + ("" if len(lat) == args.repeats else
                             f"  ({args.repeats - len(lat)} runs without an event)"), flush=True)
    finally:
        client.close()
        for proc in procs:
            proc.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main())
