"""``panel-deploy``: the one command-line entry point; runs every main job without ROS.

The CLI layer: this package reads the command line and wires scene -> model
-> simulation -> collision -> optimisation together, one module per
subcommand; the library it calls takes typed parameters, never an argparse
namespace. Misuse (bad scene, bad arguments) prints one line
``panel-deploy: error: <key path>: <what was wrong>`` and exits with code 2,
checked before any work starts (:mod:`panel_deploy.cli.checks`).
"""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import sys
import threading

from ..errors import PanelDeployError, shown
from .args import add_compare, add_set, alias


def _command(module: str, name: str):
    """The subcommand ``name`` of ``panel_deploy.cli.<module>``, imported when it runs
    (a command's imports, numba's among them, cost only that command)."""
    def run(args):
        from importlib import import_module
        return getattr(import_module(f"{__name__}.{module}"), name)(args)
    return run


def _schema(args):
    from ..scene import describe_schema
    print(describe_schema())
    return 0


def _stiffness_list(text):
    try:
        values = [float(x) for x in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected numbers separated by commas, got {shown(text)}") from None
    if not values or any(not 0 < v < float("inf") for v in values):
        raise argparse.ArgumentTypeError(f"expected finite stiffnesses > 0 N m/rad, got {shown(text)}")
    return values


#: Control characters as Python writes them in a string's repr (``\n``, ``\x1b``):
#: a key or path holding one stays on the error's one line, and a terminal
#: escape in it is shown, not obeyed.
_ESCAPES = {c: repr(chr(c))[1:-1] for c in (*range(32), 127)}


def error_line(message, prog: str = "panel-deploy") -> str:
    """The one line ``<prog>: error: <message>`` (no newline at its end)."""
    return f"{prog}: error: {str(message).translate(_ESCAPES)}"


class _Parser(argparse.ArgumentParser):
    """argparse with its errors as the one line every other error is (no usage block)."""

    def error(self, message):
        self.exit(2, error_line(message, self.prog) + "\n")


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="panel-deploy", description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="command", required=True)

    s = sub.add_parser("schema", help="print the scene schema (keys, types, units, defaults)")
    s.set_defaults(func=_schema)

    s = sub.add_parser("fold", help="Hamiltonian circuits, two-stack packing, merging, DoF")
    s.add_argument("--rows", type=int)
    s.add_argument("--cols", type=int)
    s.add_argument("--scene", help="work on the design of a scene file")
    s.add_argument("--circuit", type=int, help="only this circuit index")
    s.add_argument("--limit", type=int, help="list at most this many circuits (default 50)")
    s.add_argument("--json", action="store_true", help="machine-readable output")
    s.add_argument("--plot", metavar="FILE.png", help="draw the design and its stacks")
    s.add_argument("--rank", action="store_true",
                   help="with --scene: rank the first packing circuits by a screening run of "
                        "each (what fold.circuit: auto chooses from)")
    alias(s, "--candidates", "screening.candidates", metavar="N",
          help="with --rank: screen at most N packing circuits (default: the scene's "
               "screening.candidates)")
    alias(s, "--screen-t-end", "screening.t_end", metavar="T",
          help="with --rank: screening end time, s (default: the scene's screening.t_end; "
               "at most simulation.t_end): long enough to see slow deployments lie flat")
    alias(s, "--workers", "optimisation.workers", metavar="N",
          help="with --rank: screen on N local processes (default: the scene's "
               "optimisation.workers; 0: all cores)")
    s.add_argument("--dask", metavar="ADDRESS", help="with --rank: screen on this Dask scheduler")
    add_set(s)
    s.set_defaults(func=_command("fold", "fold_command"))

    s = sub.add_parser("simulate", help="simulate one deployment and check it for collisions")
    s.add_argument("scene", help="scene YAML file, or the name of a shipped scene")
    s.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    s.add_argument("--out", metavar="FILE.npz", help="save the sampled trajectory")
    s.add_argument("--record", metavar="FILE.mcap",
                   help="record the deployment as it is computed (ROS 2 MCAP: ros2 bag, Foxglove, rerun)")
    s.add_argument("--stiffness", metavar="RESULT.yaml", help="hinge stiffnesses from an optimisation result")
    alias(s, "--method", "simulation.method")
    alias(s, "--closure", "closure.method")
    alias(s, "--t-end", "simulation.t_end")
    add_set(s)
    s.set_defaults(func=_command("simulate", "simulate_command"))

    s = sub.add_parser("run", help="the ROS 2 node graph in one process: deploy (and optimise) live")
    s.add_argument("scene", help="scene YAML file, or the name of a shipped scene")
    s.add_argument("--optimise", action="store_true",
                   help="optimise the stiffness first, then deploy with the result")
    s.add_argument("--real-time-factor", type=float, default=1.0,
                   help="simulated seconds per wall second (0: as fast as computed)")
    s.add_argument("--rate", type=float, default=200.0, help="joint states per simulated second")
    s.add_argument("--record", metavar="FILE.mcap",
                   help="record the graph's topics (and /tf) to MCAP, as ros2 bag record would")
    s.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    s.add_argument("--namespace", default="",
                   help="ROS namespace of the nodes (e.g. array1: /array1/joint_states), so that "
                        "graphs of several arrays run side by side")
    add_set(s)
    s.set_defaults(func=_command("run", "run_command"))

    s = sub.add_parser("collide", help="collision check of a saved trajectory or a recording")
    s.add_argument("trajectory", help="trajectory .npz written by simulate --out, or an MCAP "
                                      "recording (its /joint_states)")
    s.add_argument("--scene", help="the recording's scene (file or shipped name); default: "
                                   "the one it ran")
    s.add_argument("--namespace", help="the array whose joint states to check, in a recording "
                                       "of several (e.g. array1)")
    add_compare(s, "also check this scene's deployment on the recording's times (e.g. a "
                   "calibrated scene: its first collision beside the recorded one)")
    s.add_argument("--json", action="store_true")
    add_set(s)
    s.set_defaults(func=_command("collide", "collide_command"))

    s = sub.add_parser("optimise", help="hinge stiffnesses for a collision-free deployment (Eq. 8)")
    s.add_argument("scene")
    s.add_argument("--out", metavar="RESULT.yaml", help="result file (default: print it)")
    s.add_argument("--record", metavar="FILE.mcap", help="record the deployment of the result (needs --out)")
    alias(s, "--workers", "optimisation.workers")
    s.add_argument("--dask", metavar="ADDRESS", help="run evaluations on this Dask scheduler")
    alias(s, "--method", "optimisation.method")
    alias(s, "--max-evaluations", "optimisation.max_evaluations")
    s.add_argument("--start", metavar="RESULT.yaml",
                   help="start from this result's K instead of optimisation.k0")
    s.add_argument("--springs", type=_stiffness_list,
                   help="available spring stiffnesses, N m/rad, comma-separated")
    s.add_argument("--perturb", type=int, default=0, help="tolerance check: perturbed copies")
    s.add_argument("--perturb-tol", type=float,
                   help="relative spread of k and c (default 0.05, with --perturb)")
    s.add_argument("--quiet", action="store_true", help="no progress lines")
    s.add_argument("--json", action="store_true", help="print the result as JSON")
    add_set(s)
    s.set_defaults(func=_command("optimise", "optimise_command"))

    s = sub.add_parser("replay", help="replay a recording in rerun, or render it as a PNG strip")
    s.add_argument("recording", help="MCAP recording (simulate --record, run --record, ros2 bag record)")
    view = s.add_mutually_exclusive_group()
    view.add_argument("--save", metavar="OUT.rrd", help="write a rerun recording file")
    view.add_argument("--spawn", action="store_true", help="open the rerun viewer")
    view.add_argument("--serve", action="store_true",
                      help="serve to rerun viewers on 127.0.0.1 (rerun rerun+http://127.0.0.1:PORT/proxy)")
    s.add_argument("--port", type=int, default=9876, help="port of --serve")
    s.add_argument("--png", metavar="STRIP.png", help="render frames at --at into one image")
    s.add_argument("--at", default="0,0.1,0.2,0.3,0.4", metavar="T,T,...",
                   help="instants of the --png frames, s")
    s.add_argument("--scene", help="the recording's scene (file or shipped name); default: "
                                   "the one it ran")
    s.add_argument("--namespace", help="the array to show, in a recording of several (e.g. array1)")
    add_compare(s, "also show this scene's simulated deployment at the same times (e.g. a "
                   "calibrated scene beside the deployment it was fitted to)")
    s.set_defaults(func=_command("replay", "replay_command"))

    s = sub.add_parser("calibrate", help="fit hinge damping, stiffness and air drag to recorded "
                                         "deployments, or damping to free-vibration tests; write "
                                         "the calibrated scene")
    s.add_argument("recordings", nargs="*", metavar="RECORDING",
                   help="MCAP recordings of deployments of the same array (their /joint_states)")
    s.add_argument("--free-vibration", nargs="+", metavar="RECORDING.mcap",
                   help="instead: recordings of one panel swinging on one hinge: c and k per "
                        "test (log decrement and fit) and pooled")
    s.add_argument("--scene", help="the scene to calibrate and write (file or shipped name); "
                                   "default: the one the first recording ran (free vibration: "
                                   "its rig)")
    s.add_argument("--out", metavar="CALIBRATED.yaml",
                   help="the scene with the fitted values and a calibration section (needed "
                        "for deployments)")
    s.add_argument("--fit", metavar="KIND,KIND",
                   help="deployments: what to fit, comma-separated: damping, stiffness, drag "
                        "(default damping,stiffness; drag needs air.density > 0)")
    s.add_argument("--per", metavar="scale|group",
                   help="deployments: scale: one factor on every hinge's k and c (the c/k "
                        "becomes hinges.damping_ratio); group: one per stiffness group")
    s.add_argument("--plot", metavar="FILE.png",
                   help="deployments: measured vs nominal vs fitted angles, residuals")
    s.add_argument("--until", type=float, metavar="SECONDS",
                   help="deployments: fit only the joint states up to this long after each "
                        "recording's first stamp (e.g. up to the first collision)")
    s.add_argument("--max-evaluations", type=int,
                   help="deployments: residual evaluations of the fit at most (each iteration: "
                        "one, plus a Jacobian of one simulation per parameter; default 50)")
    s.add_argument("--quiet", action="store_true", help="deployments: no progress lines")
    s.add_argument("--rig", dest="rig_scene", metavar="SCENE",
                   help="free vibration: the rig's scene (one panel on one hinge), for "
                        "recordings that carry none")
    s.add_argument("--hinge", help="free vibration: set this hinge's damping_overrides entry to c "
                                   "instead of the scene's damping_ratio to c/k")
    s.add_argument("--json", action="store_true",
                   help="free vibration: print the calibration as one JSON object")
    s.add_argument("--namespace", help="the array whose joint states to read (e.g. array1)")
    add_set(s)
    s.set_defaults(func=_command("calibrate", "calibrate_command"))

    s = sub.add_parser("export", help="export the model (MuJoCo MJCF)")
    s.add_argument("scene")
    s.add_argument("--mjcf", metavar="FILE.xml", required=True)
    add_set(s)
    s.set_defaults(func=_command("export", "export_command"))

    s = sub.add_parser("bench", help="benchmarks")
    bsub = s.add_subparsers(dest="bench", required=True)
    b = bsub.add_parser("work-precision", help="error against run time, every integrator and MuJoCo")
    b.add_argument("scene")
    b.add_argument("--out", default="work_precision.csv", help="CSV file")
    b.add_argument("--plot", default="work_precision.png", help="log-log plot")
    b.add_argument("--repeats", type=int, default=3)
    b.add_argument("--quick", action="store_true", help="fewer tolerances and steps (< 2 min)")
    add_set(b)
    b.set_defaults(func=_command("bench", "work_precision_command"))
    return p


