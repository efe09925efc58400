"""Collision check of a live joint-state stream: a simulator's, or a real array's encoders.

A real stream is not a trajectory file: its stamps are wall-clock times (or
unfilled zeros), it skips samples, its angles are noisy, and it may carry a
spanning set of hinges other than the tree's. :class:`StreamCheck` turns
such a stream into the samples a :class:`~.check.TrajectoryCheck` takes:

- times are counted from the deployment's first stamp, so a stamp of
  1.7e9 s (epoch time) keeps its sub-microsecond spacing;
- a stamp at or before the deployment's first one, once it has moved on,
  starts a new deployment (a replay, the next run); any other stamp that
  does not move forward is refused (an unfilled zero stamp repeats);
- a gap, an interval over ``GAP_FACTOR`` times the median of the last
  ``GAP_WINDOW`` ones, is counted and reported (:attr:`StreamCheck.last_gap`):
  collisions inside it are located on interpolated motion;
- hinges the stream lacks are solved from the loop closure
  (:class:`~panel_deploy.sensing.LoopSolver`), once per set of names;
- D_j is kept for the last ``KEEP`` samples only, so memory is bounded;
- for a model with panel contact, joint states cannot show an impact the
  contact absorbed: the simulator's contact onsets (one per sample interval,
  :meth:`StreamCheck.onset`) are checked beside them, and a verdict whose
  intervals' onsets did not all come says so.
"""

from __future__ import annotations

import math
import statistics
from collections import deque

import numpy as np

from ..model import hinge_order
from ..errors import TrajectoryError
from ..model import Model
from ..sensing import TreeCoordinates
from .check import TrajectoryCheck
from .settings import CollisionSettings

#: Samples whose D_j a live check keeps (between KEEP and 2 KEEP).
KEEP = 4096
#: An interval this many times the median recent one is a gap.
GAP_FACTOR = 5.0
#: Intervals the median is taken over; no gap is reported before this many.
GAP_WINDOW = 16


def onset_fields(model: Model, onset) -> tuple:
    """The fields :meth:`StreamCheck.onset` takes (those of a ``ContactOnset``)
    of a row of ``SimulationResult.contact_onsets``: pair -1 gives empty names."""
    k = int(onset[2])
    a, b = (model.bodies[i].name for i in model.contact_pairs[k]) if k >= 0 else ("", "")
    return a, b, onset[0], onset[1], onset[3:6], onset[6:9]


