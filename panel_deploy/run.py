"""The ``simulate`` job behind the CLI: scene -> model -> simulation -> collision check."""

from __future__ import annotations

import copy
import json
import math
import sys
from dataclasses import replace

import numpy as np

from .errors import SceneError


def apply_overrides(scene, args):
    """The scene with the command line's --method, --closure and --t-end applied.

    The flags are written into the scene mapping and the scene validated
    again from it: one source of truth, so the scene a saved trajectory
    stores is the one the run used, and the flags meet the same limits as
    the file (a value the schema refuses is named by its flag).
    """
    from .scene import INTEGRATORS, scene_from_dict
    flags = []
    method = getattr(args, "method", None)
    if method is not None:
        if method not in INTEGRATORS:
            raise SceneError("--method", f"expected one of {', '.join(INTEGRATORS)}, got {method!r}")
        flags.append(("--method", "simulation", "method", method))
    t_end = getattr(args, "t_end", None)
    if t_end is not None:
        if not 0 < t_end < math.inf:
            raise SceneError("--t-end", f"expected a finite number > 0, got {t_end}")
        flags.append(("--t-end", "simulation", "t_end", float(t_end)))
    if getattr(args, "closure", None):
        flags.append(("--closure", "closure", "method", args.closure))
    if not flags:
        return scene
    if scene.data is None:  # a Scene built in code, not from a mapping
        sections = {sec: replace(getattr(scene, sec), **{key: v}) for _, sec, key, v in flags}
        return scene.replace(**sections)
    data = copy.deepcopy(scene.data)
    for _, sec, key, value in flags:
        if not isinstance(data.get(sec), dict):
            data[sec] = {}
        data[sec][key] = value
    try:
        return scene_from_dict(data, source=scene.source)
    except SceneError as e:  # the scene was valid without the flags: one of them is to blame
        named = next((f for f, sec, key, _ in flags if e.path == f"{sec}.{key}"), None)
        if named:
            raise SceneError(named, e.reason) from None
        raise SceneError(", ".join(f for f, *_ in flags), f"{e.path}: {e.reason}" if e.path
                         else e.reason) from None


def scene_model(scene, stiffness_file=None):
    """The model a scene simulates.

    With ``stiffness_file`` (a result file) its k replaces the scene's, c
    following k, and :func:`damping_note` says so if the file's c differs.
    """
    from .build import build_model

    model = build_model(scene)
    if stiffness_file:
        from .optimise import load_hinges
        k, c_file = load_hinges(stiffness_file, model)
        model = model.with_stiffness(k)
        damping_note(model, c_file, stiffness_file)
    return model


def simulate_scene(scene, stiffness_file=None):
    """Simulate a scene (model as :func:`scene_model`) and check it for
    collisions: (model, result, report)."""
    from .collision import CollisionSettings, check_trajectory
    from .dynamics import simulate

    model = scene_model(scene, stiffness_file)
    result = simulate(model, scene.simulation)
    report = check_trajectory(model, result, CollisionSettings.from_scene(scene))
    return model, result, report


def damping_note(model, c_file, stiffness_file):
    """Say on stderr when a result file's damping ``c_file`` (N m s/rad per
    hinge, or None) is not the one ``model`` simulates.

    The scene decides c/k (so that ``--set hinges.damping_ratio=...`` tries a
    design under other dampers); a result optimised under another ratio then
    deploys differently, which deserves a word rather than silence.
    """
    c = np.array([h.c for h in model.hinges])
    sprung = model.stiffness > 0
    # 1e-3: a ratio given to the note's four figures (--set hinges.damping_ratio=0.1864
    # for 0.18641...) is the result's own, and the note would print two equal numbers
    if c_file is None or not sprung.any() or np.allclose(c_file, c, rtol=1e-3, atol=0.0):
        return

    def ratio(damping):
        return float(np.median(damping[sprung] / model.stiffness[sprung]))

    print(f"panel-deploy: note: {stiffness_file} gives damping c/k = {ratio(c_file):.4g} s, "
          f"the scene {ratio(c):.4g} s; simulating with the scene's (--set "
          f"hinges.damping_ratio={ratio(c_file):.4g} simulates the result's)", file=sys.stderr)


def simulate_command(args, scene) -> int:
    """``panel-deploy simulate``: print the summary; exit 0 when the run succeeded, 1 if not."""
    from .summary import deployment_summary, summary_text

    scene = apply_overrides(scene, args)
    if getattr(args, "record", None):
        from .record.deployment import record_deployment
        model = scene_model(scene, args.stiffness)
        result, report = record_deployment(args.record, scene, model)
    else:
        model, result, report = simulate_scene(scene, args.stiffness)
    if args.out:
        from .trajectory_io import save_trajectory
        save_trajectory(args.out, result, scene, model)
    summary = deployment_summary(model, result, report, flat_tol=scene.simulation.flat_tolerance)
    summary["scene"] = scene.name or scene.source
    from .validate import first_non_finite_value
    bad = first_non_finite_value(summary)
    if bad is not None:  # a NaN is never an answer: the run counts as failed
        summary.update(success=False, message=f"non-finite result: {bad} ({summary['message']})")
    print(json.dumps(summary, allow_nan=False) if args.json and bad is None else
          json.dumps(summary) if args.json else summary_text(summary))
    return 0 if result.success and bad is None else 1
