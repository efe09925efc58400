"""Checks of the command line's flags, run right after parsing and before any work.

Every flag is checked here, named as the user typed it (``--perturb-tol``,
not the internal ``stiffness_tol``), and every output path is checked (its
folder exists and is writable, it is not a folder, it is neither another
output nor one of the command's input files) so that a long simulation or
search never ends in an unwritable file or destroys what it read. Options that would be ignored or
that conflict are errors, not silently dropped. The rules themselves are in
:mod:`panel_deploy.validate`, shared with the ROS nodes; the flags that are
aliases of ``--set`` (:mod:`panel_deploy.cli.args`) meet the scene's own
validation instead.
"""

from __future__ import annotations

import os
from pathlib import Path

from ..errors import SceneError, shown
from ..validate import check_output_path, finite_number, in_place, is_stdout

#: Largest array ``fold --rows R --cols C`` counts: the frontier count's time
#: and memory grow about 3-4 fold per cell of the shorter side (12 x 12:
#: 2.7 s, 35 MB; 16 x 16: minutes, gigabytes at 20 x 20), linearly with the
#: longer one.
FOLD_MAX_SHORT_SIDE = 12
FOLD_MAX_CELLS = 400

#: Output flags of each command (attribute, flag).
OUTPUTS = {
    "simulate": (("out", "--out"), ("record", "--record")),
    "optimise": (("out", "--out"), ("record", "--record")),
    "run": (("record", "--record"),),
    "export": (("mjcf", "--mjcf"),),
    "fold": (("plot", "--plot"),),
    "replay": (("save", "--save"), ("png", "--png")),
    "bench": (("out", "--out"), ("plot", "--plot")),
    "calibrate": (("out", "--out"), ("plot", "--plot")),
}


#: Input files of each command (attribute, flag or argument name).
INPUTS = {
    "simulate": (("scene", "scene"), ("stiffness", "--stiffness")),
    "optimise": (("scene", "scene"), ("start", "--start")),
    "run": (("scene", "scene"),),
    "export": (("scene", "scene"),),
    "fold": (("scene", "--scene"),),
    "replay": (("recording", "recording"), ("scene", "--scene"), ("compare", "--compare")),
    "bench": (("scene", "scene"),),
    "calibrate": (("recordings", "RECORDING"), ("free_vibration", "--free-vibration"),
                  ("scene", "--scene"), ("rig_scene", "--rig")),
}

#: Output flags that write a picture, in the format of the file name's suffix.
PICTURES = ("--png", "--plot")


def check_args(args) -> None:
    """Check the parsed ``args`` of one command; :class:`SceneError` naming the flag."""
    from ..scene import resolve_scene

    command = getattr(args, "command", None)
    outputs = [(getattr(args, attr, None), flag) for attr, flag in OUTPUTS.get(command, ())]
    inputs = [(resolve_scene(path) if "scene" in attr else path, flag)
              for attr, flag in INPUTS.get(command, ())
              for path in _given(getattr(args, attr, None))]
    earlier = []
    args.stdout_output = None  # the flag writing standard output: human lines go to stderr
    for path, flag in outputs:
        check_output_path(path, flag)
        if path is None:
            continue
        if is_stdout(path):
            if args.stdout_output is not None:
                raise SceneError(flag, f"standard output is also {args.stdout_output}: one output "
                                       "can stream there")
            args.stdout_output = flag
            continue
        for other, other_flag in inputs:
            if _same_file(path, other):
                raise SceneError(flag, f"{path} is also the input {other_flag} ({other}): "
                                       "writing it would destroy the input; give another file")
        for other, other_flag in earlier:
            if _same_file(path, other):
                raise SceneError(flag, f"{path} is also {other_flag}: give two files")
        if flag in PICTURES:
            _picture_format(path, flag)
        earlier.append((path, flag))
    check = _CHECKS.get(command)
    if check is not None:
        check(args)


def _given(value) -> list:
    """The paths an argument holds: none, one, or a list (several positional files)."""
    if value is None:
        return []
    return list(value) if isinstance(value, list) else [value]


