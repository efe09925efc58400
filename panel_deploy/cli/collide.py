"""``panel-deploy collide``: the collision check of a saved trajectory or a recording."""

from __future__ import annotations

import json
import sys

from ..collision import CollisionSettings, check_trajectory
from ..errors import SceneError
from ..record.reader import is_mcap
from ..trajectory_io import check_stored_trajectory, load_trajectory
from ..validate import first_non_finite_value


def collide_command(args) -> int:
    """Check ``args.trajectory``: a ``.npz`` of ``simulate --out``, or the joint
    states of an MCAP recording (its scene from ``--scene``, else the one it
    ran), checked as the ``collision_monitor`` node checks the same stream
    (:func:`~panel_deploy.record.analysis.check_recording`); ``--set`` items
    apply to the scene (``collision.noise=1e-3``).

    The model is rebuilt from the scene stored in the file; only its geometry
    and tree matter here, not the stored stiffnesses. A stored run that failed
    is checked up to where it stopped, and the output says so. Exit 0; 1 if a
    number of the report came out non-finite (the inputs are checked finite
    first, so this is a safety net).
    """
    overrides = getattr(args, "set", None) or ()
    verdict, notes, beside = None, None, None
    if is_mcap(args.trajectory):
        from ..record.analysis import check_recording, read_deployment
        d = read_deployment(args.trajectory, args.scene, args.namespace, overrides)
        stream, report = check_recording(d)
        result, level_text, notes = d.track, stream.verdict()[:2], d.print_notes
        verdict = {"level": level_text[0], "message": level_text[1]}
        beside = _compared(d, args) if args.compare else None
    elif args.compare or args.release is not None:
        raise SceneError("--compare" if args.compare else "--release",
                         "only for an MCAP recording (the motion it compares with)")
    else:
        if args.scene or args.namespace:
            raise SceneError("--scene" if args.scene else "--namespace",
                             "only for an MCAP recording; a .npz trajectory carries its scene")
        result, scene, model = load_trajectory(args.trajectory)[:3]
        if overrides:
            scene = scene_with(scene, overrides)
        check_stored_trajectory(args.trajectory, result, model)
        report = check_trajectory(model, result, CollisionSettings.from_scene(scene))
    failed = getattr(result, "success", True) is False
    out = report.to_dict()
    bad = first_non_finite_value(out)
    if bad is not None:  # a NaN is never an answer
        print(f"panel-deploy: collide: non-finite result: {bad}", file=sys.stderr)
        return 1
    if verdict is not None:
        out["verdict"] = verdict
    if verdict is not None and beside is not None:
        out["compared"] = {"scene": beside[0].source, "release": beside[0].release,
                           **beside[1].to_dict()}
    if args.json:
        if failed:  # the run stopped early: the check covers only what it computed
            out["run"] = {"success": False, "status": int(result.status), "message": result.message,
                          "t_end": float(result.t[-1])}
        print(json.dumps(out, allow_nan=False))
    else:
        if failed:
            print(f"the stored run FAILED at t = {result.t[-1]:.4g} s ({result.message}): "
                  "checked up to there")
        print(report.to_text())
        if verdict is not None and verdict["level"] == 1:
            print(f"stream: {verdict['message']}")
        if verdict is not None and beside is not None:
            print(f"beside it, {beside[0].source} released at {beside[0].release:.4f} s, on the "
                  f"same times:\n{beside[1].to_text()}")
    if notes is not None:
        notes()
    return 0


def _compared(d, args):
    """``(Compared, report)``: ``--compare SCENE``'s deployment beside the recording
    and its collision check with the recording's collision settings."""
    from ..collision import CollisionSettings
    from ..record.compare import collision_report
    from .args import compared_scene

    beside = compared_scene(d, args)
    return beside, collision_report(beside, d, CollisionSettings.from_scene(d.scene))


def scene_with(scene, overrides):
    """``scene`` with ``--set`` items applied, validated; errors name the item."""
    from ..scene import apply_overrides, scene_from_dict

    try:
        return scene_from_dict(apply_overrides(scene.data, overrides), source=scene.source)
    except SceneError as e:
        raise SceneError(f"--set {e.path}", e.reason) from None
