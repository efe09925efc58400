"""The ``simulate`` job behind the CLI: scene -> model -> simulation -> collision check."""

from __future__ import annotations

import json
import sys
from dataclasses import replace

import numpy as np

from .errors import SceneError


def apply_overrides(scene, args):
    """The scene with the command line's --method, --closure and --t-end applied."""
    sim, closure = scene.simulation, scene.closure
    if getattr(args, "method", None):
        from .scene import INTEGRATORS
        if args.method not in INTEGRATORS:
            raise SceneError("--method", f"expected one of {', '.join(INTEGRATORS)}, got {args.method!r}")
        sim = replace(sim, method=args.method)
    if getattr(args, "t_end", None) is not None:
        if not args.t_end > 0:
            raise SceneError("--t-end", f"expected a number > 0, got {args.t_end}")
        sim = replace(sim, t_end=args.t_end)
    if getattr(args, "closure", None):
        closure = replace(closure, method=args.closure)
    return scene.replace(simulation=sim, closure=closure)


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
    if c_file is None or not sprung.any() or np.allclose(c_file, c, rtol=1e-6, atol=0.0):
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
    print(json.dumps(summary) if args.json else summary_text(summary))
    return 0 if result.success else 1
