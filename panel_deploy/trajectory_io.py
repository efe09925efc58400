"""Saving and loading sampled trajectories (``simulate --out``, ``collide``), and
a loaded one checked against its stored scene (:func:`check_stored_trajectory`).

Format: one ``.npz`` file (numpy's zip of ``.npy`` arrays, readable without this
package), written to a temporary file and renamed into place so that an
interrupted run never leaves a half file. docs/formats.md describes it for a
reader without this package; :data:`UNITS` and :data:`COLUMNS` are the one
statement of units and column names, stored in every file as JSON text.

Arrays: every per-sample array of :class:`~panel_deploy.dynamics.result.SimulationResult`
under its own name (``t``, ``theta``, ``omega``, ``rotation``, ``position``,
``linear_velocity``, ``angular_velocity``, ``constraint_gap``,
``closure_sigma_min``, ``cut_theta``, ``contact_onsets``), energies as ``energy_<kind>``, the
per-hinge ``stiffness`` and ``damping`` as simulated, the name arrays that
label their columns (``joint_names``, ``cut_hinge_names``, ``hinge_names``,
``body_names``), ``scene_yaml`` (the scene as YAML text with the stiffnesses
that ran), ``units`` and ``columns`` (JSON text), the run's ``success``,
``status``, ``message``, ``method``, ``scheme``, ``nfev``, ``njev``, ``nlu``,
``nsteps``, ``nswitches``, ``gap_limit``, ``wall_time``; ``format_version``.
Files of version 2 (no name arrays, no ``damping``) and 3 (no
``contact_onsets``: they load with none, so a check of them cannot see an
impact that panel contact absorbed) still load; version 2's columns are those
of the stored scene's model.
"""

from __future__ import annotations

import json
import math
import zipfile
import zlib
from pathlib import Path
from typing import NamedTuple

import numpy as np
import yaml

from .dynamics.result import ONSET_COLUMNS, PER_SAMPLE, SimulationResult, Status, no_onsets
from .errors import SceneError, TrajectoryError, shown
from .kinematics import forward_kinematics
from .validate import check_finite, foreign_file, load_yaml, yaml_problem

FORMAT_VERSION = 5
#: Versions :func:`load_trajectory` reads (2: the columns of ``theta``,
#: ``omega`` and ``cut_theta`` unnamed, no ``damping``; 2 and 3: no
#: ``contact_onsets``; 2 to 4: no ``energy_contact`` and
#: ``energy_contact_work``, whose energy balance counts the contacts' stored energy).
READABLE_VERSIONS = (2, 3, 4, 5)
_ARRAYS = PER_SAMPLE
#: The run's scalars: name -> kind (i integer, f number, U text, b bool).
_SCALARS = {"success": "b", "status": "i", "message": "U", "method": "U", "scheme": "U",
            "nfev": "i", "njev": "i", "nlu": "i", "nsteps": "i", "nswitches": "i",
            "gap_limit": "f", "wall_time": "f"}

#: SI unit of every numeric array and scalar of the file ("1": dimensionless;
#: ``energy_<kind>`` stands for every energy array).
UNITS = {"t": "s", "theta": "rad", "omega": "rad/s", "rotation": "1", "position": "m",
         "linear_velocity": "m/s", "angular_velocity": "rad/s", "constraint_gap": "m",
         "closure_sigma_min": "1", "cut_theta": "rad", "energy_<kind>": "J",
         "contact_onsets": "s, m/s, 1, m, m, m, 1, 1, 1 (by column)",
         "stiffness": "N m/rad", "damping": "N m s/rad", "gap_limit": "m", "wall_time": "s"}

#: The name array that labels the columns of each array: axis 1 of a
#: per-sample array (axis 0 is the sample), axis 0 of a per-hinge one.
COLUMNS = {"theta": "joint_names", "omega": "joint_names", "cut_theta": "cut_hinge_names",
           "rotation": "body_names", "position": "body_names", "linear_velocity": "body_names",
           "angular_velocity": "body_names", "stiffness": "hinge_names",
           "damping": "hinge_names"}


def column_names(model) -> dict:
    """The column names of a trajectory of ``model``: name array -> list of str.

    ``joint_names`` are the tree coordinates (``model.joints``: ``theta[:, i]``
    is the angle of hinge ``joint_names[i]``), ``cut_hinge_names`` the cut
    hinges, ``hinge_names`` every hinge in the model's order and
    ``body_names`` every body in the model's order.
    """
    return {"joint_names": [model.hinges[h].name for h in model.joints],
            "cut_hinge_names": [model.hinges[h].name for h in model.cut_hinges],
            "hinge_names": [h.name for h in model.hinges],
            "body_names": [b.name for b in model.bodies]}


