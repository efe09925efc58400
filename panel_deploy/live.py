"""A deployment run live: what the ROS nodes and ``panel-deploy run`` share, without ROS.

The dynamics node's parameters as a validated value (:class:`DynamicsParameters`),
the scene and model they make (:func:`configure`), the scene as the text a
``/panel_deploy/model`` message carries (:func:`scene_yaml`, :func:`scene_from_yaml`),
a sampled run handed out sample by sample while it is computed
(:func:`stream_samples`), and the wall-clock pacing of simulated time
(:class:`Pacer`).
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass, replace
from typing import NamedTuple

import numpy as np
import yaml

from .build import build_model
from .dynamics import simulate_segments
from .dynamics.report import hinge_states
from .dynamics.pack import pack
from .dynamics.result import SimulationResult, concatenate
from .errors import SceneError, shown
from .model import Model
from .scene import INTEGRATORS, Scene, SimulationSection, apply_overrides, scene_from_dict
from .validate import load_yaml, yaml_problem

#: Samples per integrator block: 50 ms of simulated time at 200 Hz, small
#: enough that the first message leaves within milliseconds of the request.
BLOCK_SAMPLES = 10


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
    data = apply_overrides(scene.data, [f"{k}={_yaml_value(v)}" for k, v in keys.items() if v])
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


def scene_yaml(scene: Scene, model: Model | None = None) -> str:
    """The scene as YAML text, as ``/panel_deploy/model`` and recordings carry it.

    With ``model``, its k per hinge becomes ``hinges.overrides`` and, when
    every sprung hinge has the same c/k, that ratio ``hinges.damping_ratio``,
    so that readers rebuild the model's k and c.
    """
    data = dict(scene.data)
    if model is not None:
        hinges = dict(data.get("hinges") or {})
        hinges["overrides"] = {h.name: float(h.k) for h in model.hinges}
        ratios = {h.c / h.k for h in model.hinges if h.k > 0}
        if ratios and max(ratios) - min(ratios) <= 1e-12 * max(ratios):
            hinges["damping_ratio"] = float(min(ratios))
        data["hinges"] = hinges
    return yaml.safe_dump(data, sort_keys=False)


def scene_from_yaml(text: str, source: str = "/panel_deploy/model") -> Scene:
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


class Sample(NamedTuple):
    """One instant of a deployment, every hinge in :func:`hinge_states` order."""

    t: float              #: s
    theta: np.ndarray     #: rad
    omega: np.ndarray     #: rad/s
    torque: np.ndarray    #: N m
    rotation: np.ndarray  #: (nb, 3, 3) body orientations in the ground frame
    position: np.ndarray  #: (nb, 3) body centroids, m


class Deployment:
    """A deployment computed block by block and handed out sample by sample.

    Iterating yields :class:`Sample` as soon as its block is integrated; the
    blocks continue one integration, so the samples are those of
    :func:`~panel_deploy.dynamics.simulate` with the same settings. After the
    iteration, :attr:`result` is the whole run (what was computed, when
    stopped early). :meth:`stop` (from any thread) ends it at the next block.
    """

    def __init__(self, model: Model, settings, block: int = BLOCK_SAMPLES):
        self.model = model
        self.settings = settings
        self.block = block
        self.names = None
        self.blocks: list = []
        self.stopped = False
        #: Set by :meth:`stop`; wait on it to sleep no longer than the run lasts.
        self.stopping = threading.Event()

    def stop(self) -> None:
        self.stopping.set()

    def __iter__(self):
        segments = simulate_segments(self.model, self.settings, segment_samples=self.block)
        packed = pack(self.model)
        try:
            for block in segments:
                self.blocks.append(block)
                names, theta, omega, torque = hinge_states(self.model, block, packed)
                self.names = names
                for j in range(len(block.t)):
                    yield Sample(float(block.t[j]), theta[j], omega[j], torque[j],
                                 block.rotation[j], block.position[j])
                if self.stopping.is_set():
                    self.stopped = True
                    return
        finally:
            segments.close()

    @property
    def result(self) -> SimulationResult | None:
        """The samples computed so far as one result (None before the first block)."""
        if not self.blocks:
            return None
        result = concatenate(self.blocks)
        if self.stopped and result.success:
            result = replace(result, success=False, status=1,
                             message=f"stopped at t = {result.t[-1]:.6g} s")
        return result


class Pacer:
    """Wall-clock pacing of simulated time: ``wait(t)`` returns when ``t`` (s,
    simulated) is due at ``real_time_factor`` simulated seconds per wall
    second, counting from the first call; 0 never waits."""

    def __init__(self, real_time_factor: float, stop: threading.Event | None = None):
        self.factor = real_time_factor
        self._stop = stop or threading.Event()
        self._origin = None

    def wait(self, t: float) -> None:
        if self.factor <= 0:
            return
        now = time.monotonic()
        if self._origin is None:
            self._origin = now - t / self.factor
        delay = self._origin + t / self.factor - now
        if delay > 0:
            self._stop.wait(delay)


def load_array(scene: str, stiffness_file: str = "") -> tuple:
    """What the ``array_model`` node publishes: ``(scene, model, scene_text)``.

    ``scene`` is a scene file or the name of a shipped scene; a
    ``stiffness_file`` (an optimisation result) sets k per hinge, and the
    scene text then carries it as ``hinges.overrides``.

    Raises
    ------
    SceneError, OptimisationError
        The scene or the stiffness file is missing or invalid.
    """
    from .optimise import load_hinges
    from .scene import load_scene, resolve_scene

    if not scene:
        raise SceneError("scene", "expected a scene file or the name of a shipped scene")
    parsed = load_scene(resolve_scene(scene))
    model = build_model(parsed)
    if not stiffness_file:
        return parsed, model, scene_yaml(parsed)
    k, _ = load_hinges(stiffness_file, model)
    model = model.with_stiffness(k)
    text = scene_yaml(parsed, model)
    return scene_from_yaml(text, source=parsed.source), model, text


def optimisation_scene(scene: Scene, **overrides) -> Scene:
    """``scene`` with ``optimisation`` keys overridden (None or empty keeps the
    scene's value), validated as a scene file's would be.

    Raises
    ------
    SceneError
        Naming ``optimisation.<key>`` and what was wrong.
    """
    from .scene import apply_overrides

    given = {k: v for k, v in overrides.items() if v is not None and v != () and v != ""}
    data = apply_overrides(scene.data, [f"optimisation.{k}={_yaml_value(v)}"
                                        for k, v in given.items()])
    return scene_from_dict(data, source=scene.source)


def _yaml_value(v) -> str:
    return yaml.safe_dump(list(v) if isinstance(v, tuple) else v, default_flow_style=True).strip()


class Throttle:
    """At most one report per ``period`` s (wall clock) of each kind: the first
    at once, the others counted and told with the next one, so a stream of
    bad messages gives a line a second instead of a line a message.

    ``throttle(kind)`` returns None to stay quiet, else how many reports of
    that kind were held back since the last one.
    """

    def __init__(self, period: float = 1.0, clock=time.monotonic):
        self.period = period
        self._clock = clock
        self._last: dict = {}
        self._held: dict = {}

    def __call__(self, kind: str) -> int | None:
        now = self._clock()
        if now - self._last.get(kind, -math.inf) < self.period:
            self._held[kind] = self._held.get(kind, 0) + 1
            return None
        self._last[kind] = now
        return self._held.pop(kind, 0)
