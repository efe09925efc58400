"""A test client for the node tests: one rclpy context, an executor thread,
node executables started as processes the way ``ros2 run`` starts them."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import itertools
import threading
import time
from contextlib import contextmanager
from pathlib import Path
from uuid import uuid4

import rclpy
from action_msgs.msg import GoalStatusArray
from rclpy.action import ActionClient
from rclpy.action.client import ClientGoalHandle
from rclpy.exceptions import InvalidHandle
from rclpy.executors import MultiThreadedExecutor
from rclpy.qos import qos_profile_action_status_default
from rclpy.node import Node
from std_srvs.srv import Trigger
from unique_identifier_msgs.msg import UUID

from panel_deploy import contract
from panel_deploy.nodes import messages

BIN = Path(sys.executable).parent
#: s a request waits for its answer before it is sent again: one can be lost while
#: the server has yet to discover this client's reply reader (a DDS race, seen once
#: in CI under load: a Deploy goal to a dynamics node just started never answered).
ANSWER = 10.0


def executable(name: str) -> str:
    path = BIN / name
    assert path.exists(), f"{name} is not installed next to {sys.executable}"
    return str(path)


def wait_for(condition, timeout=60.0, what="condition"):
    """Poll ``condition`` until true; ``what`` (text, or a callable giving it at
    the timeout, to say what state it was left in) names it in the failure."""
    end = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > end:
            raise AssertionError(f"timed out after {timeout} s waiting for "
                                 f"{what() if callable(what) else what}")
        time.sleep(0.02)


def checked_samples(diagnostics, count, idle=5.0, status="/collision_monitor") -> tuple:
    """``(checked, skipped)``: the samples the monitor's verdicts on ``diagnostics`` (a
    :meth:`Client.listen` list) say it checked and skipped, once they account for
    ``count`` or have not moved for ``idle`` s."""
    def seen():
        best = (0, 0)
        for d in list(diagnostics):
            for s in d.status:
                v = {kv.key: kv.value for kv in s.values} if s.name == status else {}
                if v.get("samples"):
                    best = max(best, (int(v["samples"]), int(v.get("skipped") or 0)),
                               key=sum)
        return best

    last, still = None, time.monotonic()
    while sum(seen()) < count and time.monotonic() - still < idle:
        if seen() != last:
            last, still = seen(), time.monotonic()
        time.sleep(0.02)
    return seen()


class Client:
    """A node in the test process with a spinning executor; collects messages."""

    def __init__(self, name="test_client"):
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = Node(name, context=self.context)
        self.executor = MultiThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.received = {}
        self._clients = {}
        self._listed = {}
        self._closing = threading.Event()
        self._apart = itertools.count()
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()

    def _spin(self):
        while not self._closing.is_set():
            try:
                self.executor.spin_once(timeout_sec=0.05)
            except InvalidHandle:
                # A publisher or subscription the test destroyed while this wait
                # was being set up (seen in CI): the next wait is built without it.
                # Uncaught, it ended this thread and the client stopped spinning.
                continue

    @contextmanager
    def publisher(self, msg_type, topic, qos):
        """A publisher of the test's own, destroyed at the end of the ``with``: on
        a node of its own that the executor never waits on. Destroyed on the
        spinning node, one left that executor answering nothing more (CI: a
        task's "cannot use Destroyable because destruction was requested", then
        the next service call unanswered for 60 s)."""
        node = Node(f"{self.node.get_name()}_publisher_{next(self._apart)}", context=self.context)
        try:
            yield node.create_publisher(msg_type, topic, qos)
        finally:
            node.destroy_node()

    def listen(self, msg_type, topic, qos=messages.qos(contract.EVENTS)):
        """The list every message on ``topic`` is appended to (one subscription per topic)."""
        if topic not in self.received:
            self.received[topic] = []
            self.node.create_subscription(msg_type, topic, self.received[topic].append, qos)
        return self.received[topic]

    def call(self, srv_type, service, request=None, timeout=60.0):
        # Clients are kept: destroying one under a spinning executor can block.
        key = (srv_type, service)
        if key not in self._clients:
            self._clients[key] = self.node.create_client(srv_type, service)
        client = self._clients[key]
        assert client.wait_for_service(timeout_sec=timeout), f"{service} not available"
        request = request if request is not None else srv_type.Request()
        return _answered(lambda: client.call_async(request), timeout, service).result()

    def has_node(self, name):
        return name in self.node.get_node_names()

    def trigger(self, service):
        return self.call(Trigger, service)

    def _listed_goals(self, server: str) -> set:
        """The goal ids (bytes) that the action server ``server`` has listed on
        its status topic, kept up to date from the first call on."""
        if server not in self._listed:
            listed = self._listed[server] = set()
            self.node.create_subscription(
                GoalStatusArray, f"{server}/_action/status",
                lambda msg: listed.update(bytes(s.goal_info.goal_id.uuid) for s in msg.status_list),
                qos_profile_action_status_default)
        return self._listed[server]

    def send_goal(self, action: contract.Service, node: str, timeout=60.0, **fields) -> "Goal":
        """A goal of ``action`` sent to the server of ``node`` (its full name), accepted.

        Sent again every ANSWER s while neither its answer nor its feedback has
        come and the server does not list it, as a service request is
        (:func:`_answered`); but a goal whose answer was lost runs all the same,
        and sent again it would run twice (a dynamics node then deployed twice
        and its clock went back, seen under load), or be aborted as one comes
        while another runs. rclpy's client loses an answer that its executor
        takes before ``send_goal_async`` has filed the request ("Ignoring
        unexpected goal response"; a goal waiting for subscribers, sent again
        after 10 s, so ended at once in CI). A goal whose feedback came, or
        that the server lists on its status topic, is running: it is taken by
        its id, not sent again.
        """
        action_type = messages.message_class(action.type)
        key = (action_type, f"{node}/{action.name}")
        listed = self._listed_goals(key[1])
        if key not in self._clients:
            self._clients[key] = ActionClient(self.node, action_type, key[1])
        client = self._clients[key]
        assert client.wait_for_server(timeout_sec=timeout), f"{key[1]} not available"
        goal = Goal()
        sent, running = [], []

        def send():
            goal_id = UUID(uuid=list(uuid4().bytes))

            def feedback(message, goal_id=goal_id):
                running.append(goal_id)
                goal.feedback.append(message.feedback)
            sent.append(goal_id)
            return client.send_goal_async(action_type.Goal(**fields), feedback_callback=feedback,
                                          goal_uuid=goal_id)
        futures = [send()]
        end = time.monotonic() + timeout
        resend = time.monotonic() + ANSWER
        lost = []  # sent goals whose answer is overdue but that the server lists
        while not any(f.done() for f in futures) and not running and not lost:
            assert time.monotonic() < end, f"{key[1]} did not answer"
            if time.monotonic() > resend:
                lost = [g for g in sent if bytes(g.uuid) in listed]
                if not lost:
                    futures.append(send())
                resend = time.monotonic() + ANSWER
            time.sleep(0.02)
        answered = [f for f in futures if f.done()]
        if answered:
            goal.start(answered[0].result())
        else:  # its answer was lost: the goal its feedback or the server's status names
            accepted = action_type.Impl.SendGoalService.Response(accepted=True)
            goal.start(ClientGoalHandle(client, (running or lost)[0], accepted))
        return goal

    def start_goal(self, action: contract.Service, node: str, **fields) -> "Goal":
        """A goal that has started (its first feedback came) or ended, sent again
        while it is aborted because the model has not reached ``node`` yet."""
        goals = []

        def attempt():
            goals.append(self.send_goal(action, node, **fields))
            wait_for(lambda: goals[-1].feedback or goals[-1].done(), what="the goal to start")
            return not goals[-1].done() or "no model" not in goals[-1].result().message
        wait_for(attempt, timeout=60, what=f"the model to reach {node}")
        return goals[-1]

    def close(self):
        self._closing.set()
        self._thread.join(timeout=5.0)
        self.executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)


def _answered(send, timeout, what):
    """The future of ``send()``, sent again every ANSWER s until one is answered
    (at most ``timeout`` s)."""
    end = time.monotonic() + timeout
    while True:
        future = send()
        done = threading.Event()
        future.add_done_callback(lambda _: done.set())
        if done.wait(max(0.0, min(ANSWER, end - time.monotonic()))):
            return future
        assert time.monotonic() < end, f"{what} did not answer"


class Goal:
    """An accepted action goal: its feedback so far and its result."""

    def __init__(self):
        self.feedback = []
        self.handle = self._result = None
        self._done = threading.Event()

    def start(self, handle):
        assert handle.accepted, "goal rejected"
        self.handle = handle
        self._result = handle.get_result_async()
        self._result.add_done_callback(lambda _: self._done.set())

    def done(self) -> bool:
        return self._done.is_set()

    def result(self, timeout=120.0):
        """The goal's result message (waits up to ``timeout`` s)."""
        assert self._done.wait(timeout), "no result"
        return self._result.result().result

    @property
    def status(self) -> int:
        """action_msgs/GoalStatus of the ended goal (4 succeeded, 5 canceled, 6 aborted)."""
        assert self._done.is_set()
        return self._result.result().status

    def cancel(self, timeout=30.0):
        done = threading.Event()
        future = self.handle.cancel_goal_async()
        future.add_done_callback(lambda _: done.set())
        assert done.wait(timeout), "the cancel was not answered"
        return future.result()


class NodeProcess:
    """A node executable run as its own process with ``--ros-args``."""

    def __init__(self, name, *params, node_name=None, namespace=None, params_file=None,
                 remaps=()):
        args = [executable(name), "--ros-args"]
        for p in params:
            args += ["-p", p]
        for rule in remaps:
            args += ["-r", ":=".join(rule)]
        if node_name:  # a name of its own, to tell this process from others of its kind
            args += ["-r", f"__node:={node_name}"]
        if namespace:
            args += ["-r", f"__ns:={namespace}"]
        if params_file:
            args += ["--params-file", str(params_file)]
        self.proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                     text=True, env=os.environ.copy())

    def stop(self, sig=signal.SIGINT, timeout=10.0):
        """Send ``sig``; return (exit code, seconds it took, stderr)."""
        start = time.monotonic()
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
        try:
            _, err = self.proc.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            _, err = self.proc.communicate()
        return self.proc.returncode, time.monotonic() - start, err