def _same_file(output, other) -> bool:
    """Whether writing ``output`` would write the file ``other``: the same path
    once resolved (links, ``..``), or the same inode (hard links). A device or
    pipe is written in place and replaces nothing, so it only matches by name."""
    output, other = Path(output), Path(other)
    if str(output) == str(other):
        return True
    try:
        if output.exists() and not output.is_file():
            return False
        return output.resolve() == other.resolve() or (
            output.exists() and other.exists() and os.path.samefile(output, other))
    except (OSError, RuntimeError, ValueError):  # a loop of links, a name too long, a NUL byte
        return False


def _positive_int(args, attr, flag, low=1):
    value = getattr(args, attr, None)
    if value is not None:
        finite_number(value, flag, low=low, integer=True)


def _fold(args):
    if getattr(args, "rank", False):
        if args.scene is None:
            raise SceneError("--rank", "needs --scene: the screening simulates the scene's panels, "
                                       "hinges and settings (--set array.rows=... resizes it)")
        if args.plot:
            raise SceneError("--plot", "not with --rank (plot one circuit: --set fold.circuit=N)")
        _dask_address(args)
    else:
        for attr, flag in (("candidates", "--candidates"), ("screen_t_end", "--screen-t-end"),
                           ("workers", "--workers"), ("dask", "--dask")):
            if getattr(args, attr, None) is not None:
                raise SceneError(flag, "only with --rank (the circuits it screens)")
    if args.scene is not None:
        given = [flag for attr, flag in (("rows", "--rows"), ("cols", "--cols"),
                                         ("circuit", "--circuit"), ("limit", "--limit"))
                 if getattr(args, attr, None) is not None]
        if given:
            raise SceneError(given[0], "not with --scene: the scene gives the array and its "
                                       "circuit (use --set array.rows=... or fold.circuit=...)")
        return
    if getattr(args, "set", None):
        raise SceneError("--set", "only with --scene (a scene to override); without it give "
                                  "--rows and --cols")
    for attr, flag in (("rows", "--rows"), ("cols", "--cols")):
        _positive_int(args, attr, flag, low=1)
    rows, cols = args.rows, args.cols
    if rows is not None and cols is not None and (min(rows, cols) > FOLD_MAX_SHORT_SIDE
                                                  or rows * cols > FOLD_MAX_CELLS):
        raise SceneError("--rows/--cols", f"{rows} x {cols} is above the enumeration limit (the "
                                          f"shorter side at most {FOLD_MAX_SHORT_SIDE}, at most "
                                          f"{FOLD_MAX_CELLS} cells): counting its circuits "
                                          "would take minutes and gigabytes")
    _positive_int(args, "circuit", "--circuit", low=0)
    _positive_int(args, "limit", "--limit", low=0)


def _optimise(args):
    _positive_int(args, "perturb", "--perturb", low=0)
    tol = getattr(args, "perturb_tol", None)
    if tol is not None:
        if not args.perturb:
            raise SceneError("--perturb-tol", "only with --perturb N (the copies it spreads)")
        finite_number(tol, "--perturb-tol", low=0)
        if not tol < 1:
            raise SceneError("--perturb-tol", f"expected a fraction in [0, 1) (k and c stay "
                                              f"positive), got {tol:g}")
    _dask_address(args)


def _dask_address(args):
    if getattr(args, "dask", None) is not None and not str(args.dask).strip():
        raise SceneError("--dask", "expected a scheduler address, got an empty string")


def _bench(args):
    _positive_int(args, "repeats", "--repeats", low=1)


def _picture_format(path, flag):
    suffix = Path(str(path)).suffix.lstrip(".").lower()
    if not suffix:
        return  # written as PNG
    from matplotlib.backend_bases import FigureCanvasBase
    formats = FigureCanvasBase.get_supported_filetypes()
    if suffix not in formats:
        raise SceneError(flag, f"cannot write a picture as .{suffix} (the suffix gives the format: "
                               f"{', '.join(sorted(formats))})")


