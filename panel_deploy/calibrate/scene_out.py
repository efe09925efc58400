"""The calibrated scene: the input scene with the fitted values written as the
keys every command and node already reads (``hinges.stiffness``,
``hinges.damping_ratio``, ``hinges.overrides``, ``hinges.damping_overrides``,
``air.drag_coefficient``), plus the fit's figures as the informational
``calibration.deployment`` entry.

With one factor per kind (``per`` scale) the factors go into the scene's
own stiffness and c/k (c_i = s_c c_i,scene and k_i = s_k k_i,scene give
c/k = s_c / s_k times the scene's), scaling its overrides alike; per group
the hinges whose k or c differ from those get an override. Either way the
scene rebuilds the fitted model's k and c.
"""

from __future__ import annotations

import copy
import math

import numpy as np

from .fit import CalibrationResult

#: What a parameter's value is, by kind.
UNITS = {"stiffness": "factor of the scene's k", "damping": "factor of the scene's c",
         "drag": "C_d"}


def _close(a: float, b: float) -> bool:
    return math.isclose(a, b, rel_tol=1e-12, abs_tol=0.0)


def calibrated_data(scene, result: CalibrationResult, collisions: dict | None = None) -> dict:
    """The scene mapping of ``scene`` with ``result``'s values applied and
    its ``calibration`` section (:func:`calibration_section`), with the
    first collisions (:func:`~.collisions.first_collisions`) when given."""
    data = copy.deepcopy(scene.data)
    p = result.parameters
    value = dict(zip(p.names, map(float, result.values)))
    if {"stiffness", "damping"} & set(p.fit):
        hinges = dict(data.get("hinges") or {})
        s_k = value.get("stiffness", 1.0)
        s_c = value.get("damping", s_k)  # without its own factor c follows k
        stiffness = scene.hinges.stiffness * (s_k if p.per == "scale" else 1.0)
        ratio = scene.hinges.damping_ratio * (s_c / s_k if p.per == "scale" else 1.0)
        hinges["stiffness"], hinges["damping_ratio"] = float(stiffness), float(ratio)
        fitted = result.model.hinges
        for key, over in (("overrides", {h.name: float(h.k) for h in fitted
                                         if not _close(h.k, stiffness)}),
                          ("damping_overrides", {h.name: float(h.c) for h in fitted
                                                 if not _close(h.c, ratio * h.k)})):
            if over:
                hinges[key] = over
            else:
                hinges.pop(key, None)
        data["hinges"] = hinges
    if "drag" in p.fit:
        data["air"] = {**(data.get("air") or {}), "drag_coefficient": value["drag"]}
    section = calibration_section(result)
    if collisions is not None:
        section["first_collision"] = collisions
    # Beside what other calibrations of the scene wrote (a free-vibration test's figures).
    data["calibration"] = {**(data.get("calibration") or {}), "deployment": section}
    return data


def _number(x: float):
    """A float for YAML: finite values rounded to 6 significant digits, else None."""
    return float(f"{x:.6g}") if np.isfinite(x) else None


def calibration_section(result: CalibrationResult) -> dict:
    """What the fit found and from which data, as plain YAML values."""
    p, u, res = result.parameters, result.uncertainty, result.residuals
    model = p.model
    parameters = {}
    for i, (name, kind, group) in enumerate(zip(p.names, p.kinds, p.groups)):
        entry = {"value": _number(result.values[i]), "nominal": _number(p.nominal[i]),
                 "unit": UNITS[kind]}
        if p.per == "group" and kind != "drag":
            entry["hinges"] = [model.hinges[h].name for h in group]
        if name in result.problems:
            entry.update(identifiable=False, why=result.problems[name], held=name in result.held)
        elif u is not None:
            se, lower, upper = u.of(name)
            entry.update(identifiable=True, standard_error=_number(se),
                         interval_95=[_number(lower), _number(upper)])
        parameters[name] = entry
    recordings = []
    for j, (run, rms) in enumerate(zip(res.runs, result.rms)):
        entry = {"file": run.path, "hinges": list(run.hinges), "samples": int(len(run.t)),
                 "duration": _number(run.duration), "first_stamp": float(run.stamp0),
                 "release_offset": _number(result.offsets[j])}
        if u is not None and f"release[{j}]" not in u.problems:
            _, lower, upper = u.of(f"release[{j}]")
            entry["release_offset_interval_95"] = [_number(lower), _number(upper)]
        entry["residual_rms"] = {h: _number(v) for h, v in rms.items()}
        recordings.append(entry)
    section = {
        "success": bool(result.success), "status": int(result.status),
        "message": result.message, "fitted": list(p.fit), "per": p.per,
        "parameters": parameters,
        "start": {name: _number(v) for name, v in zip(p.names, p.start)},
        "recordings": recordings,
        "noise": _number(result.noise),
        "samples": int(result.samples),
        "cost": _number(result.cost),
        "residual_rms": _number(result.residual_rms),
        "iterations": int(result.iterations), "simulations": int(result.simulations),
        "wall_time": _number(result.wall_time),
    }
    if u is not None:
        section["correlation"] = {"names": list(u.names),
                                  "matrix": [[_number(c) for c in row] for row in u.correlation]}
        section["condition_number"] = _number(u.condition)
    section["warnings"] = result.warnings
    return section
