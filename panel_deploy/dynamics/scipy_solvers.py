"""scipy's OdeSolver classes (``simulation.method`` RK23 ... LSODA) driven step
by step for :mod:`.integrate`: sampled by dense output, with the contact
switches located as the compiled loop locates them."""

from __future__ import annotations

import numpy as np

from . import integration, kernels, switches
from .result import Status, no_onsets

#: scipy's implicit solvers: they get the analytic Jacobian.
IMPLICIT = ("Radau", "BDF", "LSODA")


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
    near, buffers = kernels.scratch(P)

    def fun(t, y):
        counts["nfev"] += 1
        return kernels.rhs_apart(P, y, near, buffers)

    def jac(t, y):
        counts["njev"] += 1
        return kernels.rhs_jacobian_apart(P, y, near, buffers)

    opts = dict(rtol=settings.rtol, atol=settings.atol, max_step=settings.max_step)
    if name in IMPLICIT:
        opts["jac"] = jac

    t_end = t_eval[-1]
    out = [y0]
    onsets = no_onsets(len(t_eval))
    j = 1
    lo = done = 0
    nsteps = nlu = nsw = 0
    before = integration.Counters()
    status, message = Status.REACHED_T_END, "reached t_end"
    t, y, bound = t_eval[0], y0, t_end
    solver = cls(fun, t, y, bound, **opts)
    landed = False  # as in dopri5: after a located switch the next step is free
    locate = switches.locates(P, settings)
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
                frac = switches.first_switch(n, y_old, y_new, solver.t - t_old, settings.atol)
                if switches.EDGE < frac < 1.0 - switches.EDGE:
                    dt = solver.t - t_old
                    t_sw = switches.refine_switch(solver.dense_output(), n, y_old, y_new, t_old,
                                          solver.t, frac)
                    if switches.EDGE * dt < t_sw - t_old < (1.0 - switches.EDGE) * dt:
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
            integration.record_onsets(P, solver.y, solver.t, t_eval, j, onsets, near)
            if gap_limit > 0 and integration.max_gap(P, solver.y) > gap_limit:
                status = Status.GAP_EXCEEDED
                message = (f"loop-closure gap {integration.max_gap(P, solver.y):.3g} m exceeded the limit "
                           f"{gap_limit:.3g} m at t = {solver.t:.6g} s")
                break
            if nsteps >= max_steps:
                status = Status.BUDGET_EXHAUSTED
                message = f"step budget ({max_steps}) exhausted at t = {solver.t:.6g} s"
                break
            if integration.off_pace(t_eval[0], solver.t, t_end, nsteps, max_steps):
                status = Status.BUDGET_EXHAUSTED
                message = f"{integration.FAILURES[5]} ({max_steps}) at t = {solver.t:.6g} s"
                break
        done = integration.leading_finite(out, done, len(out))
        hi = max(lo, min(stop + 1, done) if status == 0 else done)
        total = integration.Counters(counts["nfev"], counts["njev"], nlu + getattr(solver, "nlu", 0), nsteps, nsw)
        block = np.array(out[lo:hi]).reshape(hi - lo, N)
        yield integration.Integration(block, status, message, total.since(before), name, onsets[lo:hi])
        before, lo = total, hi
        if status != 0:
            return
