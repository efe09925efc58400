"""Which panels get a contact between them: the panels of the stowed stacks.

In the stowed package every panel lies on the one below it, and the two
stacks stand side by side, so many panels that share no hinge touch: face on
face between layers, side on side within a layer, edge on edge across the
stacks. When the springs release the package these panels push on each
other; without a contact between them the dynamics let them pass through
each other (on 6 x 6 and larger arrays every first packing circuit did,
within 0.02-0.06 s). :func:`stowed_contacts` lists the pairs; their
contact (compliant, normal, at the corners of the overlap of the two boxes'
facing features, or with ``contact.pressure`` a pressure over it) is
:func:`panel_deploy.dynamics.panel_contact.panel_contacts`.

The rule that separates pressing from collision: a collision is
interference deeper than ``collision.tolerance`` (0.1 mm by default, the
check's own, :mod:`panel_deploy.collision.monitor`), or two panels in
contact whose points, not yet at the contact's ramp depth (10 um), approach
at ``collision.impact_speed`` (0.05 m/s by default) or faster along the
normal: an impact, though the contact stopped it within the tolerance (the
integrator records the fastest such approach at each of its steps,
``SimulationResult.contact_onsets``). With ``contact.k_p`` = 1e7 N/m
a face pressed with 50 N sits 10 um deep, a tenth of the tolerance, and
0.1 um deeper per newton beyond, so pressing stays far within it; what
goes deeper slowly is a press the contact could not hold (a jam against
the hinge stops), and the collision report says that its verdict depends
on k_p (:func:`panel_deploy.collision.check.compliance_note`). At 1e6 N/m
the first packing circuit of 6 x 6 pressed 0.7 mm in 0.09 s against the
stops; at 1e7 it holds, at the same run time (docs/findings.md 3.2).

Which pairs: by default every unhinged pair, so that no verdict depends
on which pairs were given a contact. ``contact.reach`` limits them to the
pairs that far apart in the stowed stacks, for speed (10 x 10: 412 pairs
within two thicknesses against 3569, 0.6x the run time); pairs beyond it
meet as interference, and a slow one is then a press of panels without a
contact.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from .kinematics import forward_kinematics
from .model import Model

#: Boxes this close (m) in the stowed state touch: the packing stacks panels
#: exactly one thickness apart, so only rounding separates touching faces.
TOUCHING = 1e-9


def aligned_overlap(model: Model, R, p, a: int, b: int):
    """The intersection (lo, hi), m, of bodies a and b as axis-aligned boxes in
    poses (R, p) that keep every body axis along a frame axis; ``lo > hi``
    along a direction in which they are apart."""
    lo, hi = [], []
    for i in (a, b):
        half = np.abs(R[i]) @ (0.5 * model.bodies[i].size)
        lo.append(p[i] - half)
        hi.append(p[i] + half)
    return np.maximum(lo[0], lo[1]), np.minimum(hi[0], hi[1])


def touching_region(model: Model, R, p, a: int, b: int, reach: float = 0.0):
    """Where bodies a and b touch in poses (R, p) that keep every body axis
    along a frame axis (stowed, flat: each body is then its own axis-aligned
    box): the box (lo, hi), m, with ``hi - lo`` zero along the directions of
    contact; None if they are further apart than ``reach`` (m) or
    interpenetrate. Boxes apart by at most ``reach`` give the (inverted,
    ``lo > hi`` along the gap) box between them."""
    low, high = aligned_overlap(model, R, p, a, b)
    gap = high - low
    if np.linalg.norm(np.minimum(gap, 0.0)) > reach + TOUCHING or not np.any(gap <= TOUCHING):
        return None
    return low, high


def stowed_contacts(model: Model, pairs=None, reach: float = 0.0) -> tuple:
    """The body pairs of ``model`` that touch in its stowed stacks.

    Parameters
    ----------
    model : Model
    pairs : iterable of (int, int), optional
        Body pairs to look at; by default ``model.collision_pairs`` (the
        unhinged ones: a hinged pair's contact at theta = 0 or pi is the
        hinge's own, Eq. 3-4).
    reach : float
        m; pairs this far apart count as touching.

    Returns
    -------
    tuple of (int, int)
        The pairs that touch at ``model.theta_stowed`` (none for a design
        whose stowed panels are not all along the frame axes).
    """
    R, p = forward_kinematics(model, model.theta_stowed)
    if not np.allclose(np.abs(R), np.round(np.abs(R)), atol=1e-9):
        return ()
    return tuple((int(a), int(b)) for a, b in (model.collision_pairs if pairs is None else pairs)
                 if touching_region(model, R, p, a, b, reach) is not None)


def with_panel_contacts(model: Model, k_p: float, c_p: float, pairs=None,
                        reach: float | None = 0.0, mu_p: float = 0.0,
                        friction_speed: float = 1.0e-3, pressure: bool = False) -> Model:
    """``model`` with contacts of stiffness k_p (N/m), damping c_p (N s/m)
    and Coulomb friction coefficient mu_p, viscous below ``friction_speed``
    (m/s), between ``pairs`` (default ``model.collision_pairs``, the
    unhinged ones): all of them for ``reach`` None, else those that touch in
    the stowed stacks within ``reach`` (m, :func:`stowed_contacts`). Faces
    push at the corners of their overlap, or with ``pressure`` over it
    (``Model.contact_pressure``)."""
    chosen = (tuple((int(a), int(b)) for a, b in (model.collision_pairs if pairs is None else pairs))
              if reach is None else stowed_contacts(model, pairs, reach))
    return replace(model, contact_pairs=chosen, k_p=float(k_p), c_p=float(c_p), mu_p=float(mu_p),
                   friction_speed=float(friction_speed), contact_pressure=bool(pressure))
