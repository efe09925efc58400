"""What every integrator of :mod:`.integrate` shares: the blocks a run yields
(:class:`Integration`) and their :class:`Counters`, the work limits that end
a run early (the pace, the loop-closure gap) and the contact onsets recorded
per sample interval."""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numba import njit

from . import articulated, closure, kernels, panel_contact
from ._jit import FLOAT_MATH
from .result import Status


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
    = failure with ``message``); ``method`` the :data:`.integrate.METHODS` entry that ran
    ("tsit5" or "ros34pw2" for "compiled"); ``onsets`` (s_done, 9) the
    fastest panel contact onset in each sample's interval (:func:`record_onsets`).
    """

    y: np.ndarray
    status: Status
    message: str
    counters: Counters
    method: str
    onsets: np.ndarray


#: A run whose pace so far would need more than PACE_FACTOR step budgets to
#: reach t_end ends as soon as that shows, instead of spending the whole budget
#: first (minutes, for a tolerance below what double precision can meet). The
#: pace is checked every hundredth of the budget, and never before PACE_MIN_STEPS
#: steps: the first steps are small by design (the starting step), and a run
#: that starts slowly and speeds up (a stiff transient) stays far inside the factor.
PACE_FACTOR, PACE_MIN_STEPS = 100.0, 1000


@njit(cache=True, **FLOAT_MATH)
def off_pace(t0, t, t_end, nsteps, max_steps) -> bool:
    """Whether the pace of ``nsteps`` steps from t0 to t, at a check point,
    projects past PACE_FACTOR budgets by t_end."""
    if nsteps % max(PACE_MIN_STEPS, max_steps // 100) != 0:
        return False
    return (t_end - t) * nsteps > PACE_FACTOR * max_steps * (t - t0)


#: What the compiled loop's failure codes say: 1-4 are minus the Status of the
#: failure; 5, a budget failure found early (:func:`off_pace`), is also -4.
FAILURES = {1: "step size collapsed", 2: "non-finite state or derivative",
             3: "loop-closure gap exceeded the limit", 4: "step budget exhausted",
             5: f"on pace to need over {PACE_FACTOR:g} times the step budget"}


@njit(cache=True, **FLOAT_MATH)
def max_gap(P, y):
    """Largest loop-closure gap at state y, m."""
    n = P.n
    R, p, _, _, _ = kernels.kinematics(P, y[:n], y[n:2 * n])
    return closure.largest_gap(P, R, p)


@njit(cache=True, **FLOAT_MATH)
def evaluated_gap(P, y, scratch):
    """:func:`max_gap` at y where the run's last right-hand side was at y
    (the compiled loops evaluate it at an accepted step's end): on the O(n)
    path y's poses are in the run's ``scratch`` (:func:`kernels.scratch`) to
    take, not to compute again (2 % of 10 x 10's run). Compiled callers only:
    from Python numba would type the scratch's StructRef array by array."""
    if articulated.applies(P.n):
        return closure.largest_gap(P, scratch[1].R, scratch[1].p)
    return max_gap(P, y)


def leading_finite(rows, done, upto):
    """Advance ``done`` over the finite rows of ``rows`` below ``upto``."""
    while done < upto and np.all(np.isfinite(rows[done])):
        done += 1
    return done


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
