"""The result of one deployment simulation, sampled at s evenly spaced instants.

A failed run is data, as in :func:`scipy.integrate.solve_ivp`: ``success`` is
False, ``status``/``message`` say why, and the arrays hold the samples computed
before the failure (``t`` may then be shorter than requested).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from enum import IntEnum

import numpy as np


class Status(IntEnum):
    """:attr:`SimulationResult.status`: 0 when the run reached t_end, else why it
    stopped (as :func:`scipy.integrate.solve_ivp`'s status, a code to test; the
    message says where and what)."""

    REACHED_T_END = 0
    #: Stopped on request before t_end (a cancelled Deploy goal, Ctrl-C):
    #: not a failure of the integration, but not a whole run either, so
    #: ``success`` is False (unlike scipy's 1, an event's termination).
    STOPPED = 1
    #: The step size fell below round-off of t (or a scipy solver gave up: its
    #: failures are step-size failures).
    STEP_COLLAPSE = -1
    #: A state or derivative became NaN or infinite.
    NON_FINITE = -2
    #: A loop-closure gap exceeded ``simulation.gap_limit`` (the cut hinge came apart).
    GAP_EXCEEDED = -3
    #: The step budget ran out before t_end.
    BUDGET_EXHAUSTED = -4
    #: The relative energy balance error exceeded :data:`ENERGY_LIMIT`: the
    #: integration created or lost that much energy, so the trajectory is not
    #: an answer (tighten ``simulation.rtol``).
    ENERGY_DRIFT = -5
    #: The panel contacts' law created or lost more than :data:`ENERGY_LIMIT`
    #: of the start energy (:func:`~.report.contact_energy_error`): where a
    #: pair changes the features it touches by, the energy a law built on the
    #: separating axis stores jumps, and the bodies get it back or lose it when
    #: the pair parts. The integration is not at fault; the contact model is.
    CONTACT_ENERGY = -6


#: Relative energy balance error above which a run fails (Status.ENERGY_DRIFT),
#: and share of the start energy the panel contacts' law may create or lose
#: (Status.CONTACT_ENERGY).
#: Our runs stay far below it (the paper scene: 1.3e-6 at rtol 1e-6, 5.1e-5 at
#: 1e-4); with every damper at 0 the compiled integrator at rtol 1e-4 drifted
#: by 26 % and the run said "ok".
ENERGY_LIMIT = 0.01
#: Initial energy (J) below which the relative energy balance error is
#: round-off divided by round-off (k = 0 and g = 0: 1e17): not checked,
#: reported as None.
ENERGY_FLOOR = 1e-12


@dataclass
class SimulationResult:
    """Sampled trajectory of a deployment.

    Shapes: s samples, n coordinates (tree hinges), nb bodies.

    Attributes
    ----------
    t : (s,) ndarray
        Sample instants t_j, s, evenly spaced from 0 to t_end.
    theta, omega : (s, n) ndarray
        Hinge angles (rad) and rates (rad/s) of the tree coordinates.
    rotation : (s, nb, 3, 3) ndarray
        Body orientation in the ground frame (flat array frame).
    position : (s, nb, 3) ndarray
        Body centroid in the ground frame, m.
    linear_velocity, angular_velocity : (s, nb, 3) ndarray
        Centroid velocity (m/s) and angular velocity (rad/s), ground frame.
    energy : dict of str -> (s,) ndarray
        "kinetic", "spring" (hinge springs, contact and penalty springs),
        "contact" (the panel contacts' part of "spring"), "gravity"
        (potential, zero at the flat state), "dissipated" (work done by all
        dampers and the air drag since t = 0), "constraint_work" (done on the
        system by the exact closure's forces since t = 0) and "contact_work"
        (done by the bodies on the panel contacts' springs since t = 0; where
        the contact law is conservative, "contact" less its start value), in J.
    constraint_gap : (s,) ndarray
        Largest loop-closure gap |MM'|, |NN'| over the cut hinges, m (zeros
        for a tree).
    closure_sigma_min : (s, k) ndarray
        The k smallest singular values of the loop-closure Jacobian (empty
        second axis for a tree).
    cut_theta : (s, m) ndarray
        Angles of the m cut hinges, rad (they are not coordinates: computed
        from the body poses; empty second axis for a tree).
    contact_onsets : (s, 9) ndarray (columns :data:`ONSET_COLUMNS`)
        Row j: the fastest panel contact onset in (t_{j-1}, t_j] (the fastest
        approach of a contact point of ``model.contact_pairs`` not yet 10 um
        deep, :func:`~panel_deploy.dynamics.kernels.contact_onsets`, at the end
        of each of the integrator's steps): its time (s), approach speed along the normal
        (m/s), the pair's index in ``model.contact_pairs``, the contact point
        (m) and the normal (first body towards the second), ground frame;
        time nan, speed 0 and index -1 where none (every row without panel
        contacts). What tells an impact the contact absorbed from a press.
    success : bool
    status : Status
        0 (``Status.REACHED_T_END``), 1 stopped on request, or the negative
        code of the failure: -1 step-size collapse, -2 non-finite state, -3
        loop-closure gap above its limit, -4 step budget exhausted, -5
        energy balance error above :data:`ENERGY_LIMIT`.
    message : str
    nfev, njev, nlu, nsteps, nswitches : int
        Right-hand-side and Jacobian evaluations, LU decompositions, steps,
        located contact switches.
    wall_time : float
        s.
    method : str
        ``simulation.method`` as asked for.
    scheme : str
        The integrator that ran: ``method``, or for "compiled" the scheme it
        chose ("tsit5" or "ros34pw2"), or "tsit5, then ros34pw2 from t = T s" where
        tsit5 handed over (:func:`~panel_deploy.dynamics.compiled.integrate_compiled`).
    gap_limit : float
        Loop-closure gap that would have ended the run, m (0 for a tree).
    """

    t: np.ndarray
    theta: np.ndarray
    omega: np.ndarray
    rotation: np.ndarray
    position: np.ndarray
    linear_velocity: np.ndarray
    angular_velocity: np.ndarray
    energy: dict
    constraint_gap: np.ndarray
    closure_sigma_min: np.ndarray
    cut_theta: np.ndarray
    contact_onsets: np.ndarray
    success: bool
    status: Status
    message: str
    nfev: int = 0
    njev: int = 0
    nlu: int = 0
    nsteps: int = 0
    nswitches: int = 0
    wall_time: float = 0.0
    method: str = ""
    scheme: str = ""
    gap_limit: float = 0.0

    def head(self, n: int) -> SimulationResult:
        """The first ``n`` samples (counters, status and message unchanged)."""
        per_sample = {name: getattr(self, name)[:n] for name in PER_SAMPLE}
        return replace(self, **per_sample, energy={k: v[:n] for k, v in self.energy.items()})


#: The columns of ``SimulationResult.contact_onsets``: time (s), approach speed
#: (m/s), index in ``Model.contact_pairs``, contact point (m), normal.
ONSET_COLUMNS = ("t", "speed", "pair", "x", "y", "z", "nx", "ny", "nz")


def no_onsets(s: int) -> np.ndarray:
    """``contact_onsets`` of s samples without an onset: time nan, speed 0, pair -1."""
    onsets = np.full((s, len(ONSET_COLUMNS)), np.nan)
    onsets[:, 1] = 0.0
    onsets[:, 2] = -1.0
    return onsets


#: The per-sample arrays of a :class:`SimulationResult` (first axis: samples).
PER_SAMPLE = ("t", "theta", "omega", "rotation", "position", "linear_velocity",
              "angular_velocity", "constraint_gap", "closure_sigma_min", "cut_theta",
              "contact_onsets")


def concatenate(blocks) -> SimulationResult:
    """One result from consecutive blocks of :func:`~.simulate.simulate_segments`.

    Per-sample arrays are joined; counters and ``wall_time`` are summed;
    ``success``, ``status`` and ``message`` are the last block's.
    """
    blocks = list(blocks)
    if not blocks:
        raise ValueError("concatenate: no blocks")
    last = blocks[-1]
    per_sample = {name: np.concatenate([getattr(b, name) for b in blocks]) for name in PER_SAMPLE}
    energy = {k: np.concatenate([b.energy[k] for b in blocks]) for k in last.energy}
    counters = {name: sum(getattr(b, name) for b in blocks)
                for name in ("nfev", "njev", "nlu", "nsteps", "nswitches", "wall_time")}
    return replace(last, **per_sample, **counters, energy=energy)
