"""Deployment simulation: ``simulate(model, settings) -> SimulationResult``, or
the same run (bit for bit) handed out in blocks of samples by
``simulate_segments``."""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from ..errors import ModelError
from ..model import Model, State
from . import kernels
from .integrate import integrate_blocks
from .pack import pack
from .report import contact_energy_created, total_energy
from .result import ENERGY_FLOOR, ENERGY_LIMIT, SimulationResult, Status

#: Gap at which a loop closure counts as blown up, as a fraction of the
#: smallest in-plane panel edge (10 % of a 0.1 m panel = 10 mm).
GAP_LIMIT_FRACTION = 0.1


def default_gap_limit(model: Model) -> float:
    """Closure blow-up threshold, m: ``GAP_LIMIT_FRACTION`` x smallest panel edge."""
    return GAP_LIMIT_FRACTION * min(min(b.size[0], b.size[1]) for b in model.bodies)


def simulate(model: Model, settings, state: State | None = None, *,
             max_steps: int = 2_000_000, gap_limit: float | None = None) -> SimulationResult:
    """Simulate the deployment of ``model`` from ``state`` (default: stowed, at rest).

    This is :func:`simulate_segments` in one block (one code path): its
    blocks joined are this result bit for bit.

    Parameters
    ----------
    model : Model
    settings : SimulationSection (or any object with its attributes)
        ``t_end`` (s, absolute end time), ``method`` (a name in
        :data:`~panel_deploy.dynamics.integrate.METHODS`: RK23, RK45, DOP853,
        Radau, BDF, LSODA; dopri5, tsit5, ros34pw2, or compiled, which takes
        ros34pw2 when the model is stiff at the start state and tsit5 otherwise),
        ``rtol``, ``atol``, ``max_step`` (s),
        ``samples`` (number of evenly spaced t_j from ``state.t`` to
        ``t_end``) and ``events`` (locate contact switches).
    state : State, optional
    max_steps : int
        Accepted-step budget; exhausting it ends the run with success False.
    gap_limit : float, optional
        Loop-closure gap (m) that ends the run as a blow-up; default
        :func:`default_gap_limit`. Ignored for a tree.

    Returns
    -------
    SimulationResult
        On failure (step collapse, non-finite state, gap blow-up, budget,
        relative energy balance error above
        :data:`~panel_deploy.dynamics.result.ENERGY_LIMIT`) ``success`` is
        False, ``status`` the cause (a negative
        :class:`~panel_deploy.dynamics.result.Status`) and the arrays hold the samples
        computed before it (all finite; for the energy, up to the first sample
        over the limit). ``energy`` also has
        "constraint_work", the work done on the system by the exact-closure
        constraint forces (Baumgarte stabilisation makes it non-zero; zero for
        penalty), so that ``kinetic + spring + gravity + dissipated -
        constraint_work`` is constant.

    Raises
    ------
    ModelError
        If the state does not fit the model, t_end is not after state.t, or
        the method is not one of the names above.
    """
    return next(simulate_segments(model, settings, state, max_steps=max_steps,
                                  gap_limit=gap_limit))


def simulate_segments(model: Model, settings, state: State | None = None, *,
                      segment_samples: int | None = None, max_steps: int = 2_000_000,
                      gap_limit: float | None = None):
    """:func:`simulate`, handed out in consecutive blocks of samples.

    The blocks are ONE integration, paused between blocks: the integrator
    (the compiled loop's state, or the scipy solver object) runs only as far
    as the block asked for needs and continues from where it stopped when the
    next block is asked for. Joined, the blocks' per-sample arrays are bit
    for bit those of :func:`simulate` (which is this generator's single
    block), for every method. A consumer that can stop early (at the first
    collision, or when the array first lies flat) closes the generator and
    the rest of the run is never integrated.

    Parameters
    ----------
    model, settings, state, max_steps, gap_limit
        As for :func:`simulate`; ``max_steps`` is the budget of the whole run,
        and "compiled" picks its scheme at the start state (handing over from
        tsit5 to ROS34PW2 at most once, inside a block).
    segment_samples : int, optional
        Samples per block (the first block also holds the start sample);
        default all of them in one block.

    Yields
    ------
    SimulationResult
        One per block, its ``t`` continuing the previous block's; counters
        (``nfev``, ``nsteps``, ...) and ``wall_time`` are the block's own
        (they sum to :func:`simulate`'s; ROS34PW2 fills the samples a step
        passes, so a block it filled ahead costs nothing). The last block is
        the one that reaches ``t_end`` or fails (``success`` False, as in
        :func:`simulate`); a failing block holds the samples reached, which
        may be fewer or (ROS34PW2) more than ``segment_samples``.

    Raises
    ------
    ModelError
        As :func:`simulate`; also if ``segment_samples`` is not a positive
        integer.
    """
    if segment_samples is not None and not (isinstance(segment_samples, int)
                                            and segment_samples >= 1):
        raise ModelError(f"segment_samples: expected an integer >= 1, got {segment_samples!r}")
    state = State.stowed(model) if state is None else state
    n = model.n_coords
    theta = np.asarray(state.theta, dtype=float)
    omega = np.asarray(state.omega, dtype=float)
    if theta.shape != (n,) or omega.shape != (n,):
        raise ModelError(f"state: expected theta and omega of shape ({n},), "
                         f"got {theta.shape} and {omega.shape}")
    if not (np.all(np.isfinite(theta)) and np.all(np.isfinite(omega))):
        raise ModelError("state: theta and omega must be finite")
    if not settings.t_end > state.t:
        raise ModelError(f"simulation.t_end: {settings.t_end:g} s is not after the start "
                         f"time {state.t:g} s")
    P = pack(model)
    limit = (default_gap_limit(model) if gap_limit is None else gap_limit) if model.cut_hinges else 0.0
    t_eval = np.linspace(state.t, settings.t_end, settings.samples)
    y = kernels.state_vector(theta, omega)
    last = len(t_eval) - 1
    block = last if segment_samples is None else segment_samples
    stops = [*range(block, last, block), last]
    blocks = integrate_blocks(P, y, t_eval, settings, max_steps, limit, stops)
    first = 0
    energy_0 = contact_0 = None
    while True:
        start = time.perf_counter()
        run = next(blocks, None)
        wall = time.perf_counter() - start
        if run is None:
            return
        result = _result(P, t_eval[first:first + len(run.y)], run, settings.method, wall, limit)
        total = total_energy(result.energy)
        if energy_0 is None and len(total):
            energy_0, contact_0 = total[0], result.energy["contact"][0]
        failed = _energy_failure(result, total, energy_0, contact_0)
        if failed is not None:
            blocks.close()
            yield failed
            return
        yield result
        first += len(run.y)


