"""What a deployment runs: the dynamics node's parameters as a validated value
(:class:`DynamicsParameters`), the scene and model they make (:func:`configure`),
the one rule for k and c (:func:`apply_stiffness`), and what the ``array_model``
node publishes (:func:`load_array`)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .build import build_model
from .errors import SceneError, shown
from .model import Model
from .scene import INTEGRATORS, Scene, SimulationSection, apply_overrides, scene_from_dict
from .scene_text import scene_from_yaml, scene_yaml, yaml_value


@dataclass(frozen=True)
class DynamicsParameters:
    """What the ``dynamics`` node's parameters ask of the next deployment.

    A value that keeps the scene's own is the default of each field.

    Attributes
    ----------
    stiffness : tuple of float
        k, N m/rad: one per stiffness group (``model.hinge_groups``)
        or one per hinge (model order); empty: the scene's.
    damping_ratio : float
        c/k, s, for every hinge; negative: the scene's.
    method : str
        Integrator (``simulation.method``); empty: the scene's.
    rtol : float
        ``simulation.rtol`` (atol keeps its ratio to it); 0: the scene's.
    closure : str
        "penalty" or "exact"; empty: the scene's.
    t_end : float
        s; 0: the scene's.
    rate_hz : float
        Samples per simulated second: a run has ``round(t_end * rate_hz) + 1``.
    real_time_factor : float
        Simulated seconds per wall second; 0: as fast as computed.
    """

    stiffness: tuple = ()
    damping_ratio: float = -1.0
    method: str = ""
    rtol: float = 0.0
    closure: str = ""
    t_end: float = 0.0
    rate_hz: float = 200.0
    real_time_factor: float = 1.0

    def __post_init__(self):
        if any(not (isinstance(k, (int, float)) and math.isfinite(k) and k >= 0)
               for k in self.stiffness):
            raise SceneError("stiffness", f"expected finite numbers >= 0 N m/rad, got "
                                          f"{shown(list(self.stiffness))}")
        for name, low in (("damping_ratio", None), ("rtol", 0.0), ("t_end", 0.0),
                          ("rate_hz", 0.0), ("real_time_factor", 0.0)):
            v = getattr(self, name)
            if not math.isfinite(v) or (low is not None and v < low):
                raise SceneError(name, f"expected a finite number >= {low:g}, got {shown(v)}"
                                 if low is not None else f"expected a finite number, got {shown(v)}")
        if not self.rate_hz > 0:
            raise SceneError("rate_hz", f"expected a number > 0, got {shown(self.rate_hz)}")
        if self.method and self.method not in INTEGRATORS:
            raise SceneError("method", f"expected one of {', '.join(INTEGRATORS)} (or empty for "
                                       f"the scene's), got {shown(self.method)}")
        if self.closure not in ("", "penalty", "exact"):
            raise SceneError("closure", f"expected penalty or exact (or empty for the scene's), "
                                        f"got {shown(self.closure)}")
        if self.rtol >= 1:
            raise SceneError("rtol", f"expected a relative tolerance below 1, got {shown(self.rtol)}")
        if self.t_end:  # the schema's limit holds before a scene has arrived too
            SimulationSection.__dataclass_fields__["t_end"].metadata["parse"](self.t_end, "t_end")


def apply_stiffness(model: Model, stiffness, damping_ratio: float | None = None) -> Model:
    """``model`` with k given per stiffness group or per hinge (N m/rad).

    ``damping_ratio`` (c/k, s) sets every hinge's damping; None keeps each
    hinge's c/k. Empty ``stiffness`` keeps the model's k.

    Raises
    ------
    SceneError
        ``stiffness`` whose length is neither the group count nor the hinge count.
    """
    k = np.asarray(stiffness, dtype=float) if len(stiffness) else model.stiffness
    groups = model.hinge_groups or tuple((i,) for i in range(len(model.hinges)))
    if k.shape == (len(groups),) and len(groups) != len(model.hinges):
        per_hinge = np.empty(len(model.hinges))
        for g, idx in enumerate(groups):
            per_hinge[list(idx)] = k[g]
        k = per_hinge
    if k.shape != (len(model.hinges),):
        raise SceneError("stiffness", f"expected {len(groups)} values (one per stiffness group: "
                                      f"{_group_text(model, groups)}) or {len(model.hinges)} (one per "
                                      f"hinge), got {k.size}")
    c = None if damping_ratio is None else damping_ratio * k
    return model.with_stiffness(k, c)


def result_model(scene: Scene, model: Model, result_file) -> tuple:
    """The one rule for a result file (``optimise --out``): its k per hinge, c
    following k at the scene's c/k (Rayleigh damping, paper section 3.3), as the
    dynamics node's ``stiffness`` and ``damping_ratio`` parameters do.

    Returns ``(model, c_file)``: the model so damped, and the file's own c per
    hinge (N m s/rad), so that a caller can say when it differs.

    Raises
    ------
    OptimisationError
        The file is missing, invalid, or not for this model's hinges.
    """
    from .optimise import load_hinges

    k, c_file = load_hinges(result_file, model)
    return apply_stiffness(model, k, scene.hinges.damping_ratio), c_file


def damping_ratio_of(model: Model, c) -> float | None:
    """The c/k (s) of damping ``c`` per hinge on ``model``'s k: the median over
    sprung hinges (one value for a result of one damping ratio); None unsprung."""
    sprung = model.stiffness > 0
    if not sprung.any():
        return None
    return float(np.median(np.asarray(c, dtype=float)[sprung] / model.stiffness[sprung]))


def _group_text(model, groups):
    return "; ".join(",".join(model.hinges[i].name for i in g) for g in groups)


#: The dynamics parameter that sets each scene key :func:`configure` overrides.
PARAMETER_OF = {"simulation.t_end": "t_end", "simulation.max_step": "t_end",
                "simulation.samples": "rate_hz", "simulation.method": "method",
                "simulation.rtol": "rtol", "simulation.atol": "rtol", "closure.method": "closure"}


def configure(scene: Scene, params: DynamicsParameters) -> tuple:
    """The scene and model a deployment with ``params`` runs: ``(scene, model)``.

    Raises
    ------
    SceneError
        Naming the parameter whose value the scene cannot take.
    """
    sim = scene.simulation
    t_end = params.t_end or sim.t_end
    keys = {"simulation.t_end": t_end, "simulation.samples": round(t_end * params.rate_hz) + 1,
            "simulation.method": params.method, "closure.method": params.closure}
    if params.rtol:
        keys.update({"simulation.rtol": params.rtol,
                     "simulation.atol": sim.atol * params.rtol / sim.rtol})
    data = apply_overrides(scene.data, [f"{k}={yaml_value(v)}" for k, v in keys.items() if v])
    try:  # the limits and cross-key rules of a scene file, as the command line has them
        scene = scene_from_dict(data, source=scene.source)
    except SceneError as e:
        parameter = PARAMETER_OF.get(e.path)
        if parameter is None:
            raise
        if e.path == "simulation.samples":
            raise SceneError(parameter, f"{params.rate_hz:g} Hz over {t_end:g} s gives "
                                        f"{keys[e.path]} samples: {e.reason}") from None
        raise SceneError(parameter, e.reason if e.path.endswith("." + parameter)
                         else f"{e.reason} (scene key {e.path})") from None
    model = build_model(scene)
    ratio = None if params.damping_ratio < 0 else params.damping_ratio
    return scene, apply_stiffness(model, params.stiffness, ratio)


def load_array(scene: str, stiffness_file: str = "") -> tuple:
    """What the ``array_model`` node publishes: ``(scene, model, scene_text)``.

    ``scene`` is a scene file or the name of a shipped scene; a
    ``stiffness_file`` (an optimisation result) sets k per hinge
    (:func:`result_model`), and the scene text then carries it as
    ``hinges.overrides``.

    Raises
    ------
    SceneError, OptimisationError
        The scene or the stiffness file is missing or invalid.
    """
    from .ranking import resolve_circuit
    from .scene import load_scene, resolve_scene

    if not scene:
        raise SceneError("scene", "expected a scene file or the name of a shipped scene")
    # fold.circuit: auto resolved here, so that the scene it publishes names the
    # circuit chosen, and every node builds that one without ranking again
    parsed = resolve_circuit(load_scene(resolve_scene(scene)))
    model = build_model(parsed)
    if not stiffness_file:
        return parsed, model, scene_yaml(parsed)
    model = result_model(parsed, model, stiffness_file)[0]
    text = scene_yaml(parsed, model)
    return scene_from_yaml(text, source=parsed.source), model, text
