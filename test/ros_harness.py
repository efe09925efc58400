"""A test client for the node tests: one rclpy context, an executor thread,
node executables started as processes the way ``ros2 run`` starts them."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import rclpy
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node
from std_srvs.srv import Trigger

from panel_deploy import contract
from panel_deploy.nodes import messages

BIN = Path(sys.executable).parent


def executable(name: str) -> str:
    path = BIN / name
    assert path.exists(), f"{name} is not installed next to {sys.executable}"
    return str(path)


def wait_for(condition, timeout=60.0, what="condition"):
    end = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > end:
            raise AssertionError(f"timed out after {timeout} s waiting for {what}")
        time.sleep(0.02)


def checked_samples(diagnostics, count, idle=5.0, status="/collision_monitor") -> int:
    """The samples the monitor's verdicts on ``diagnostics`` (a :meth:`Client.listen` list)
    say it checked, once that reaches ``count`` or has not moved for ``idle`` s."""
    def checked():
        return max([int(kv.value) for d in list(diagnostics) for s in d.status for kv in s.values
                    if kv.key == "samples" and s.name == status] or [0])

    seen, still = -1, time.monotonic()
    while checked() < count and time.monotonic() - still < idle:
        if checked() != seen:
            seen, still = checked(), time.monotonic()
        time.sleep(0.02)
    return checked()


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
        self._closing = threading.Event()
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()

    def _spin(self):
        while not self._closing.is_set():
            self.executor.spin_once(timeout_sec=0.05)

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
        future = client.call_async(request if request is not None else srv_type.Request())
        done = threading.Event()
        future.add_done_callback(lambda _: done.set())
        assert done.wait(timeout), f"{service} did not answer"
        return future.result()

    def has_node(self, name):
        return name in self.node.get_node_names()

    def trigger(self, service):
        return self.call(Trigger, service)

    def close(self):
        self._closing.set()
        self._thread.join(timeout=5.0)
        self.executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)


class NodeProcess:
    """A node executable run as its own process with ``--ros-args``."""

    def __init__(self, name, *params, node_name=None, namespace=None, params_file=None):
        args = [executable(name), "--ros-args"]
        for p in params:
            args += ["-p", p]
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
