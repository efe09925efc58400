"""Time integrators behind one interface, in one registry, :data:`METHODS`
(as scipy's ``solve_ivp`` keeps its ``METHODS``): scipy's OdeSolver classes,
and an adaptive loop compiled whole with numba around either an explicit
Runge-Kutta 5(4) pair (Tsitouras' "tsit5" or Dormand and Prince's "dopri5")
or the linearly implicit Rosenbrock-W ROS34PW2 ("ros34pw2", for the stiff
penalty and contact terms); "compiled" takes tsit5 or ros34pw2, whichever
suits the start state (:func:`.compiled.choose_scheme`). The compiled loop
is :mod:`.compiled` (the explicit pairs' step :mod:`.erk`), scipy's driver :mod:`.scipy_solvers`; what
they share, :mod:`.integration`; the switch location, :mod:`.switches`.

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

from dataclasses import dataclass
from functools import partial
from typing import Callable

import numpy as np

from ..errors import ModelError
from . import compiled, kernels, scipy_solvers
from .integration import Counters, Integration
from .result import Status, no_onsets


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
        finite = bool(np.all(np.isfinite(kernels.rhs(P, y0, kernels.scratch(P)))))
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
    return Method(name, description, partial(scipy_solvers.integrate_scipy, name))


def _compiled(name: str, description: str) -> Method:
    return Method(name, description, partial(compiled.integrate_compiled, name))


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
    _compiled("tsit5", "explicit Tsitouras 5(4) in the same loop: fewer steps at the same "
                       "tolerance"),
    _compiled("ros34pw2", "linearly implicit Rosenbrock-W ROS34PW2, compiled, for the stiff "
                          "penalty and contact terms"),
    _compiled("compiled", "tsit5 or ros34pw2, whichever suits the start state (choose_scheme); "
                          "tsit5 hands over to ros34pw2 once held at its stability limit"),
)}
