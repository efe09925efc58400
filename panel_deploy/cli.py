"""``panel-deploy``: the one command-line entry point; runs every main job without ROS.

Each subcommand only wires scene -> model -> simulation -> collision ->
optimisation together. Misuse (bad scene, bad arguments) prints one line
``panel-deploy: error: <key path>: <what was wrong>`` and exits with code 2.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import threading

from .errors import PanelDeployError, SceneError


def _load(args):
    from .scene import load_scene, resolve_scene
    return load_scene(resolve_scene(args.scene), getattr(args, "set", None) or ())


def cmd_schema(args):
    from .scene import describe_schema
    print(describe_schema())
    return 0


def cmd_fold(args):
    from .fold.report import fold_command
    if not args.scene:
        if args.rows is None or args.cols is None:
            raise SceneError("--rows/--cols", "give --rows and --cols, or --scene FILE")
        return fold_command(args)
    import json

    from .build import scene_design
    from .fold.report import design_dict, design_text

    d = scene_design(_load(args))
    print(json.dumps(design_dict(d), indent=1) if args.json else design_text(d))
    if args.plot:
        from .fold.plot import plot_design
        plot_design(d, args.plot)
    return 0 if d.stowed is not None else 1


def cmd_simulate(args):
    from .run import simulate_command
    return simulate_command(args, _load(args))


def cmd_collide(args):
    from .collision import collide_command
    return collide_command(args)


def cmd_optimise(args):
    from .optimise import optimise_command
    if args.record and not args.out:
        raise SceneError("--record", "needs --out RESULT.yaml: the recording deploys the K written there")
    scene = _load(args)
    code = optimise_command(args, scene)
    if args.record and code != 130:
        from .record.deployment import record_optimum
        record_optimum(args.record, scene, args.out)
        print(f"recorded the deployment of {args.out} -> {args.record}", file=sys.stderr)
    return code


def cmd_replay(args):
    from .record.replay import replay_command
    return replay_command(args)


def cmd_export(args):
    from .export import export_command
    return export_command(args, _load(args))


def cmd_bench(args):
    from .bench import work_precision_command
    return work_precision_command(args, _load(args))


def cmd_run(args):
    from .nodes import load
    if not args.rate > 0:
        raise SceneError("--rate", f"expected a rate > 0 Hz, got {args.rate}")
    if not args.real_time_factor >= 0:
        raise SceneError("--real-time-factor", f"expected a number >= 0, got {args.real_time_factor}")
    scene = _load(args)  # a bad scene is one line here, before any node starts
    return load("graph").run_graph(scene, optimise=args.optimise,
                                   real_time_factor=args.real_time_factor, rate_hz=args.rate,
                                   as_json=args.json, record=args.record)


def _stiffness_list(text):
    try:
        values = [float(x) for x in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected numbers separated by commas, got {text!r}") from None
    if not values or any(not 0 < v < float("inf") for v in values):
        raise argparse.ArgumentTypeError(f"expected finite stiffnesses > 0 N m/rad, got {text!r}")
    return values


def _add_set(parser):
    parser.add_argument("--set", action="append", metavar="KEY=VALUE",
                        help="override a scene key, VALUE read as YAML "
                             "(e.g. --set gravity=[0,0,0] --set simulation.t_end=3); repeatable")


class _Parser(argparse.ArgumentParser):
    """argparse with its errors as the one line every other error is (no usage block)."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message}\n")


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="panel-deploy", description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="command", required=True)

    s = sub.add_parser("schema", help="print the scene schema (keys, types, units, defaults)")
    s.set_defaults(func=cmd_schema)

    s = sub.add_parser("fold", help="Hamiltonian circuits, two-stack packing, merging, DoF")
    s.add_argument("--rows", type=int)
    s.add_argument("--cols", type=int)
    s.add_argument("--scene", help="work on the design of a scene file")
    s.add_argument("--circuit", type=int, help="only this circuit index")
    s.add_argument("--limit", type=int, help="list at most this many circuits (default 50)")
    s.add_argument("--json", action="store_true", help="machine-readable output")
    s.add_argument("--plot", metavar="FILE.png", help="draw the design and its stacks")
    _add_set(s)
    s.set_defaults(func=cmd_fold)

    s = sub.add_parser("simulate", help="simulate one deployment and check it for collisions")
    s.add_argument("scene", help="scene YAML file, or the name of a shipped scene")
    s.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    s.add_argument("--out", metavar="FILE.npz", help="save the sampled trajectory")
    s.add_argument("--record", metavar="FILE.mcap",
                   help="record the deployment as it is computed (ROS 2 MCAP: ros2 bag, Foxglove, rerun)")
    s.add_argument("--stiffness", metavar="RESULT.yaml", help="hinge stiffnesses from an optimisation result")
    s.add_argument("--method", help="override simulation.method")
    s.add_argument("--closure", choices=("penalty", "exact"), help="override closure.method")
    s.add_argument("--t-end", type=float, help="override simulation.t_end (s)")
    _add_set(s)
    s.set_defaults(func=cmd_simulate)

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
    _add_set(s)
    s.set_defaults(func=cmd_run)

    s = sub.add_parser("collide", help="collision check of a saved trajectory or a recording")
    s.add_argument("trajectory", help="trajectory .npz written by simulate --out, or an MCAP "
                                      "recording (its /joint_states)")
    s.add_argument("--scene", help="the recording's scene (file or shipped name); default: "
                                   "its /panel_deploy/model")
    s.add_argument("--json", action="store_true")
    s.set_defaults(func=cmd_collide)

    s = sub.add_parser("optimise", help="hinge stiffnesses for a collision-free deployment (Eq. 8)")
    s.add_argument("scene")
    s.add_argument("--out", metavar="RESULT.yaml", help="result file (default: print it)")
    s.add_argument("--record", metavar="FILE.mcap", help="record the deployment of the result (needs --out)")
    s.add_argument("--workers", type=int, help="parallel evaluations (default: all cores)")
    s.add_argument("--dask", metavar="ADDRESS", help="run evaluations on this Dask scheduler")
    s.add_argument("--method", choices=("local", "global"), help="override optimisation.method")
    s.add_argument("--max-evaluations", type=int, help="override optimisation.max_evaluations")
    s.add_argument("--start", metavar="RESULT.yaml",
                   help="start from this result's K instead of optimisation.k0")
    s.add_argument("--springs", type=_stiffness_list,
                   help="available spring stiffnesses, N m/rad, comma-separated")
    s.add_argument("--perturb", type=int, default=0, help="tolerance check: perturbed copies")
    s.add_argument("--perturb-tol", type=float,
                   help="relative spread of k and c (default 0.05, with --perturb)")
    s.add_argument("--quiet", action="store_true", help="no progress lines")
    s.add_argument("--json", action="store_true", help="print the result as JSON")
    _add_set(s)
    s.set_defaults(func=cmd_optimise)

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
                                   "its /panel_deploy/model")
    s.set_defaults(func=cmd_replay)

    s = sub.add_parser("export", help="export the model (MuJoCo MJCF)")
    s.add_argument("scene")
    s.add_argument("--mjcf", metavar="FILE.xml", required=True)
    _add_set(s)
    s.set_defaults(func=cmd_export)

    s = sub.add_parser("bench", help="benchmarks")
    bsub = s.add_subparsers(dest="bench", required=True)
    b = bsub.add_parser("work-precision", help="error against run time, every integrator and MuJoCo")
    b.add_argument("scene")
    b.add_argument("--out", default="work_precision.csv", help="CSV file")
    b.add_argument("--plot", default="work_precision.png", help="log-log plot")
    b.add_argument("--repeats", type=int, default=3)
    b.add_argument("--quick", action="store_true", help="fewer tolerances and steps (< 2 min)")
    _add_set(b)
    b.set_defaults(func=cmd_bench)
    return p


def _interrupt(signum, frame):
    # numba hands arrays back from compiled code through a Python callback
    # (numba.core.serialize) whose errors it does not check: raised there, the
    # KeyboardInterrupt would surface as a SystemError. Deliver it again a
    # moment later instead, when the interpreter is back in our code.
    if frame is not None and frame.f_globals.get("__name__", "").startswith("numba"):
        threading.Timer(0.01, os.kill, (os.getpid(), signum)).start()
        return
    raise KeyboardInterrupt


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    # A service manager's SIGTERM ends a long job like Ctrl-C does: the
    # optimiser then still writes the best K it has.
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGTERM, _interrupt)
    try:
        from .cli_checks import check_args
        check_args(args)  # every flag and output path, before any work
        return args.func(args) or 0
    except PanelDeployError as e:
        print(f"panel-deploy: error: {e}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # output piped into head & co.: not an error of ours
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except KeyboardInterrupt:
        print("panel-deploy: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
