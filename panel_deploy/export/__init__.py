"""Export a model to other simulators' formats (MuJoCo MJCF) and to URDF."""

from .mjcf import export_mjcf, qpos_index
from .urdf import link_poses, model_urdf

__all__ = ["export_mjcf", "qpos_index", "model_urdf", "link_poses"]
