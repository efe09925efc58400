"""Saving and loading sampled trajectories (``simulate --out``, ``collide``).

Format: one ``.npz`` file (numpy's zip of arrays), written to a temporary file
and renamed into place so that an interrupted run never leaves a half file.

Arrays: every per-sample array of :class:`~panel_deploy.dynamics.result.SimulationResult`
under its own name (``t``, ``theta``, ``omega``, ``rotation``, ``position``,
``linear_velocity``, ``angular_velocity``, ``constraint_gap``,
``closure_sigma_min``, ``cut_theta``), energies as ``energy_<kind>``, and
``scene_yaml`` (the scene mapping as YAML text), ``stiffness`` (k per hinge,
N m/rad, as simulated), ``hinge_names``, ``body_names``, and the run's
``success``, ``status``, ``message``, ``method``, ``scheme``, ``nfev``,
``njev``, ``nlu``, ``nsteps``, ``nswitches``, ``gap_limit``, ``wall_time``;
``format_version``.
"""

from __future__ import annotations

import math
import zipfile
import zlib
from pathlib import Path

import numpy as np
import yaml

from .dynamics.result import PER_SAMPLE, SimulationResult, Status
from .errors import SceneError, TrajectoryError, shown
from .validate import load_yaml, yaml_problem

FORMAT_VERSION = 2
_ARRAYS = PER_SAMPLE
#: The run's scalars: name -> kind (i integer, f number, U text, b bool).
_SCALARS = {"success": "b", "status": "i", "message": "U", "method": "U", "scheme": "U",
            "nfev": "i", "njev": "i", "nlu": "i", "nsteps": "i", "nswitches": "i",
            "gap_limit": "f", "wall_time": "f"}


def save_trajectory(path, result: SimulationResult, scene, model, flag: str = "--out") -> Path:
    """Write ``result`` with what is needed to rebuild its model; returns the path.

    Atomic; if the write fails, the trajectory is saved in a fallback file
    and the :class:`~panel_deploy.errors.PanelDeployError` (naming ``flag``)
    says where (:func:`~panel_deploy.validate.write_atomic`).
    """
    path = Path(path)
    payload = {name: getattr(result, name) for name in _ARRAYS}
    payload.update({f"energy_{k}": v for k, v in result.energy.items()})
    payload.update(
        scene_yaml=np.array(yaml.safe_dump(scene.data, sort_keys=False)),
        stiffness=model.stiffness, hinge_names=np.array([h.name for h in model.hinges]),
        body_names=np.array([b.name for b in model.bodies]),
        format_version=np.array(FORMAT_VERSION))
    payload.update({name: np.array(getattr(result, name)) for name in _SCALARS})
    from .validate import write_atomic
    return write_atomic(path, lambda f: np.savez_compressed(f, **payload), flag, mode="wb")


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
    if path.is_dir():
        raise TrajectoryError(f"{path}: is a folder, not a trajectory file")
    try:
        _check_declared_sizes(path)
        with np.load(path, allow_pickle=False) as z:
            data = {k: z[k] for k in z.files}
    except TrajectoryError:
        raise
    except (zipfile.BadZipFile, zlib.error, ValueError, OSError, EOFError, KeyError,
            NotImplementedError, RuntimeError, UnicodeDecodeError) as e:
        reason = str(e).splitlines()[0] if str(e) else type(e).__name__
        raise TrajectoryError(f"{path}: not a readable trajectory file ({reason})") from None
    if "format_version" not in data:
        raise TrajectoryError(f"{path}: missing arrays format_version")
    version = _scalar(path, data, "format_version", "i")
    if version != FORMAT_VERSION:
        raise TrajectoryError(f"{path}: format_version {version}, expected {FORMAT_VERSION} "
                              "(simulate it again with this version's simulate --out)")
    missing = [k for k in (*_ARRAYS, *_SCALARS, "scene_yaml", "stiffness") if k not in data]
    if missing:
        raise TrajectoryError(f"{path}: missing arrays {', '.join(missing)}")
    _check_arrays(path, data)
    try:
        scene = scene_from_dict(load_yaml(_scalar(path, data, "scene_yaml", "U")))
    except SceneError as e:
        raise TrajectoryError(f"{path}: stored scene is invalid ({e})") from None
    except yaml.YAMLError as e:
        raise TrajectoryError(f"{path}: stored scene is invalid ({yaml_problem(e)})") from None
    energy = {k[len("energy_"):]: v for k, v in data.items() if k.startswith("energy_")}
    run = {name: _scalar(path, data, name, kind) for name, kind in _SCALARS.items()}
    status = run["status"]
    if status not in Status._value2member_map_:
        raise TrajectoryError(f"{path}: status: {status} is not a simulation status "
                              f"({', '.join(f'{s.value} {s.name}' for s in Status)})")
    run.update(success=bool(run["success"]), status=Status(status))
    if run["success"] != (status == Status.REACHED_T_END):
        raise TrajectoryError(f"{path}: success {run['success']} contradicts status {status}")
    result = SimulationResult(**{k: data[k] for k in _ARRAYS}, energy=energy, **run)
    return result, scene, data["stiffness"]


#: Bytes per body and sample of a trajectory, with room: pose, velocities
#: (144 bytes) and the hinge angles, rates and closure values that go with a body.
_BYTES_PER_BODY_SAMPLE = 256


