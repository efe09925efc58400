"""Collision check of a sampled trajectory (paper section 3.2 and Eq. 7).

:func:`check_trajectory` feeds a :class:`~panel_deploy.dynamics.result.SimulationResult`
to a :class:`~.monitor.CollisionMonitor` one sample at a time (the same code a
live stream uses) and stops at the first collision: the trajectory after it
is invalid.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from ..model import Model
from ..scene import IMPACT_SPEED
from .event import CollisionEvent
from .monitor import CollisionMonitor
from .settings import CollisionSettings


@dataclass
class CollisionReport:
    """What the collision check found on one trajectory.

    Shapes: P checked pairs, s_c samples kept (up to and including the
    sample that revealed the first collision; a live check keeps the last
    ones only, from ``first_sample`` on).

    Attributes
    ----------
    pairs : (P, 2) ndarray of int
        Body indices of every checked pair (``model.collision_pairs``).
    pair_names : list of (str, str)
    t : (s_c,) ndarray
        Sample instants kept, s.
    distances : (s_c, P) ndarray
        Signed distance D_j of every pair, m (the paper's D_j is
        ``max(distances, 0)``); where ``exact`` is False, a lower bound above
        ``collision.margin`` (broad phase).
    exact : (s_c, P) ndarray of bool
    n_valid : int
        Samples before the first collision (all if none): rows
        ``[:n_valid - first_sample]`` are the valid trajectory.
    first_collision : CollisionEvent or None
        The earliest collision.
    events : list of CollisionEvent
        Every pair that started colliding in (t_{j-1}, t_j], j the sample
        of the first collision.
    V : (P,) ndarray
        Eq. (7) at that sample, m/s, zero for pairs not colliding (all zero
        if none). Before the third sample Eq. (7) is undefined and the
        event's ``normal_speed`` stands in.
    v : float
        max V, m/s (0 if no collision).
    d : float
        Smallest distance over the valid trajectory, m, among the pairs that
        count (see :mod:`.monitor`: designed contacts are left out); inf if
        none counted.
    d_time : float
    d_pair : (str, str) or None
    counters : dict
    collision : CollisionSettings
        What the check used.
    wall_time : float
        s spent in the check.
    first_sample : int
        Index of the sample in row 0 (samples before it were not kept).
    note : str or None
        When the first collision is a press (:func:`compliance_note`), why
        its verdict can depend on a compliance of the model.
    press_speed : float
        The fastest panel contact onset over the valid trajectory, all of
        them slower than ``collision.impact_speed`` (presses, not impacts),
        m/s; 0 if none (and without panel contact). How far the verdict is
        from an impact: ``impact_speed - press_speed``.
    press_time : float
        Its time, s (nan if none).
    press_pair : (str, str) or None
    """

    pairs: np.ndarray
    pair_names: list
    t: np.ndarray
    distances: np.ndarray
    exact: np.ndarray
    n_valid: int
    first_collision: CollisionEvent | None
    events: list
    V: np.ndarray
    v: float
    d: float
    d_time: float
    d_pair: tuple | None
    counters: dict
    collision: CollisionSettings
    wall_time: float = 0.0
    flat_contact: np.ndarray = field(default=None, repr=False)
    first_sample: int = 0
    note: str | None = None
    press_speed: float = 0.0
    press_time: float = math.nan
    press_pair: tuple | None = None

    @property
    def samples_checked(self) -> int:
        return self.first_sample + len(self.t)

    @property
    def collided(self) -> bool:
        return self.first_collision is not None

    @property
    def valid_until(self) -> float:
        """Last valid sample instant, s (nan if even the first sample collides)."""
        row = self.n_valid - 1 - self.first_sample
        return float(self.t[row]) if 0 <= row < len(self.t) else math.nan

    def first_collision_dict(self) -> dict | None:
        """The first collision as plain values (time, pair, point, speeds), or None."""
        if self.first_collision is None:
            return None
        out = self.first_collision.to_dict()
        out["v"] = self.v
        return out

    def to_dict(self, arrays: bool = False) -> dict:
        """JSON-able summary; with ``arrays`` also t, distances (m) and exact."""
        out = {
            "collided": self.collided,
            "first_collision": self.first_collision_dict(),
            "colliding_pairs": [e.to_dict() for e in self.events],
            "v": self.v,
            "d": None if math.isinf(self.d) else self.d,
            "d_time": None if math.isnan(self.d_time) else self.d_time,
            "d_pair": list(self.d_pair) if self.d_pair else None,
            "samples_checked": self.samples_checked,
            "valid_samples": int(self.n_valid),
            "valid_until": None if math.isnan(self.valid_until) else self.valid_until,
            "pairs_checked": int(len(self.pairs)),
            "tolerance": self.collision.tolerance,
            "refine": self.collision.refine,
            "counters": dict(self.counters),
            "wall_time": self.wall_time,
            "note": self.note,
            "press_speed": self.press_speed,
            "press_time": None if math.isnan(self.press_time) else self.press_time,
            "press_pair": list(self.press_pair) if self.press_pair else None,
        }
        if arrays:
            out.update(t=self.t.tolist(), pairs=[list(n) for n in self.pair_names],
                       distances=self.distances.tolist(), exact=self.exact.tolist())
        return out

    def to_text(self) -> str:
        """A few lines of text for the command line."""
        lines = []
        if self.first_collision is None:
            lines.append(f"no collision in {self.samples_checked} samples up to t = {self.t[-1]:.4f} s"
                         if len(self.t) else "no samples")
        else:
            e = self.first_collision
            touch = f", first touch at {e.contact_time:.4f} s" if e.contact_time is not None else ""
            row = e.sample - self.first_sample
            t_j = f", t_j = {self.t[row]:.4f} s" if 0 <= row < len(self.t) else ""
            lines.append(f"first collision at t = {e.t:.4f} s (sample {e.sample}"
                         f"{t_j}{touch}): {e.names[0]} - {e.names[1]}"
                         f"{_how_found(e)}")
            lines.append(f"  at ({e.point[0]:.4f}, {e.point[1]:.4f}, {e.point[2]:.4f}) m, "
                         f"approach speed v = {self.v:.4f} m/s ({'at the touch' if e.impact else 'Eq. 7'}), "
                         f"normal speed {e.normal_speed:.4f} m/s")
            if len(self.events) > 1:
                others = ", ".join(f"{a}-{b}" for a, b in (x.names for x in self.events[1:]))
                lines.append(f"  also colliding by t_j: {others}")
            if self.note:
                lines.append(f"  note: {self.note}")
        if math.isinf(self.d):
            lines.append("d: no pair counted")
        else:
            lines.append(f"d = {self.d * 1e3:.3f} mm at t = {self.d_time:.4f} s "
                         f"({self.d_pair[0]} - {self.d_pair[1]}), over {self.n_valid} valid samples")
        if self.press_pair:
            lines.append(f"fastest press {self.press_speed:.3g} m/s at t = {self.press_time:.4f} s "
                         f"({self.press_pair[0]} - {self.press_pair[1]}), impacts from "
                         f"{self.collision.impact_speed:g} m/s")
        return "\n".join(lines)


def _how_found(e: CollisionEvent) -> str:
    if e.impact:
        return " (an impact that panel contact absorbed, found between samples by the integrator)"
    return " (between samples)" if e.refined else ""


def compliance_note(model: Model, event: CollisionEvent | None,
                    impact_speed: float = IMPACT_SPEED) -> str | None:
    """Why the verdict on a first collision that is a press (normal speed
    below ``impact_speed``, m/s, ``collision.impact_speed``) can depend on a
    compliance of the model, or None.

    Two panels in contact (``model.contact_pairs``) went deeper than the
    tolerance against the contact's stiffness k_p; with the penalty closure
    a press can be the loop's compliance at work (with the exact closure
    some vanish, issue 33).
    """
    if event is None or abs(event.normal_speed) >= impact_speed:
        return None
    speed = f"a press at {abs(event.normal_speed):.3f} m/s"
    if tuple(sorted(event.bodies)) in model.contact_pairs:
        return (f"{speed} of two panels in contact: it went past the tolerance against "
                f"contact.k_p = {model.k_p:g} N/m (a stiffer contact may hold it, or it is a jam)")
    if model.cut_hinges and model.closure.method == "penalty":
        return (f"{speed} with the penalty closure (k_M = {model.closure.k_M:g} N/m): it can come "
                "from the closure's compliance; check with --closure exact")
    return None


def _collision_settings(collision) -> CollisionSettings:
    if collision is None:
        return CollisionSettings()
    if isinstance(collision, CollisionSettings):
        return collision
    return CollisionSettings.from_scene(collision)


def check_trajectory(model: Model, result, collision=None, *, stop_at_first: bool = True) -> CollisionReport:
    """Distances D_j, first collision, V_j, v and d of a sampled trajectory.

    Parameters
    ----------
    model : Model
        The model that was simulated.
    result : SimulationResult
        Uses ``t``, ``theta`` and ``omega``; a failed run is checked over
        the samples it has.
    collision : CollisionSettings, CollisionSection or Scene, optional
    stop_at_first : bool
        Stop at the sample that reveals the first collision (the rest is
        invalid). False checks every sample (``events`` then still holds
        only the first collision's sample).

    Returns
    -------
    CollisionReport
    """
    check = TrajectoryCheck(model, collision, capacity=len(result.t))
    check.feed(result, stop_at_first=stop_at_first)
    return check.report()


class TrajectoryCheck:
    """:func:`check_trajectory` taken in pieces: feed samples as they come, then report.

    What :func:`~panel_deploy.optimise.evaluate.run_deployment` uses to stop
    a simulation at its first collision instead of checking it afterwards.

    Parameters
    ----------
    model : Model
    collision : CollisionSettings, CollisionSection or Scene, optional
    capacity : int
        Samples to preallocate D_j for (it grows when exceeded).
    keep : int, optional
        Keep D_j of the last ``keep`` to ``2 keep`` samples only (a live
        stream's memory stays bounded); None keeps every sample.
    """

    def __init__(self, model: Model, collision=None, capacity: int = 64, keep: int | None = None):
        self._start = time.perf_counter()
        self.collision = _collision_settings(collision)
        self.monitor = CollisionMonitor(model, self.collision)
        P = len(self.monitor.pairs)
        self._t = np.empty(capacity)
        self._D = np.empty((capacity, P))
        self._exact = np.empty((capacity, P), dtype=bool)
        self.checked = 0
        self.keep = keep
        self._dropped = 0
        self.first_events: list = []
        self.n_valid = None
        self.d, self.d_time, self.d_pair = math.inf, math.nan, None
        self.press = None  # the fastest onset row below the impact speed, before any collision
        # contact pair index -> checked pair index (contact pairs are collision pairs)
        index = {pair: k for k, pair in enumerate(model.collision_pairs)} if model.contact_pairs else {}
        self._impact_pair = [index[pair] for pair in model.contact_pairs]

    @property
    def collided(self) -> bool:
        return bool(self.first_events)

    def feed(self, result, *, stop_at_first: bool = True, poses: bool = False) -> bool:
        """Check the samples of ``result`` (a SimulationResult or a block of one).

        Returns True once a collision has been found; with ``stop_at_first``
        the samples after the one that revealed it are not checked. With
        ``poses`` the bodies' poses are taken from ``result.rotation`` and
        ``result.position`` instead of being recomputed from ``theta``: for
        a result just simulated, not for one read from a file, whose poses
        could disagree with its angles.
        """
        onsets = getattr(result, "contact_onsets", None)  # a recording's track has none
        for j in range(len(result.t)):
            if self.collided and stop_at_first:
                break
            self.update(result.t[j], result.theta[j], result.omega[j],
                        (result.rotation[j], result.position[j]) if poses else None,
                        None if onsets is None else onsets[j])
        return self.collided

    def update(self, t, theta, omega, poses=None, onset=None) -> list:
        """Check one sample (``poses`` as :meth:`CollisionMonitor.update`); the collision events it revealed.

        ``onset``, a row of ``SimulationResult.contact_onsets``, is the
        fastest panel contact onset since the last sample: at
        ``collision.impact_speed`` or faster it is an impact, a collision
        although the contact kept the panels within the tolerance (a live
        stream has no such row).
        """
        m = self.monitor
        events = m.update(t, theta, omega, poses)
        if onset is not None and onset[1] >= self.collision.impact_speed:
            events = sorted([*events, self._impact(onset, self.checked)], key=lambda e: e.t)
        elif onset is not None and not (events or self.first_events):
            self._note_press(onset)
        j = self.checked - self._dropped
        if self.keep is not None and j == 2 * self.keep:
            # Amortised O(P) per sample: drop the older half once per keep samples.
            for rows in (self._t, self._D, self._exact):
                rows[:self.keep] = rows[self.keep:j]
            self._dropped += self.keep
            j = self.keep
        if j == len(self._t):
            grow = max(64, j) if self.keep is None else min(max(64, j), 2 * self.keep - j)
            self._t = np.concatenate([self._t, np.empty(grow)])
            self._D = np.concatenate([self._D, np.empty((grow, self._D.shape[1]))])
            self._exact = np.concatenate([self._exact, np.empty((grow, self._D.shape[1]), bool)])
        self._t[j], self._D[j], self._exact[j] = t, m.distances, m.exact
        self.checked += 1
        if events and not self.first_events:
            self.first_events, self.n_valid = events, self.checked - 1
        if not self.first_events and m.min_distance < self.d:
            self.d, self.d_time, self.d_pair = m.min_distance, float(t), m.pair_names(m.min_pair)
        return events

    def onset(self, onset) -> list:
        """Check a contact onset that comes apart from its sample (a live
        stream's ``ContactOnset``, after the joint state it belongs to was
        checked): a row of ``SimulationResult.contact_onsets`` with t on this
        check's time. Returns ``[event]`` for an impact (at
        ``collision.impact_speed`` or faster), else ``[]``; the first
        collision is then the one :meth:`update` with the onset would give.
        """
        if not onset[1] >= self.collision.impact_speed:
            if not self.first_events:
                self._note_press(onset)
            return []
        # The samples before the onset are valid; the one whose interval holds it is not.
        kept = self.checked - self._dropped
        sample = self._dropped + int(np.searchsorted(self._t[:kept], onset[0]))
        event = self._impact(onset, sample)
        if not self.first_events or sample < self.n_valid:
            self.first_events, self.n_valid = [event], sample
        elif sample == self.n_valid:
            self.first_events = sorted([*self.first_events, event], key=lambda e: e.t)
        return [event]

    def _note_press(self, onset) -> None:
        """Keep ``onset`` (a contact onset row slower than the impact speed) if
        it is the fastest so far."""
        if onset[1] > 0.0 and (self.press is None or onset[1] > self.press[1]):
            self.press = np.array(onset, dtype=float)

    def _impact(self, onset, sample: int) -> CollisionEvent:
        """The collision event of a contact onset record (``result.ONSET_COLUMNS``),
        revealed by sample number ``sample``."""
        m = self.monitor
        k = self._impact_pair[int(onset[2])]
        speed = float(onset[1])
        return CollisionEvent(
            t=float(onset[0]), contact_time=float(onset[0]), sample=sample, pair=k,
            bodies=tuple(int(b) for b in m.pairs[k]), names=m.pair_names(k), distance=0.0, point=np.array(onset[3:6]),
            normal=np.array(onset[6:9]), approach_speed=speed, normal_speed=speed, refined=True,
            impact=True)

    def report(self) -> CollisionReport:
        """The :class:`CollisionReport` of everything fed so far."""
        m, P, n = self.monitor, len(self.monitor.pairs), self.checked - self._dropped
        # Eq. (7) needs two earlier samples; before that the kinematic speed stands in.
        V = np.zeros(P)
        for e in self.first_events:
            V[e.pair] = e.approach_speed if math.isfinite(e.approach_speed) else e.normal_speed
        return CollisionReport(
            pairs=m.pairs, pair_names=[m.pair_names(k) for k in range(P)],
            t=self._t[:n].copy(), distances=self._D[:n].copy(), exact=self._exact[:n].copy(),
            n_valid=self.checked if self.n_valid is None else self.n_valid,
            first_collision=self.first_events[0] if self.first_events else None,
            events=self.first_events, V=V, v=float(V.max()) if self.first_events else 0.0,
            d=self.d, d_time=self.d_time, d_pair=self.d_pair,
            counters=dict(m.counters, exact_fallbacks=m.exact_fallbacks),
            collision=self.collision, wall_time=time.perf_counter() - self._start,
            flat_contact=m.flat_contact, first_sample=self._dropped,
            note=compliance_note(self.monitor.model, self.first_events[0] if self.first_events else None,
                                 self.collision.impact_speed),
            **self._press_fields())

    def _press_fields(self) -> dict:
        if self.press is None:
            return {}
        k = self._impact_pair[int(self.press[2])]
        return dict(press_speed=float(self.press[1]), press_time=float(self.press[0]),
                    press_pair=self.monitor.pair_names(k))
