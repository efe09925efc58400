"""One deployment of a scene: scene -> model -> simulation -> collision check."""

from __future__ import annotations

import sys

import numpy as np


def scene_model(scene, stiffness_file=None):
    """The model a scene simulates.

    With ``stiffness_file`` (a result file) its k replaces the scene's, c
    following k, and :func:`damping_note` says so if the file's c differs.
    """
    from .build import build_model

    model = build_model(scene)
    if stiffness_file:
        from .configure import result_model
        model, c_file = result_model(scene, model, stiffness_file)
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
    from .configure import damping_ratio_of

    c = np.array([h.c for h in model.hinges])
    # 1e-3: a ratio given to the note's four figures (--set hinges.damping_ratio=0.1864
    # for 0.18641...) is the result's own, and the note would print two equal numbers
    if c_file is None or model.stiffness.max(initial=0) <= 0 or \
            np.allclose(c_file, c, rtol=1e-3, atol=0.0):
        return
    ratio = damping_ratio_of(model, c_file)
    print(f"panel-deploy: note: {stiffness_file} gives damping c/k = {ratio:.4g} s, "
          f"the scene {damping_ratio_of(model, c):.4g} s; simulating with the scene's (--set "
          f"hinges.damping_ratio={ratio:.4g} simulates the result's)", file=sys.stderr)