def _energy_failure(result: SimulationResult, total, energy_0, contact_0) -> SimulationResult | None:
    """``result`` up to its first sample where the relative energy balance
    error (the integration's) or the energy the panel contacts' law has
    created or lost (their stored energy less ``contact_0``, its start value,
    less the work done on them) exceeds :data:`~.result.ENERGY_LIMIT` of the
    start energy ``energy_0``, as a failure (Status.ENERGY_DRIFT or
    CONTACT_ENERGY); None if there is none (or the run starts without energy,
    where the errors mean nothing)."""
    if energy_0 is None or abs(energy_0) < ENERGY_FLOOR:
        return None
    drift = np.abs(total - energy_0) / abs(energy_0)
    created = contact_energy_created(result.energy, contact_0) / abs(energy_0)
    over = np.flatnonzero((drift > ENERGY_LIMIT) | (np.abs(created) > ENERGY_LIMIT))
    if not len(over):
        return None
    j = over[0]
    if drift[j] > ENERGY_LIMIT:
        status = Status.ENERGY_DRIFT
        message = (f"energy balance error {drift[j]:.3g} above {ENERGY_LIMIT:g} at t = {result.t[j]:.6g} s: "
                   f"the integration is not accurate enough (tighten simulation.rtol)")
    else:
        status = Status.CONTACT_ENERGY
        message = (f"the panel contacts' law {'created' if created[j] > 0 else 'lost'} "
                   f"{abs(created[j]) * abs(energy_0):.3g} J ({abs(created[j]):.3g} of the start energy) "
                   f"by t = {result.t[j]:.6g} s: where a pair changes the features it touches by, the "
                   f"law's stored energy jumps (docs/findings.md 3.2); the integration is not at fault")
    return replace(result.head(j + 1), success=False, status=status, message=message)


def body_states(P, theta, omega):
    """Pose and velocity of every body, indexed like ``model.bodies``.

    ``P`` is :func:`~panel_deploy.dynamics.pack.pack` of the model; ``theta``
    (rad) and ``omega`` (rad/s) are (n,). Returns the rotations (nb, 3, 3),
    centroids (nb, 3) m, centroid velocities (nb, 3) m/s and angular
    velocities (nb, 3) rad/s, in the ground frame.
    """
    return kernels.body_states(P, np.ascontiguousarray(theta, dtype=float),
                               np.ascontiguousarray(omega, dtype=float))


def _result(P, t, run, method, wall, gap_limit) -> SimulationResult:
    n = P.n
    Y = run.y
    R, p, v, w, observed, gaps, Js, cut_theta = kernels.observe_samples(P, np.ascontiguousarray(Y))
    k_sigma = min(5 * len(P.cut_a), n)
    # one LAPACK call over the stack of Jacobians, not one a sample
    sigma = (np.linalg.svd(Js, compute_uv=False)[:, ::-1][:, :k_sigma] if k_sigma
             else np.empty((len(Y), 0)))
    energy = dict(zip(("kinetic", "spring", "contact", "gravity"), observed.T.copy()))
    energy |= dict(zip(("dissipated", "constraint_work", "contact_work"), Y[:, 2 * n:].T.copy()))
    return SimulationResult(
        t=t, theta=Y[:, :n].copy(), omega=Y[:, n:2 * n].copy(),
        rotation=R, position=p, linear_velocity=v, angular_velocity=w,
        energy=energy, constraint_gap=gaps, closure_sigma_min=sigma, cut_theta=cut_theta,
        contact_onsets=run.onsets,
        success=run.status == 0, status=run.status, message=run.message,
        **run.counters._asdict(), wall_time=wall, method=method, scheme=run.method,
        gap_limit=gap_limit)
