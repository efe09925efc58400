"""The free-vibration rig: one panel swinging on one hinge, and what its model
says about it (inertia, gravity and air drag torques about the hinge axis).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..errors import TrajectoryError
from ..model import AirParameters


@dataclass(frozen=True)
class Rig:
    """One panel on one hinge, about the hinge axis (SI units).

    ``gravity`` holds (g0, g1, g2) of the gravity torque G(theta) = g0 + g1
    sin(theta) + g2 cos(theta), N m: one rigid body turning about a fixed axis
    has exactly this form. ``drag`` is D, the air torque -C_d D |omega| omega
    per unit drag coefficient, N m s^2 (0 without air). ``k`` and ``c`` are
    the rig scene's own, of one spring.
    """

    hinge: str
    springs: int
    inertia: float
    gravity: tuple
    drag: float
    drag_coefficient: float
    k: float
    c: float

    def gravity_torque(self, theta):
        g0, g1, g2 = self.gravity
        return g0 + g1 * np.sin(theta) + g2 * np.cos(theta)

    def gravity_gradient(self, theta):
        """dG/dtheta, N m/rad (negative: gravity stiffens the swing)."""
        _, g1, g2 = self.gravity
        return g1 * np.cos(theta) - g2 * np.sin(theta)


def rig_of(model, source: str = "") -> Rig:
    """The :class:`Rig` of a model of one panel on one hinge.

    I, G and D come from the dynamics kernels' own mass matrix and
    generalised forces, so the rig obeys the package's model exactly.

    Raises
    ------
    TrajectoryError
        The model is not two bodies joined by one hinge (``source`` names the recording).
    """
    from ..dynamics.kernels import mass_and_bias
    from ..dynamics.panel_contact import near_pairs
    from ..dynamics.pack import pack

    if len(model.hinges) != 1 or model.n_coords != 1:
        raise TrajectoryError(f"{source}: not one panel on one hinge: its scene has "
                              f"{model.n_bodies} bodies and {len(model.hinges)} hinges")
    h = model.hinges[0]
    P = pack(model)
    free = P._replace(k=np.zeros_like(P.k), c=np.zeros_like(P.c))

    def force(P, theta, omega):
        return float(mass_and_bias(P, np.array([theta]), np.array([omega]), near_pairs(P))[1][0])

    angles = (0.0, 0.5 * np.pi, np.pi)
    g = np.linalg.solve([[1.0, np.sin(a), np.cos(a)] for a in angles],
                        [force(free, a, 0.0) for a in angles])
    drag = 0.0
    if model.air.density > 0:
        # with a unit drag coefficient, D is the torque at omega = 1 rad/s
        unit = pack(replace(model, air=AirParameters(model.air.density, 1.0)))
        unit = unit._replace(k=free.k, c=free.c)
        drag = force(unit, 1.0, 0.0) - force(unit, 1.0, 1.0)
    inertia = float(mass_and_bias(P, np.array([1.0]), np.array([0.0]), near_pairs(P))[0][0, 0])
    return Rig(h.name, int(h.springs), inertia, tuple(float(x) for x in g), float(drag),
               float(model.air.drag_coefficient if model.air.density > 0 else 0.0),
               float(h.k), float(h.c))