#: Code in which an interrupt is deferred instead of raised: numba and llvmlite
#: load the kernels through C callbacks that do not check for errors (raised
#: there, a KeyboardInterrupt became a SystemError, a segfault, or a C
#: extension's "ImportError: initialization failed"), and importlib, whose
#: imports run those extensions' initialisation.
DEFERRED_IN = ("numba", "llvmlite", "importlib")
#: How often a deferred interrupt looks again whether it may be raised, s.
RETRY_S = 0.01


def deferring(frame) -> bool:
    """Whether ``frame`` or one of its callers is code of :data:`DEFERRED_IN`,
    or a string run by ``exec``: CPython 3.11 marks a KeyboardInterrupt raised
    in one (rosbags compiles its serialisers so) as unhandled even when caught,
    and the process then ends killed by SIGINT instead of with its exit code.
    Strings run in ``__main__`` are the program itself, not such code:
    ``python -c``'s, and what it execs there (execnet's bootstrap, under
    which every test of a pytest-xdist worker runs)."""
    while frame is not None:
        code = frame.f_code
        name = frame.f_globals.get("__name__", "")
        if name.partition(".")[0] in DEFERRED_IN or (
                code.co_filename == "<string>" and code.co_name == "<module>"
                and name != "__main__"):
            return True
        frame = frame.f_back
    return False


