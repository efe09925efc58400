"""What a deployment did, in numbers a person reads: flat time, releases, energy.

Functions of a model and a :class:`~panel_deploy.dynamics.result.SimulationResult`;
no simulation happens here.
"""

from __future__ import annotations

import numpy as np

FLAT_TOLERANCE = 0.05  # rad: every hinge within ~3 degrees of flat counts as flat
RELEASE_TOLERANCE = 0.01  # rad: a hinge has left its stowed angle


def all_angles(model, result) -> tuple[list, np.ndarray]:
    """Hinge names and angles (s, n_hinges), rad, tree coordinates and cut hinges."""
    names = [model.hinges[h].name for h in model.joints]
    theta = result.theta
    cut = result.extra.get("cut_theta") if result.extra else None
    if model.cut_hinges and cut is not None and len(cut):
        names += [model.hinges[h].name for h in model.cut_hinges]
        theta = np.hstack([theta, cut])
    return names, theta


def time_to_flat(model, result, tolerance=FLAT_TOLERANCE) -> float | None:
    """First sample time (s) at which every hinge is within ``tolerance`` of 0, or None."""
    _, theta = all_angles(model, result)
    flat = np.all(np.abs(theta) < tolerance, axis=1)
    return float(result.t[np.argmax(flat)]) if flat.any() else None


def release_times(model, result, tolerance=RELEASE_TOLERANCE) -> dict:
    """Per hinge: first time (s) it is more than ``tolerance`` from its stowed angle, or None."""
    names, theta = all_angles(model, result)
    stowed = np.array([model.hinges[h].theta_stowed
                       for h in (*model.joints, *model.cut_hinges)])[:theta.shape[1]]
    moved = np.abs(theta - stowed) > tolerance
    return {n: (float(result.t[np.argmax(moved[:, i])]) if moved[:, i].any() else None)
            for i, n in enumerate(names)}


def energy_balance_error(result) -> float:
    """max_t |E(t) - E(0)| / E_spring(0), where E = kinetic + spring + gravity
    + dissipated - constraint work (zero for a run with no stored energy)."""
    e = result.energy
    total = e["kinetic"] + e["spring"] + e["gravity"] + e["dissipated"] - e.get("constraint_work", 0.0)
    scale = e["spring"][0] if len(total) and e["spring"][0] > 0 else 0.0
    return float(np.max(np.abs(total - total[0])) / scale) if scale else 0.0


def deployment_summary(model, result, collision=None) -> dict:
    """One JSON-able dict: outcome, flat time, releases, final angles, energy, gap, cost."""
    names, theta = all_angles(model, result)
    sigma = result.closure_sigma_min
    out = {
        "success": bool(result.success), "status": int(result.status), "message": result.message,
        "method": result.method, "closure": model.closure.method if model.cut_hinges else "none",
        "t_end": float(result.t[-1]) if len(result.t) else 0.0,
        "time_to_flat": time_to_flat(model, result),
        "release_times": release_times(model, result),
        "final_angles": {n: float(x) for n, x in zip(names, theta[-1])} if len(theta) else {},
        "energy_balance_error": energy_balance_error(result),
        "max_constraint_gap": float(np.max(result.constraint_gap)) if len(result.constraint_gap) else 0.0,
        "min_closure_sigma": (float(np.min(sigma[:, 0])) if sigma.ndim == 2 and sigma.shape[1] and len(sigma)
                              else None),
        "wall_time": float(result.wall_time), "nfev": int(result.nfev), "nsteps": int(result.nsteps),
    }
    if collision is not None:
        out["collision"] = collision.to_dict()
    return out


def summary_text(s: dict) -> str:
    """The summary as a few lines of text."""
    def fmt(x, unit=""):
        return "never" if x is None else f"{x:.4g}{unit}"

    lines = [f"{'ok' if s['success'] else 'FAILED'}: {s['message']}",
             f"method {s['method']}, closure {s['closure']}, simulated to {s['t_end']:.4g} s "
             f"in {s['wall_time']:.3g} s wall ({s['nsteps']} steps, {s['nfev']} evaluations)",
             f"first flat (all hinges within {FLAT_TOLERANCE} rad): {fmt(s['time_to_flat'], ' s')}",
             f"energy balance error {s['energy_balance_error']:.2e} of the stored spring energy; "
             f"max constraint gap {s['max_constraint_gap']:.3g} m"
             + ("" if s["min_closure_sigma"] is None else
                f"; smallest closure singular value {s['min_closure_sigma']:.2e}")]
    released = s["release_times"]
    stuck = [n for n, t in released.items() if t is None]
    lines.append("hinges released (s): " + ", ".join(f"{n} {fmt(t)}" for n, t in released.items()))
    if stuck:
        lines.append(f"never left the stowed angle: {', '.join(stuck)}")
    c = s.get("collision")
    if c is not None:
        first = c.get("first_collision")
        if first:
            lines.append(f"first collision at {first['t']:.4g} s between {' and '.join(first['pair'])}, "
                         f"approach speed v = {c['v']:.4g} m/s; d = {fmt(c['d'], ' m')} before it")
        else:
            lines.append(f"no collision; smallest distance d = {fmt(c['d'], ' m')}")
    return "\n".join(lines)

