"""Saving and loading sampled trajectories (``simulate --out``, ``collide``).

Format: one ``.npz`` file (numpy's zip of arrays), written to a temporary file
and renamed into place so that an interrupted run never leaves a half file.

Arrays: every array attribute of :class:`~panel_deploy.dynamics.result.SimulationResult`
under its own name (``t``, ``theta``, ``omega``, ``rotation``, ``position``,
``linear_velocity``, ``angular_velocity``, ``constraint_gap``,
``closure_sigma_min``), energies as ``energy_<kind>``, and
``scene_yaml`` (the scene mapping as YAML text), ``stiffness`` (k per hinge,
N m/rad, as simulated), ``hinge_names``, ``body_names``, ``success``,
``status``, ``message``, ``method``, ``format_version``.
"""

from __future__ import annotations

import os
import tempfile
import zipfile
from pathlib import Path

import numpy as np
import yaml

from .dynamics.result import SimulationResult
from .errors import SceneError, TrajectoryError

FORMAT_VERSION = 1
_ARRAYS = ("t", "theta", "omega", "rotation", "position", "linear_velocity",
           "angular_velocity", "constraint_gap", "closure_sigma_min")


def save_trajectory(path, result: SimulationResult, scene, model) -> Path:
    """Write ``result`` with what is needed to rebuild its model; returns the path."""
    path = Path(path)
    payload = {name: getattr(result, name) for name in _ARRAYS}
    payload.update({f"energy_{k}": v for k, v in result.energy.items()})
    payload.update(
        scene_yaml=np.array(yaml.safe_dump(scene.data, sort_keys=False)),
        stiffness=model.stiffness, hinge_names=np.array([h.name for h in model.hinges]),
        body_names=np.array([b.name for b in model.bodies]), success=np.array(result.success),
        status=np.array(result.status), message=np.array(result.message),
        method=np.array(result.method), format_version=np.array(FORMAT_VERSION))
    fd, tmp = tempfile.mkstemp(dir=path.parent if str(path.parent) else ".", suffix=".npz.part")
    try:
        with os.fdopen(fd, "wb") as f:
            np.savez_compressed(f, **payload)
        os.replace(tmp, path)
    except BaseException:
        os.unlink(tmp)
        raise
    return path


def load_trajectory(path):
    """Read a trajectory file.

    Returns
    -------
    result : SimulationResult
    scene : Scene
        Rebuilt from the stored scene mapping.
    stiffness : (n_hinges,) ndarray
        N m/rad, as simulated.

    Raises
    ------
    TrajectoryError
        If the file is missing, not a trajectory file, truncated, or its arrays
        have inconsistent shapes.
    """
    from .scene import scene_from_dict

    path = Path(path)
    if not path.exists():
        raise TrajectoryError(f"{path}: trajectory file not found")
    if not zipfile.is_zipfile(path):
        raise TrajectoryError(f"{path}: not a trajectory file (expected an .npz archive)")
    try:
        with np.load(path, allow_pickle=False) as z:
            data = {k: z[k] for k in z.files}
    except (zipfile.BadZipFile, ValueError, OSError, EOFError) as e:
        raise TrajectoryError(f"{path}: not a readable trajectory file ({e})") from None
    missing = [k for k in (*_ARRAYS, "scene_yaml", "stiffness", "format_version") if k not in data]
    if missing:
        raise TrajectoryError(f"{path}: missing arrays {', '.join(missing)}")
    if int(data["format_version"]) != FORMAT_VERSION:
        raise TrajectoryError(f"{path}: format_version {int(data['format_version'])}, "
                              f"expected {FORMAT_VERSION}")
    s = len(data["t"])
    for k in _ARRAYS[1:]:
        if len(data[k]) != s:
            raise TrajectoryError(f"{path}: {k} has {len(data[k])} samples, t has {s}")
    try:
        scene = scene_from_dict(yaml.safe_load(str(data["scene_yaml"])))
    except (SceneError, yaml.YAMLError) as e:
        raise TrajectoryError(f"{path}: stored scene is invalid ({e})") from None
    energy = {k[len("energy_"):]: v for k, v in data.items() if k.startswith("energy_")}
    result = SimulationResult(**{k: data[k] for k in _ARRAYS}, energy=energy,
                              success=bool(data["success"]), status=int(data["status"]),
                              message=str(data["message"]), method=str(data["method"]))
    return result, scene, data["stiffness"]
