"""``panel-deploy simulate``: one deployment, its summary, and the trajectory or recording."""

from __future__ import annotations

import json

from ..pipeline import scene_model, simulate_scene
from ..summary import deployment_summary, deployment_text
from ..validate import first_non_finite_value
from .args import result_scene, scene_of


def simulate_command(args) -> int:
    """Print the deployment's summary (``--json``: one object); write ``--out``
    (trajectory) and ``--record`` (MCAP). Exit 0 when the run succeeded, 1 if
    not (or if a number in the summary came out non-finite)."""
    scene = scene_of(args, resolve=not args.stiffness)
    if args.stiffness:
        scene = result_scene(scene, args.stiffness)
    if args.record:
        from ..record.deployment import check_recordable, record_deployment
        check_recordable(scene)
        model = scene_model(scene, args.stiffness)
        result, report = record_deployment(args.record, scene, model)
    else:
        model, result, report = simulate_scene(scene, args.stiffness)
    if args.out:
        from ..trajectory_io import save_trajectory
        save_trajectory(args.out, result, scene, model)
    summary = deployment_summary(model, result, report, flat_tolerance=scene.simulation.flat_tolerance)
    summary["scene"] = scene.name or scene.source
    if scene.fold.circuit_choice is not None:
        summary["circuit_choice"] = scene.fold.circuit_choice
    bad = first_non_finite_value(summary)
    if bad is not None:  # a NaN is never an answer: the run counts as failed
        summary.update(success=False, message=f"non-finite result: {bad} ({summary['message']})")
    print(json.dumps(summary, allow_nan=bad is not None) if args.json else deployment_text(summary))
    return 0 if result.success and bad is None else 1
