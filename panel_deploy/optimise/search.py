"""Stiffness optimisation, paper section 3.3 and Fig. 4.

Local search: L-BFGS-B (bounded quasi-Newton; the paper used fmincon's
interior-reflective Newton method) on x = log10 k per hinge group (and
log10 c/k, when the damping ratio is a variable), restarted
from a new random K_0 while the best K still collides or does not reach
flat. Global search: differential evolution seeded with K_0, then the local
search from its best point. When c/k is a variable, both start with a line
search in c/k along K_0 (:meth:`_Search.damping_line`).

Why the gradient is taken the way it is: f(K) is piecewise and noisy. The
first collision is found on a sample grid, so v jumps when the collision
moves by one sample; d is a minimum over samples and changes slope when the
closest pair or instant switches; a collision appearing or vanishing jumps f
from -q d to p v. Finite differences at scipy's default step (~1e-8) would
measure those jumps and the integrator's error, not the trend. So the
gradient is a forward difference with a deliberately large step
:data:`FD_STEP` in log10 k (0.05, a 12 % change of the spring): that
moves the deployment's events by several sample intervals, so the difference
averages over the sampling noise, and the n + 1 evaluations of a gradient
run as one parallel batch.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from typing import Callable, NamedTuple

import numpy as np
from scipy.optimize import differential_evolution, minimize, minimize_scalar

from ..errors import OptimisationError
from .evaluate import Evaluation, run_deployment
from .parallel import BudgetExhausted, Cancelled, Evaluator, Job, make_backend
from .problem import StiffnessProblem

#: How far (decades of c/k, a factor 2) and how finely (1.2 %) the ends of
#: the result's feasible c/k range are looked for (:meth:`_Search.centre_damping`):
#: the paper scene's optima stay feasible over 3-20 % of c/k.
CENTRE_REACH, CENTRE_TOL = math.log10(2.0), 0.005
#: A c/k window this wide (decades: +-5 %) ends the look for a wider one, among
#: this many of the best feasible K.
CENTRE_WIDE, CENTRE_CANDIDATES = math.log10(1.1), 3
#: Evaluations the centring needs at most: per candidate both far ends and
#: the bisection steps of both sides; then the middle.
CENTRE_EVALUATIONS = CENTRE_CANDIDATES * (2 + 2 * math.ceil(math.log2(CENTRE_REACH / CENTRE_TOL))) + 1


class Progress(NamedTuple):
    """What a progress callback receives after every batch of evaluations."""

    phase: str          #: "K_0", "global", "local 1", "local 2" (restart), ...
    iteration: int      #: solver iterations completed in this phase
    nfev: int           #: simulations spent so far
    best_f: float       #: objective of the best K so far
    collision: bool     #: the best K so far collides
    reached_flat: bool  #: the best K so far ends flat
    elapsed: float      #: s since the start


def print_progress(p: Progress, file=None) -> None:
    """One line per progress report (the CLI's default)."""
    print(f"{p.phase:>9}  it {p.iteration:3d}  nfev {p.nfev:4d}  best f {p.best_f:+.5f}  "
          f"collision {'yes' if p.collision else 'no '}  flat {'yes' if p.reached_flat else 'no '}  "
          f"{p.elapsed:7.1f} s", file=file, flush=True)


@dataclass
class OptimisationResult:
    """Result of :func:`optimise`, in the manner of scipy's ``OptimizeResult``.

    Attributes
    ----------
    k, c : (n_hinges,) ndarray
        Best stiffness (N m/rad) and its damping (N m s/rad), per hinge.
    best : Evaluation
        The best K's evaluation (``best.outcome`` has v, d, collision, flat).
    initial : Evaluation
        The evaluation of K_0 (None if the budget did not allow it).
    problem : StiffnessProblem
        Groups, bounds, K_0.
    success : bool
        The best K is collision-free and reaches flat.
    status : int
        0 feasible and the solver converged; 1 feasible, stopped by the
        evaluation budget or the iteration limit; 2 no feasible K found;
        3 interrupted (Ctrl-C, SIGTERM or ``stop``): the best K of the
        evaluations done so far.
    message : str
    nfev : int
        Simulations run (cached repeats not counted).
    nit : int
        Solver iterations over all phases.
    nstarts : int
        Local searches started (1 + restarts used).
    method : str
        "local" or "global".
    wall_time : float
        s.
    first_feasible : tuple of (int, float) or None
        Evaluations spent and s elapsed when the first feasible K came
        back (the rest of the budget only improves d), None if none did.
    history : list of Evaluation
        Every evaluation, in the order run.
    damping_window : (float, float) or None
        When c/k is a variable and a feasible K was found: the c/k range (s)
        over which the result's K stays feasible (to 1.2 %, within a factor 2
        of the c/k the search gave it). ``k``, ``c`` and ``best`` are
        then one of the best few feasible K at the middle of its window
        (:meth:`_Search.centre_damping`), which may score a little worse
        than the largest-d K in ``history``. None otherwise, and when the
        middle was not feasible (a hole in the window).
    """

    k: np.ndarray
    c: np.ndarray
    best: Evaluation
    initial: Evaluation | None
    problem: StiffnessProblem
    success: bool
    status: int
    message: str
    nfev: int
    nit: int
    nstarts: int
    method: str
    wall_time: float
    first_feasible: tuple | None = None
    history: list = field(default_factory=list, repr=False)
    damping_window: tuple | None = None

    @property
    def f(self) -> float:
        return self.best.f

    @property
    def outcome(self):
        return self.best.outcome


#: Forward-difference step of the gradient, in log10 k (a 12 % change of the
#: spring; see the module docstring).
FD_STEP = 0.05
#: Iterations a local search may spend while every K seen so far collides
#: before it restarts from a new K_0.
PATIENCE = 3
#: Differential evolution population per variable (global method).
POPSIZE = 2


def optimise(model, scene, *, k0=None, groups=None, workers=None, dask_address=None,
             progress: Callable | None = None, stop: Callable | None = None,
             evaluation=run_deployment) -> OptimisationResult:
    """Choose hinge stiffnesses K so that the array deploys without collision.

    Minimises f(K) of :func:`~panel_deploy.optimise.evaluate.objective`
    (Eq. (8) plus a term for not reaching flat) over one stiffness per hinge
    group, with c following k (Rayleigh damping): c = beta k with the
    model's beta, or with one beta for all hinges searched within
    ``optimisation.damping_ratio_bounds`` when the scene gives them.

    Parameters
    ----------
    model : Model
        Base model; its c/k ratios set the damping (or the start c/k, when
        the damping ratio is a variable).
    scene : Scene
        ``optimisation`` gives p, q, flat_weight, bounds, k0,
        damping_ratio_bounds, method, restarts, max_evaluations, workers,
        seed, rtol, refine;
        ``simulation`` and ``collision``, as :func:`search_scene`
        adjusts them, are used for every evaluation.
    k0 : float, (n_groups,) or (n_hinges,) array_like, optional
        Starting stiffness (N m/rad): one value, one per group, or one per
        hinge (a previous result's K, to go on from it); default the
        scene's ``optimisation.k0``.
    groups : sequence of sequence of (int or str), optional
        Hinges sharing one stiffness; default ``model.hinge_groups``
        (the scene's ``hinges.groups``).
    workers : int, optional
        Local processes; 0 all cores, 1 in this process. Default
        ``scene.optimisation.workers``.
    dask_address : str, optional
        Run the evaluations on this Dask scheduler instead of locally.
    progress : callable, optional
        Called with a :class:`Progress` after every batch of evaluations.
    stop : callable, optional
        Asked before every batch of evaluations (from the search's thread);
        True ends the search as Ctrl-C does: status 3, the best K so far.
    evaluation : callable
        ``evaluation(model, scene) -> Outcome``, picklable, top-level;
        default simulate + collision check.

    Returns
    -------
    OptimisationResult

    Raises
    ------
    OptimisationError
        Bad bounds, K_0, groups, workers, method, budget, or an unreachable
        scheduler.
    """
    opt = scene.optimisation
    if opt.method not in ("local", "global"):
        raise OptimisationError(f"method: expected local or global, got {opt.method!r}")
    for name, value, low in (("max_evaluations", opt.max_evaluations, 1),
                             ("restarts", opt.restarts, 0)):
        if not isinstance(value, int) or isinstance(value, bool) or value < low:
            raise OptimisationError(f"{name}: expected an integer >= {low}, got {value!r}")
    problem = StiffnessProblem.from_model(model, opt.bounds, opt.k0 if k0 is None else k0,
                                          groups, opt.damping_ratio_bounds)
    rng = np.random.default_rng(opt.seed)
    backend = make_backend(Job(model, search_scene(scene), evaluation),
                           opt.workers if workers is None else workers, dask_address)
    search = _Search(problem, backend, opt.max_evaluations, progress, stop)
    start = time.perf_counter()
    try:
        converged = search.run(opt.method, opt.restarts, rng)
    finally:
        backend.close()
    return search.result(opt.method, converged, time.perf_counter() - start)


def search_scene(scene):
    """``scene`` as the search evaluates it: ``optimisation.rtol`` and
    ``optimisation.refine`` in place of the scene's own (None keeps them).

    Looser settings than the scene's can pay in the search, since the caller
    re-checks the optimum with the scene's own, tightened
    (:func:`~panel_deploy.optimise.manufacture.verify`). Measured on the
    paper scene: checking collisions at the samples only (the paper's D_j)
    instead of also between them is 2-3.7x faster (K_0 0.3 s instead of
    0.65 s; a collision-free run to 1.26 s 1.0 s instead of 3.5 s) with the
    same outcome, the collision time then on the sample grid (0.440 s
    instead of 0.4393 s). rtol 1e-3 instead of 1e-4 halves an evaluation far
    from the optimum, but near the gravity scene's feasible set it flipped a
    verdict, so that scene searches at its own rtol. atol keeps its ratio to
    rtol.
    """
    sim, col, opt = scene.simulation, scene.collision, scene.optimisation
    if opt.rtol is not None:
        sim = replace(sim, rtol=opt.rtol, atol=sim.atol * opt.rtol / sim.rtol)
    if opt.refine is not None:
        col = replace(col, refine=opt.refine)
    return scene.replace(simulation=sim, collision=col)


class _Search:
    """State of one optimisation run: evaluator, phase, iteration counts."""

    def __init__(self, problem, backend, max_evaluations, progress, stop=None):
        self.problem = problem
        self.progress = progress
        self.evaluator = Evaluator(backend, max_evaluations, on_batch=self._report, stop=stop)
        self.phase = ""
        self.iteration = 0
        self.nit = 0
        self.nstarts = 0
        self.budget_spent = False
        self.interrupted = False
        self.centred = None
        self.damping_window = None

    def _report(self):
        if self.progress is not None:
            b = self.evaluator.best
            self.progress(Progress(self.phase, self.iteration, self.evaluator.nfev, float(b.f),
                                   b.outcome.collided, b.outcome.reached_flat,
                                   self.evaluator.elapsed))

    def _iterated(self, *_):
        self.iteration += 1
        self.nit += 1

    def _batch(self, xs) -> list:
        return self.evaluator.map([self.problem.k_of(x) for x in xs],
                                  [self.problem.c_of(x) for x in xs])

    def fun_and_grad(self, x):
        """f(x) and its forward-difference gradient, as one parallel batch."""
        lo, hi = np.array(self.problem.x_bounds).T
        # Step backwards where a forward step would leave the bounds.
        h = np.where(x + FD_STEP <= hi, FD_STEP, -FD_STEP)
        h = np.where(x + h >= lo, h, hi - x)
        points = [x] + [x + h[i] * np.eye(len(x))[i] for i in range(len(x))]
        f = np.array([e.f for e in self._batch(points)])
        return f[0], (f[1:] - f[0]) / h

    def _iterated_local(self, *_):
        self._iterated()
        # Eq. (8) inside the colliding region only asks for a slower impact,
        # which softer springs always give: the search then slides towards the
        # lower bound and never leaves the region. Fig. 4's answer is a new
        # K_0, so a start still colliding after PATIENCE iterations ends.
        if self.iteration >= PATIENCE and self.evaluator.best.outcome.collided:
            raise StopIteration

    def local(self, x0) -> bool:
        """One L-BFGS-B run from x0; True if it converged."""
        self.nstarts += 1
        self.phase, self.iteration = f"local {self.nstarts}", 0
        res = minimize(self.fun_and_grad, x0, jac=True, method="L-BFGS-B",
                       bounds=self.problem.x_bounds, callback=self._iterated_local,
                       # ftol near the objective's noise level: below it the
                       # solver would only chase sampling noise.
                       options={"ftol": 1e-4, "gtol": 1e-4, "maxiter": 50})
        return bool(res.success)

    def global_(self, rng, x0) -> None:
        """Differential evolution over the whole box, seeded with x0."""
        self.phase, self.iteration = "global", 0
        n = self.problem.n
        generations = max(1, (self.evaluator.max_evaluations - self.evaluator.nfev)
                          // (POPSIZE * n) - 1)

        def batch(xs):
            return np.array([e.f for e in self._batch(np.atleast_2d(xs.T))])

        differential_evolution(batch, self.problem.x_bounds, x0=x0,
                               popsize=POPSIZE, maxiter=generations, vectorized=True,
                               updating="deferred", polish=False, tol=1e-3,
                               rng=rng, callback=self._iterated)

    def damping_line(self, x0) -> np.ndarray:
        """x0 with the c/k that suits K_0 best: a bounded scalar search in log10 c/k.

        Along K_0 the score is V-shaped in c/k: light damping collides (f = p v
        falls as damping slows the panels), heavy damping stays folded past the
        end time (the flat term grows), and between lie K_0's feasible c/k, if
        any. On the paper scene that window is 0.18-0.20 s, a twentieth of the
        bounds [0.043, 0.3] s in log c/k, so differential evolution's initial
        population rarely lands in it (3 of 8 seeds found a feasible K in 400
        evaluations); Brent's method, at most 20 evaluations run one after the
        other, hit it with its third (8 of 8 seeds).
        """
        self.phase, self.iteration = "c/k", 0

        def f(u):
            self._iterated()
            return self._batch([np.append(x0[:-1], u)])[0].f

        minimize_scalar(f, bounds=self.problem.x_bounds[-1], method="bounded",
                        options={"xatol": 0.005, "maxiter": 20})
        best = self.evaluator.best
        return self.problem.x_of(best.k, best.c)

    def centre_damping(self) -> None:
        """Move the result's c/k to the middle of the c/k range over which it is feasible.

        The search maximises d, and on the paper scene d grows as damping falls,
        so its optimum sits near the lower end of its c/k window, where
        collisions begin, and some optima are feasible at their own c/k only.
        The hinge damping is what a build controls least (paper section 5), so
        the result is chosen for margin in c/k: of the :data:`CENTRE_CANDIDATES`
        feasible K with the lowest f, the first whose window spans
        :data:`CENTRE_WIDE` (else the widest), at its window's middle. That
        trades a little d for margin both ways. If the middle is not feasible
        (the window has a hole), the result stays the search's best K.
        """
        candidates, seen = [], set()
        for ev in sorted((e for e in self.evaluator.history if e.outcome.feasible),
                         key=lambda e: e.f):
            if (key := self.evaluator.key(ev.k)) not in seen:
                seen.add(key)
                candidates.append(ev)
            if len(candidates) == CENTRE_CANDIDATES:
                break
        if not candidates:
            return
        self.phase, self.iteration = "centre", 0
        widest = None
        for ev in candidates:
            window = self._feasible_range(ev)
            if widest is None or window[1] - window[0] > widest[1][1] - widest[1][0]:
                widest = (ev, window)
            if window[1] - window[0] >= CENTRE_WIDE:
                break
        ev, (lo, hi) = widest
        x = self.problem.x_of(ev.k, ev.c)
        centre = self._batch([np.append(x[:-1], (lo + hi) / 2)])[0]
        if centre.outcome.feasible:
            self.centred = centre
            self.damping_window = (10.0 ** lo, 10.0 ** hi)

    def _feasible_range(self, ev) -> tuple:
        """(lower, upper) log10 c/k between which ``ev``'s K stays feasible.

        Both ends by bisection, side by side as batches of two, to
        :data:`CENTRE_TOL` within :data:`CENTRE_REACH` of ``ev``'s own c/k
        (which is feasible).
        """
        x = self.problem.x_of(ev.k, ev.c)
        lo, hi = self.problem.x_bounds[-1]
        # Per side [known feasible, known infeasible or the reach's end], in log10 c/k.
        sides = [[x[-1], max(lo, x[-1] - CENTRE_REACH)], [x[-1], min(hi, x[-1] + CENTRE_REACH)]]

        def at(us):
            self._iterated()
            return self._batch([np.append(x[:-1], u) for u in us])

        for side, far in zip(sides, at([side[1] for side in sides])):
            if far.outcome.feasible:
                side[0] = side[1]
        while unresolved := [side for side in sides if abs(side[1] - side[0]) > CENTRE_TOL]:
            mids = [(side[0] + side[1]) / 2 for side in unresolved]
            for side, mid, e in zip(unresolved, mids, at(mids)):
                side[0 if e.outcome.feasible else 1] = mid
        return sides[0][0], sides[1][0]

    def run(self, method, restarts, rng) -> bool:
        """Fig. 4: search, restart while no feasible K; True if the last local search converged.

        When c/k is a variable, :data:`CENTRE_EVALUATIONS` evaluations are
        kept back from the budget (if it has twice that) to centre the
        result's c/k afterwards.
        """
        x0 = self.problem.x0
        converged = False
        # A budget too small to spare them leaves c/k where the search put it.
        reserve = CENTRE_EVALUATIONS if (self.problem.damping_variable and
                                         self.evaluator.max_evaluations >= 2 * CENTRE_EVALUATIONS) else 0
        self.evaluator.max_evaluations -= reserve
        try:
            self.phase = "K_0"
            self.initial = self._batch([x0])[0]
            if self.problem.damping_variable:
                x0 = self.damping_line(x0)
            if method == "global":
                self.global_(rng, x0)
                x0 = self.problem.x_of(self.evaluator.best.k, self.evaluator.best.c)
            for attempt in range(restarts + 1):
                if attempt:
                    lo, hi = np.array(self.problem.x_bounds).T
                    x0 = rng.uniform(lo, hi)
                converged = self.local(x0)
                if self.evaluator.best.outcome.feasible:
                    break
        except BudgetExhausted:
            self.budget_spent = True
            converged = False
        except (KeyboardInterrupt, Cancelled):
            # What was evaluated is still a result: the caller can save it.
            if self.evaluator.best is None:
                raise
            self.interrupted = True
            return False
        self.evaluator.max_evaluations += reserve
        if reserve:
            try:
                self.centre_damping()
            except (KeyboardInterrupt, Cancelled):
                self.interrupted = True
        return converged

    def result(self, method, converged, wall_time) -> OptimisationResult:
        best = self.evaluator.best if self.centred is None else self.centred
        feasible = best is not None and best.outcome.feasible
        if best is None:
            raise OptimisationError("max_evaluations: the budget does not allow a single evaluation")
        if self.interrupted:
            status = 3
            message = (f"interrupted after {self.evaluator.nfev} evaluations; the best K so far "
                       f"is {'collision-free and flat' if feasible else 'not feasible'}")
        elif not feasible:
            status = 2
            what = "collides" if best.outcome.collided else (
                "does not reach flat" if best.outcome.simulated else "fails to simulate")
            message = (f"no collision-free K reaching flat found in {self.evaluator.nfev} "
                       f"evaluations and {self.nstarts} start(s); the best K {what}")
        elif converged:
            status, message = 0, "collision-free and flat; local search converged"
        else:
            status = 1
            message = ("collision-free and flat; stopped by the evaluation budget"
                       if self.budget_spent else
                       "collision-free and flat; local search stopped before converging")
        if self.centred is not None and not self.interrupted:
            message += "; c/k centred in its feasible range %.4g-%.4g s" % self.damping_window
        return OptimisationResult(
            k=best.k, c=best.c, best=best, initial=getattr(self, "initial", None),
            problem=self.problem, success=feasible, status=status, message=message,
            nfev=self.evaluator.nfev, nit=self.nit, nstarts=self.nstarts, method=method,
            wall_time=wall_time, first_feasible=self.evaluator.first_feasible,
            history=list(self.evaluator.history), damping_window=self.damping_window)
