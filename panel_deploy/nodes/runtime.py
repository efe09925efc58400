"""How every node starts, declares its parameters and stops.

Signals: rclpy's own SIGINT handler makes ``rclpy.spin`` raise
``ExternalShutdownException`` with a traceback, and races with shutdown; we
install our own SIGINT/SIGTERM handlers that only set a flag, and spin in a
``spin_once`` loop that checks it, so Ctrl-C and a service manager's SIGTERM
end a node with exit code 0 and no traceback.
"""

from __future__ import annotations

import signal
import sys
import threading

import rclpy
from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
from rclpy.exceptions import ParameterUninitializedException
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.signals import SignalHandlerOptions
from std_msgs.msg import String
from std_srvs.srv import Trigger

from ..errors import PanelDeployError
from ..live import scene_from_yaml
from . import messages

#: ROS parameter type of each Python default.
_TYPES = {bool: Parameter.Type.BOOL, int: Parameter.Type.INTEGER,
          float: Parameter.Type.DOUBLE, str: Parameter.Type.STRING}


def declare(node, parameters: dict) -> None:
    """Declare ``{name: (default, description)}``; a default given as a
    ``Parameter.Type`` declares an array without a value (read as empty)."""
    for name, (default, description) in parameters.items():
        node.declare_parameter(name, default, ParameterDescriptor(description=description))


def values(node, names) -> dict:
    """Current values of parameters; an unset array parameter reads as ``()``."""
    out = {}
    for name in names:
        try:
            out[name] = _plain(node.get_parameter(name).value)
        except ParameterUninitializedException:
            out[name] = ()
    return out


def _plain(value):
    """Array parameter values (rclpy gives ``array.array``) as tuples."""
    return value if isinstance(value, (str, bytes)) or not hasattr(value, "__len__") else tuple(value)


def trigger_service(node, name, callback):
    """A ``std_srvs/Trigger`` service whose callback cannot leave a caller
    without an answer: an unexpected error becomes ``success=False`` with
    its message, and is logged."""
    def guarded(request, response):
        try:
            return callback(request, response)
        except Exception as e:  # the node lives on; the caller learns why
            node.get_logger().error(f"{name} failed: {type(e).__name__}: {e}")
            response.success, response.message = False, f"failed: {type(e).__name__}: {e}"
            return response
    return node.create_service(Trigger, name, guarded)


def validator(node, check):
    """An on-set callback: ``check(changes)`` with ``{name: value}`` of the
    parameters being set raises a :class:`PanelDeployError` to refuse them,
    whose message reaches the caller as the reason."""
    def callback(params):
        try:
            check({p.name: _plain(p.value) for p in params})
        except PanelDeployError as e:
            return SetParametersResult(successful=False, reason=str(e))
        except Exception as e:  # a bug must not accept a value unchecked
            return SetParametersResult(successful=False, reason=f"{type(e).__name__}: {e}")
        return SetParametersResult(successful=True)
    node.add_on_set_parameters_callback(callback)


class WorkerNode(Node):
    """A node that follows ``/panel_deploy/model`` and runs one long job at a
    time (a deployment, a search) in a thread of its own, so that its
    services answer at once."""

    def __init__(self, name, **kwargs):
        super().__init__(name, **kwargs)
        self.scene = None  # the last valid scene received
        self._worker = None
        self.create_subscription(String, "/panel_deploy/model", self._on_model, messages.LATCHED)

    def _on_model(self, msg):
        try:
            self.scene = scene_from_yaml(msg.data)
        except PanelDeployError as e:
            self.get_logger().warning(f"ignored a model: {e}")

    @property
    def running(self) -> bool:
        return self._worker is not None and self._worker.is_alive()

    def busy(self, response, job: str, stop: str) -> bool:
        """Refuse in ``response`` (and return True) while ``job`` runs or before a model came."""
        if self.running:
            response.success, response.message = False, f"{job} is running; {stop} it first"
        elif self.scene is None:
            response.success, response.message = False, "no model yet on /panel_deploy/model"
        else:
            return False
        return True

    def start_job(self, target, *args) -> None:
        self._worker = threading.Thread(target=target, args=args, daemon=True)
        self._worker.start()


def spin(nodes, stop: threading.Event) -> None:
    """Run ``nodes`` on one executor until ``stop`` is set.

    Single-threaded: no callback waits on another (long work and service
    calls run in the nodes' own worker threads), and a thread pool doubled
    the collision monitor's time per message.
    """
    executor = SingleThreadedExecutor()
    for node in nodes:
        executor.add_node(node)
    try:
        while not stop.is_set() and rclpy.ok():
            try:
                executor.spin_once(timeout_sec=0.05)
            except Exception as e:  # a failing callback must not take the node down
                nodes[0].get_logger().error(f"callback failed: {type(e).__name__}: {e}")
    finally:
        for node in nodes:
            close = getattr(node, "close", None)
            if close is not None:
                close()
        executor.shutdown(timeout_sec=2.0)
        for node in nodes:
            node.destroy_node()


def start(argv=None) -> threading.Event:
    """Initialise rclpy with ``argv`` (``--ros-args`` included) and our signal
    handlers; the returned event is set by SIGINT or SIGTERM."""
    rclpy.init(args=sys.argv if argv is None else argv,
               signal_handler_options=SignalHandlerOptions.NO)
    stop = threading.Event()
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, lambda *_: stop.set())
    return stop


def node_main(make_node, argv=None) -> int:
    """Body of a node executable: start, build the node, spin until a signal; exit code."""
    stop = start(argv)
    try:
        node = make_node()
    except PanelDeployError as e:
        print(f"panel-deploy: error: {e}", file=sys.stderr)
        rclpy.try_shutdown()
        return 2
    try:
        spin([node], stop)
    finally:
        rclpy.try_shutdown()
    return 0
