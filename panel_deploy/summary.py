"""A deployment and its collision check as one JSON-able dict and as text.

Numbers come from :mod:`panel_deploy.dynamics.report` and the collision report;
this module only puts them together for the CLI, the nodes and recordings.
"""

from __future__ import annotations

from .dynamics import dynamics_summary
from .dynamics.result import ENERGY_LIMIT
from .model import FLAT_TOLERANCE


def deployment_summary(model, result, collision=None, *, flat_tolerance=FLAT_TOLERANCE) -> dict:
    """Dynamics summary (hinge release times included) + closure + collision, JSON-ready.

    ``flat_tolerance`` (rad): the scene's ``simulation.flat_tolerance``.
    """
    out = dynamics_summary(model, result, flat_tolerance=flat_tolerance)
    out.update(status=int(result.status),
               closure=model.closure.method if model.cut_hinges else "none")
    if collision is not None:
        out["collision"] = collision.to_dict()
    return out


def deployment_text(s: dict) -> str:
    """The summary as a few lines of text."""
    def fmt(x, unit=""):
        return "never" if x is None else f"{x:.4g}{unit}"

    lines = [f"{'ok' if s['success'] else 'FAILED'}: {s['message']}",
             f"method {s['method']}"
             + ("" if s.get("scheme") in (None, "", s["method"]) else f" ({s['scheme']})")
             + f", closure {s['closure']}, simulated to {s['t_end']:.4g} s "
             f"in {s['wall_time']:.3g} s wall ({s['nsteps']} steps, {s['nfev']} evaluations)",
             f"first flat (every hinge within {s['flat_tolerance']} rad of 0): "
             f"{fmt(s['time_to_flat'], ' s')}",
             _balance_text(s['energy_balance_error'])
             + ("" if s.get("contact_energy_error") is None else  # none in older recordings
                f"; energy the panel contacts' law created or lost {s['contact_energy_error']:.2e} (relative)")
             + "; "
             f"max constraint gap {s['max_constraint_gap']:.3g} m"
             + ("" if s["min_closure_sigma"] is None else
                f"; smallest closure singular value {s['min_closure_sigma']:.2e}")]
    choice = s.get("circuit_choice")
    if choice:
        from .ranking import choice_text
        lines.append(f"circuit {choice['index']}: {choice_text(choice)}")
    lines.append("hinges released at (s): "
                 + ", ".join(f"{n} {fmt(t)}" for n, t in s["release_times"].items()))
    if s["locked_hinges"]:
        lines.append(f"never left the stowed angle: {', '.join(s['locked_hinges'])}")
    c = s.get("collision")
    if c is not None:
        # a failed run's numbers are of its trajectory up to the failure, often
        # a numerical one: shown, but not as the deployment's outcome
        partial = "" if s["success"] else " (up to the failure: not a result)"
        first = c["first_collision"]
        d = "none (no pair has cleared the stowed package)" if c["d"] is None else f"{c['d']:.4g} m"
        if first:
            # The paper counts a deployment complete when the array first lies flat.
            after = (" (after the array first lay flat: the deployment was complete)"
                     if s["time_to_flat"] is not None and first["t"] > s["time_to_flat"] else "")
            how = " (an impact the panel contact absorbed)" if first.get("impact") else ""
            lines.append(f"first collision at {first['t']:.4g} s{after} between {' and '.join(first['pair'])}"
                         f"{how}, approach speed v = {c['v']:.4g} m/s; smallest distance before it d = {d}"
                         + partial)
            if c.get("note"):
                lines.append(f"  note: {c['note']}")
        else:
            lines.append(f"no collision; smallest distance d = {d}{partial}")
    return "\n".join(lines)


def _balance_text(error) -> str:
    if error is None:
        return "energy balance error not meaningful (no energy at the start, or non-finite)"
    text = f"energy balance error {error:.2e} (relative)"
    if error > ENERGY_LIMIT:  # the run failed for it (Status.ENERGY_DRIFT)
        text += (f" -- LARGE (above {ENERGY_LIMIT:g}): the integration is inaccurate, "
                 "tighten simulation.rtol")
    return text
