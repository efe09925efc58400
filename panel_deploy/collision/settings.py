"""How collisions are detected (:class:`CollisionSettings`): the scene's
``collision`` section as the monitor and the checks take it, checked once."""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

from ..errors import SceneError, shown
from ..scene import COLLISION_MARGIN, IMPACT_SPEED, check_collision_tolerance


@dataclass(frozen=True)
class CollisionSettings:
    """How collisions are detected. Lengths in m, times in s.

    Attributes
    ----------
    tolerance : float
        Interference depth beyond which touching panels collide (scene
        ``collision.tolerance``); at least
        :data:`~panel_deploy.scene.MIN_COLLISION_TOLERANCE`.
    refine : bool
        Check between samples (scene ``collision.refine``).
    resolution : float
        Depth slack of the between-sample guarantee.
    time_resolution : float
        Precision of a located collision or first-touch time.
    margin : float
        Broad phase: a pair whose cheap lower bound exceeds this is not
        computed exactly at a sample (its entry of D holds the bound), unless
        it could be the smallest distance of that sample. ``inf`` computes all.
    prune : bool
        Between samples, screen the pairs of each interval by an O(1) cap on
        their speed bound before the bound itself (:func:`.refine.refine_interval`):
        the same decisions and results, to the bit, at O(pairs) instead of
        O(pairs x path length) a sample. False bounds every pair (the
        reference the tests compare against).
    second_order : bool
        Between samples, a pair the speed bound leaves open is bounded once
        more from its exact speed at the ends and a bound on its
        acceleration (:mod:`.motion`, "Second-order bound") before it is
        bisected: the same guarantee in fewer bisection steps, where panels
        that ride together hang on fast-turning hinges. False: the speed
        bound only.
    noise : float
        Standard deviation of the measured angles, rad (encoders); 0 for a
        simulated stream. Above 0 a pair collides only when it is deeper
        than the tolerance plus what the noise can fake, and approaching
        (:mod:`.monitor`, "Noisy streams").
    speed_interval : float
        Spacing of the two distances of Eq. (7), s; 0: the stream's own
        samples (:mod:`.monitor`, "Approach speed").
    stamps : str
        "header" (a sample's time is when it was measured) or "receipt" (when
        it arrived: nothing is interpolated between samples;
        :mod:`.monitor`, "Receipt timing").
    impact_speed : float
        m/s: two panels in contact (``model.contact_pairs``) that meet this
        fast or faster along the normal collide (scene
        ``collision.impact_speed``); a collision slower than it is a press
        (:func:`~.check.compliance_note`).
    """

    tolerance: float = 1.0e-4
    refine: bool = True
    resolution: float = 1.0e-6
    time_resolution: float = 1.0e-6
    margin: float = COLLISION_MARGIN
    prune: bool = True
    second_order: bool = True
    noise: float = 0.0
    speed_interval: float = 0.0
    stamps: str = "header"
    impact_speed: float = IMPACT_SPEED

    def __post_init__(self):
        check_collision_tolerance(self.tolerance, "collision.tolerance")
        for f in ("tolerance", "resolution", "time_resolution", "margin", "noise", "speed_interval"):
            v = getattr(self, f)
            if not v >= 0 or (f in ("resolution", "time_resolution") and v == 0):
                raise SceneError(f"collision.{f}", f"expected a number > 0, got {shown(v)}")
        if not (math.isfinite(self.noise) and self.noise <= 0.1):  # as the scene key's range
            raise SceneError("collision.noise", f"expected a standard deviation of at most 0.1 "
                                                f"rad, got {shown(self.noise)}")
        if not (self.impact_speed > 0 and math.isfinite(self.impact_speed)):
            raise SceneError("collision.impact_speed", f"expected a number of m/s > 0, got "
                                                       f"{shown(self.impact_speed)}")
        if not math.isfinite(self.speed_interval):
            raise SceneError("collision.speed_interval", "expected a finite number of s, got inf")
        if self.margin < self.tolerance:
            raise SceneError("collision.margin",
                             f"must be >= collision.tolerance ({self.tolerance:g}), got {self.margin:g}")

    @classmethod
    def from_scene(cls, scene, **overrides) -> "CollisionSettings":
        """Settings from a Scene (or its ``collision`` section); missing keys
        keep defaults. ``collision.speed_interval: null`` is the scene's
        sample interval (0, the stream's own samples, without a simulation
        section)."""
        section = getattr(scene, "collision", scene)
        known = {f.name for f in fields(cls)}
        values = {k: getattr(section, k) for k in known if hasattr(section, k)}
        if values.get("speed_interval", 0.0) is None:
            sim = getattr(scene, "simulation", None)
            values["speed_interval"] = sim.t_end / (sim.samples - 1) if sim is not None else 0.0
        values.update(overrides)
        return cls(**values)
