"""``panel-deploy calibrate --free-vibration A.mcap B.mcap ...``: hinge damping from
free-vibration tests (one panel swinging on one hinge), the scene's damping set from them."""

from __future__ import annotations

import json

import yaml

from ..errors import SceneError, shown
from ..validate import write_atomic
from .args import scene_of


def _target_scene(args):
    """The scene to calibrate: ``--scene``, else the first recording's rig
    (its own scene, else ``--rig``), with the ``--set`` items."""
    if args.scene:
        return scene_of(args)
    from ..record.analysis import recorded_scene

    return recorded_scene(args.free_vibration[0], args.rig_scene, args.namespace,
                          overrides=args.set or (), scene_flag="--rig")[1]


def free_vibration_command(args) -> int:
    """Read and check the scene to write and every recording first (one line
    and exit 2 for the first bad one), then analyse, print the report
    (``--json``: the calibration as one object) and write ``--out``. Exit 1
    when no test could be fitted."""
    from ..build import build_model
    from ..free_vibration import (calibrate, calibrated_scene, calibration_record, read_swing,
                                  report_text)

    scene = _target_scene(args) if args.out else None
    if args.hinge:
        names = [h.name for h in build_model(scene).hinges]
        if args.hinge not in names:
            raise SceneError("--hinge", f"{shown(args.hinge)} is no hinge of the scene (hinges: "
                                        f"{', '.join(names)})")
    readings = [read_swing(path, args.rig_scene, args.namespace) for path in args.free_vibration]
    cal = calibrate(readings)
    if args.json:
        print(json.dumps(calibration_record(cal, args.hinge)))
    else:
        print(report_text(cal))
    if not cal.success:
        return 1
    if args.out:
        data = calibrated_scene(scene.data, cal, args.hinge)
        text = ("# Calibrated by panel-deploy calibrate --free-vibration: see the calibration "
                "section.\n" + yaml.safe_dump(data, sort_keys=False))
        write_atomic(args.out, lambda f: f.write(text), "--out")
        if not args.json:  # standard output stays one JSON object
            what = f"hinges.damping_overrides.{args.hinge}" if args.hinge else "hinges.damping_ratio"
            print(f"{what} -> {args.out}")
    return 0
