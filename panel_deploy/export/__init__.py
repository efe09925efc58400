"""Export a model to other simulators' formats (MuJoCo MJCF)."""

from .mjcf import export_command, export_mjcf, qpos_index

__all__ = ["export_mjcf", "export_command", "qpos_index"]
