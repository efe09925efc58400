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
from rcl_interfaces.msg import (FloatingPointRange, IntegerRange, ParameterDescriptor,
                                ParameterType, SetParametersResult)
from rclpy.exceptions import ParameterUninitializedException
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.signals import SignalHandlerOptions
from rclpy.task import Future
from std_srvs.srv import Trigger

from .. import contract
from ..errors import PanelDeployError, SceneError, shown
from ..scene_text import scene_from_yaml
from . import messages


def declare(node, parameters: dict, check=None) -> None:
    """Declare ``{name: (default, description[, (low, high)])}``, then set the
    values given at start (command line, params file, overrides) through the
    checks of a later set: type, range, then ``check`` (see :func:`_validator`).

    A default given as a ``Parameter.Type`` declares an array of that type
    whose value is empty (``get_parameters`` and ``ros2 param dump`` then
    answer for it too). ``(low, high)`` becomes the descriptor's range, so
    ``ros2 param describe`` shows it. An integer (array) given for a double
    (array) is taken as doubles, at start and on set: ``-p rate_hz:=500`` and
    ``ros2 param set`` send integers for whole numbers.

    Raises
    ------
    SceneError
        A value given at start that a set would refuse, naming the parameter.
    """
    given = []
    for name, (default, description, *bounds) in parameters.items():
        # Declared once untyped to read the start value whatever its type,
        # which a typed declaration would refuse with a traceback.
        value = node.declare_parameter(name, None, ParameterDescriptor(dynamic_typing=True)).value
        node.undeclare_parameter(name)
        node.declare_parameter(name, default, _descriptor(default, description, *bounds),
                               ignore_override=True)
        if value is not None:
            given.append(Parameter(name, value=value))
        elif isinstance(default, Parameter.Type):  # an empty list alone would be typed bytes
            node.set_parameters([Parameter(name, default, [])])
    node.add_pre_set_parameters_callback(lambda params: [_coerced(node, p) for p in params])
    if check is not None:
        _validator(node, check)
    given = [_coerced(node, p) for p in given]
    for p in given:  # rclpy's reason for a wrong type does not name the parameter
        expected = node.describe_parameter(p.name).type
        if p.type_.value != expected:
            raise SceneError(p.name, f"expected {_TYPE_NAMES.get(expected, 'another type')}, "
                                     f"got {shown(p.value)}")
    if given:
        result = node.set_parameters_atomically(given)
        if not result.successful:
            raise SceneError("", result.reason)


_TYPE_NAMES = {ParameterType.PARAMETER_BOOL: "true or false",
               ParameterType.PARAMETER_INTEGER: "an integer",
               ParameterType.PARAMETER_DOUBLE: "a number",
               ParameterType.PARAMETER_STRING: "a string",
               ParameterType.PARAMETER_DOUBLE_ARRAY: "a list of numbers"}


def _descriptor(default, description, bounds=None) -> ParameterDescriptor:
    descriptor = ParameterDescriptor(description=description)
    if bounds is not None:
        low, high = bounds
        if isinstance(default, float):
            descriptor.floating_point_range = [FloatingPointRange(
                from_value=float(low), to_value=float(high), step=0.0)]
        else:
            descriptor.integer_range = [IntegerRange(from_value=low, to_value=high, step=1)]
    return descriptor


def _coerced(node, p: Parameter) -> Parameter:
    """``p`` with integers as doubles where the declared type is double (array)."""
    if not node.has_parameter(p.name):
        return p
    expected = node.describe_parameter(p.name).type
    if expected == ParameterType.PARAMETER_DOUBLE and p.type_ == Parameter.Type.INTEGER:
        return Parameter(p.name, Parameter.Type.DOUBLE, float(p.value))
    if (expected == ParameterType.PARAMETER_DOUBLE_ARRAY
            and p.type_ == Parameter.Type.INTEGER_ARRAY):
        return Parameter(p.name, Parameter.Type.DOUBLE_ARRAY, [float(v) for v in p.value])
    return p


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


def publisher(node, topic: contract.Topic):
    """``node``'s publisher of a contract topic, with the contract's type and QoS."""
    return node.create_publisher(messages.message_class(topic.type), topic.name,
                                 messages.qos(topic.qos))


