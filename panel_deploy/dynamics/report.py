"""Reports made from a SimulationResult: when each hinge releases, when the array
first lies flat, and the one-dict summary the CLI prints."""

from __future__ import annotations

import numpy as np

from ..model import FLAT_TOLERANCE, Model, hinge_order
from .closure import cut_rates
from .hinges import hinge_law
from .pack import pack
from .result import ENERGY_FLOOR, SimulationResult

#: A hinge has left its stowed angle once |theta - theta_stowed| exceeds this, rad.
RELEASE_TOL = 1e-2
def hinge_angles(model: Model, result: SimulationResult):
    """Names and angles (s, n_hinges) of every hinge, in :func:`hinge_order`."""
    idx = hinge_order(model)
    theta = np.column_stack([result.theta, result.cut_theta])
    return [model.hinges[h].name for h in idx], idx, theta


def hinge_states(model: Model, result: SimulationResult, packed=None):
    """Angle, rate and torque of every hinge at every sample, as a joint-state stream carries them.

    Hinges are in :func:`hinge_angles` order (tree coordinates, then cut
    hinges). A cut hinge's rate is the exact time derivative of its angle
    (the dynamics kernels' own, valid also while the penalty closure lets
    the loop open by micrometres). The torque is the hinge's own law,
    Eq. (2)-(4): springs, dampers and joint-limit contact, N m, acting on
    ``body_b``.

    ``packed``, :func:`~.pack.pack` of the model, saves packing it again
    (for a stream of blocks).

    Returns
    -------
    names : list of str
    theta, omega, torque : (s, n_hinges) ndarray
        rad, rad/s, N m.
    """
    names, idx, theta = hinge_angles(model, result)
    s = len(result.t)
    omega = np.empty((s, len(idx)))
    omega[:, :model.n_coords] = result.omega
    if model.cut_hinges:
        P = pack(model) if packed is None else packed
        for j in range(s):
            omega[j, model.n_coords:] = cut_rates(P, result.rotation[j, P.body],
                                                  result.angular_velocity[j, P.body])
    torque = np.empty_like(omega)
    for col, h in enumerate(idx):
        hinge = model.hinges[h]
        for j in range(s):
            torque[j, col] = hinge_law(theta[j, col], omega[j, col], hinge.k_hinge, hinge.c_hinge,
                                       model.k_s, model.c_s, model.stop_ramp)[0]
    return names, theta, omega, torque


def first_time(t, mask):
    """First sample time where ``mask`` holds, or None."""
    hit = np.flatnonzero(mask)
    return float(t[hit[0]]) if len(hit) else None


def total_energy(energy: dict) -> np.ndarray:
    """E_kin + E_spring + E_grav + E_diss - W_constraint at every sample of a
    result's ``energy``, J: constant in an exact integration. The panel
    contacts' springs count by the work done on them ("contact_work"), not
    by the energy they store ("contact", part of "spring"), so the sum checks
    the integration, not the contact law (:func:`contact_energy_error`);
    a trajectory file written before that record existed counts the stored
    energy."""
    total = (energy["kinetic"] + energy["spring"] + energy["gravity"] + energy["dissipated"]
             - energy["constraint_work"])
    if "contact_work" in energy:
        total = total - energy["contact"] + energy["contact_work"]
    return total


def energy_balance_error(result: SimulationResult) -> np.ndarray:
    """|E_kin + E_spring + E_grav + E_diss - W_constraint - E_0| / E_0 at every sample."""
    total = total_energy(result.energy)
    return np.abs(total - total[0]) / abs(total[0])


def contact_energy_created(energy: dict, contact_0: float) -> np.ndarray:
    """The energy the panel contacts' law has created (J, < 0: lost) by every
    sample of a result's ``energy``: their stored energy less ``contact_0``,
    its value at the run's start, less the work the bodies did on them."""
    return energy["contact"] - contact_0 - energy["contact_work"]


def contact_energy_error(result: SimulationResult) -> float | None:
    """Largest energy the panel contacts' law created or lost, relative to the
    run's start energy: ``|E_contact(t) - E_contact(0) - W_contact(t)| / E_0``
    over the samples, where W_contact is the work the bodies did on the
    contacts' springs. Zero for a conservative law; a law built on the
    separating axis changes its stored energy at once where a pair changes
    the features it touches by (docs/findings.md 3.2). None where
    the contacts stored and took nothing at every sample, without the record
    (an older file) or where the balance means nothing (:func:`balance_error`)."""
    energy = result.energy
    touched = "contact_work" in energy and (np.any(energy["contact"]) or np.any(energy["contact_work"]))
    if not touched or balance_error(result) is None:
        return None
    created = contact_energy_created(energy, energy["contact"][0])
    return float(np.abs(created).max() / abs(total_energy(energy)[0]))


def balance_error(result: SimulationResult) -> float | None:
    """Largest relative energy balance error of a run, or None when it means
    nothing: no energy at the start (k = 0, g = 0) or non-finite energies."""
    total = total_energy(result.energy)
    if len(total) == 0 or not np.all(np.isfinite(total)) or abs(total[0]) < ENERGY_FLOOR:
        return None
    return float(energy_balance_error(result).max())


def hinge_release_report(model: Model, result: SimulationResult, *, release_tol=RELEASE_TOL,
                         flat_tolerance=FLAT_TOLERANCE) -> dict:
    """When each hinge leaves its stowed angle, and when the array first lies flat.

    Times are sample instants t_j (so resolved to the sample spacing), s.

    Returns
    -------
    dict with
        "hinges": {name: {"released_at": float or None, "final": rad}},
        "flat_at": float or None (first t_j with all |theta| <= flat_tolerance),
        "locked": names of hinges that never left their stowed angle,
        "release_tol", "flat_tolerance".
    """
    names, idx, theta = hinge_angles(model, result)
    stowed = np.array([model.hinges[h].theta_stowed for h in idx])
    hinges = {}
    for k, name in enumerate(names):
        hinges[name] = {"released_at": first_time(result.t, np.abs(theta[:, k] - stowed[k]) > release_tol),
                        "final": float(theta[-1, k])}
    return {"hinges": hinges,
            "flat_at": first_time(result.t, np.all(np.abs(theta) <= flat_tolerance, axis=1)),
            "locked": [nm for nm, h in hinges.items() if h["released_at"] is None],
            "release_tol": release_tol, "flat_tolerance": flat_tolerance}


def dynamics_summary(model: Model, result: SimulationResult, *, flat_tolerance=FLAT_TOLERANCE) -> dict:
    """One-dict summary of a run for the CLI (SI units, JSON-ready); ``flat_tolerance`` in rad."""
    names, _, theta = hinge_angles(model, result)
    report = hinge_release_report(model, result, flat_tolerance=flat_tolerance)
    return {
        "success": bool(result.success), "message": result.message, "method": result.method,
        "scheme": result.scheme, "t_end": float(result.t[-1]), "time_to_flat": report["flat_at"],
        "flat_tolerance": flat_tolerance,
        "final_angles": dict(zip(names, map(float, theta[-1]))),
        "release_times": {n: h["released_at"] for n, h in report["hinges"].items()},
        "locked_hinges": report["locked"],
        "energy_balance_error": balance_error(result),
        "contact_energy_error": contact_energy_error(result),
        "max_constraint_gap": float(result.constraint_gap.max()),
        "min_closure_sigma": (float(result.closure_sigma_min[:, 0].min())
                              if result.closure_sigma_min.shape[1] else None),
        "wall_time": float(result.wall_time), "nfev": int(result.nfev),
        "nsteps": int(result.nsteps), "switches": int(result.nswitches),
    }
