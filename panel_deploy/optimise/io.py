"""The optimisation result file (YAML) and reading stiffness back from it.

Format (``format: panel_deploy.stiffness/1``)::

    format: panel_deploy.stiffness/1
    scene: paper_4x4
    hinges:                      # every hinge of the model, N m/rad and N m s/rad
      h_1_1-1_2: {k: 0.0123, c: 0.000529}
      ...
    groups: [[h_1_1-1_2, h_1_3-1_4], ...]
    bounds: [0.001, 0.2]         # N m/rad
    damping_ratio: 0.043         # s, c/k of the result (median over sprung hinges)
    damping_ratio_bounds: null   # s, [lower, upper] if c/k was searched for too
    damping_window: null         # s, then the c/k range over which K is feasible
    f: -0.21                     # objective, Eq. (8) + flat term
    v: 0.0                       # m/s, approach speed at the first collision
    d: 0.021                     # m, smallest proximal distance
    collision: null              # or {time, pair, ...} of the first collision
    reached_flat: true
    flat_residual: 0.003         # rad, closest approach to flat (largest |theta|) before any collision
    initial: {f, v, d, collision, ...}   # the same for K_0
    success, status, message, nfev, nit, nstarts, method, wall_time
    first_feasible: {nfev, wall_time}    # when the first feasible K came back, or null
    circuit: 11                  # fold.circuit optimised (an index or the cells in order)
    circuit_choice: {...}        # with fold.circuit: auto, how the ranking chose it

:func:`load_stiffness` reads only ``hinges`` (and accepts a plain
``{hinge: k}`` mapping there), so hand-written files work too.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import yaml

from ..errors import OptimisationError, shown

FORMAT = "panel_deploy.stiffness/1"
#: Every top-level key a result file may have (what :func:`result_to_dict` and
#: ``panel-deploy optimise`` write); any other is refused by :func:`load_hinges`.
RESULT_KEYS = ("format", "scene", "hinges", "groups", "bounds", "damping_ratio",
               "damping_ratio_bounds", "damping_window", "f", "v", "d", "collision",
               "flat_residual", "reached_flat", "simulated", "message", "t_stop", "press_speed",
               "initial",
               "success", "status", "nfev", "nit", "nstarts", "method", "wall_time",
               "first_feasible", "verification", "manufacture", "tolerance", "circuit",
               "circuit_choice")


def result_to_dict(result, scene_name: str = "", extra: dict | None = None) -> dict:
    """Plain-Python form of an :class:`~panel_deploy.optimise.search.OptimisationResult`.

    ``extra`` (plain values) is appended, e.g. the verification and
    manufacturing checks of ``panel-deploy optimise``. A NaN or inf anywhere
    in it makes the result a failure (``success`` false, the message names
    the first such key): a NaN is never an answer.
    """
    from ..validate import first_non_finite_value
    names = result.problem.hinge_names
    out = {"format": FORMAT, "scene": scene_name,
           "hinges": {n: {"k": float(k), "c": float(c)}
                      for n, k, c in zip(names, result.k, result.c)},
           "groups": result.problem.group_names(),
           "bounds": [float(b) for b in result.problem.bounds],
           "damping_ratio": float(np.median(result.c / result.k)),
           "damping_ratio_bounds": None if result.problem.damping_bounds is None
           else [float(b) for b in result.problem.damping_bounds],
           "damping_window": None if result.damping_window is None
           else [float(b) for b in result.damping_window]}
    out.update(result.best.to_dict())
    out["initial"] = result.initial.to_dict() if result.initial is not None else None
    out.update(success=bool(result.success), status=int(result.status), message=result.message,
               nfev=int(result.nfev), nit=int(result.nit), nstarts=int(result.nstarts),
               method=result.method, wall_time=round(float(result.wall_time), 3),
               first_feasible=None if result.first_feasible is None else
               {"nfev": int(result.first_feasible[0]),
                "wall_time": round(float(result.first_feasible[1]), 3)})
    out.update(extra or {})
    bad = first_non_finite_value(out)
    if bad is not None:
        out.update(success=False, message=f"non-finite result: {bad} ({out['message']})")
    return out


def dump_result(result, scene_name: str = "", extra: dict | None = None) -> str:
    """The YAML text :func:`save_result` writes."""
    return yaml.safe_dump(result_to_dict(result, scene_name, extra), sort_keys=False,
                          default_flow_style=None)


def save_result(result, path, scene_name: str = "", extra: dict | None = None,
                flag: str = "--out") -> Path:
    """Write ``result`` as YAML to ``path`` (see the module docstring); returns the path.

    Raises :class:`~panel_deploy.errors.PanelDeployError` naming ``flag`` and
    the fallback file holding the result if ``path`` cannot be written.
    """
    from ..validate import write_atomic
    text = dump_result(result, scene_name, extra)
    # an interrupted run never leaves half a result file; a failed write keeps
    # the result in a fallback file (the error says where)
    return write_atomic(path, lambda f: f.write(text), flag)


def load_stiffness(path, model) -> np.ndarray:
    """Hinge stiffnesses from a result file, in the order of ``model.hinges``.

    Parameters
    ----------
    path : str or Path
        A file written by :func:`save_result`, or any YAML mapping with a
        ``hinges`` mapping of hinge name to ``{k: ...}`` or to a number.
    model : Model
        Every one of its hinges must be given, and no other.

    Returns
    -------
    k : (n_hinges,) ndarray
        N m/rad; use ``model.with_stiffness(k)`` (damping follows k).

    Raises
    ------
    OptimisationError
        ``stiffness file ...`` naming the file and the offending entry.
    """
    return load_hinges(path, model)[0]


def load_damping(path, model) -> np.ndarray | None:
    """Hinge damping (N m s/rad) from a result file, or None if it gives no ``c``.

    As :func:`load_stiffness`; a file that gives ``c`` must give it for every hinge.
    """
    return load_hinges(path, model)[1]


def load_hinges(path, model) -> tuple:
    """``(k, c)`` of every hinge of ``model`` from one reading of a result file.

    k as :func:`load_stiffness`, c as :func:`load_damping` (None if the file
    gives none); a bare number for a hinge is its k.
    """
    data, where = _read_result(path)
    given = data["hinges"]
    names = [h.name for h in model.hinges]
    unknown = sorted(set(map(str, given)) - set(names))
    missing = [n for n in names if n not in given]
    # a result of fold.circuit: auto names the circuit it is for, which a scene
    # with another circuit (or auto ranking another first) does not build
    circuit = (f"; the file is for fold.circuit {data['circuit']}, "
               f"--set fold.circuit={data['circuit']} builds it") if "circuit" in data else ""
    if unknown:
        raise OptimisationError(f"{where}: hinges.{unknown[0]}: no such hinge in this model "
                                f"(hinges are: {', '.join(names)}{circuit})")
    if missing:
        raise OptimisationError(f"{where}: hinges: missing {', '.join(missing)}{circuit}")
    entries = [given[name] if isinstance(given[name], dict) else {"k": given[name]}
               for name in names]
    for name, entry in zip(names, entries):
        extra = [str(key) for key in entry if key not in ("k", "c")]
        if extra:
            raise OptimisationError(f"{where}: hinges.{name}.{extra[0]}: unknown key "
                                    "(expected k and c)")

    def values(key, unit):
        out = np.empty(len(names))
        for i, (name, entry) in enumerate(zip(names, entries)):
            value = entry.get(key)
            if isinstance(value, bool) or not isinstance(value, (int, float)) \
                    or not math.isfinite(value) or value < 0:
                raise OptimisationError(f"{where}: hinges.{name}.{key}: expected a finite number "
                                        f">= 0 {unit}, got {shown(value)}")
            out[i] = value
        return out

    k = values("k", "N m/rad")
    return k, values("c", "N m s/rad") if any("c" in e for e in entries) else None


def result_circuit(path):
    """The ``circuit`` a result file says it was optimised on (an index, or the
    cells in order), or None if it does not say.

    Raises
    ------
    OptimisationError
        As :func:`load_hinges`, for a file it cannot read.
    """
    return _read_result(path)[0].get("circuit")


def _read_result(path) -> tuple:
    """``(mapping, where)`` of a result file whose top level is valid, ``where``
    naming it for messages."""
    from ..errors import PanelDeployError
    from ..validate import load_yaml, read_text, yaml_problem

    where = f"stiffness file {str(path)!r}"
    try:
        data = load_yaml(read_text(path, "stiffness file"))
    except PanelDeployError as e:
        raise OptimisationError(f"{where}: cannot read ({str(e).rpartition(': ')[2]})") from None
    except yaml.YAMLError as e:
        raise OptimisationError(f"{where}: not valid YAML ({yaml_problem(e)})") from None
    if not isinstance(data, dict) or not isinstance(data.get("hinges"), dict):
        raise OptimisationError(f"{where}: expected a mapping with a 'hinges' mapping "
                                f"(hinge name -> k), as written by panel-deploy optimise")
    if "format" in data and data["format"] != FORMAT:
        raise OptimisationError(f"{where}: format: expected {FORMAT}, got {shown(data['format'])}")
    # A hand-written file (no format) gets no unknown key past: a misspelt key
    # would be ignored silently. Files save_result wrote may carry extra sections.
    unknown = [str(key) for key in data if key not in RESULT_KEYS] if "format" not in data else []
    if unknown:
        raise OptimisationError(f"{where}: {unknown[0]}: unknown key (a result file has "
                                f"{', '.join(RESULT_KEYS)})")
    return data, where
