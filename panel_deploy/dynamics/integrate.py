"""Time integrators behind one interface, in one registry, :data:`METHODS`
(as scipy's ``solve_ivp`` keeps its ``METHODS``): scipy's OdeSolver classes,
and an adaptive loop compiled whole with numba around either an explicit
Dormand-Prince 5(4) ("dopri5") or the linearly implicit Rosenbrock-W ROS34PW2
("ros34pw2", for the stiff penalty and contact terms); "compiled" takes the
one of those two that suits the start state (:func:`choose_scheme`).

Both sample the state at given instants t_j (scipy by dense output, the compiled
loop by stepping exactly onto them), stop explicitly on failure, and can locate
the contact switches (a tree hinge crossing theta = 0 or pi, where Eq. 4 changes
the torque law) so that no step straddles one: a step that crosses a switch is
redone to end on it. Switches in the first or last 0.1 % of a step are left
alone (the step is already at the switch), and so is a switch in the step right
after a located one: a hinge resting on its limit chatters across it, and
locating every crossing would stall the run (Zeno), as it did at t = 0 on the
paper scene. Cut-hinge angles are not state
variables, so their switches are not located.

A run can be handed out in blocks of samples (:func:`integrate_blocks`): the
integrator pauses after the step that fills a block's last sample and resumes
from its own state (the compiled loop's carry, or the live scipy solver), so
the blocks joined are the uninterrupted run bit for bit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import partial
from typing import Callable, NamedTuple

import numpy as np
from numba import njit

from ..errors import ModelError
from . import articulated, closure, hinges, kernels, panel_contact, rosenbrock, stiff
from ._jit import FLOAT_MATH
from .result import Status, no_onsets

#: scipy's implicit solvers: they get the analytic Jacobian.
IMPLICIT = ("Radau", "BDF", "LSODA")
#: Switches closer than this fraction of a step to either end are not relocated.
EDGE = 1e-3


class Counters(NamedTuple):
    """The work of an integration, or of one block of it."""

    nfev: int = 0       # right-hand-side evaluations
    njev: int = 0       # Jacobian evaluations
    nlu: int = 0        # LU decompositions
    nsteps: int = 0     # accepted steps
    nswitches: int = 0  # located contact switches

    def since(self, before: Counters) -> Counters:
        return Counters(*(int(a) - int(b) for a, b in zip(self, before)))


@dataclass
class Integration:
    """Raw output of an integrator.

    ``y`` (s_done, N) holds the samples reached; ``status`` a
    :class:`~panel_deploy.dynamics.result.Status` (0 = t_end reached, negative
    = failure with ``message``); ``method`` the :data:`METHODS` entry that ran
    ("dopri5" or "ros34pw2" for "compiled"); ``onsets`` (s_done, 9) the
    fastest panel contact onset in each sample's interval (:func:`record_onsets`).
    """

    y: np.ndarray
    status: Status
    message: str
    counters: Counters
    method: str
    onsets: np.ndarray


# --- work limits (shared by both integrators) ---

#: A run whose pace so far would need more than PACE_FACTOR step budgets to
#: reach t_end ends as soon as that shows, instead of spending the whole budget
#: first (minutes, for a tolerance below what double precision can meet). The
#: pace is checked every hundredth of the budget, and never before PACE_MIN_STEPS
#: steps: the first steps are small by design (the starting step), and a run
#: that starts slowly and speeds up (a stiff transient) stays far inside the factor.
PACE_FACTOR, PACE_MIN_STEPS = 100.0, 1000


@njit(cache=True, **FLOAT_MATH)
def _off_pace(t0, t, t_end, nsteps, max_steps) -> bool:
    """Whether the pace of ``nsteps`` steps from t0 to t, at a check point,
    projects past PACE_FACTOR budgets by t_end."""
    if nsteps % max(PACE_MIN_STEPS, max_steps // 100) != 0:
        return False
    return (t_end - t) * nsteps > PACE_FACTOR * max_steps * (t - t0)


# --- switch location (shared by both integrators) ---

@njit(cache=True, **FLOAT_MATH)
def _modes(theta):
    out = np.empty(theta.shape[0], dtype=np.int64)
    for i in range(theta.shape[0]):
        out[i] = hinges.contact_mode(theta[i])
    return out


@njit(cache=True, **FLOAT_MATH)
def _boundary(m_old, m_new):
    return 0.0 if min(m_old, m_new) == 0 else math.pi


@njit(cache=True, **FLOAT_MATH)
def _hermite(th0, w0, th1, w1, h, s):
    """Cubic Hermite interpolant of theta at fraction s of a step of length h."""
    s2 = s * s
    s3 = s2 * s
    return ((2 * s3 - 3 * s2 + 1) * th0 + (s3 - 2 * s2 + s) * h * w0
            + (-2 * s3 + 3 * s2) * th1 + (s3 - s2) * h * w1)


def locates(P, settings) -> bool:
    """Whether a run locates the contact switches: ``settings.events``, and the
    stops of the paper's law (``P.stop_ramp`` 0), whose torque jumps at the
    switch; with a ramp it has no kink there to locate."""
    return bool(settings.events) and P.stop_ramp == 0.0


@njit(cache=True, **FLOAT_MATH)
def first_switch(n, y0, y1, h, tol):
    """Fraction of the step (0..1) at which the first tree hinge changes contact
    mode, by bisection on the cubic Hermite interpolant of theta; 2.0 if none.

    Crossings that stay within ``tol`` (rad) of the limit are ignored: the kink
    they cause is below the integration tolerance, and a hinge held on its limit
    (e.g. locked by the loop at the singular stowed state) crosses it at
    round-off amplitude on every step.
    """
    best = 2.0
    for i in range(n):
        m0 = hinges.contact_mode(y0[i])
        m1 = hinges.contact_mode(y1[i])
        if m0 == m1:
            continue
        b = _boundary(m0, m1)
        g0 = y0[i] - b
        if max(abs(g0), abs(y1[i] - b)) <= tol:
            continue
        lo, hi = 0.0, 1.0
        for _ in range(50):
            mid = 0.5 * (lo + hi)
            g = _hermite(y0[i], y0[n + i], y1[i], y1[n + i], h, mid) - b
            if (g > 0) == (g0 > 0):
                lo = mid
            else:
                hi = mid
        best = min(best, hi)
    return best


@njit(cache=True, **FLOAT_MATH)
def max_gap(P, y):
    """Largest loop-closure gap at state y, m."""
    n = P.n
    R, p, _, _, _ = kernels.kinematics(P, y[:n], y[n:2 * n])
    return closure.largest_gap(P, R, p)


# --- compiled Dormand-Prince 5(4) ---

_C = np.array([0.0, 1 / 5, 3 / 10, 4 / 5, 8 / 9, 1.0])
_A = np.array([
    [0.0, 0.0, 0.0, 0.0, 0.0],
    [1 / 5, 0.0, 0.0, 0.0, 0.0],
    [3 / 40, 9 / 40, 0.0, 0.0, 0.0],
    [44 / 45, -56 / 15, 32 / 9, 0.0, 0.0],
    [19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729, 0.0],
    [9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656],
])
_B = np.array([35 / 384, 0.0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84])
_E = np.array([71 / 57600, 0.0, -71 / 16695, 71 / 1920, -17253 / 339200, 22 / 525, -1 / 40])


@njit(cache=True, **FLOAT_MATH)
def _rms_norm(e, y0, y1, rtol, atol):
    s = 0.0
    for i in range(e.shape[0]):
        sc = atol + rtol * max(abs(y0[i]), abs(y1[i]))
        s += (e[i] / sc) ** 2
    return math.sqrt(s / e.shape[0])


@njit(cache=True, **FLOAT_MATH)
def _dopri5_step(P, y, f, h, K, near=None):
    """One Dormand-Prince step of length h; returns (y1, err) and leaves rhs(y1) in K[6]
    (``near``: the run's candidate list, :func:`panel_contact.near_pairs`)."""
    N = y.shape[0]
    K[0] = f
    yi = np.empty(N)
    for st in range(1, 6):
        for i in range(N):
            s = y[i]
            for q in range(st):
                s += h * _A[st, q] * K[q, i]
            yi[i] = s
        K[st] = kernels.rhs(P, yi, near)
    y1 = np.empty(N)
    for i in range(N):
        s = y[i]
        for q in range(6):
            s += h * _B[q] * K[q, i]
        y1[i] = s
    K[6] = kernels.rhs(P, y1, near)
    err = np.empty(N)
    for i in range(N):
        s = 0.0
        for q in range(7):
            s += h * _E[q] * K[q, i]
        err[i] = s
    return y1, err


#: Compiled schemes (keys of ``COMPILED_LOOPS``).
DOPRI5, ROS34PW2 = 0, 1
SCHEMES = {"dopri5": DOPRI5, "ros34pw2": ROS34PW2}
#: Key of the ROS34PW2 loop on the O(n) path (where :func:`articulated.applies`).
ROS34PW2_TERMS = 2


@njit(cache=True, **FLOAT_MATH)
def record_onsets(P, y, t, t_eval, j, onsets, near, evaluated=False):
    """The contact onsets of the accepted step that ended at (t, y) into the
    row of the sample interval (t_{k-1}, t_k] that holds t, given j, the next
    sample to fill, with the run's candidate list ``near``: those its last
    right-hand side met if ``evaluated`` (it was at y:
    :func:`panel_contact.take_onsets`), else found at y
    (:func:`kernels.contact_onsets`)."""
    k = j - 1 if t <= t_eval[j - 1] else j
    if k < t_eval.shape[0]:
        if evaluated:
            panel_contact.take_onsets(near, t, onsets[k])
        else:
            kernels.contact_onsets(P, y, t, onsets[k], near)


def _compiled_loop(scheme):
    """The compiled loop of one scheme: ``loop(P, t_eval, Y, j, j_stop, carry,
    counts, rtol, atol, max_step, locate, max_steps, gap_limit)``.

    One loop per scheme, not one with both: ``implicit`` is a constant of
    each, so numba prunes the other scheme's branches before typing them, and
    a run compiles only its own stepper (compile time is most of a first
    run; numba caches each closure apart, by the value of ``implicit``).
    Likewise ``structured`` (``scheme`` ROS34PW2_TERMS: ROS34PW2 with the
    O(n) stiff Jacobian): chosen at run time inside one loop, it cost the
    paper scene's dense steps ~6 %.

    DOPRI5 steps exactly onto every t_eval[j]. ROS34PW2 steps freely and fills
    the samples it passes by cubic Hermite interpolation of y and f at the step
    ends (third order, as the method), so a fine sample grid does not cap its
    step: at 1 ms samples on the paper scene, stepping onto them took ~2x the
    steps the tolerance needed.

    ``scheme`` DOPRI5: explicit Dormand-Prince 5(4) (scipy RK45's tableau and
    step control). ROS34PW2: the Rosenbrock-W method of :mod:`.rosenbrock`
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
    ``counts`` (7,) int64 holds nfev, njev, nlu, nsteps, nswitches and the
    landed and rejected flags, all totals over the run. Both are updated in
    place, so the next call (with the returned j) continues exactly as one
    uninterrupted call would; the Jacobian blocks need no carrying, as they
    are stale after an accepted step. A first call passes ``carry`` = (t0, 0,
    y0, 0...) and zero ``counts``: nfev == 0 marks the start, where f(y0) and
    the starting step are computed. ``max_steps`` bounds the run's total
    nsteps.

    Returns (j, status, code): j the next sample to fill; status 0 ok
    (j > j_stop, or j == s at the end), -1 failure with code: 1 step
    collapse, 2 non-finite state, 3 gap above gap_limit, 4 max_steps, the
    negated :class:`~panel_deploy.dynamics.result.Status`, or 5, on pace to
    need far more than max_steps (:func:`_off_pace`; status -4 too) (rows of Y
    from j on stay NaN).
    """
    structured = scheme == ROS34PW2_TERMS
    implicit = scheme == ROS34PW2 or structured

    @njit(cache=True, **FLOAT_MATH)
    def loop(P, t_eval, Y, onsets, j, j_stop, carry, counts, rtol, atol, max_step,
             locate, max_steps, gap_limit):
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
        expo = -1.0 / (rosenbrock.ERROR_ORDER if implicit else 5)
        near = panel_contact.near_pairs(P)
        if nfev == 0:
            f = kernels.rhs(P, y, near)
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
                    y1, err, ok = rosenbrock.step_terms(P, y, f, step, jac, K, near)
                else:
                    y1, err, ok = rosenbrock.step(P, y, f, step, A, B, K, near)
                nfev += 3
                nlu += 1
            else:
                y1, err = _dopri5_step(P, y, f, step, K, near)
                nfev += 6
            en = _rms_norm(err, y, y1, rtol, atol)
            if not math.isfinite(en):
                h = 0.2 * step
            elif en > 1.0:
                h = step * max(0.2, 0.9 * en ** expo)
                rejected = True
            else:
                frac = first_switch(n, y, y1, step, atol) if locate and not landed else 2.0
                if EDGE < frac < 1.0 - EDGE:
                    h = frac * step
                    nswitches += 1
                    landed = True
                    continue
                landed = False
                t_old, y_old, f_old = t, y, f
                t = target if lands else t + step
                y = y1
                if implicit:
                    f = kernels.rhs(P, y, near)
                    nfev += 1
                    fresh = False
                    while j < s and t_eval[j] <= t:
                        frac = (t_eval[j] - t_old) / step
                        for i in range(N):
                            Y[j, i] = _hermite(y_old[i], f_old[i], y[i], f[i], step, frac)
                        j += 1
                else:
                    f = K[6].copy()
                    if lands:
                        Y[j] = y
                        j += 1
                # the step's last right-hand side was at its end: DOPRI5's K[6], f
                record_onsets(P, y, t, t_eval, j, onsets, near, True)
                nsteps += 1
                if gap_limit > 0.0 and max_gap(P, y) > gap_limit:
                    status, code = -1, 3
                    break
                if nsteps >= max_steps:
                    status, code = -1, 4
                    break
                if _off_pace(t_eval[0], t, t_eval[s - 1], nsteps, max_steps):
                    status, code = -1, 5
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
        return j, status, code

    return loop


#: The compiled loop of each scheme (see :func:`_compiled_loop`).
COMPILED_LOOPS = {k: _compiled_loop(k) for k in (DOPRI5, ROS34PW2, ROS34PW2_TERMS)}


#: What the compiled loop's failure codes say: 1-4 are minus the Status of the
#: failure; 5, a budget failure found early (:func:`_off_pace`), is also -4.
_FAILURES = {1: "step size collapsed", 2: "non-finite state or derivative",
             3: "loop-closure gap exceeded the limit", 4: "step budget exhausted",
             5: f"on pace to need over {PACE_FACTOR:g} times the step budget"}


#: ``choose_scheme`` takes ROS34PW2 when DOPRI5's stability limit on the
#: negative real axis, about 3.3 / rho, is below this step, s.
STIFF_STEP = 2e-4


def stiffness(P, y) -> float:
    """Spectral radius (1/s) of the stiff part of the Jacobian at state y."""
    n = P.n
    A, B, ok = stiff.stiff_jacobian(P, y, panel_contact.near_pairs(P))
    if not (ok and np.all(np.isfinite(A)) and np.all(np.isfinite(B))):
        return math.inf
    J = np.block([[np.zeros((n, n)), np.eye(n)], [A, B]])
    return float(np.abs(np.linalg.eigvals(J)).max())


def choose_scheme(P, y0) -> str:
    """The compiled scheme for ``method="compiled"``: "ros34pw2" if the model is
    stiff at y0 (``3.3 / stiffness > STIFF_STEP``), else "dopri5".

    Measured crossover: on the paper scene (penalty closure, rho ~ 7e4 1/s at
    the stowed state) ROS34PW2 needs 3-25 x less time than DOPRI5 for the
    same error from rtol 1e-2 to 1e-6; on mildly stiff or non-stiff models
    (rho < 1e4 1/s) DOPRI5, of order 5 against 3, is as fast or faster,
    increasingly so at tight tolerances. Contacts that start later (k_s, c_s)
    are not foreseen: a tree that starts out of contact gets DOPRI5.
    """
    return "ros34pw2" if stiffness(P, y0) * STIFF_STEP > 3.3 else "dopri5"  # a model without stiffness: 0


def _leading_finite(rows, done, upto):
    """Advance ``done`` over the finite rows of ``rows`` below ``upto``."""
    while done < upto and np.all(np.isfinite(rows[done])):
        done += 1
    return done


def integrate_compiled(name, P, y0, t_eval, settings, max_steps, gap_limit, stops):
    """The compiled loop of scheme ``name`` ("dopri5", "ros34pw2", or "compiled":
    :func:`choose_scheme` picks) called once per block of samples (see
    :func:`integrate_blocks`)."""
    scheme = choose_scheme(P, y0) if name == "compiled" else name
    key = SCHEMES[scheme]
    if key == ROS34PW2 and articulated.applies(P.n):
        key = ROS34PW2_TERMS
    loop = COMPILED_LOOPS[key]
    s, N = len(t_eval), len(y0)
    Y = np.full((s, N), np.nan)
    Y[0] = y0
    onsets = no_onsets(s)
    carry = np.zeros(2 + 2 * N)
    carry[0] = t_eval[0]
    carry[2:2 + N] = y0
    counts = np.zeros(7, dtype=np.int64)
    before = Counters()
    j, lo, done = 1, 0, 0
    for stop in stops:
        status = code = 0
        if j <= stop:  # else ROS34PW2 filled this block already
            try:
                j, status, code = loop(
                    P, t_eval, Y, onsets, j, int(stop), carry, counts, settings.rtol,
                    settings.atol, settings.max_step, locates(P, settings), max_steps, gap_limit)
            except ZeroDivisionError:  # 1/0 in boxes.py, on numba's error model (the dynamics: inf)
                status, code = -1, -Status.NON_FINITE
        message = _FAILURES.get(code, "")
        status = Status(-min(code, 4) if status else 0)
        done = _leading_finite(Y, done, j)
        hi = min(stop + 1, done) if status == 0 else done
        msg = "reached t_end" if status == 0 else (
            f"{message} at t = {t_eval[done - 1]:.6g} s (last sample); integration stopped")
        total = Counters(*(int(c) for c in counts[:5]))
        yield Integration(Y[lo:max(lo, hi)], status, msg, total.since(before), scheme,
                          onsets[lo:max(lo, hi)])
        before = total
        lo = max(lo, hi)
        if status != 0:
            return


# --- scipy OdeSolver driver ---

def integrate_scipy(name, P, y0, t_eval, settings, max_steps, gap_limit, stops):
    """Drive scipy's OdeSolver ``name`` step by step, sampling by dense output; a
    generator of blocks as :func:`integrate_blocks`, the solver kept alive
    across them.

    A step that crosses a contact switch (when ``settings.events``) is
    discarded and redone by a new solver started at the step's beginning with
    ``t_bound`` at the switch; then a new solver continues from the switch.
    """
    import scipy.integrate

    cls = getattr(scipy.integrate, name)
    n, N = P.n, len(y0)
    counts = {"nfev": 0, "njev": 0}
    near = panel_contact.near_pairs(P)

    def fun(t, y):
        counts["nfev"] += 1
        return kernels.rhs(P, y, near)

    def jac(t, y):
        counts["njev"] += 1
        return kernels.rhs_jacobian(P, y, kernels.rhs(P, y, near), near)

    opts = dict(rtol=settings.rtol, atol=settings.atol, max_step=settings.max_step)
    if name in IMPLICIT:
        opts["jac"] = jac

    t_end = t_eval[-1]
    out = [y0]
    onsets = no_onsets(len(t_eval))
    j = 1
    lo = done = 0
    nsteps = nlu = nsw = 0
    before = Counters()
    status, message = Status.REACHED_T_END, "reached t_end"
    t, y, bound = t_eval[0], y0, t_end
    solver = cls(fun, t, y, bound, **opts)
    landed = False  # as in dopri5: after a located switch the next step is free
    locate = locates(P, settings)
    for stop in stops:
        while j <= stop:
            if solver.status == "finished":
                nlu += getattr(solver, "nlu", 0)
                t, y, bound = solver.t, solver.y, t_end
                solver = cls(fun, t, y, bound, **opts)
                continue
            t_old, y_old = solver.t, solver.y.copy()
            try:
                msg = solver.step()
            except (ValueError, np.linalg.LinAlgError, ZeroDivisionError) as e:  # LU on inf, 1/0
                status = Status.NON_FINITE
                message = f"{name} failed at t = {t_old:.6g} s: {e}"
                break
            if solver.status == "failed":
                status = Status.STEP_COLLAPSE
                message = f"{name} failed at t = {t_old:.6g} s: {msg}"
                break
            y_new = solver.y
            if not np.all(np.isfinite(y_new)):
                status, message = Status.NON_FINITE, f"non-finite state at t = {solver.t:.6g} s"
                break
            nsteps += 1
            if locate and not landed:
                frac = first_switch(n, y_old, y_new, solver.t - t_old, settings.atol)
                if EDGE < frac < 1.0 - EDGE:
                    dt = solver.t - t_old
                    t_sw = _refine_switch(solver.dense_output(), n, y_old, y_new, t_old,
                                          solver.t, frac)
                    if EDGE * dt < t_sw - t_old < (1.0 - EDGE) * dt:
                        nsw += 1
                        nlu += getattr(solver, "nlu", 0)
                        solver = cls(fun, t_old, y_old, t_sw, **opts)
                        landed = True
                        continue
            landed = False
            sol = solver.dense_output()
            while j < len(t_eval) and t_eval[j] <= solver.t:
                out.append(sol(t_eval[j]))
                j += 1
            record_onsets(P, solver.y, solver.t, t_eval, j, onsets, near)
            if gap_limit > 0 and max_gap(P, solver.y) > gap_limit:
                status = Status.GAP_EXCEEDED
                message = (f"loop-closure gap {max_gap(P, solver.y):.3g} m exceeded the limit "
                           f"{gap_limit:.3g} m at t = {solver.t:.6g} s")
                break
            if nsteps >= max_steps:
                status = Status.BUDGET_EXHAUSTED
                message = f"step budget ({max_steps}) exhausted at t = {solver.t:.6g} s"
                break
            if _off_pace(t_eval[0], solver.t, t_end, nsteps, max_steps):
                status = Status.BUDGET_EXHAUSTED
                message = f"{_FAILURES[5]} ({max_steps}) at t = {solver.t:.6g} s"
                break
        done = _leading_finite(out, done, len(out))
        hi = max(lo, min(stop + 1, done) if status == 0 else done)
        total = Counters(counts["nfev"], counts["njev"], nlu + getattr(solver, "nlu", 0), nsteps, nsw)
        block = np.array(out[lo:hi]).reshape(hi - lo, N)
        yield Integration(block, status, message, total.since(before), name, onsets[lo:hi])
        before, lo = total, hi
        if status != 0:
            return


def _refine_switch(sol, n, y_old, y_new, t_old, t_new, frac):
    """Switch time from the solver's own dense output (better than the Hermite guess)."""
    from scipy.optimize import brentq

    m0 = _modes(y_old[:n])
    m1 = _modes(y_new[:n])
    best = t_old + frac * (t_new - t_old)
    for i in np.flatnonzero(m0 != m1):
        b = _boundary(m0[i], m1[i])
        g = lambda t: sol(t)[i] - b  # noqa: E731
        if np.sign(g(t_old)) != np.sign(g(t_new)):
            best = min(best, brentq(g, t_old, t_new, xtol=1e-14))
    return best


def integrate_blocks(P, y0, t_eval, settings, max_steps, gap_limit, stops=None):
    """Integrate the packed model from y0 with ``settings.method`` (a name in
    :data:`METHODS`), sampling at t_eval (see module docstring), as ONE run
    handed out in blocks of samples.

    ``stops`` are increasing sample indices, the last ``len(t_eval) - 1``
    (default: that one alone, one block). A generator: the integrator runs
    only as far as the block asked for needs, and continues where it stopped
    when the next one is asked for (closing the generator ends the run), so
    the blocks joined are bit for bit what one block would be. It yields one
    :class:`Integration` per stop: ``y`` the samples after the previous stop
    up to this one (the first block from sample 0), counters the block's own,
    ``max_steps`` the budget of the whole run. A failure ends it: the failing
    block holds the samples reached (these may run past its stop) and its
    negative :class:`~panel_deploy.dynamics.result.Status`.

    Raises
    ------
    ModelError
        If ``settings.method`` is not in :data:`METHODS`.
    """
    method = METHODS.get(settings.method)
    if method is None:
        raise ModelError(f"simulation.method: expected one of {', '.join(METHODS)}, "
                         f"got {settings.method!r}")
    stops = (len(t_eval) - 1,) if stops is None else stops
    try:
        finite = bool(np.all(np.isfinite(kernels.rhs(P, y0, panel_contact.near_pairs(P)))))
    except ZeroDivisionError:
        finite = False
    if not finite:
        return _not_started(y0, f"non-finite derivative at t = {t_eval[0]:.6g} s, the start "
                                "(the hinge or gravity forces overflow); integration not started",
                            settings.method)
    return method.blocks(P, y0, t_eval, settings, max_steps, gap_limit, stops)


def _not_started(y0, message, method):
    """The one block of a run that failed at its first sample."""
    yield Integration(y0[None, :].copy(), Status.NON_FINITE, message, Counters(nfev=1), method,
                      no_onsets(1))


@dataclass(frozen=True)
class Method:
    """An integrator of :data:`METHODS`: its name (``simulation.method``), what
    it is, and ``blocks(P, y0, t_eval, settings, max_steps, gap_limit, stops)``,
    the generator of :class:`Integration` blocks :func:`integrate_blocks` returns."""

    name: str
    description: str
    blocks: Callable


def _scipy(name: str, description: str) -> Method:
    return Method(name, description, partial(integrate_scipy, name))


def _compiled(name: str, description: str) -> Method:
    return Method(name, description, partial(integrate_compiled, name))


#: Every integrator by its ``simulation.method`` name. scipy.integrate is
#: imported by the runs that use it: importing it costs every command ~0.4 s.
METHODS = {m.name: m for m in (
    _scipy("RK23", "scipy's explicit Bogacki-Shampine 3(2)"),
    _scipy("RK45", "scipy's explicit Dormand-Prince 5(4)"),
    _scipy("DOP853", "scipy's explicit Dormand-Prince 8(5,3)"),
    _scipy("Radau", "scipy's implicit Radau IIA of order 5, with the analytic Jacobian"),
    _scipy("BDF", "scipy's implicit variable-order BDF, with the analytic Jacobian"),
    _scipy("LSODA", "scipy's LSODA (Adams or BDF, switching), with the analytic Jacobian"),
    _compiled("dopri5", "explicit Dormand-Prince 5(4) in a loop compiled whole with numba"),
    _compiled("ros34pw2", "linearly implicit Rosenbrock-W ROS34PW2, compiled, for the stiff "
                          "penalty and contact terms"),
    _compiled("compiled", "dopri5 or ros34pw2, whichever suits the start state (choose_scheme)"),
)}
