"""The c/k phases of a search whose damping ratio is a variable
(``optimisation.damping_ratio_bounds``): a line search in c/k along K_0 before
the K search, and centring the result's c/k in its feasible range after it.

Both work on a :class:`~panel_deploy.optimise.search.Run` (its evaluator,
problem and progress counts); the last search variable is log10 c/k.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import minimize_scalar

#: How far (decades of c/k, a factor 2) and how finely (1.2 %) the ends of
#: the result's feasible c/k range are looked for (:func:`centre_damping`):
#: the paper scene's optima stay feasible over 3-20 % of c/k.
CENTRE_REACH, CENTRE_TOL = math.log10(2.0), 0.005
#: A c/k window this wide (decades: +-5 %) ends the look for a wider one, among
#: this many of the best feasible K.
CENTRE_WIDE, CENTRE_CANDIDATES = math.log10(1.1), 3
#: Evaluations the centring needs at most: per candidate both far ends and
#: the bisection steps of both sides; then the middle.
CENTRE_EVALUATIONS = CENTRE_CANDIDATES * (2 + 2 * math.ceil(math.log2(CENTRE_REACH / CENTRE_TOL))) + 1


def damping_line(run, x0) -> np.ndarray:
    """x0 with the c/k that suits K_0 best: a bounded scalar search in log10 c/k.

    Along K_0 the score is V-shaped in c/k: light damping collides (f = p v
    falls as damping slows the panels), heavy damping stays folded past the
    end time (the flat term grows), and between lie K_0's feasible c/k, if
    any. On the paper scene that window is 0.18-0.20 s, a twentieth of the
    bounds [0.043, 0.3] s in log c/k, so differential evolution's initial
    population rarely lands in it (3 of 8 seeds found a feasible K in 400
    evaluations); Brent's method, at most 20 evaluations run one after the
    other, hit it with its third (8 of 8 seeds).

    Both ends of the bounds are evaluated first, as one batch: Brent's bounded
    method never evaluates them, and where every lighter damping collides
    the score has no slope to lead it there. On 8 x 8 (docs/findings.md 4.8)
    K_0 deploys only at the heaviest c/k allowed, 2 s, the c/k at which the
    screening ranked the circuit; Brent's 11 evaluations all collided.
    """
    run.start_phase("c/k")
    run.batch([np.append(x0[:-1], u) for u in run.problem.x_bounds[-1]])

    def f(u):
        run.iterated()
        return run.batch([np.append(x0[:-1], u)])[0].f

    minimize_scalar(f, bounds=run.problem.x_bounds[-1], method="bounded",
                    options={"xatol": 0.005, "maxiter": 20})
    return run.x_of(run.evaluator.best)


def centre_damping(run):
    """The result moved to the middle of the c/k range over which it is
    feasible: ``(evaluation, (lower, upper) c/k in s)``, or None.

    The search maximises d, and on the paper scene d grows as damping falls,
    so its optimum sits near the lower end of its c/k window, where
    collisions begin, and some optima are feasible at their own c/k only.
    The hinge damping is what a build controls least (paper section 5), so
    the result is chosen for margin in c/k: of the :data:`CENTRE_CANDIDATES`
    feasible K with the lowest f, the first whose window spans
    :data:`CENTRE_WIDE` (else the widest), at its window's middle. That
    trades a little d for margin both ways. None if no K is feasible, or if
    the middle is not (the window has a hole): the result stays the search's
    best K.
    """
    candidates, seen = [], set()
    for ev in sorted((e for e in run.evaluator.history if e.outcome.feasible), key=lambda e: e.f):
        if (key := run.evaluator.key(ev.k)) not in seen:
            seen.add(key)
            candidates.append(ev)
        if len(candidates) == CENTRE_CANDIDATES:
            break
    if not candidates:
        return None
    run.start_phase("centre")
    widest = None
    for ev in candidates:
        window = feasible_range(run, ev)
        if widest is None or window[1] - window[0] > widest[1][1] - widest[1][0]:
            widest = (ev, window)
        if window[1] - window[0] >= CENTRE_WIDE:
            break
    ev, (lo, hi) = widest
    x = run.x_of(ev)
    centre = run.batch([np.append(x[:-1], (lo + hi) / 2)])[0]
    if not centre.outcome.feasible:
        return None
    return centre, (10.0 ** lo, 10.0 ** hi)


def feasible_range(run, ev) -> tuple:
    """(lower, upper) log10 c/k between which ``ev``'s K stays feasible.

    Both ends by bisection, side by side as batches of two, to
    :data:`CENTRE_TOL` within :data:`CENTRE_REACH` of ``ev``'s own c/k
    (which is feasible).
    """
    x = run.x_of(ev)
    lo, hi = run.problem.x_bounds[-1]
    # Per side [known feasible, known infeasible or the reach's end], in log10 c/k.
    sides = [[x[-1], max(lo, x[-1] - CENTRE_REACH)], [x[-1], min(hi, x[-1] + CENTRE_REACH)]]

    def at(us):
        run.iterated()
        return run.batch([np.append(x[:-1], u) for u in us])

    for side, far in zip(sides, at([side[1] for side in sides])):
        if far.outcome.feasible:
            side[0] = side[1]
    while unresolved := [side for side in sides if abs(side[1] - side[0]) > CENTRE_TOL]:
        mids = [(side[0] + side[1]) / 2 for side in unresolved]
        for side, mid, e in zip(unresolved, mids, at(mids)):
            side[0 if e.outcome.feasible else 1] = mid
    return sides[0][0], sides[1][0]