class StoredTrajectory(NamedTuple):
    """What :func:`load_trajectory` reads back."""

    #: The run, columns as :func:`column_names` of ``model`` names them.
    result: SimulationResult
    #: Rebuilt from the stored scene.
    scene: object
    #: The stored scene's model with the stored k and c per hinge.
    model: object
    #: k per hinge as simulated, N m/rad.
    stiffness: np.ndarray
    #: c per hinge as simulated, N m s/rad (version 2: the scene's c/k times k).
    damping: np.ndarray
    #: The file's format_version.
    version: int


def save_trajectory(path, result: SimulationResult, scene, model, flag: str = "--out") -> Path:
    """Write ``result`` with what is needed to rebuild its model; returns the path.

    The stored scene carries ``model``'s k per hinge (as
    :func:`~panel_deploy.scene_text.scene_yaml` writes it) and ``damping`` its c,
    so that the file says exactly what ran. Atomic; if the write fails, the
    trajectory is saved in a fallback file and the
    :class:`~panel_deploy.errors.PanelDeployError` (naming ``flag``) says
    where (:func:`~panel_deploy.validate.write_atomic`).
    """
    from .scene_text import scene_yaml
    from .validate import write_atomic

    path = Path(path)
    payload = {name: getattr(result, name) for name in _ARRAYS}
    payload.update({f"energy_{k}": v for k, v in result.energy.items()})
    payload.update({name: np.array(names, dtype=str)
                    for name, names in column_names(model).items()})
    payload.update(
        scene_yaml=np.array(scene_yaml(scene, model)), stiffness=model.stiffness,
        damping=np.array([h.c for h in model.hinges]),
        units=np.array(json.dumps(UNITS)), columns=np.array(json.dumps(COLUMNS)),
        format_version=np.array(FORMAT_VERSION))
    payload.update({name: np.array(getattr(result, name)) for name in _SCALARS})
    return write_atomic(path, lambda f: np.savez_compressed(f, **payload), flag, mode="wb")


def load_trajectory(path) -> StoredTrajectory:
    """Read a trajectory file (format version 2, 3 or 4).

    Raises
    ------
    TrajectoryError
        If the file is missing, not a trajectory file, truncated, its arrays
        have inconsistent shapes, or its column names are not those of the
        stored scene's model.
    """
    from .build import build_model
    from .scene import scene_from_dict

    path = Path(path)
    if not path.exists():
        raise TrajectoryError(f"{path}: trajectory file not found")
    if path.is_dir() or not zipfile.is_zipfile(path):
        raise TrajectoryError(f"{path}: {foreign_file(path) or 'not a trajectory file (expected an .npz archive)'}")
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
    if version not in READABLE_VERSIONS:
        raise TrajectoryError(f"{path}: format_version {version}, expected one of "
                              f"{', '.join(map(str, READABLE_VERSIONS))} (simulate it again "
                              "with this version's simulate --out)")
    named = (*COLUMNS.values(), "damping") if version >= 3 else ()
    if version < 4:
        data["contact_onsets"] = no_onsets(len(data["t"]) if "t" in data else 0)
    missing = [k for k in dict.fromkeys((*_ARRAYS, *_SCALARS, "scene_yaml", "stiffness", *named))
               if k not in data]
    if missing:
        raise TrajectoryError(f"{path}: missing arrays {', '.join(missing)}")
    _check_arrays(path, data)
    try:
        scene = scene_from_dict(load_yaml(_scalar(path, data, "scene_yaml", "U")))
        model = build_model(scene)
    except SceneError as e:
        raise TrajectoryError(f"{path}: stored scene is invalid ({e})") from None
    except yaml.YAMLError as e:
        raise TrajectoryError(f"{path}: stored scene is invalid ({yaml_problem(e)})") from None
    if version >= 3:
        _check_names(path, data, column_names(model))
    stiffness, damping = data["stiffness"], data.get("damping")
    for name, values in (("stiffness", stiffness), ("damping", damping)):
        if values is not None and values.shape != (len(model.hinges),):
            raise TrajectoryError(f"{path}: {name} has shape {values.shape}; the stored scene's "
                                  f"model has {len(model.hinges)} hinges")
    pair = data["contact_onsets"][:, 2]
    if np.any(pair >= len(model.contact_pairs)):
        j = int(np.argmax(pair >= len(model.contact_pairs)))
        raise TrajectoryError(f"{path}: contact_onsets[{j}, 2] = {pair[j]:g}: the stored scene's "
                              f"model has {len(model.contact_pairs)} contact pairs")
    model = model.with_stiffness(stiffness, damping)  # version 2: c follows k, as it ran
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
    return StoredTrajectory(result, scene, model, stiffness,
                            np.array([h.c for h in model.hinges]), version)