class Interrupts:
    """SIGINT and SIGTERM as a KeyboardInterrupt, raised only where that is safe.

    In code of :data:`DEFERRED_IN` the signal is noted and looked at again
    every :data:`RETRY_S` (SIGALRM, so no thread is started inside a
    signal handler) until the interpreter is back in other code. Once the
    command is over (:attr:`over`), a signal only waits for the exit under way.

    The KeyboardInterrupt is raised once: a repeated signal does not interrupt
    the command's winding up (the optimiser writing its best K). timeout(1)
    sends its SIGTERM to the command and again to its process group, and the
    second one, raised while the worker pool shut down, lost the result file
    in 4 of 10 runs.
    """

    SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGALRM)

    def __init__(self):
        self.received = None  # the first SIGINT or SIGTERM
        self.raised = False
        self.over = False
        self.previous = {}

    def __call__(self, signum, frame):
        if signum != signal.SIGALRM and self.received is None:
            self.received = signum
        if self.received is None or self.over or self.raised:
            return
        if deferring(frame):
            signal.setitimer(signal.ITIMER_REAL, RETRY_S)
            return
        self.raised = True
        raise KeyboardInterrupt

    def install(self):
        self.previous = {sig: signal.signal(sig, self) for sig in self.SIGNALS}

    def exiting(self):
        """For a process whose exit is under way: a signal from now on waits
        for it. Ignored, not handled: the interpreter's finalisation puts back
        the default action of every signal with a Python handler, which killed
        a command with a late second SIGTERM (exit -15 instead of its code)."""
        signal.setitimer(signal.ITIMER_REAL, 0)
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, signal.SIG_IGN)

    def restore(self):
        if not self.previous:
            return  # never installed (a thread other than the main one)
        signal.setitimer(signal.ITIMER_REAL, 0)
        for sig, handler in self.previous.items():
            signal.signal(sig, handler)