def subscription(node, topic: contract.Topic, callback, **kwargs):
    """``node``'s subscription to a contract topic, with the contract's type and QoS."""
    return node.create_subscription(messages.message_class(topic.type), topic.name, callback,
                                    messages.qos(topic.qos), **kwargs)


#: The parameter that puts a prefix before every frame a node sends (``array1/``).
FRAME_PREFIX = "frame_prefix"
FRAME_PREFIX_DOC = ("prefix of every frame on /tf, /tf_static and the markers (like "
                    "robot_state_publisher's): two arrays side by side, e.g. 'array1/'")


def check_frame_prefix(changes) -> None:
    """Refuse a ``frame_prefix`` among ``changes`` that tf2 frames cannot start with."""
    prefix = changes.get(FRAME_PREFIX, "")
    if prefix.startswith("/") or any(c.isspace() for c in prefix):
        raise PanelDeployError(f"{FRAME_PREFIX}: {shown(prefix)}: tf2 frames start with no '/' "
                               "and hold no spaces")


def trigger_service(node, service: contract.Service, callback):
    """``node``'s ``std_srvs/Trigger`` service of the contract (``~/`` + its name),
    whose callback cannot leave a caller without an answer: an unexpected
    error becomes ``success=False`` with its message, and is logged."""
    name = f"~/{service.name}"

    def guarded(request, response):
        try:
            return callback(request, response)
        except Exception as e:  # the node lives on; the caller learns why
            node.get_logger().error(f"{name} failed: {type(e).__name__}: {e}")
            response.success, response.message = False, f"failed: {type(e).__name__}: {e}"
            return response
    return node.create_service(Trigger, name, guarded)


def _validator(node, check):
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
    """A node that follows ``panel_deploy/model`` and serves one long job at a
    time (a deployment, a search) as an action: each goal runs in a thread of
    its own, so that the executor goes on serving while it runs."""

    def __init__(self, name, **kwargs):
        super().__init__(name, **kwargs)
        self.scene = None  # the last valid scene received
        self._worker = None
        subscription(self, contract.MODEL, self._on_model)

    def _on_model(self, msg):
        try:
            self.scene = scene_from_yaml(msg.data)
        except PanelDeployError as e:
            self.get_logger().warning(f"ignored a model: {e}")

    @property
    def running(self) -> bool:
        return self._worker is not None and self._worker.is_alive()

    def action_server(self, action: contract.Service, start, cancel, report):
        """The contract's ``action`` (``~/`` + its name). Every goal is accepted;
        ``start(goal)`` returns ``(target, args)`` to run in the worker thread,
        whose return value is the goal's result, or raises a PanelDeployError
        whose message aborts the goal (the caller learns why, unlike a
        rejection). A goal that comes while one runs, or before a model, is
        aborted so too. ``cancel()`` asks the running job to end early. An
        exception in the job ends it, not the node: it is logged, aborts the
        goal and goes out as an ERROR status on ``report`` (a DiagnosticArray
        publisher) for diagnostics tools; the next goal runs."""
        from rclpy.action import ActionServer, CancelResponse

        result_type = messages.message_class(action.type).Result
        job = f"~/{action.name}"

        async def execute(goal_handle):
            try:
                if self.running:
                    raise PanelDeployError(f"{job} is running: cancel its goal first")
                if self.scene is None:
                    raise PanelDeployError("no model yet on " +
                                           self.resolve_topic_name(contract.MODEL.name))
                target, args = start(goal_handle)
            except PanelDeployError as e:
                goal_handle.abort()
                return result_type(success=False, message=str(e))
            done = Future()

            def guarded():
                try:
                    done.set_result(target(goal_handle, *args))
                except Exception as e:  # the job ends, not the node: the caller learns why
                    text = f"{job} failed: {type(e).__name__}: {e}"
                    self.get_logger().error(text)
                    report.publish(messages.diagnostics(
                        self.get_clock().now().nanoseconds * 1e-9,
                        messages.status(self.get_fully_qualified_name(), messages.ERROR, text)))
                    done.set_result(result_type(success=False, message=text))
            self._worker = threading.Thread(target=guarded, daemon=True)
            self._worker.start()
            result = await done
            if goal_handle.is_cancel_requested:
                goal_handle.canceled()
            elif result.success:
                goal_handle.succeed()
            else:
                goal_handle.abort()
            return result

        def on_cancel(goal_handle):
            cancel()
            return CancelResponse.ACCEPT
        return ActionServer(self, messages.message_class(action.type), f"~/{action.name}",
                            execute, cancel_callback=on_cancel)


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
        _spin_while(executor, nodes[0], lambda: not stop.is_set())
    finally:
        # Workers are stopped and joined while the executor still spins: one
        # may be waiting on a service answer or a callback to end its job.
        closing = threading.Thread(target=_close, args=(nodes,), daemon=True)
        closing.start()
        _spin_while(executor, nodes[0], closing.is_alive)
        executor.shutdown(timeout_sec=2.0)
        for node in nodes:
            node.destroy_node()