class StreamCheck:
    """Collision check of a joint-state stream, one deployment at a time.

    Parameters
    ----------
    model : Model
    collision : CollisionSettings

    Attributes
    ----------
    names : list of str
        Every hinge a stream may carry (tree hinges, then cut hinges).
    required : list of str
        The tree hinges, in coordinate order: without the loop closure a
        stream would have to carry these.
    check : TrajectoryCheck or None
        The current deployment's check (None before its first sample).
    deployments : int
        Deployments seen.
    origin : float or None
        The current deployment's first stamp, s: its times count from here.
    refused : dict of str -> int
        Joint states refused in the current deployment, by field.
    refused_onsets : dict of str -> int
        Contact onsets refused in the current deployment, by field.
    gaps : int
        Gaps in the current deployment.
    largest_gap : float
        Its longest interval between samples, s.
    last_gap : float or None
        The interval before the last sample when it was a gap, s.
    solved : list of str
        Hinges the last sample solved from the loop closure.
    measured : list of str
        Hinges the last sample carried.
    last_theta : ndarray or None
        The tree angles of the last sample checked, rad.
    skipped : int
        Samples of the current deployment left unchecked by :meth:`skip`.
    onsets : int
        Sample intervals of the current deployment whose contact onsets were
        checked (:meth:`onset`).

    Notes
    -----
    Above its capacity a live monitor checks the newest sample and skips the
    ones that waited too long (:meth:`skip`), but never more than ``span`` s
    of them in a row: the checked samples stay at most ``span`` plus one
    interval apart (the scene's own sample interval: what ``simulate``
    checks on), so the check between them (Hermite motion) finds what a
    check at that rate finds. ``d`` is then the smallest distance over the
    checked samples and what was refined between them, an upper bound of the
    stream's own, and the verdict says how many samples it skipped.
    """

    def __init__(self, model: Model, collision: CollisionSettings):
        self.model = model
        self.collision = collision
        self.names = [model.hinges[h].name for h in hinge_order(model)]
        self.required = self.names[:model.n_coords]
        self._coordinates = TreeCoordinates(model)
        self.check = None
        self.deployments = 0
        self.origin = None
        self.refused: dict = {}
        self.refused_onsets: dict = {}
        self.gaps, self.largest_gap, self.last_gap = 0, 0.0, None
        self.solved: list = []
        self.measured: list = []
        self.last_theta = None
        self.skipped = 0
        self.onsets = 0
        self._contact = {}  # (name_a, name_b) -> (contact pair index, normal sign), both orders
        for k, (a, b) in enumerate(model.contact_pairs):
            a, b = model.bodies[a].name, model.bodies[b].name
            self._contact[a, b], self._contact[b, a] = (k, 1.0), (k, -1.0)
        self._skipping = False  # the next interval spans skipped samples: not a gap
        self._intervals = deque(maxlen=GAP_WINDOW)
        self._last = None

    def reset(self) -> None:
        """Forget the current deployment: the next sample starts a new one."""
        self.check = None

    def refuse(self, field: str, onset: bool = False) -> None:
        """Count a joint state (or with ``onset`` a contact onset) refused for
        ``field`` (the node's reading errors too)."""
        counts = self.refused_onsets if onset else self.refused
        counts[field] = counts.get(field, 0) + 1

    def skip(self, t: float, span: float) -> bool:
        """Leave the sample at stamp ``t`` (s) unchecked, counted in
        :attr:`skipped`, and return True; or return False for a sample that
        must be checked: one ``span`` s or more after the last checked, a
        deployment's first, or one that starts a new one or is out of order
        (its refusal is :meth:`update`'s to say)."""
        if self.check is None or not self._last < t < self._last + span:
            return False
        self.skipped += 1
        self._skipping = True
        return True

    def update(self, t: float, theta, omega=None, onset=None) -> list:
        """Check the sample at stamp ``t`` (s); ``theta``, ``omega`` (rad, rad/s)
        of :attr:`required`; ``onset``, when its contact onset comes with it
        (a recording's), the fields :meth:`onset` takes after the stamp.
        Returns the collision events it revealed.

        Raises
        ------
        TrajectoryError
            A stamp that is neither after the last nor a new deployment's, an
            interval the check cannot search, or an onset :meth:`onset`
            refuses; nothing is changed.
        """
        row = None if onset is None else self._onset_row(*onset)
        if self.check is not None and t <= self.origin and self._last > self.origin:
            self.check = None
        elif self.check is not None and not t > self._last:
            raise TrajectoryError(f"header.stamp: {t:.9g} s is not after the last sample "
                                  f"({self._last:.9g} s)")
        if self.check is None:
            return self._start(t, theta, omega)
        if onset is not None:
            self.onsets += 1
            if row is not None:
                row[0] -= self.origin
        events = self.check.update(t - self.origin, theta, omega, onset=row)
        self._interval(t - self._last)
        self._last, self.last_theta = t, np.asarray(theta, dtype=float)
        return events

    def update_joints(self, t: float, names, position, velocity=None, onset=None) -> list:
        """:meth:`update` from a message's hinges: ``names`` any set the loop
        closure completes, ``position`` (rad) and ``velocity`` (rad/s, or None)
        in the same order; ``onset`` as :meth:`update` takes it.

        Raises
        ------
        TrajectoryError
            Names that do not determine the tree's angles (naming one), or
            angles that cannot close the loop; nothing is changed.
        """
        theta, omega = self.coordinates(names, position, velocity)
        return self.update(t, theta, omega, onset)

    def onset(self, stamp: float, body_a: str, body_b: str, t: float, speed: float,
              point, normal) -> list:
        """Check the contact onset of the sample interval that ends at ``stamp``
        (s, a joint state's): the pair ``body_a``, ``body_b`` (both empty: no
        pair came to press) came to press at ``t`` (s, the stamp's clock)
        with approach speed ``speed`` (m/s) at ``point`` (m) along ``normal``
        (from body_a towards body_b). Returns the collision events it revealed
        (an impact: ``collision.impact_speed`` or faster). An onset of no
        interval of the current deployment (before its first joint state: a
        late one of the last deployment) is not counted.

        Raises
        ------
        TrajectoryError
            A pair that is not a contact pair of the model, or a value not
            finite; nothing is changed.
        """
        row = self._onset_row(body_a, body_b, t, speed, point, normal)
        if self.check is None or not stamp > self.origin:
            return []
        self.onsets += 1
        if row is None:
            return []
        row[0] -= self.origin
        return self.check.onset(row)

    def _onset_row(self, body_a, body_b, t, speed, point, normal):
        """An onset's fields as a row of ``SimulationResult.contact_onsets`` (t in
        the stamp's clock), or None for no onset; refused as :meth:`onset` says."""
        if not (body_a or body_b):
            return None
        found = self._contact.get((body_a, body_b))
        if found is None:
            raise TrajectoryError(f"body_a: {body_a!r} and {body_b!r} are not a contact pair "
                                  f"of the model")
        row = np.array([t, speed, found[0], *point, *(found[1] * np.asarray(normal, float))])
        if not np.all(np.isfinite(row)):
            field = ("t", "speed", "pair", "point", "point", "point", "normal", "normal",
                     "normal")[int(np.argmin(np.isfinite(row)))]
            raise TrajectoryError(f"{field}: not finite in the onset of {body_a} - {body_b}")
        return row

    def coordinates(self, names, position, velocity=None) -> tuple:
        """Tree angles and rates (None without ``velocity``) of a message's hinges
        (:class:`~panel_deploy.sensing.TreeCoordinates`)."""
        theta, omega = self._coordinates(names, position, velocity)
        self.solved, self.measured = self._coordinates.solved, list(names)
        return theta, omega

    def _start(self, t, theta, omega) -> list:
        check = TrajectoryCheck(self.model, self.collision, keep=KEEP)
        events = check.update(0.0, theta, omega)
        self.check, self.origin, self._last = check, t, t
        self.last_theta = np.asarray(theta, dtype=float)
        self.deployments += 1
        self.refused, self.refused_onsets = {}, {}
        self.gaps, self.largest_gap, self.last_gap = 0, 0.0, None
        self.skipped, self._skipping, self.onsets = 0, False, 0
        self._intervals.clear()
        return events

    def _interval(self, dt: float) -> None:
        if self._skipping:  # the stream had samples here: neither a gap nor its typical interval
            self._skipping, self.last_gap = False, None
            return
        typical = self.typical_interval
        self.last_gap = dt if typical is not None and dt > GAP_FACTOR * typical else None
        if self.last_gap is not None:
            self.gaps += 1
        else:
            self._intervals.append(dt)
        self.largest_gap = max(self.largest_gap, dt)

    @property
    def last_stamp(self) -> float | None:
        """The stamp of the last sample checked, s, in the stream's own clock (None before one)."""
        return None if self.check is None else self._last

    @property
    def typical_interval(self) -> float | None:
        """Median of the recent intervals between samples, s (None before there are enough)."""
        # statistics, not numpy: 16 floats, at every sample (numpy's median costs ~30x more)
        return float(statistics.median(self._intervals)) if len(self._intervals) == GAP_WINDOW \
            else None

    def verdict(self, onsets_in_flight: bool = False) -> tuple:
        """``(level, message, values)``: level 0 no collision so far, 1 a
        clean verdict the stream's faults (refused messages, gaps, skipped
        samples, contact onsets missing) put in doubt, 2 collided (the faults
        said after it). Times in ``values`` count from ``origin``.

        For a model with panel contact every sample interval's contact onset
        must have been checked (:meth:`onset`); ``onsets_in_flight`` (a live
        monitor whose onsets are still coming) lets the latest ones be
        missing for now."""
        c = self.check
        if c is None:
            refused = sum(self.refused.values())
            if refused:  # something arrives, nothing is checked: not OK
                worst = max(self.refused, key=self.refused.get)
                return 1, (f"no joint state checked: {refused} refused ({worst}: "
                           f"{self.refused[worst]})"), {"deployment": self.deployments,
                                                         "refused": refused}
            return 0, "waiting for joint states", {"deployment": self.deployments}
        refused = sum(self.refused.values())
        values = {"deployment": self.deployments, "origin": self.origin,
                  "t": self._last - self.origin, "samples": c.checked,
                  "d": None if c.d == math.inf else c.d, "d_pair": list(c.d_pair or ()),
                  "d_time": None if c.d_pair is None else c.d_time,
                  "distance_now": (c.monitor.min_distance
                                   if math.isfinite(c.monitor.min_distance) else None),
                  "refused": refused,
                  "gaps": self.gaps, "largest_gap": self.largest_gap, "skipped": self.skipped,
                  "solved": list(self.solved), "measured": list(self.measured),
                  "contact_pairs": len(self.model.contact_pairs)}
        values.update({f"refused_{field}": n for field, n in self.refused.items()})
        faults = []
        if refused:
            worst = max(self.refused, key=self.refused.get)
            faults.append(f"{refused} joint states refused ({worst}: {self.refused[worst]})")
        if self.gaps:
            faults.append(f"{self.gaps} gaps in the stream (longest {self.largest_gap * 1e3:.1f} ms)")
        if self.skipped:
            faults.append(f"{self.skipped} of {self.skipped + c.checked} joint states skipped to "
                          f"keep up (the newest checked); d is over the checked ones, an upper "
                          f"bound")
        contacts = len(self.model.contact_pairs)
        intervals = c.checked + self.skipped - 1
        if contacts:
            values["onsets"] = self.onsets
        if self.refused_onsets:
            worst = max(self.refused_onsets, key=self.refused_onsets.get)
            values["refused_onsets"] = sum(self.refused_onsets.values())
            faults.append(f"{values['refused_onsets']} contact onsets refused ({worst}: "
                          f"{self.refused_onsets[worst]})")
        if contacts and not onsets_in_flight and self.onsets < intervals:
            # Joint states cannot show an impact the contact absorbed (issue 33).
            faults.append(
                f"panel contact on {contacts} pairs, but no contact onsets came: an impact "
                f"the contact absorbs does not show in joint states and was not checked"
                if self.onsets == 0 else
                f"the contact onsets of {intervals - self.onsets} of {intervals} sample "
                f"intervals did not come: impacts in them were not checked")
        if c.collided:
            e = c.first_events[0]
            values.update(first_collision_pair=list(e.names), first_collision_t=e.t,
                          approach_speed=max(x.approach_speed if math.isfinite(x.approach_speed)
                                             else x.normal_speed for x in c.first_events))
            # The collision stands; what the stream lacked is said beside it.
            return 2, "; ".join([f"collision between {e.names[0]} and {e.names[1]} at "
                                 f"t = {e.t:.4f} s", *faults]), values
        if faults:
            return 1, "no collision seen, but " + "; ".join(faults), values
        return 0, "no collision", values
