"""One evaluation of a stiffness set K: simulate, check for collisions, score.

The score is the paper's Eq. (8) plus a term for deployments that never reach
flat (see :func:`objective`). Every evaluation builds a fresh model copy
(:meth:`~panel_deploy.model.Model.with_stiffness`) and a fresh state, and the
functions here are top-level so that process pools and Dask workers can
pickle them.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace

import numpy as np

from ..dynamics.report import hinge_angles
from ..model import FLAT_TOLERANCE
from ..errors import OptimisationError

#: Approach speed (m/s) charged to a run whose simulation failed: faster than
#: any approach seen in the paper scene (tip speeds stay below ~3 m/s), so a
#: failure always scores worse than a collision, yet finite for the solvers.
FAILED_SPEED = 10.0


@dataclass(frozen=True)
class Outcome:
    """What one deployment run says about K.

    Attributes
    ----------
    collided : bool
        A collision was found (before the end time).
    v : float
        Approach speed at the first collision, Eq. (7), m/s (0 if none).
    d : float
        Smallest proximal distance, m, as Eq. (8) takes it: the minimum
        over all D_j, so 0 for a run that collides (the colliding pair's
        entry of D is 0 there) and the smallest distance over the run
        otherwise.
    flat_residual : float
        How close the valid part of the run came to flat: the smallest, over
        its samples, of the largest |theta| of any hinge (cut hinges included),
        rad. At most ``flat_tolerance`` when the array reached flat.
    first_collision : dict or None
        ``t`` (s), ``pair`` (two body names) and whatever else the
        collision check reports, as plain YAML-able values.
    simulated : bool
        The simulation reached the end time (``SimulationResult.success``).
    message : str
    wall_time : float
        s, for this run.
    t_stop : float
        Last simulated instant, s: the sample that revealed the first
        collision, the first flat sample, or the end time (NaN when nothing
        was simulated; None in :meth:`summary`).
    flat_tolerance : float
        The largest |theta| at which the run counted as flat, rad (the
        scene's ``simulation.flat_tolerance``).
    press_speed : float
        The fastest panel contact onset of the valid run, slower than the
        scene's ``collision.impact_speed``, m/s (0 if none):
        :attr:`~panel_deploy.collision.CollisionReport.press_speed`.
    """

    collided: bool
    v: float
    d: float
    flat_residual: float
    first_collision: dict | None = None
    simulated: bool = True
    message: str = ""
    wall_time: float = 0.0
    t_stop: float = math.nan
    flat_tolerance: float = FLAT_TOLERANCE
    press_speed: float = 0.0

    @property
    def reached_flat(self) -> bool:
        """The array lay flat at some sample (every |theta| <= ``flat_tolerance``)."""
        return self.simulated and self.flat_residual <= self.flat_tolerance

    @property
    def feasible(self) -> bool:
        """Collision-free until it first lies flat: what the optimisation is for."""
        return self.simulated and not self.collided and self.reached_flat


@dataclass(frozen=True)
class Evaluation:
    """K, the damping it implies, its outcome and its score f.

    ``k`` and ``c`` are per hinge (model order), N m/rad and N m s/rad.
    """

    k: np.ndarray
    c: np.ndarray
    f: float
    outcome: Outcome = field(repr=False)

    def to_dict(self) -> dict:
        """Plain-Python summary (for YAML/JSON)."""
        o = self.outcome
        return {"f": float(self.f), "v": float(o.v), "d": float(o.d),
                "collision": o.first_collision if o.collided else None,
                "flat_residual": float(o.flat_residual), "reached_flat": o.reached_flat,
                "simulated": o.simulated, "message": o.message,
                "t_stop": float(o.t_stop) if math.isfinite(o.t_stop) else None,
                "press_speed": float(o.press_speed)}


def objective(outcome: Outcome, p: float, q: float, flat_weight: float) -> float:
    """Score of one run: the paper's Eq. (8) plus a flat term.

    ``f = p v - q d + flat_weight * max(0, r - tol)`` with ``r`` the
    outcome's flat residual, how close to flat the valid run came, and
    ``tol`` its ``flat_tolerance`` (rad).
    Eq. (8) cannot see a deployment that locks (a hinge that never leaves its
    stowed angle may keep all panels far apart, which Eq. (8) rewards); the
    flat term charges it in proportion to how far from flat it stays, and
    vanishes for every run that reaches flat, where f is exactly the paper's.
    With the scene defaults (p = 1 s/m, q = 10 /m, flat_weight = 1 /rad) a
    0.1 m/s approach, a 10 mm clearance and a 0.1 rad leftover angle all
    score 0.1.

    Only a feasible run earns clearance: a colliding one has d = 0 already
    (:attr:`Outcome.d`, Eq. 8), and one that never lies flat counts d as 0,
    since not reaching flat is as much a failure as a collision. So every
    feasible run (f <= 0) scores better than every infeasible one (f >= 0).
    Otherwise a run that swings close to flat and falls back, keeping the
    panels far apart, outscores one that deploys with less room: on the
    paper scene differential evolution kept such a run, 0.15 rad from flat
    with d = 45 mm, at f = -0.35.

    A failed simulation scores as a collision at :data:`FAILED_SPEED` that
    stays folded (residual pi).
    """
    if not outcome.simulated:
        return p * FAILED_SPEED + flat_weight * math.pi
    d = outcome.d if outcome.feasible else 0.0
    return p * outcome.v - q * d + flat_weight * max(0.0, outcome.flat_residual - outcome.flat_tolerance)


def plain(value):
    """``value`` with numpy scalars and arrays turned into Python numbers and lists."""
    if isinstance(value, dict):
        return {str(k): plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [plain(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    return value


def damping_ratio(model) -> np.ndarray:
    """c/k of every hinge (s), shape (n_hinges,): what keeps c following k.

    A hinge with k = 0 (for example a snapped result) takes the median ratio
    of the others, so that a stiffness given to it later gets damping too.
    """
    k = model.stiffness
    c = np.array([h.c for h in model.hinges])
    beta = np.divide(c, k, out=np.full_like(k, np.nan), where=k > 0)
    known = beta[np.isfinite(beta)]
    if known.size == 0:
        raise OptimisationError("hinges: every hinge has k = 0, so c/k (Rayleigh damping) is unknown")
    return np.where(np.isfinite(beta), beta, np.median(known))


#: Samples simulated between two checks for an early stop (first collision or
#: first flat): 20 samples (0.1 s on the paper scene) restart the integrator
#: ~20 times in a 2 s run, against the seconds a run that would go on past
#: its first collision costs.
SEGMENT_SAMPLES = 20


def run_deployment(model, scene) -> Outcome:
    """Simulate ``model`` from the stowed state, checking for collisions as it goes.

    The run stops at the first collision (the trajectory after it is invalid,
    paper section 3.2) or when the array first lies flat (the paper counts a
    deployment complete then, section 4; the swinging about flat that follows
    is not checked), so a colliding K costs only the time up to its collision.
    ``scene`` is a :class:`~panel_deploy.scene.Scene` (its ``simulation``
    and ``collision`` sections are used).
    """
    from ..collision import TrajectoryCheck
    from ..dynamics import simulate_segments

    start = time.perf_counter()
    sim = scene.simulation
    check = TrajectoryCheck(model, scene.collision, capacity=sim.samples)
    closest = math.inf
    result = None
    for result in simulate_segments(model, sim, segment_samples=SEGMENT_SAMPLES):
        spread = np.max(np.abs(hinge_angles(model, result)[2]), axis=1)
        flat = np.flatnonzero(spread <= sim.flat_tolerance)
        block = result.head(flat[0] + 1) if len(flat) else result
        n_before = check.checked
        check.feed(block, poses=True)
        valid = spread[:(check.n_valid if check.collided else check.checked) - n_before]
        closest = min(closest, float(valid.min()) if len(valid) else math.inf)
        if check.collided or len(flat):
            break
    report = check.report()
    return Outcome(
        collided=report.collided,
        v=float(report.v),
        # A colliding run's D_j has a zero entry, so Eq. (8) earns it no
        # clearance: a slow collision must not outscore a collision-free run.
        # d is inf when no pair can collide; no clearance is earned then either.
        d=float(report.d) if math.isfinite(report.d) and not report.collided else 0.0,
        flat_residual=closest if math.isfinite(closest) else math.pi,
        first_collision=plain(report.first_collision_dict()) if report.collided else None,
        simulated=bool(result.success),
        message=result.message,
        wall_time=time.perf_counter() - start,
        t_stop=float(report.t[-1]) if len(report.t) else math.nan,
        flat_tolerance=sim.flat_tolerance,
        press_speed=float(report.press_speed))


def evaluate(model, k, scene, *, c=None, evaluation=run_deployment) -> Evaluation:
    """Score one stiffness set.

    Parameters
    ----------
    model : Model
        The base model; it is not changed.
    k : (n_hinges,) array_like
        Stiffness of every hinge, N m/rad.
    scene : Scene
        ``simulation``, ``collision`` and ``optimisation`` (p, q,
        flat_weight) sections.
    c : (n_hinges,) array_like, optional
        Damping, N m s/rad; by default ``c = beta k`` with beta the base
        model's :func:`damping_ratio` (Rayleigh damping, paper section 3.3).
    evaluation : callable, optional
        ``evaluation(model, scene) -> Outcome``, a picklable top-level
        function; :func:`run_deployment` by default.

    Returns
    -------
    Evaluation
    """
    k = np.asarray(k, dtype=float)
    c = damping_ratio(model) * k if c is None else np.asarray(c, dtype=float)
    # The scene's flat criterion judges every run, whatever a hook filled in.
    outcome = replace(evaluation(model.with_stiffness(k, c), scene),
                      flat_tolerance=scene.simulation.flat_tolerance)
    opt = scene.optimisation
    return Evaluation(k, c, objective(outcome, opt.p, opt.q, opt.flat_weight), outcome)