def _release(args):
    """``--release`` (of collide and replay): a number, and only with ``--compare``."""
    if args.release is not None:
        if not args.compare:
            raise SceneError("--release", "only with --compare SCENE (the model it releases)")
        finite_number(args.release, "--release")


def _replay(args):
    finite_number(args.port, "--port", low=1, high=65535, integer=True)
    _release(args)
    if args.compare and args.png and not (args.save or args.spawn or args.serve):
        raise SceneError("--compare", "shown in rerun (--save, --spawn, --serve), not in --png")
    save = getattr(args, "save", None)
    if save is not None and Path(save).suffix != ".rrd" and not in_place(save):
        # A rerun file under another name would replace whatever had it (a scene, a bag);
        # a device or pipe (/dev/stdout) is written in place and replaces nothing.
        raise SceneError("--save", f"expected a rerun file name ending in .rrd, got {shown(save)}")
    if args.serve:
        import socket
        with socket.socket() as probe:
            try:
                probe.bind(("127.0.0.1", args.port))
            except OSError as e:
                raise SceneError("--port", f"cannot serve on 127.0.0.1:{args.port} "
                                           f"({e.strerror or e}: another program has it); "
                                           "choose a free one with --port") from None


#: What ``calibrate`` fits of recorded deployments unless ``--fit`` says.
DEFAULT_FIT = "damping,stiffness"


def _calibrate(args):
    deployment = ("--fit", args.fit is not None), ("--per", args.per is not None), \
        ("--plot", args.plot is not None), ("--until", args.until is not None), \
        ("--max-evaluations", args.max_evaluations is not None), ("--quiet", args.quiet)
    if args.free_vibration:
        if args.recordings:
            raise SceneError("RECORDING", "give deployments or --free-vibration tests, not both")
        for flag, given in deployment:
            if given:
                raise SceneError(flag, "only for recorded deployments, not with --free-vibration")
        if args.out is None:
            # these only shape the scene --out writes: without it they would be ignored
            for flag, given in (("--scene", args.scene), ("--hinge", args.hinge), ("--set", args.set)):
                if given:
                    raise SceneError(flag, "only with --out CALIBRATED.yaml (the scene it shapes)")
        return
    if not args.recordings:
        raise SceneError("RECORDING", "give the recordings of deployments to fit (or "
                                      "--free-vibration RECORDING.mcap ... for swing tests)")
    for flag, given in (("--rig", args.rig_scene), ("--hinge", args.hinge), ("--json", args.json)):
        if given:
            raise SceneError(flag, "only with --free-vibration")
    if args.out is None:
        raise SceneError("--out", "required: the calibrated scene CALIBRATED.yaml to write")
    args.fit = DEFAULT_FIT if args.fit is None else args.fit
    args.per = "scale" if args.per is None else args.per
    args.max_evaluations = 50 if args.max_evaluations is None else args.max_evaluations
    from ..calibrate.parameters import KINDS, PER

    kinds = [kind.strip() for kind in str(args.fit).split(",")]
    for kind in kinds:
        if kind not in KINDS:
            raise SceneError("--fit", f"no parameter {shown(kind)} to fit (expected some of "
                                      f"{', '.join(KINDS)}, comma-separated)")
    if len(set(kinds)) != len(kinds):
        raise SceneError("--fit", f"{shown(args.fit)} names a parameter twice")
    args.fit = ",".join(kinds)
    if args.per not in PER:
        raise SceneError("--per", f"expected one of {', '.join(PER)}, got {shown(args.per)}")
    _positive_int(args, "max_evaluations", "--max-evaluations", low=1)
    if args.until is not None:
        finite_number(args.until, "--until", low=0, low_open=True)
    if len(set(map(str, args.recordings))) != len(args.recordings):
        raise SceneError("RECORDING", "a recording is given twice: it would count twice in the fit")


_CHECKS = {"fold": _fold, "optimise": _optimise, "bench": _bench, "replay": _replay,
           "collide": _release, "calibrate": _calibrate}
