"""The compiled step loop: the whole adaptive loop in numba around either
an explicit Runge-Kutta 5(4) pair (:mod:`.erk`: Tsitouras' or Dormand and
Prince's) or the linearly implicit Rosenbrock-W ROS34PW2
(:mod:`.rosenbrock`), and the choice between the two for
``simulation.method: compiled`` (:func:`choose_scheme`)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from . import articulated, erk, integration, kernels, panel_contact, rosenbrock, stiff, switches
from ._jit import FLOAT_MATH
from .result import Status, no_onsets

#: Compiled loops (keys of ``COMPILED_LOOPS``): the explicit pairs' (each
#: pair is an argument, :data:`.erk.PAIRS`) and ROS34PW2's.
EXPLICIT, ROS34PW2 = 0, 1
#: The loop of each compiled scheme's name.
SCHEMES = {**{name: EXPLICIT for name in erk.PAIRS}, "ros34pw2": ROS34PW2}
#: Key of the ROS34PW2 loop on the O(n) path (where :func:`articulated.applies`).
ROS34PW2_TERMS = 2
#: Hairer's DOPRI5 code calls a problem stiff after 15 accepted steps at the
#: stability limit, and forgets them after 6 below it. Status of an explicit
#: loop that found so (``hand_over``).
STIFF_STEPS, STIFF_RESET, HAND_OVER = 15, 6, 1


@njit(cache=True, **FLOAT_MATH)
def rms_norm(e, y0, y1, rtol, atol):
    """The error norm of step control: the root mean square of e scaled by
    atol + rtol max(|y0|, |y1|) (scipy's)."""
    s = 0.0
    for i in range(e.shape[0]):
        sc = atol + rtol * max(abs(y0[i]), abs(y1[i]))
        s += (e[i] / sc) ** 2
    return math.sqrt(s / e.shape[0])


def compiled_loop(scheme):
    """The compiled loop of one scheme: ``loop(P, t_eval, Y, onsets, j, j_stop,
    carry, counts, rtol, atol, max_step, locate, max_steps, gap_limit,
    hand_over, pair)``, ``pair`` the explicit pair (:data:`.erk.PAIRS`; ROS34PW2's
    loops take one too, and leave it).

    One loop per scheme, not one with both: ``implicit`` is a constant of
    each, so numba prunes the other scheme's branches before typing them, and
    a run compiles only its own stepper (compile time is most of a first
    run; numba caches each closure apart, by the value of ``implicit``).
    Likewise ``structured`` (``scheme`` ROS34PW2_TERMS: ROS34PW2 with the
    O(n) stiff Jacobian): chosen at run time inside one loop, it cost the
    paper scene's dense steps ~6 %.

    The explicit pairs step exactly onto every t_eval[j]. ROS34PW2 steps freely and fills
    the samples it passes by cubic Hermite interpolation of y and f at the step
    ends (third order, as the method), so a fine sample grid does not cap its
    step: at 1 ms samples on the paper scene, stepping onto them took ~2x the
    steps the tolerance needed.

    ``scheme`` EXPLICIT: the explicit 5(4) ``pair`` with scipy RK45's step
    control. ROS34PW2: the Rosenbrock-W method of :mod:`.rosenbrock`
    with the stiff Jacobian (:func:`stiff.stiff_jacobian`, or for
    ROS34PW2_TERMS :func:`rosenbrock.terms`; about one RHS call) taken at the
    start of every step; the first stage reuses f(y), so a
    step costs 4 RHS calls, the stiff Jacobian and one factorisation of W (an
    n x n LU, or O(n) on the articulated path).

    One run may take several calls. ``Y`` (s, N) is the run's sample array
    (``Y[0]`` the start state, unfilled rows NaN), ``j`` the next sample to
    fill; the call returns after the accepted step that fills sample
    ``j_stop`` (ROS34PW2 may fill several past it in that step), on failure,
    or at t_eval[-1]. ``carry`` (2 + 2N,) float holds t, h, y and f = rhs(y);
    ``counts`` (9,) int64 holds nfev, njev, nlu, nsteps, nswitches, the
    landed and rejected flags and the two counts of the stiffness test below,
    all totals over the run. Both are updated in
    place, so the next call (with the returned j) continues exactly as one
    uninterrupted call would; the Jacobian blocks need no carrying, as they
    are stale after an accepted step. A first call passes ``carry`` = (t0, 0,
    y0, 0...) and zero ``counts``: nfev == 0 marks the start, where f(y0) and
    the starting step are computed. ``max_steps`` bounds the run's total
    nsteps.

    ``hand_over`` (EXPLICIT only): test every accepted step for the stability
    limit (:func:`.erk.stiffness_ratio` above the pair's ``stiff_ratio``) and
    return with status
    ``HAND_OVER`` once STIFF_STEPS accepted steps have been at it, with never
    STIFF_RESET in a row below it in between: the caller goes on with
    ROS34PW2 from ``carry`` (:func:`integrate_compiled`).

    Returns (j, status, code): j the next sample to fill; status 0 ok
    (j > j_stop, or j == s at the end), HAND_OVER, -1 failure with code: 1 step
    collapse, 2 non-finite state, 3 gap above gap_limit, 4 max_steps, the
    negated :class:`~panel_deploy.dynamics.result.Status`, or 5, on pace to
    need far more than max_steps (:func:`.integration.off_pace`; status -4 too) (rows of Y
    from j on stay NaN).
    """
    structured = scheme == ROS34PW2_TERMS
    implicit = scheme == ROS34PW2 or structured

    @njit(cache=True, **FLOAT_MATH)
    def loop(P, t_eval, Y, onsets, j, j_stop, carry, counts, rtol, atol, max_step,
             locate, max_steps, gap_limit, hand_over, pair):
        N = Y.shape[1]
        n = P.n
        s = t_eval.shape[0]
        t = carry[0]
        h = carry[1]
        y = carry[2:2 + N].copy()
        f = carry[2 + N:2 + 2 * N].copy()
        nfev = counts[0]
        njev = counts[1]
        nlu = counts[2]
        nsteps = counts[3]
        nswitches = counts[4]
        # the last step was shortened onto a switch: do not locate in the next
        landed = counts[5] != 0
        rejected = counts[6] != 0  # the last attempt was rejected by the error test
        stiff_steps = counts[7]  # consecutive accepted explicit steps at the stability limit
        calm_steps = counts[8]  # accepted steps below it since the last at it
        expo = -1.0 / (rosenbrock.ERROR_ORDER if implicit else 5)
        scratch = kernels.scratch(P)
        near = scratch[0]
        if nfev == 0:
            f = kernels.rhs(P, y, scratch)
            nfev = 1
            # Hairer, Norsett & Wanner (II.4) starting step
            sc = np.empty(N)
            for i in range(N):
                sc[i] = atol + rtol * abs(y[i])
            d0 = math.sqrt(np.mean((y / sc) ** 2))
            d1 = math.sqrt(np.mean((f / sc) ** 2))
            h = 1e-6 if d0 < 1e-5 or d1 < 1e-5 else 0.01 * d0 / d1
            h = min(h, max_step)
        K = np.empty((7, N))
        fresh = False  # jac, or A and B, taken at the current y (a rejected step keeps them)
        status = 0
        code = 0
        while j < s:
            if not np.all(np.isfinite(f)):
                status, code = -1, 2
                break
            if j > j_stop:
                break
            target = t_eval[-1] if implicit else t_eval[j]
            step = min(h, max_step, target - t)
            lands = step == target - t
            if implicit:
                if not fresh:
                    if structured:
                        jac = rosenbrock.terms(P, y, near)
                    else:
                        A, B, ok = stiff.stiff_jacobian(P, y, near)
                    njev += 1
                    fresh = True
                if structured:
                    y1, err, ok = rosenbrock.step_terms(P, y, f, step, jac, K, scratch)
                else:
                    y1, err, ok = rosenbrock.step(P, y, f, step, A, B, K, scratch)
                nfev += 3
                nlu += 1
            else:
                y1, err, y6 = erk.step(P, y, f, step, pair, K, scratch)
                nfev += 6
            en = rms_norm(err, y, y1, rtol, atol)
            if not math.isfinite(en):
                h = 0.2 * step
            elif en > 1.0:
                h = step * max(0.2, 0.9 * en ** expo)
                rejected = True
            else:
                frac = switches.first_switch(n, y, y1, step, atol) if locate and not landed else 2.0
                if switches.EDGE < frac < 1.0 - switches.EDGE:
                    h = frac * step
                    nswitches += 1
                    landed = True
                    continue
                landed = False
                t_old, y_old, f_old = t, y, f
                t = target if lands else t + step
                y = y1
                if implicit:
                    f = kernels.rhs(P, y, scratch)
                    nfev += 1
                    fresh = False
                    while j < s and t_eval[j] <= t:
                        frac = (t_eval[j] - t_old) / step
                        for i in range(N):
                            Y[j, i] = switches.hermite(y_old[i], f_old[i], y[i], f[i], step, frac)
                        j += 1
                else:
                    f = K[6].copy()
                    if lands:
                        Y[j] = y
                        j += 1
                # the step's last right-hand side was at its end: the explicit pair's K[6], f
                integration.record_onsets(P, y, t, t_eval, j, onsets, near, True)
                nsteps += 1
                if gap_limit > 0.0 and integration.evaluated_gap(P, y, scratch) > gap_limit:
                    status, code = -1, 3
                    break
                if nsteps >= max_steps:
                    status, code = -1, 4
                    break
                if integration.off_pace(t_eval[0], t, t_eval[s - 1], nsteps, max_steps):
                    status, code = -1, 5
                    break
                if not implicit:
                    if hand_over:
                        if erk.stiffness_ratio(K, y, y6, step, 2 * n) > pair.stiff_ratio:
                            stiff_steps += 1
                            calm_steps = 0
                        else:
                            calm_steps += 1
                            if calm_steps == STIFF_RESET:
                                stiff_steps = 0
                        if stiff_steps == STIFF_STEPS:
                            status = HAND_OVER
                            break
                grow = min(10.0, 0.9 * en ** expo) if en > 0 else 10.0
                # After a rejection do not grow again at once (Hairer & Wanner II.4):
                # the error estimate just said the step was too long.
                h = step * (min(1.0, grow) if rejected else grow)
                rejected = False
                continue
            if h < 10.0 * np.finfo(np.float64).eps * max(1.0, abs(t)):
                status, code = -1, 1
                break
        carry[0] = t
        carry[1] = h
        carry[2:2 + N] = y
        carry[2 + N:2 + 2 * N] = f
        counts[0] = nfev
        counts[1] = njev
        counts[2] = nlu
        counts[3] = nsteps
        counts[4] = nswitches
        counts[5] = 1 if landed else 0
        counts[6] = 1 if rejected else 0
        counts[7] = stiff_steps
        counts[8] = calm_steps
        return j, status, code

    return loop


#: The compiled loop of each scheme (see :func:`compiled_loop`).
COMPILED_LOOPS = {k: compiled_loop(k) for k in (EXPLICIT, ROS34PW2, ROS34PW2_TERMS)}


#: ``choose_scheme`` takes ROS34PW2 when an explicit pair's stability limit on
#: the negative real axis, about 3.3 / rho, is below this step, s.
STIFF_STEP = 2e-4

#: The explicit pair of ``method: compiled``: Tsitouras' takes 4-10 % fewer
#: evaluations than Dormand and Prince's on the larger arrays at the scenes'
#: tolerances, with errors as small or smaller (docs/findings.md 5).
EXPLICIT_PAIR = "tsit5"


def _stiff_part(P, y):
    """[[0, I], [A, B]] (2n, 2n, 1/s) of the stiff part of the Jacobian at y
    (:func:`.stiff.stiff_jacobian`), or None where it is not finite."""
    n = P.n
    A, B, ok = stiff.stiff_jacobian(P, y, panel_contact.near_pairs(P))
    if not (ok and np.all(np.isfinite(A)) and np.all(np.isfinite(B))):
        return None
    return np.block([[np.zeros((n, n)), np.eye(n)], [A, B]])


def _radius(J) -> float:
    """Spectral radius of :func:`_stiff_part`'s J (inf for None)."""
    return math.inf if J is None else float(np.abs(np.linalg.eigvals(J)).max())


def stiffness(P, y) -> float:
    """Spectral radius (1/s) of the stiff part of the Jacobian at state y."""
    return _radius(_stiff_part(P, y))


#: Squarings of :func:`radius_bound`: for a diagonalisable J = X L X^-1 of
#: size N the bound exceeds the radius by at most the factor
#: ``(sqrt(N) cond(X))^(1 / 2^k)``, 1.34 for N = 170 and cond(X) = 1e3 at k = 5.
SQUARINGS = 5


def radius_bound(J) -> float:
    """An upper bound (1/s) on the spectral radius of the square matrix J:
    ``|J^m|_F^(1/m)`` for m = 2^SQUARINGS, which no eigenvalue exceeds (the
    Frobenius norm is submultiplicative) and which falls to the radius as m
    grows (Gelfand's formula). Each power is rescaled to norm 1 and the
    scales kept as logarithms, so none overflows or underflows; a power
    that is exactly zero leaves the bound of the one before. Five products
    of (2n, 2n) matrices: 1.3 ms on 10 x 10 against 7 ms for the
    eigenvalues."""
    X = np.array(J, dtype=float)
    log_bound = 0.0
    weight = 1.0
    for k in range(SQUARINGS + 1):
        if k:
            X = X @ X
        largest = float(np.abs(X).max())
        if largest == 0.0:
            return 0.0 if k == 0 else math.exp(log_bound)
        X /= largest
        norm = float(np.linalg.norm(X))  # >= 1: no underflow
        X /= norm
        log_bound += weight * (math.log(largest) + math.log(norm))
        weight *= 0.5
    return math.exp(log_bound)


def choose_scheme(P, y0) -> str:
    """The compiled scheme for ``method="compiled"``: "ros34pw2" if the model is
    stiff at y0 (``3.3 / stiffness > STIFF_STEP``), else :data:`EXPLICIT_PAIR`.
    The eigenvalues are computed only where :func:`radius_bound` cannot rule
    stiffness out (10 x 10: 7 ms of a 0.4 s run).

    Measured crossover (with DOPRI5, whose stability region Tsitouras' pair
    matches within 6 %): on the paper scene (penalty closure, rho ~ 7e4 1/s at
    the stowed state) ROS34PW2 needs 3-25 x less time than DOPRI5 for the
    same error from rtol 1e-2 to 1e-6; on mildly stiff or non-stiff models
    (rho < 1e4 1/s) DOPRI5, of order 5 against 3, is as fast or faster,
    increasingly so at tight tolerances. Contacts that start later (k_s, c_s)
    are not foreseen: a tree that starts out of contact gets the explicit pair.
    """
    J = _stiff_part(P, y0)
    limit = 3.3 / STIFF_STEP
    if J is not None and radius_bound(J) <= limit:
        return EXPLICIT_PAIR
    return "ros34pw2" if _radius(J) > limit else EXPLICIT_PAIR


def _loop_of(scheme, P):
    """The compiled loop that runs ``scheme`` (a name of :data:`SCHEMES`) on P."""
    key = SCHEMES[scheme]
    return COMPILED_LOOPS[ROS34PW2_TERMS if key == ROS34PW2 and articulated.applies(P.n) else key]


def integrate_compiled(name, P, y0, t_eval, settings, max_steps, gap_limit, stops):
    """The compiled loop of scheme ``name`` (a name of :data:`SCHEMES`, or
    "compiled": :func:`choose_scheme` picks) called once per block of samples
    (see :func:`integrate_blocks`).

    "compiled" that starts on its explicit pair hands over to ROS34PW2 for the
    rest of the run once the pair's steps are held at its stability limit (the loop's
    ``hand_over``), as LSODA does: choose_scheme judges the start state
    alone, and a heavily damped array turns stiff soon after it (10 x 10 at
    c/k 3 s within 0.1 s) or once its hinges come onto their stops (8 x 8 at
    c/k 2 s at 3.75 s). The run's ``scheme`` then says when it handed over.
    One way only: the lightly damped deployments whose steps are set by
    accuracy never reach the limit (docs/findings.md 5).
    """
    scheme = choose_scheme(P, y0) if name == "compiled" else name
    hand_over = name == "compiled" and scheme == EXPLICIT_PAIR
    loop = _loop_of(scheme, P)
    pair = erk.PAIRS.get(scheme, erk.PAIRS[EXPLICIT_PAIR])  # ROS34PW2's loops leave it
    s, N = len(t_eval), len(y0)
    Y = np.full((s, N), np.nan)
    Y[0] = y0
    onsets = no_onsets(s)
    carry = np.zeros(2 + 2 * N)
    carry[0] = t_eval[0]
    carry[2:2 + N] = y0
    counts = np.zeros(9, dtype=np.int64)
    before = integration.Counters()
    j, lo, done = 1, 0, 0
    for stop in stops:
        status = code = 0
        while j <= stop:  # else ROS34PW2 filled this block already
            try:
                j, status, code = loop(
                    P, t_eval, Y, onsets, j, int(stop), carry, counts, settings.rtol,
                    settings.atol, settings.max_step, switches.locates(P, settings), max_steps,
                    gap_limit, hand_over, pair)
            except ZeroDivisionError:  # 1/0 in boxes.py, on numba's error model (the dynamics: inf)
                status, code = -1, -Status.NON_FINITE
            if status != HAND_OVER:
                break
            status, hand_over, loop = 0, False, _loop_of("ros34pw2", P)
            scheme = f"{scheme}, then ros34pw2 from t = {carry[0]:.6g} s"
        message = integration.FAILURES.get(code, "")
        status = Status(-min(code, 4) if status else 0)
        done = integration.leading_finite(Y, done, j)
        hi = min(stop + 1, done) if status == 0 else done
        msg = "reached t_end" if status == 0 else (
            f"{message} at t = {t_eval[done - 1]:.6g} s (last sample); integration stopped")
        total = integration.Counters(*(int(c) for c in counts[:5]))
        yield integration.Integration(Y[lo:max(lo, hi)], status, msg, total.since(before), scheme,
                          onsets[lo:max(lo, hi)])
        before = total
        lo = max(lo, hi)
        if status != 0:
            return
