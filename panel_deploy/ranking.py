"""Rank an array's packing circuits by how well they deploy: a screening run of each.

Every circuit that packs into two stacks is a design, but most of them do not
deploy: their panels collide on the way out or never lie flat. A screening run
tells them apart cheaply: the scene's own panels, hinges, closure, gravity,
air and collision settings, on one circuit at a time, simulated from the
stowed state with a short end time and a loose tolerance
(:class:`ScreeningSettings`), stopping at the first collision or the first
flat sample (:func:`panel_deploy.optimise.run_deployment`, what the stiffness
search evaluates). A colliding circuit then costs only the time up to its
collision.

:func:`rank_circuits` screens at most ``candidates`` packing circuits, the
first ones in circuit index order (:func:`panel_deploy.fold.circuits`), so a
10 x 10 array (4.7e11 circuits) is a bounded job; :func:`resolve_circuit`
turns a scene's ``fold.circuit: auto`` into the best-ranked index.

The screening is a triage, not the verdict: its loose tolerance and short
end time can misjudge a marginal circuit, so the chosen circuit's deployment
is the scene's own simulation (``panel-deploy simulate``).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from functools import partial

from .errors import PanelDeployError, SceneError
from .fold import designs
from .fold.report import short_reason

#: Circuits examined for packing at most while looking for the candidates
#: (a design costs 1-40 ms, 4 x 4 .. 10 x 10).
MAX_EXAMINED = 1000
#: Outcome classes, best first (the first item of :attr:`Screening.score`).
FLAT, NO_COLLISION, COLLISION, FAILED, NOT_SCREENED = range(5)
OUTCOMES = ("flat", "no collision", "collision", "failed", "not screened")


@dataclass(frozen=True)
class ScreeningSettings:
    """How each candidate was simulated: the scene's own settings but these.

    Attributes
    ----------
    t_end : float
        End time, s: the scene's ``simulation.t_end`` if shorter.
    rtol, atol : float
        Integrator tolerances: the scene's own if looser.
    samples : int
        Sample instants, the scene's sample interval kept over ``t_end``.
    refine : bool
        Collisions looked for between samples too (else at the samples only).
    damping_ratio : float or None
        c/k of every hinge, s; None: the scene's hinges as they are.
    """

    t_end: float
    rtol: float
    atol: float
    samples: int
    refine: bool
    damping_ratio: float | None = None

    @classmethod
    def of(cls, scene, t_end: float | None = None, rtol: float | None = None,
           refine: bool = False) -> "ScreeningSettings":
        """The screening settings of ``scene`` (its ``screening`` section) for
        the requested ``t_end`` (s) and ``rtol``, if given."""
        own = scene.screening
        t_end = own.t_end if t_end is None else t_end
        rtol = own.rtol if rtol is None else rtol
        if not (isinstance(t_end, (int, float)) and t_end > 0 and math.isfinite(t_end)):
            raise SceneError("t_end", f"expected a screening end time > 0 s, got {t_end!r}")
        if not (isinstance(rtol, (int, float)) and rtol > 0 and math.isfinite(rtol)):
            raise SceneError("rtol", f"expected a screening tolerance > 0, got {rtol!r}")
        sim = scene.simulation
        t = min(float(t_end), sim.t_end)
        r = max(float(rtol), sim.rtol)
        return cls(t_end=t, rtol=r, atol=sim.atol * r / sim.rtol,
                   samples=max(3, round((sim.samples - 1) * t / sim.t_end) + 1),
                   refine=bool(refine) and scene.collision.refine,
                   damping_ratio=own.damping_ratio)

    def scene(self, scene):
        """``scene`` simulated and checked as the screening does."""
        hinges = scene.hinges
        if self.damping_ratio is not None:
            hinges = replace(hinges, damping_ratio=self.damping_ratio)
        return scene.replace(
            hinges=hinges,
            simulation=replace(scene.simulation, t_end=self.t_end, rtol=self.rtol,
                               atol=self.atol, samples=self.samples),
            collision=replace(scene.collision, refine=self.refine))

    def to_dict(self) -> dict:
        return {"t_end": self.t_end, "rtol": self.rtol, "atol": self.atol,
                "samples": self.samples, "refine": self.refine,
                "damping_ratio": self.damping_ratio}


@dataclass(frozen=True)
class Screening:
    """One candidate circuit and its screening run.

    Attributes
    ----------
    index : int
        Circuit index (:func:`panel_deploy.fold.circuits` order).
    packs : bool
        It folds into two stacks; only those are screened.
    outcome : int
        :data:`FLAT` (collision-free until the first flat sample),
        :data:`NO_COLLISION` (collision-free to the screening end time, never
        flat), :data:`COLLISION`, :data:`FAILED` (the simulation failed before
        any collision) or :data:`NOT_SCREENED` (does not pack, or the scene
        cannot build it: ``message`` says why).
    message : str
        Why the simulation failed (also after a collision; a run that fails
        at the screening tolerance is run again at the scene's, and this
        says so), or why the circuit was not screened; empty otherwise.
    collision_time : float
        First collision, s; NaN if none.
    collision_pair : (str, str) or None
        The bodies of the first collision.
    time_to_flat : float
        First sample with every |theta| <= ``simulation.flat_tolerance``, s;
        NaN if not reached.
    flat_residual : float
        Closest approach to flat before the run stopped: the smallest, over
        samples, of the largest |theta|, rad (pi if nothing was simulated).
    clearance : float
        Smallest distance between panels of a collision-free run, m (0 for
        a colliding one, NaN if not simulated).
    wall_time : float
        s spent building and screening this candidate.
    press_speed : float
        The fastest panel contact onset of a collision-free run (every one
        slower than ``collision.impact_speed``, or it would have collided),
        m/s; 0 without any (and for other outcomes).
    margin : float
        Of a collision-free run, the stiffness search's own score of it
        (:func:`~panel_deploy.optimise.evaluate.objective`, the scene's p, q
        and flat_weight) with its fastest press standing in for the approach
        speed v: ``p v_press - q d`` when it lies flat, ``p v_press +
        flat_weight (r - tol)`` when not (d is earned only by reaching
        flat). Smaller is better: far from an impact, clear of the other
        panels, close to flat. NaN for other outcomes.
    """

    index: int
    packs: bool
    outcome: int
    message: str = ""
    collision_time: float = math.nan
    collision_pair: tuple | None = None
    time_to_flat: float = math.nan
    flat_residual: float = math.pi
    clearance: float = math.nan
    wall_time: float = 0.0
    press_speed: float = 0.0
    margin: float = math.nan

    @property
    def score(self) -> tuple:
        """Sort key, smaller is better: the outcome class, then within it the
        :attr:`margin` (FLAT, NO_COLLISION) or the latest first collision
        (COLLISION); then the earliest time to flat, then the circuit index.

        By margin, not by closeness to flat alone: on 8 x 8 (docs/findings.md
        4.8) the two circuits closest to flat after 8 s pressed panels
        together at 0.048 and 0.037 m/s, against an impact speed of 0.05,
        and the design found for the first met an impact at the re-check;
        the third, its fastest press 0.0003 m/s and 75 mm clear, gave a
        design the re-check passed, in 88 s."""
        within = {FLAT: self.margin, NO_COLLISION: self.margin,
                  COLLISION: -self.collision_time}.get(self.outcome, 0.0)
        flat = self.time_to_flat if self.outcome == FLAT else 0.0
        return (self.outcome, within, flat, self.index)

    @property
    def screened(self) -> bool:
        return self.outcome != NOT_SCREENED

    def to_dict(self) -> dict:
        def number(x):
            return None if math.isnan(x) else float(x)
        return {"index": self.index, "packs": self.packs, "outcome": OUTCOMES[self.outcome],
                "message": self.message, "collision_time": number(self.collision_time),
                "collision_pair": list(self.collision_pair) if self.collision_pair else None,
                "time_to_flat": number(self.time_to_flat),
                "flat_residual": float(self.flat_residual), "clearance": number(self.clearance),
                "press_speed": float(self.press_speed), "margin": number(self.margin),
                "wall_time": self.wall_time}

    def text(self) -> str:
        """The outcome in a few words."""
        if self.outcome >= FAILED:
            return f"{OUTCOMES[self.outcome]}: {self.message}"
        note = f" ({self.message})" if self.message else ""
        press = f", fastest press {self.press_speed:.3g} m/s" if self.press_speed > 0 else ""
        if self.outcome == FLAT:
            return f"flat at {self.time_to_flat:.4g} s, no collision{press}{note}"
        if self.outcome == NO_COLLISION:
            return f"no collision, closest to flat {self.flat_residual:.3g} rad{press}{note}"
        return (f"collision at {self.collision_time:.4g} s: "
                f"{' - '.join(self.collision_pair or ())}{note}")


@dataclass(frozen=True)
class Ranking:
    """Circuits of an array ranked by their screening runs.

    Attributes
    ----------
    rows, cols : int
    settings : ScreeningSettings
    candidates : int
        Most packing circuits screened (the bound asked for).
    examined : int
        Circuits examined, in index order from 0, to find them.
    table : tuple of Screening
        Every examined circuit, best first by :attr:`Screening.score`
        (those that do not pack last).
    wall_time : float
        s for the whole ranking.
    """

    rows: int
    cols: int
    settings: ScreeningSettings
    candidates: int
    examined: int
    table: tuple
    wall_time: float

    @property
    def screened(self) -> tuple:
        """Indices of the circuits screened, in index order."""
        return tuple(sorted(s.index for s in self.table if s.screened))

    @property
    def best(self) -> Screening | None:
        """The best-ranked screened circuit, or None if none was screened."""
        return self.table[0] if self.table and self.table[0].screened else None

    def to_dict(self) -> dict:
        return {"rows": self.rows, "cols": self.cols, "settings": self.settings.to_dict(),
                "candidates": self.candidates, "examined": self.examined,
                "screened": list(self.screened), "wall_time": self.wall_time,
                "ranking": [s.to_dict() for s in self.table]}

    def text(self) -> str:
        s = self.settings
        lines = [f"{self.rows} x {self.cols} array: {len(self.screened)} packing circuit(s) "
                 f"screened of {self.examined} examined (at most {self.candidates}), "
                 f"t_end {s.t_end:g} s, rtol {s.rtol:g}, atol {s.atol:g}, {s.samples} samples, "
                 f"{'' if s.damping_ratio is None else f'c/k {s.damping_ratio:g} s, '}"
                 f"collisions {'between samples too' if s.refine else 'at the samples'}; "
                 f"{self.wall_time:.3g} s",
                 " rank  circuit  wall (s)  outcome"]
        for rank, e in enumerate(self.table, 1):
            wall = f"{e.wall_time:8.3f}" if e.screened else f"{'-':>8}"
            lines.append(f"{rank if e.screened else '-':>5}  {e.index:7d}  {wall}  {e.text()}")
        return "\n".join(lines)


def screen_circuit(scene, index: int, settings: ScreeningSettings) -> Screening:
    """The screening run of circuit ``index`` (assumed to pack) under ``scene``.

    The scene's ground and merges are kept; a scene that cannot build this
    circuit (a merge list, hinge override or cut hinge naming another
    circuit's hinges) gives :data:`NOT_SCREENED` with the reason.
    """
    from .build import build_model
    from .optimise.evaluate import objective, run_deployment

    start = time.perf_counter()
    candidate = settings.scene(scene.replace(fold=replace(scene.fold, circuit=index)))
    try:
        model = build_model(candidate)
    except PanelDeployError as e:
        return Screening(index, True, NOT_SCREENED, f"not built: {e}",
                         wall_time=time.perf_counter() - start)
    o = run_deployment(model, candidate)
    # the message of the last simulated block: only a failure's says something
    message = "" if o.simulated else o.message
    sim = scene.simulation
    if not (o.simulated or o.collided) and settings.rtol > sim.rtol:
        # a failure of the loose tolerance (3 x 4 circuit 1 fails the energy
        # balance at 1e-4, and deploys at the paper's 1e-6): once more at the scene's
        message = (f"failed at rtol {settings.rtol:g} ({o.message}); "
                   f"screened at the scene's {sim.rtol:g}")
        o = run_deployment(model, replace(settings, rtol=sim.rtol, atol=sim.atol).scene(candidate))
        if not o.simulated:
            message = o.message
    wall = time.perf_counter() - start
    if o.collided:  # found before any failure, on the valid part of the run
        c = o.first_collision
        return Screening(index, True, COLLISION, message, float(c["t"]), tuple(c["pair"]),
                         flat_residual=o.flat_residual, clearance=0.0, wall_time=wall)
    if not o.simulated:
        return Screening(index, True, FAILED, message, flat_residual=o.flat_residual,
                         wall_time=wall)
    flat = o.reached_flat
    opt = scene.optimisation
    margin = objective(replace(o, v=o.press_speed), opt.p, opt.q, opt.flat_weight)
    return Screening(index, True, FLAT if flat else NO_COLLISION, message,
                     time_to_flat=o.t_stop if flat else math.nan, flat_residual=o.flat_residual,
                     clearance=o.d, wall_time=wall, press_speed=o.press_speed, margin=margin)


def rank_circuits(scene, candidates: int | None = None, *, t_end: float | None = None,
                  rtol: float | None = None, refine: bool = False,
                  max_examined: int = MAX_EXAMINED,
                  progress: Callable[[Screening], None] | None = None,
                  task_map: Callable | None = None) -> Ranking:
    """Rank the first ``candidates`` packing circuits of ``scene``'s array by screening runs.

    Parameters
    ----------
    scene : Scene
        Its array, fold ground and merges, physics and ``screening`` section
        (the defaults of the next three, and the screening's c/k);
        ``fold.circuit`` is ignored.
    candidates : int, optional
        Most packing circuits screened: the first ones in index order.
    t_end : float, optional
        Screening end time, s (the scene's ``simulation.t_end`` if shorter).
    rtol : float, optional
        Screening relative tolerance (the scene's ``simulation.rtol`` if
        looser); atol keeps the scene's ratio to rtol.
    refine : bool
        Look for collisions between samples too (only if the scene's
        ``collision.refine`` does); False checks at the samples, 2-3.7x
        faster on the paper scene, the collision time then on the sample grid.
    max_examined : int
        Most circuits examined for packing while looking for the candidates.
    progress : callable, optional
        Called with each examined circuit's :class:`Screening` as it is done
        (those that do not pack first).
    task_map : callable, optional
        ``task_map(fn, items)``, an iterable of ``fn(item)`` in order, to run
        the screenings on (:func:`panel_deploy.optimise.parallel.task_map`:
        local processes or a Dask cluster); default: one after the other in
        this process. The screenings are independent, so the ranking is the
        same either way.

    Returns
    -------
    Ranking
        Ordered by :attr:`Screening.score`: circuits collision-free until
        they lie flat first, then collision-free to the end time (each by
        :attr:`Screening.margin`: farthest from an impact, clearest and
        closest to flat first), then colliding (latest first collision
        first), then failed simulations, then circuits not screened (not
        packing, or not buildable by the scene).

    Raises
    ------
    SceneError
        For ``candidates`` or ``max_examined`` below 1, or a bad ``t_end`` or ``rtol``.
    """
    candidates = scene.screening.candidates if candidates is None else candidates
    for name, value in (("candidates", candidates), ("max_examined", max_examined)):
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise SceneError(name, f"expected an integer >= 1, got {value!r}")
    settings = ScreeningSettings.of(scene, t_end, rtol, refine)
    start = time.perf_counter()
    table, examined, packing = [], 0, []
    for index, design in designs(scene.array.rows, scene.array.cols):
        if len(packing) == candidates or examined == max_examined:
            break
        examined += 1
        if design.stowed is None:
            table.append(Screening(index, False, NOT_SCREENED,
                                   f"does not pack: {short_reason(design.reason)}"))
            if progress is not None:
                progress(table[-1])
        else:
            packing.append(index)
    screen = partial(screen_circuit, scene, settings=settings)
    for entry in (map if task_map is None else task_map)(screen, packing):
        table.append(entry)
        if progress is not None:
            progress(entry)
    table.sort(key=lambda s: s.score)
    return Ranking(scene.array.rows, scene.array.cols, settings, candidates, examined,
                   tuple(table), time.perf_counter() - start)


#: Circuits ``fold.circuit: auto`` chose, by the scene's content (see
#: :func:`_content`): one ranking per scene however often it is loaded and built.
_CHOSEN: dict = {}
#: Scenes remembered at most (the oldest is forgotten first).
_CHOSEN_MAX = 32


def _content(scene) -> str:
    """What a ranking depends on: every section but the informational ones."""
    return repr((scene.array, replace(scene.fold, circuit_choice=None), scene.screening, scene.hinges,
                 scene.contact, scene.closure, scene.gravity, scene.simulation,
                 scene.collision, scene.air))


def choose_circuit(scene, progress: Callable[[Screening], None] | None = None,
                   task_map: Callable | None = None) -> dict:
    """``fold.circuit: auto`` of ``scene``: the best-ranked circuit of
    :func:`rank_circuits` (the scene's ``screening``; ``progress`` and
    ``task_map`` as there), as the mapping ``fold.circuit_choice`` records
    (``index``, ``by``, ``outcome``, ``screened``, ``examined``,
    ``screening``). Ranked once per scene content in a process.

    Raises
    ------
    SceneError
        Naming ``fold.circuit`` if no circuit of the array packs into two
        stacks, or none that packs can be built from the scene.
    """
    key = _content(scene)
    if key not in _CHOSEN:
        ranking = rank_circuits(scene, progress=progress, task_map=task_map)
        best = ranking.best
        arr = scene.array
        if best is None:
            built = [s for s in ranking.table if s.packs]
            why = (f"no packing circuit can be built from this scene (circuit {built[0].index}: "
                   f"{built[0].message})" if built else
                   f"no circuit of the {arr.rows} x {arr.cols} array packs into two stacks "
                   f"({ranking.examined} examined)")
            raise SceneError("fold.circuit", f"auto: {why}")
        if len(_CHOSEN) >= _CHOSEN_MAX:
            del _CHOSEN[next(iter(_CHOSEN))]
        _CHOSEN[key] = {"index": best.index, "by": "ranking", "outcome": best.text(),
                        "screened": list(ranking.screened), "examined": ranking.examined,
                        "ranked": [{"index": s.index, "outcome": s.text()}
                                   for s in ranking.table if s.outcome < FAILED],
                        "screening": ranking.settings.to_dict()}
    return dict(_CHOSEN[key])


def resolve_circuit(scene, progress: Callable[[Screening], None] | None = None,
                    task_map: Callable | None = None):
    """``scene`` with ``fold.circuit: auto`` replaced by the chosen index
    (:func:`choose_circuit`), ``fold.circuit_choice`` saying how, in its
    sections and in the mapping it stores (what recordings and trajectory
    files carry); any other scene as it is.

    Raises
    ------
    SceneError
        As :func:`choose_circuit`.
    """
    if scene.fold.circuit != "auto":
        return scene
    return _with_choice(scene, choose_circuit(scene, progress, task_map))


def next_ranked(scene, why: str):
    """The circuit after ``scene``'s in the ranking that chose it: ``scene``
    (resolved from ``fold.circuit: auto`` by :func:`resolve_circuit`) on the
    next circuit of ``circuit_choice['ranked']`` (the screened circuits whose
    simulation did not fail, best first), its ``circuit_choice`` saying
    ``why`` the one before was passed over; None when the ranking has no
    further circuit, or ``scene``'s circuit was not chosen by a ranking."""
    choice = scene.fold.circuit_choice
    ranked = [e["index"] for e in (choice or {}).get("ranked", ())]
    if not choice or choice.get("by") != "ranking" or scene.fold.circuit not in ranked:
        return None
    at = ranked.index(scene.fold.circuit) + 1
    if at == len(ranked):
        return None
    passed = [*choice.get("passed_over", ()), {"index": scene.fold.circuit, "why": why}]
    return _with_choice(scene, {**choice, "index": ranked[at], "rank": at + 1,
                                "outcome": choice["ranked"][at]["outcome"],
                                "passed_over": passed})


def choice_text(choice: dict) -> str:
    """How ``fold.circuit: auto`` chose a circuit (a ``fold.circuit_choice``
    mapping: :func:`resolve_circuit`, :func:`next_ranked`, or a stiffness
    file's circuit) in one line."""
    if choice.get("by") != "ranking":
        return f"fold.circuit: auto, the circuit of {choice.get('by')} {choice.get('file', '')}".rstrip()
    rank = choice.get("rank", 1)
    passed = "".join(f"; circuit {p['index']} passed over: {p['why']}"
                     for p in choice.get("passed_over", ()))
    return (f"fold.circuit: auto, chosen by ranking ({'the best' if rank == 1 else f'ranked {rank}'}"
            f" of {len(choice.get('screened', ()))} screened: {choice.get('outcome')}{passed})")


def _with_choice(scene, choice: dict):
    """``scene`` on circuit ``choice['index']``, ``fold.circuit_choice`` =
    ``choice`` in its sections and in the mapping it stores."""
    data = scene.data
    if data is not None:
        data = {**data, "fold": {**(data.get("fold") or {}), "circuit": choice["index"],
                                 "circuit_choice": choice}}
    return replace(scene, fold=replace(scene.fold, circuit=choice["index"],
                                       circuit_choice=choice), data=data)
