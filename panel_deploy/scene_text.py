"""The scene as text: what ``/panel_deploy/model``, recordings and trajectory
files carry (:func:`scene_yaml`), read back and validated (:func:`scene_from_yaml`),
and a scene with keys replaced (:func:`optimisation_scene`)."""

from __future__ import annotations

import yaml

from . import contract
from .errors import SceneError
from .model import Model
from .scene import OptimisationSection, Scene, apply_overrides, parse_section, scene_from_dict
from .validate import load_yaml, yaml_problem


def scene_yaml(scene: Scene, model: Model | None = None) -> str:
    """The scene as YAML text, as ``/panel_deploy/model`` and recordings carry it.

    With ``model``, its k per hinge becomes ``hinges.overrides`` and its c:
    when every sprung hinge has the same c/k, that ratio as
    ``hinges.damping_ratio``, else each c as ``hinges.damping_overrides``,
    so that readers rebuild the model's k and c exactly.
    """
    data = dict(scene.data)
    if model is not None:
        hinges = dict(data.get("hinges") or {})
        hinges.pop("damping_overrides", None)
        hinges["overrides"] = {h.name: float(h.k) for h in model.hinges}
        ratios = {h.c / h.k for h in model.hinges if h.k > 0}
        unsprung = [h for h in model.hinges if h.k == 0 and h.c != 0]
        if all(h.c == scene.hinges.damping_ratio * h.k for h in model.hinges):
            pass  # the scene's own ratio rebuilds every c to the last bit
        elif ratios and max(ratios) - min(ratios) <= 1e-12 * max(ratios) and not unsprung:
            hinges["damping_ratio"] = float(min(ratios))
        else:
            hinges["damping_overrides"] = {h.name: float(h.c) for h in model.hinges}
        data["hinges"] = hinges
    return yaml.safe_dump(data, sort_keys=False)


def scene_from_yaml(text: str, source: str = contract.resolve(contract.MODEL.name)) -> Scene:
    """Parse and validate a scene sent as YAML text.

    Raises
    ------
    SceneError
        Text that is not YAML, or not a valid scene.
    """
    try:
        data = load_yaml(text)
    except yaml.YAMLError as e:
        raise SceneError(source, f"not valid YAML ({yaml_problem(e)})") from None
    return scene_from_dict(data, source=source)


def optimisation_scene(scene: Scene, **overrides) -> Scene:
    """``scene`` with ``optimisation`` keys overridden (None or empty keeps the
    scene's value), validated as a scene file's would be.

    Raises
    ------
    SceneError
        Naming ``optimisation.<key>`` and what was wrong.
    """
    data = apply_overrides(scene.data, [f"optimisation.{k}={yaml_value(v)}"
                                        for k, v in _given(overrides).items()])
    return scene_from_dict(data, source=scene.source)


def check_optimisation(**overrides) -> None:
    """Check ``optimisation`` keys as :func:`optimisation_scene` does, before
    any scene is known (a node without a model yet): each key on its own, as
    in a scene file.

    Raises
    ------
    SceneError
        Naming ``optimisation.<key>`` and what was wrong.
    """
    given = {k: list(v) if isinstance(v, tuple) else v for k, v in _given(overrides).items()}
    parse_section(OptimisationSection, given, "optimisation")


def _given(overrides: dict) -> dict:
    """The keys of ``overrides`` that are set (None or empty keeps the scene's value)."""
    return {k: v for k, v in overrides.items() if v is not None and v != () and v != ""}


def yaml_value(v) -> str:
    """``v`` as a YAML flow value for :func:`~panel_deploy.scene.apply_overrides`."""
    return yaml.safe_dump(list(v) if isinstance(v, tuple) else v, default_flow_style=True).strip()