def main(argv=None) -> int:
    """The ``panel-deploy`` command; ``argv`` None: this process's own command
    line, SIGINT and SIGTERM then ignored until the process exits (a signal
    during the interpreter's exit would otherwise kill it with the exit code
    already decided)."""
    # A service manager's SIGTERM ends a long job like Ctrl-C does: the
    # optimiser then still writes the best K it has.
    interrupts = Interrupts()
    if threading.current_thread() is threading.main_thread():
        interrupts.install()
    try:
        args = build_parser().parse_args(argv)
        from .checks import check_args
        check_args(args)  # every flag and output path, before any work
        if args.stdout_output is None:
            code = args.func(args) or 0
        else:  # a binary streams to standard output: every human line goes to stderr
            with contextlib.redirect_stdout(sys.stderr):
                code = args.func(args) or 0
        if interrupts.received and not interrupts.raised:
            # deferred to the end of the command (kernels loading up to its last moment)
            raise KeyboardInterrupt
        return code
    except PanelDeployError as e:
        print(error_line(e), file=sys.stderr)
        return 2
    except BrokenPipeError:  # output piped into head & co.: not an error of ours
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except KeyboardInterrupt:
        interrupts.over = True
        print("panel-deploy: interrupted", file=sys.stderr)
        return 130
    finally:
        interrupts.over = True
        if argv is not None:
            interrupts.restore()
        elif interrupts.previous:
            interrupts.exiting()
