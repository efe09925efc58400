"""``panel-deploy export SCENE --mjcf FILE.xml``: the scene's model for MuJoCo."""

from __future__ import annotations

from ..build import build_model
from ..export import export_mjcf
from ..validate import write_atomic
from .args import scene_of


def export_command(args) -> int:
    """Write the model of ``args.scene`` (``--set`` applied) as MJCF to ``args.mjcf``."""
    model = build_model(scene_of(args))
    text = export_mjcf(model)
    write_atomic(args.mjcf, lambda f: f.write(text), "--mjcf")
    print(f"wrote {args.mjcf}: {model.n_bodies} bodies, {model.n_coords} joints, "
          f"{len(model.cut_hinges)} cut hinge(s)")
    return 0
