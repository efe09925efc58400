"""A pair starting to collide (:class:`CollisionEvent`), as the monitor
reports it and the checks, the nodes and the recordings pass it on."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class CollisionEvent:
    """A pair starting to collide.

    Attributes
    ----------
    t : float
        First instant with sd < -tolerance, s.
    contact_time : float or None
        Last instant before ``t`` at which the pair touched (sd = 0), s;
        None if it was already in contact at the previous sample.
    sample : int
        Index j of the update (sample t_j) that reported it; t_{j-1} < t <= t_j.
    pair : int
        Index into :attr:`CollisionMonitor.pairs`.
    bodies : (int, int)
    names : (str, str)
    distance : float
        Signed distance at ``t``, m (just below -tolerance).
    point, normal : (3,) ndarray
        Where (m, ground frame) and along which unit direction (body a
        towards body b) the pair interferes at ``t``.
    approach_speed : float
        V_j of Eq. (7), (D_{j-2} - D_{j-1}) / (t_{j-1} - t_{j-2}), m/s; nan
        before the third sample.
    normal_speed : float
        -d sd/dt at ``t`` from the body velocities at ``point`` along
        ``normal``, m/s (> 0 approaching).
    refined : bool
        True if found between samples (D_j itself may show no interference:
        the panels passed through each other).
    impact : bool
        True for two panels in contact (``model.contact_pairs``) that came to
        press at ``CollisionSettings.impact_speed`` or faster: an impact the
        contact absorbed, found by the integrator (``t`` its step's end,
        ``distance`` 0); False for an interference deeper than the tolerance.
    """

    t: float
    contact_time: float | None
    sample: int
    pair: int
    bodies: tuple
    names: tuple
    distance: float
    point: np.ndarray
    normal: np.ndarray
    approach_speed: float
    normal_speed: float
    refined: bool
    impact: bool = False

    def to_dict(self) -> dict:
        return {"t": self.t, "contact_time": self.contact_time, "sample": self.sample,
                "pair": list(self.names), "bodies": list(self.bodies), "distance": self.distance,
                "point": self.point.tolist(), "normal": self.normal.tolist(),
                "approach_speed": None if math.isnan(self.approach_speed) else self.approach_speed,
                "normal_speed": self.normal_speed, "refined": self.refined, "impact": self.impact}