def _check_declared_sizes(path):
    """Refuse a member whose ``.npy`` header declares more data than the member
    holds, or more samples than a scene can have, and an archive declaring more
    than the largest trajectory a scene can ask for, before numpy allocates it:
    a 300-byte header can declare a terabyte, and 8 GB of zeros deflate to 8 MB."""
    from .scene import MAX_SAMPLES, MAX_SIDE

    largest = MAX_SAMPLES * MAX_SIDE ** 2 * _BYTES_PER_BODY_SAMPLE
    total = 0
    with zipfile.ZipFile(path) as archive:
        for info in archive.infolist():
            where = f"{path}: {info.filename}"
            if not info.filename.endswith(".npy"):
                raise TrajectoryError(f"{where}: not an array (a trajectory file holds only "
                                      ".npy members)")
            with archive.open(info) as f:
                version = np.lib.format.read_magic(f)
                if version not in ((1, 0), (2, 0)):
                    raise TrajectoryError(f"{where}: .npy format version {version} is not "
                                          "one numpy.savez writes for these arrays")
                read_header = (np.lib.format.read_array_header_1_0 if version == (1, 0)
                               else np.lib.format.read_array_header_2_0)
                shape, _, dtype = read_header(f)
                declared = math.prod(shape) * dtype.itemsize
                held = info.file_size - f.tell()
            if declared > held:
                raise TrajectoryError(f"{where}: its header declares shape {shown(shape)} of "
                                      f"{dtype} ({declared} bytes), but the member holds "
                                      f"{held} bytes")
            if info.filename[:-len(".npy")] in _ARRAYS and shape and shape[0] > MAX_SAMPLES:
                raise TrajectoryError(f"{where}: {shape[0]} samples, above the limit of "
                                      f"{MAX_SAMPLES} a scene can ask for")
            total += declared
    if total > largest:
        raise TrajectoryError(f"{path}: its arrays declare {total} bytes, above the {largest} "
                              f"of the largest trajectory a scene can ask for ({MAX_SAMPLES} "
                              f"samples of {MAX_SIDE} x {MAX_SIDE} panels)")


def _scalar(path, data, name, kind):
    """Stored 0-d array ``name`` as a Python value of kind i (integer), f (a
    finite number), b (bool) or U (text); TrajectoryError naming it if it has
    another type or shape."""
    a = data[name]
    accepted = {"i": "iu", "f": "fiu", "b": "biu", "U": "U"}[kind]
    ok = a.shape == () and a.dtype.kind in accepted and (kind != "f" or np.isfinite(a))
    if not ok:
        want = {"i": "an integer", "f": "a finite number", "b": "true or false",
                "U": "text"}[kind]
        raise TrajectoryError(f"{path}: {name}: expected {want}, got an array of "
                              f"{a.dtype} with shape {a.shape}")
    return a.item()


def _check_arrays(path, data):
    """Dtype, shape and sample count of every stored per-sample array."""
    from .validate import check_finite

    def float_array(name, ndim):
        a = data[name]
        if a.dtype.kind not in "fiu" or a.ndim != ndim:
            raise TrajectoryError(f"{path}: {name}: expected a {ndim}-d array of numbers, got "
                                  f"{a.dtype} with shape {a.shape}")
        return a

    t = float_array("t", 1)
    s = len(t)
    if s == 0:
        raise TrajectoryError(f"{path}: t: no samples")
    check_finite("t", t, str(path), TrajectoryError)
    if s > 1 and not np.all(np.diff(t) > 0):
        raise TrajectoryError(f"{path}: t[{int(np.argmax(np.diff(t) <= 0)) + 1}]: sample "
                              "instants must increase")
    theta = float_array("theta", 2)
    for name, ndim in (("omega", 2), ("rotation", 4), ("position", 3), ("linear_velocity", 3),
                       ("angular_velocity", 3), ("constraint_gap", 1), ("closure_sigma_min", 2),
                       ("cut_theta", 2)):
        a = float_array(name, ndim)
        if len(a) != s:
            raise TrajectoryError(f"{path}: {name} has {len(a)} samples, t has {s}")
    if len(theta) != s:
        raise TrajectoryError(f"{path}: theta has {len(theta)} samples, t has {s}")
    if data["omega"].shape != theta.shape:
        raise TrajectoryError(f"{path}: omega has shape {data['omega'].shape}, theta "
                              f"{theta.shape}")
    nb = data["position"].shape[1]
    for name, shape in (("rotation", (s, nb, 3, 3)), ("position", (s, nb, 3)),
                        ("linear_velocity", (s, nb, 3)), ("angular_velocity", (s, nb, 3))):
        if data[name].shape != shape:
            raise TrajectoryError(f"{path}: {name} has shape {data[name].shape}, expected {shape}")
    for name in data:
        if name.startswith("energy_") and (data[name].dtype.kind not in "fiu"
                                           or data[name].shape != (s,)):
            raise TrajectoryError(f"{path}: {name} has shape {data[name].shape}, expected ({s},)")
    k = data["stiffness"]
    if k.dtype.kind not in "fiu" or k.ndim != 1:
        raise TrajectoryError(f"{path}: stiffness: expected a 1-d array of numbers, got "
                              f"{k.dtype} with shape {k.shape}")
