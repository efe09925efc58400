"""``panel-deploy collide``: the collision check of a saved trajectory or a recording."""

from __future__ import annotations

import json
import sys

from ..build import build_model
from ..collision import CollisionSettings, check_trajectory
from ..errors import SceneError
from ..record.reader import is_mcap
from ..trajectory_io import load_trajectory
from ..validate import check_stored_trajectory, first_non_finite_value


def collide_command(args) -> int:
    """Check ``args.trajectory``: a ``.npz`` of ``simulate --out`` or the
    ``/joint_states`` of an MCAP recording (its scene from ``--scene``, else
    from the recording).

    The model is rebuilt from the scene stored in the file; only its geometry
    and tree matter here, not the stored stiffnesses. A stored run that failed
    is checked up to where it stopped, and the output says so. Exit 0; 1 if a
    number of the report came out non-finite (the inputs are checked finite
    first, so this is a safety net).
    """
    mcap = is_mcap(args.trajectory)
    if mcap:
        from ..record.analysis import recording_trajectory
        result, scene = recording_trajectory(args.trajectory, args.scene)
        model = build_model(scene)
    elif args.scene:
        raise SceneError("--scene", "only for an MCAP recording; a .npz trajectory carries its scene")
    else:
        result, scene, model = load_trajectory(args.trajectory)[:3]
    check_stored_trajectory(args.trajectory, result, model)
    report = check_trajectory(model, result, CollisionSettings.from_scene(scene))
    failed = getattr(result, "success", True) is False
    out = report.to_dict()
    bad = first_non_finite_value(out)
    if bad is not None:  # a NaN is never an answer
        print(f"panel-deploy: collide: non-finite result: {bad}", file=sys.stderr)
        return 1
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
    return 0