def _check_names(path, data, expected):
    """The stored name arrays must be 1-d text and equal the model's."""
    for name, want in expected.items():
        a = data[name]
        if a.dtype.kind != "U" or a.ndim != 1:
            raise TrajectoryError(f"{path}: {name}: expected a 1-d array of text, got {a.dtype} "
                                  f"with shape {a.shape}")
        got = [str(x) for x in a]
        if got != want:
            i = next((i for i, (g, w) in enumerate(zip(got, want)) if g != w), min(len(got), len(want)))
            held = shown(got[i]) if i < len(got) else "nothing"
            wanted = shown(want[i]) if i < len(want) else "nothing"
            raise TrajectoryError(f"{path}: {name}[{i}] is {held}; the stored scene's model has "
                                  f"{wanted} there ({len(want)} names)")


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
                       ("cut_theta", 2), ("contact_onsets", 2)):
        a = float_array(name, ndim)
        if len(a) != s:
            raise TrajectoryError(f"{path}: {name} has {len(a)} samples, t has {s}")
    if len(theta) != s:
        raise TrajectoryError(f"{path}: theta has {len(theta)} samples, t has {s}")
    onsets = data["contact_onsets"]
    if onsets.shape[1] != len(ONSET_COLUMNS):
        raise TrajectoryError(f"{path}: contact_onsets has {onsets.shape[1]} columns, expected "
                              f"{len(ONSET_COLUMNS)} ({', '.join(ONSET_COLUMNS)})")
    speed, pair = onsets[:, 1], onsets[:, 2]
    bad = ~((speed >= 0) & np.isfinite(speed) & (pair >= -1) & (pair == np.round(pair)))
    if bad.any():
        j = int(np.argmax(bad))
        raise TrajectoryError(f"{path}: contact_onsets[{j}]: speed {speed[j]:g} and pair "
                              f"{pair[j]:g}: expected a finite speed >= 0 and a pair index >= -1")
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
    for name in ("stiffness", "damping"):
        k = data.get(name)
        if k is None:
            continue
        if k.dtype.kind not in "fiu" or k.ndim != 1:
            raise TrajectoryError(f"{path}: {name}: expected a 1-d array of numbers, got "
                                  f"{k.dtype} with shape {k.shape}")
        if not np.all((k >= 0) & np.isfinite(k)):  # NaN fails too
            i = int(np.argmin((k >= 0) & np.isfinite(k)))
            raise TrajectoryError(f"{path}: {name}[{i}] = {k[i]}: expected a finite number >= 0")


#: Largest disagreement (m, and in rotation matrix entries) between a stored
#: pose and the one recomputed from the stored angles: round-off of the
#: forward kinematics, with room for a file written on another machine.
POSE_TOLERANCE = 1e-6


def check_stored_trajectory(where, result, model):
    """A loaded trajectory checked against the model of its stored scene.

    ``t``, ``theta`` and ``omega`` must be finite (first bad index named);
    theta/omega must have one column per coordinate of ``model``; stored poses
    (if ``result`` has them) must have one row per body and agree with the
    poses recomputed from theta within :data:`POSE_TOLERANCE`. Raises
    :class:`~panel_deploy.errors.TrajectoryError` naming ``where`` and the array.
    """
    for name in ("t", "theta", "omega"):
        check_finite(name, getattr(result, name), str(where), TrajectoryError)
    n, nb = model.n_coords, model.n_bodies
    for name in ("theta", "omega"):
        a = np.asarray(getattr(result, name))
        if name == "omega" and a.ndim == 1 and len(a) == len(result.t):
            continue  # a recording without velocities (encoders): one placeholder per sample
        if a.ndim != 2 or a.shape[1] != n:
            raise TrajectoryError(f"{where}: {name} has shape {a.shape}; the stored scene's "
                                  f"model has {n} hinge coordinates")
    rotation, position = getattr(result, "rotation", None), getattr(result, "position", None)
    if rotation is None or position is None:
        return
    rotation, position = np.asarray(rotation), np.asarray(position)
    if position.shape[1:] != (nb, 3) or rotation.shape[1:] != (nb, 3, 3):
        raise TrajectoryError(f"{where}: position/rotation have shapes {position.shape}, "
                              f"{rotation.shape}; the stored scene's model has {nb} bodies")
    s = len(result.t)
    for j in sorted({0, s // 2, s - 1}):
        R, p = forward_kinematics(model, result.theta[j])
        for name, stored, computed in (("position", position[j], p), ("rotation", rotation[j], R)):
            err = np.abs(np.asarray(stored) - computed)
            if not np.all(err <= POSE_TOLERANCE):  # NaN fails too
                b = int(np.argmax(np.nan_to_num(err, nan=np.inf).reshape(nb, -1).max(axis=1)))
                raise TrajectoryError(
                    f"{where}: {name}[{j}, {b}] ({model.bodies[b].name}) differs from the pose "
                    f"its theta gives in the stored scene by {float(np.nanmax(err)):.3g} "
                    f"(tolerance {POSE_TOLERANCE:g}): the poses or the scene do not belong to "
                    "these angles")
