"""Stiffness optimisation, paper section 3.3 and Fig. 4.

Local search: L-BFGS-B (bounded quasi-Newton; the paper used fmincon's
interior-reflective Newton method) on x = log10 k per hinge group (and
log10 c/k, when the damping ratio is a variable), restarted
from a new random K_0 while the best K still collides or does not reach
flat. Global search: differential evolution seeded with K_0, then the local
search from its best point. When c/k is a variable, both start with a line
search in c/k along K_0 (:func:`.damping.damping_line`).

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

import time
from dataclasses import dataclass, field, replace
from typing import Callable, NamedTuple

import numpy as np
from scipy.optimize import differential_evolution, minimize

from ..errors import OptimisationError
from ..progress import time_left
from .damping import CENTRE_EVALUATIONS, centre_damping, damping_line
from .evaluate import Evaluation, run_deployment
from .parallel import BudgetExhausted, Cancelled, Evaluator, Job, make_backend
from .problem import StiffnessProblem


class Progress(NamedTuple):
    """What a progress callback receives after every batch of evaluations."""

    phase: str          #: "K_0", "global", "local 1", "local 2" (restart), ...
    iteration: int      #: solver iterations completed in this phase
    nfev: int           #: simulations spent so far
    best_f: float       #: objective of the best K so far
    collision: bool     #: the best K so far collides
    reached_flat: bool  #: the best K so far ends flat
    elapsed: float      #: s since the start


def print_progress(p: Progress, file=None, budget: int | None = None) -> None:
    """One line per progress report (the CLI's default); with the evaluation
    ``budget``, how long it leaves at this pace."""
    print(f"{p.phase:>9}  it {p.iteration:3d}  nfev {p.nfev:4d}  best f {p.best_f:+.5f}  "
          f"collision {'yes' if p.collision else 'no '}  flat {'yes' if p.reached_flat else 'no '}  "
          f"{p.elapsed:7.1f} s{time_left(p.elapsed, p.nfev, budget)}", file=file, flush=True)


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
        (:func:`.damping.centre_damping`), which may score a little worse
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
    run = Run(problem, backend, opt.max_evaluations, progress, stop)
    start = time.perf_counter()
    try:
        ended = _search(run, opt.method, opt.restarts, rng)
    finally:
        closed_interrupted = _close(backend)
    ended.interrupted |= closed_interrupted
    return _result(run, opt.method, ended, time.perf_counter() - start)


def _close(backend) -> bool:
    """Close ``backend`` even when Ctrl-C or SIGTERM comes meanwhile (its
    workers must not outlive the search, and the evaluations made are still a
    result); True if one came."""
    interrupted = False
    while True:
        try:
            backend.close()
            return interrupted
        except KeyboardInterrupt:
            interrupted = True


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
    instead of 0.4393 s; measured with one spring per L2-L3/L3-L4 line). rtol
    1e-3 instead of 1e-4 halves an evaluation far from the optimum, but near
    the gravity scene's feasible set it flipped a verdict, so that scene
    searches at 1e-4 (its simulation.rtol then, now 1e-6 for the time to
    flat). atol keeps its ratio to rtol.
    """
    sim, col, opt = scene.simulation, scene.collision, scene.optimisation
    if opt.rtol is not None:
        sim = replace(sim, rtol=opt.rtol, atol=sim.atol * opt.rtol / sim.rtol)
    if opt.refine is not None:
        col = replace(col, refine=opt.refine)
    return scene.replace(simulation=sim, collision=col)


class Run:
    """What the phases of one optimisation share: the problem, the cached and
    budgeted evaluator, and the phase and iteration counts progress reports show."""

    def __init__(self, problem, backend, max_evaluations, progress=None, stop=None):
        self.problem = problem
        self.progress = progress
        self.evaluator = Evaluator(backend, max_evaluations, on_batch=self._report, stop=stop)
        self.phase = ""
        self.iteration = 0
        self.nit = 0

    def start_phase(self, phase: str) -> None:
        self.phase, self.iteration = phase, 0

    def iterated(self, *_):
        self.iteration += 1
        self.nit += 1

    def batch(self, xs) -> list:
        """Evaluations of the search points ``xs`` (x = log10 k per group, and log10 c/k)."""
        return self.evaluator.map([self.problem.k_of(x) for x in xs],
                                  [self.problem.c_of(x) for x in xs])

    def x_of(self, ev):
        return self.problem.x_of(ev.k, ev.c)

    def _report(self):
        if self.progress is not None:
            b = self.evaluator.best
            self.progress(Progress(self.phase, self.iteration, self.evaluator.nfev, float(b.f),
                                   b.outcome.collided, b.outcome.reached_flat,
                                   self.evaluator.elapsed))


class KSearch:
    """The search over K of paper Fig. 4 on a :class:`Run`: local L-BFGS-B runs
    with restarts, after an optional differential evolution."""

    def __init__(self, run: Run):
        self.run = run
        self.nstarts = 0

    def fun_and_grad(self, x):
        """f(x) and its forward-difference gradient, as one parallel batch."""
        lo, hi = np.array(self.run.problem.x_bounds).T
        # Step backwards where a forward step would leave the bounds.
        h = np.where(x + FD_STEP <= hi, FD_STEP, -FD_STEP)
        h = np.where(x + h >= lo, h, hi - x)
        points = [x] + [x + h[i] * np.eye(len(x))[i] for i in range(len(x))]
        f = np.array([e.f for e in self.run.batch(points)])
        return f[0], (f[1:] - f[0]) / h

    def _iterated_local(self, *_):
        self.run.iterated()
        # Eq. (8) inside the colliding region only asks for a slower impact,
        # which softer springs always give: the search then slides towards the
        # lower bound and never leaves the region. Fig. 4's answer is a new
        # K_0, so a start still colliding after PATIENCE iterations ends.
        if self.run.iteration >= PATIENCE and self.run.evaluator.best.outcome.collided:
            raise StopIteration

    def local(self, x0) -> bool:
        """One L-BFGS-B run from x0; True if it converged."""
        self.nstarts += 1
        self.run.start_phase(f"local {self.nstarts}")
        res = minimize(self.fun_and_grad, x0, jac=True, method="L-BFGS-B",
                       bounds=self.run.problem.x_bounds, callback=self._iterated_local,
                       # ftol near the objective's noise level: below it the
                       # solver would only chase sampling noise.
                       options={"ftol": 1e-4, "gtol": 1e-4, "maxiter": 50})
        return bool(res.success)

    def global_(self, rng, x0) -> None:
        """Differential evolution over the whole box, seeded with x0."""
        run = self.run
        run.start_phase("global")
        n = run.problem.n
        generations = max(1, (run.evaluator.max_evaluations - run.evaluator.nfev)
                          // (POPSIZE * n) - 1)

        def batch(xs):
            return np.array([e.f for e in run.batch(np.atleast_2d(xs.T))])

        differential_evolution(batch, run.problem.x_bounds, x0=x0,
                               popsize=POPSIZE, maxiter=generations, vectorized=True,
                               updating="deferred", polish=False, tol=1e-3,
                               rng=rng, callback=run.iterated)

    def search(self, x0, method, restarts, rng) -> bool:
        """From x0: the global phase (if ``method`` is "global"), then local
        searches, restarted from a random K_0 while the best K is not feasible;
        True if the last local search converged."""
        if method == "global":
            self.global_(rng, x0)
            x0 = self.run.x_of(self.run.evaluator.best)
        converged = False
        for attempt in range(restarts + 1):
            if attempt:
                lo, hi = np.array(self.run.problem.x_bounds).T
                x0 = rng.uniform(lo, hi)
            converged = self.local(x0)
            if self.run.evaluator.best.outcome.feasible:
                break
        return converged


@dataclass
class _Ended:
    """How :func:`_search` ended."""

    converged: bool = False          # the last local search converged
    nstarts: int = 0                 # local searches started
    budget_spent: bool = False
    short: tuple = ()                # the batch that did not fit, the evaluations left
    interrupted: bool = False        # Ctrl-C, SIGTERM or stop: the best K so far
    initial: Evaluation | None = None
    centred: Evaluation | None = None  # the result moved to the middle of its c/k window
    window: tuple | None = None        # that window, s


def _search(run: Run, method, restarts, rng) -> _Ended:
    """Fig. 4 on ``run``, with the c/k phases of :mod:`.damping` when c/k is a
    variable.

    :data:`~.damping.CENTRE_EVALUATIONS` evaluations are kept back from the
    budget (if it has twice that) to centre the result's c/k afterwards.
    """
    problem, evaluator = run.problem, run.evaluator
    k_search = KSearch(run)
    ended = _Ended()
    # A budget too small to spare them leaves c/k where the search put it.
    reserve = CENTRE_EVALUATIONS if (problem.damping_variable and
                                     evaluator.max_evaluations >= 2 * CENTRE_EVALUATIONS) else 0
    evaluator.max_evaluations -= reserve
    try:
        run.start_phase("K_0")
        x0 = problem.x0
        ended.initial = run.batch([x0])[0]
        if problem.damping_variable:
            x0 = damping_line(run, x0)
        ended.converged = k_search.search(x0, method, restarts, rng)
    except BudgetExhausted as e:
        ended.budget_spent = True
        ended.short = e.args
    except (KeyboardInterrupt, Cancelled):
        # What was evaluated is still a result: the caller can save it.
        if evaluator.best is None:
            raise
        ended.interrupted = True
    ended.nstarts = k_search.nstarts
    evaluator.max_evaluations += reserve
    if reserve and not ended.interrupted:
        try:
            found = centre_damping(run)
            if found is not None:
                ended.centred, ended.window = found
        except (KeyboardInterrupt, Cancelled):
            ended.interrupted = True
    return ended


def _result(run: Run, method, ended: _Ended, wall_time) -> OptimisationResult:
    """The :class:`OptimisationResult` of a finished :func:`_search`."""
    evaluator = run.evaluator
    best = evaluator.best if ended.centred is None else ended.centred
    if best is None:
        raise OptimisationError("max_evaluations: the budget does not allow a single evaluation")
    feasible = best.outcome.feasible
    if ended.interrupted:
        status = 3
        message = (f"interrupted after {evaluator.nfev} evaluations; the best K so far "
                   f"is {'collision-free and flat' if feasible else 'not feasible'}")
    elif not feasible:
        status = 2
        what = "collides" if best.outcome.collided else (
            "does not reach flat" if best.outcome.simulated else "fails to simulate")
        message = (f"no collision-free K reaching flat found in {evaluator.nfev} "
                   f"evaluations and {ended.nstarts} start(s); the best K {what}")
        if ended.short:
            # a budget below one generation of differential evolution (2 K per
            # variable) buys only the line search: say so, not just the count
            message += "; the search's next batch ({} K) did not fit in the {} left".format(
                *ended.short)
    elif ended.converged:
        status, message = 0, "collision-free and flat; local search converged"
    else:
        status = 1
        message = ("collision-free and flat; stopped by the evaluation budget (its next "
                   "batch, {} K, did not fit in the {} left)".format(*ended.short)
                   if ended.budget_spent else
                   "collision-free and flat; local search stopped before converging")
    if ended.centred is not None and not ended.interrupted:
        message += "; c/k centred in its feasible range %.4g-%.4g s" % ended.window
    return OptimisationResult(
        k=best.k, c=best.c, best=best, initial=ended.initial,
        problem=run.problem, success=feasible, status=status, message=message,
        nfev=evaluator.nfev, nit=run.nit, nstarts=ended.nstarts, method=method,
        wall_time=wall_time, first_feasible=evaluator.first_feasible,
        history=list(evaluator.history), damping_window=ended.window)
