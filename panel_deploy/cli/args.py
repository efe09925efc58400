"""The one way a command line changes a scene: ``--set KEY=VALUE``.

The convenience flags (``--method``, ``--closure``, ``--t-end``,
``--max-evaluations``, ``--workers``) are thin aliases: argparse appends them
to ``--set`` as they come (the last of a flag and a ``--set`` of the same key
wins, as two ``--set`` would), so they meet the scene's own validation and
limits, the scene a run stores is the one it used, and an error names the flag
the user typed.
"""

from __future__ import annotations

import argparse

from ..errors import SceneError


class SceneKey(argparse.Action):
    """``--flag VALUE`` as ``--set KEY=VALUE`` (VALUE read as YAML)."""

    def __init__(self, option_strings, dest, key, **kwargs):
        self.key = key
        kwargs.setdefault("help", f"the same as --set {key}=VALUE")
        super().__init__(option_strings, dest, **kwargs)

    def __call__(self, parser, namespace, value, option_string=None):
        if not str(value).strip():
            parser.error(f"{option_string}: expected a value for {self.key}, got an empty string")
        namespace.set = [*(getattr(namespace, "set", None) or ()), f"{self.key}={value}"]
        namespace.aliases = {**(getattr(namespace, "aliases", None) or {}), self.key: option_string}
        setattr(namespace, self.dest, value)


def add_compare(parser, help_text: str) -> None:
    """``--compare SCENE`` and its ``--release`` (collide and replay of a recording)."""
    parser.add_argument("--compare", metavar="SCENE", help=help_text)
    parser.add_argument("--release", type=float, metavar="SECONDS",
                        help="with --compare: release its model this long after the recording's "
                             "first joint state (default: the offset calibrate found, else 0)")


def add_set(parser) -> None:
    """``--set KEY=VALUE``, repeatable."""
    parser.add_argument("--set", action="append", metavar="KEY=VALUE",
                        help="override a scene key, VALUE read as YAML "
                             "(e.g. --set gravity=[0,0,0] --set simulation.t_end=3); repeatable")


def alias(parser, flag: str, key: str, **kwargs) -> None:
    """``flag`` as a thin alias of ``--set key=VALUE``."""
    parser.add_argument(flag, action=SceneKey, key=key, **kwargs)


def scene_of(args, name_attr: str = "scene", resolve: bool = True, parallel: bool = False):
    """The scene ``args`` name (a file, a shipped scene's name, or an MCAP
    recording: the scene its deployment ran, overrides included), with the
    ``--set`` items and their aliases applied, and with ``resolve`` its
    ``fold.circuit: auto`` resolved (:func:`chosen_circuit`; with ``parallel``
    the screenings run where the command's evaluations do:
    ``optimisation.workers`` or ``--dask``).

    Raises
    ------
    SceneError
        As :func:`panel_deploy.scene.load_scene`; a bad value given by an
        alias is named by that flag (``--t-end: ...``), not by ``--set``.
    """
    from ..scene import load_scene, resolve_scene

    from ..record.reader import is_mcap

    aliases = getattr(args, "aliases", None) or {}
    name, overrides = getattr(args, name_attr), getattr(args, "set", None) or ()
    try:
        if is_mcap(name):
            from ..record.analysis import recorded_scene
            scene = recorded_scene(name, overrides=overrides)[1]
        else:
            scene = load_scene(resolve_scene(name), overrides)
    except SceneError as e:
        flag = next((f for key, f in aliases.items()
                     if str(e.path) == f"--set {key}" or str(e.path).startswith(f"--set {key}[")),
                    None)
        if flag is None:
            raise
        raise SceneError(flag, e.reason) from None
    if not resolve:
        return scene
    if parallel:
        return chosen_circuit(scene, scene.optimisation.workers, getattr(args, "dask", None))
    return chosen_circuit(scene)


def result_scene(scene, result_file):
    """``scene`` to deploy the result file ``result_file`` (``--stiffness``)
    on: with ``fold.circuit: auto``, the circuit the file was optimised on if
    it names one (``fold.circuit_choice`` says so), rather than a new ranking
    whose first circuit may be another; else as :func:`chosen_circuit`.

    Raises
    ------
    OptimisationError
        The file cannot be read, or its ``circuit`` is not one of the scene's array.
    """
    from ..build import design_of
    from ..errors import OptimisationError
    from ..optimise.io import result_circuit
    from ..scene import apply_overrides, scene_from_dict
    from ..scene_text import yaml_value

    circuit = result_circuit(result_file) if scene.fold.circuit == "auto" else None
    if circuit is None:
        return chosen_circuit(scene)
    choice = {"index": circuit, "by": "stiffness file", "file": str(result_file)}
    try:
        scene = scene_from_dict(apply_overrides(scene.data, [
            f"fold.circuit={yaml_value(circuit)}", f"fold.circuit_choice={yaml_value(choice)}"]),
            source=scene.source)
        design_of(scene)  # checked here, so that the error names the file
        return scene
    except SceneError as e:
        raise OptimisationError(f"stiffness file {str(result_file)!r}: circuit: "
                                f"{e.reason}") from None


def chosen_circuit(scene, workers: int = 1, dask_address: str | None = None):
    """``scene`` with ``fold.circuit: auto`` resolved to the best-ranked circuit
    (:func:`panel_deploy.ranking.resolve_circuit`: a screening run of
    the first packing circuits, with a progress line, on ``workers`` local
    processes or the Dask scheduler at ``dask_address``), which a note on
    stderr names; any other scene as it is."""
    if scene.fold.circuit != "auto":
        return scene
    import sys

    from ..ranking import resolve_circuit
    from ..optimise.parallel import task_map
    from ..progress import Progress

    with (task_map(workers, dask_address) as screen,
          Progress(None, "fold.circuit: auto", "circuits") as bar):
        scene = resolve_circuit(scene, progress=lambda _: bar.update(), task_map=screen)
    c = scene.fold.circuit_choice
    print(f"panel-deploy: note: fold.circuit: auto chose circuit {c['index']}, the best-ranked of "
          f"{len(c['screened'])} screened ({c['outcome']}; panel-deploy fold --rank shows the "
          "ranking)", file=sys.stderr)
    return scene


def compared_scene(d, args):
    """``--compare SCENE``'s deployment beside the recorded deployment ``d``, at its
    times (:func:`panel_deploy.record.compare.compared`): the scene as written,
    ``--set`` not applied, ``fold.circuit: auto`` resolved (:func:`chosen_circuit`)."""
    from ..record.compare import compared
    from ..scene import load_scene, resolve_scene

    return compared(d, chosen_circuit(load_scene(resolve_scene(args.compare))), args.compare, args.release)