def _spin_while(executor, node, condition) -> None:
    while condition() and rclpy.ok():
        try:
            executor.spin_once(timeout_sec=0.05)
        except Exception as e:  # a failing callback must not take the node down
            node.get_logger().error(f"callback failed: {type(e).__name__}: {e}")


def _close(nodes) -> None:
    for node in nodes:
        close = getattr(node, "close", None)
        if close is not None:
            close()


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


def _ros_args_error(e) -> str:
    """One line of rcl's refusal of the command line's ``--ros-args`` (a remap
    rule it cannot parse, a name that is no ROS name): rclpy's message runs to
    several lines with a caret and rcl's source positions."""
    text = str(e).replace("failed to initialize rcl: ", "")
    return _printable(text.split(". Error:")[0].split(", at /")[0].splitlines()[0])


def _printable(text: str, limit: int = 160) -> str:
    """``text`` on one line (control characters escaped), at most ``limit`` characters."""
    text = "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)
    return text if len(text) <= limit else text[:limit - 3] + "..."


def _check_remaps(argv) -> None:
    """The node's name and namespace remaps (``-r __ns:=/array1``, ``-r __node:=x``)
    checked as ROS names before rcl parses them (rcl logs its own lines first)."""
    from rclpy.validate_namespace import validate_namespace
    from rclpy.validate_node_name import validate_node_name

    args = list(argv)
    for i, arg in enumerate(args[:-1]):
        if arg not in ("-r", "--remap"):
            continue
        rule = args[i + 1].split(":", 1)[1] if args[i + 1].count(":=") and \
            args[i + 1].split(":=")[0].count(":") else args[i + 1]
        key, _, value = rule.partition(":=")
        check = {"__ns": validate_namespace, "__node": validate_node_name}.get(key)
        if check is None:
            continue
        try:
            check(value)
        except Exception as e:  # rclpy's message is three lines with a caret
            reason = str(e).splitlines()[0].split(": ", 1)[-1].rstrip(":")
            raise SceneError("--ros-args", f"-r {_printable(args[i + 1])}: {reason}") from None


def node_main(make_node, argv=None) -> int:
    """Body of a node executable: start, build the node, spin until a signal; exit code."""
    from rclpy.exceptions import InvalidNamespaceException, InvalidNodeNameException
    from rclpy.impl.implementation_singleton import rclpy_implementation

    refused = (rclpy_implementation.RCLError, InvalidNamespaceException, InvalidNodeNameException)
    try:
        _check_remaps(sys.argv if argv is None else argv)
        stop = start(argv)
    except PanelDeployError as e:
        print(f"panel-deploy: error: {e}", file=sys.stderr)
        return 2
    except refused as e:
        print(f"panel-deploy: error: --ros-args: {_ros_args_error(e)}", file=sys.stderr)
        return 2
    try:
        node = make_node()
    except PanelDeployError as e:
        print(f"panel-deploy: error: {e}", file=sys.stderr)
        rclpy.try_shutdown()
        return 2
    except refused as e:
        print(f"panel-deploy: error: --ros-args: {_ros_args_error(e)}", file=sys.stderr)
        rclpy.try_shutdown()
        return 2
    try:
        spin([node], stop)
    finally:
        rclpy.try_shutdown()
    return 0
