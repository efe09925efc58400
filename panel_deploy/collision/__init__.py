"""Collision detection between panels (paper section 3.2, Eq. 7).

``check_trajectory(model, result, collision) -> CollisionReport`` checks a
sampled trajectory (:class:`TrajectoryCheck` takes it in blocks as they are
simulated); :class:`CollisionMonitor` does the same on a stream of joint
states (``update(t, theta, omega=None) -> events``) and :class:`StreamCheck`
on a live one (stamps, gaps, noise, partial sensing). What counts as a
collision, and what is guaranteed between samples, is stated in
:mod:`panel_deploy.collision.monitor`; distance accuracy in
:mod:`panel_deploy.collision.geometry`.
"""

from .check import CollisionReport, TrajectoryCheck, check_trajectory
from .event import CollisionEvent
from .geometry import BoxSet, PairGeometry
from .monitor import CollisionMonitor
from .settings import CollisionSettings
from .stream import StreamCheck

__all__ = ["BoxSet", "CollisionEvent", "CollisionMonitor", "CollisionReport", "CollisionSettings",
           "PairGeometry", "StreamCheck", "TrajectoryCheck", "check_trajectory"]
