"""Streaming collision monitor: feed joint states one at a time, get events.

What counts as a collision
--------------------------
Let sd_p(t) be the signed distance of pair p (m; > 0 apart, < 0 minus the
penetration depth) for the pairs of ``model.collision_pairs`` (panels that
share no hinge; hinged neighbours are never checked, so a hinge reaching
theta = 0 or pi is a contact, not a collision). Pair p **collides** at the
first instant t with

    sd_p(t) < -tolerance            (tolerance = CollisionSection.tolerance)

i.e. interference deeper than the tolerance. Touching within the tolerance
is not a collision. That is deliberate, because the design has contacts on
purpose: in the stowed package adjacent layers and the two stacks touch, and
in the flat array the panels on either side of a slit (and diagonal
neighbours, at a corner) touch. The dynamics lets unhinged panels pass
through each other, so a real impact keeps going into interference and
crosses the tolerance within about tolerance / approach speed after the
first touch; the event also gives that first touch (``contact_time``).

The smallest distance ``d`` leaves out these designed contacts and the
stowed package itself: a pair counts towards d at a sample unless it touches
(sd <= tolerance) in the flat state, or has not yet cleared the package. With
h the height of the package at release (the first update: spread of the body
centroids along the ground normal plus the largest panel thickness), a pair
has cleared it once its distance exceeds its release distance by more than h,
or from the start if it was more than h apart at release. In the stowed stacks
every pair is at most h apart, so without this rule d would be the stack
spacing for every K and Eq. (8)'s -q d could not rank collision-free designs.
Pairs that have not cleared the package are still checked for collisions.

Between samples
---------------
With ``refine`` on, every interval (t_{j-1}, t_j] is checked under the
motion of :mod:`.motion` (cubic Hermite interpolation of theta, omega;
linear when the stream gives no omega): a pair whose lower bound
(sd_a + sd_b - L (t_b - t_a)) / 2 could fall below -tolerance - resolution,
and (``second_order``) whose second-order bound sd_a - tau (V_a + A tau / 2)
on the first half, tau = (t_b - t_a) / 2, or sd_b - tau (V_b + A tau / 2) on
the second could too (V the pair's exact speed at an end, A a bound on its
acceleration; :mod:`.motion`), is bisected, with the bounds recomputed on
each half. Guarantee: for the
interpolated motion, no pair reaches sd < -(tolerance + resolution) between
two samples unnoticed, and a reported collision time is the first instant
with sd < -tolerance to within ``time_resolution``. Exception: a pair in
contact (|sd| <= tolerance) at *both* ends of an interval is checked at the
samples and at the interval's mid-point only, so a press shorter than half
an interval can pass unseen. Such pairs slide on each other (the stowed
stacks, the slits near flat) at up to tens of m/s tangentially; a speed
bound cannot tell sliding from approach, and proving them would cost
~L h / tolerance bisections per interval (measured: 50x the time of the
whole check on the paper scene). The mid-point is there because such a
pair can also press in and come back without passing through: on the paper
scene, two mirror neighbours of the stacks (r4c1 - r4c4) pressed 0.16 mm
into each other for 4.2 ms at 0.03 m/s, between two 5 ms samples at which
they were within the 0.1 mm tolerance. (Nothing is claimed about motion
that differs from the interpolant; feed denser samples to tighten that.)
Between samples the distances are exact to 1e-12 m without FCL
(:func:`.geometry.box_signed_distance`), within ``CERTIFY_TOL`` of the
certified FCL distances D of the samples.

Approach speed
--------------
Eq. (7) is a difference quotient, V_j = (D_{j-2} - D_{j-1}) / (t_{j-1} - t_{j-2}),
so it depends on where the samples fall: on the paper scene's first impact
4.23 m/s from 200 Hz samples, 4.10 m/s from 1 kHz ones. With
``speed_interval`` dt > 0 it is evaluated on a fixed grid instead, whatever
the stream's rate: t_{j-1} is the last instant of 0, dt, 2 dt, ... (from the
first sample) before the collision, t_{j-2} = t_{j-1} - dt, and the distances
there are exact distances of the motion between the stored samples. A stream
sampled on that grid gives exactly Eq. (7) of its own samples; a denser one
gives the same value to within the interpolation error (the nodes use the
scene's sample interval, 5 ms for the paper's 200 Hz). The instantaneous
``normal_speed`` needs no grid at all. When the history does not reach back
two intervals (the start of a stream), the two samples before the collision
are used.

Noisy streams
-------------
Encoder angles carry noise. With ``noise`` sigma > 0 (rad, per hinge), a
pair's distance at a sample can be off by up to
depth_p = sum_k 3 sigma rho_k (rho_k the distance of the pair's bodies from
the hinge lines of its path, as in the speed bound of :mod:`.motion`), so a
pair collides at the first sample where sd < -(tolerance + depth_p) *and* its
distance fell since the previous sample: overlap within what noise explains,
or a pair moving apart, is not a collision. Noisy samples are not
interpolated (a cubic through noise says nothing between the samples), so
collisions are found at the samples: the time is the sample's, ``refined``
False, ``contact_time`` None. The detection comes later by about
depth_p / approach speed than in a clean stream.

Receipt timing
--------------
With ``stamps`` "receipt" a sample's time is when it arrived (the
middleware's source or receive time; a recording's log time), not when it
was measured: the angles are true, their times carry the transport's jitter
(on a loaded machine 1 ms typical, tens of ms at worst). Jitter is no
motion, so nothing is interpolated between such samples (a cubic through
jittered times invents speeds): a pair collides only at a sample whose
measured configuration interferes deeper than the tolerance, which timing
cannot fake. What receipt timing cannot give: the instant of a collision
better than the arrival interval, and an approach speed (Eq. 7) better than
jitter / ``speed_interval`` relative.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np
from numba import njit

from ..dynamics.pack import pack
from ..dynamics.simulate import body_states
from ..errors import TrajectoryError
from ..model import Model
from .event import CollisionEvent
from .geometry import _ROUNDING, CERTIFY_TOL, BoxSet, PairGeometry, box_signed_distance, corner_bound, least_overlap
from .motion import HermiteSegment, PairSpeedBound
from .refine import MAX_DEPTH, poses, refine_interval, stack
from .settings import CollisionSettings

#: Samples kept at most for Eq. (7) over a speed interval (module docstring).
HISTORY = 4096
#: How many standard deviations of angle noise a noisy stream's distances are
#: allowed (module docstring, "Noisy streams").
NOISE_SIGMAS = 3.0


@dataclass
class _Sample:
    t: float
    theta: np.ndarray
    omega: np.ndarray
    distances: np.ndarray
    exact: np.ndarray
    linear: bool
    radii: np.ndarray | None


def _segment(prev: _Sample, cur: _Sample) -> HermiteSegment:
    """Motion between two samples: Hermite, or linear in theta when no rates were given."""
    if cur.linear:
        w = (cur.theta - prev.theta) / (cur.t - prev.t)
        return HermiteSegment(prev.t, prev.theta, w, cur.t, cur.theta, w)
    return HermiteSegment(prev.t, prev.theta, prev.omega, cur.t, cur.theta, cur.omega)


class CollisionMonitor:
    """Distances and collision events of a stream of joint states.

    The same object serves a saved trajectory (:func:`check_trajectory` feeds
    it sample by sample) and a live stream (simulator or encoder messages).

    Parameters
    ----------
    model : Model
    settings : CollisionSettings, optional

    Attributes
    ----------
    pairs : (P, 2) ndarray of int
        ``model.collision_pairs``.
    flat_contact : (P,) ndarray of bool
        Pairs touching in the flat state (left out of d).
    resting : (P,) ndarray of bool or None
        Pairs that have not cleared the stowed package (see the module
        docstring); None before the first update.
    package_height : float
        h of the module docstring, m (nan before the first update).
    colliding : (P,) ndarray of bool
        Pairs with sd < -tolerance at the last update.
    distances : (P,) ndarray
        Signed distances at the last update, m; where ``exact`` is False a
        lower bound, above ``collision.margin`` or, for a resting pair, one that
        decides its collision, touching and release as the exact one would.
    exact : (P,) ndarray of bool
    min_distance : float
        Smallest distance of the last update over the pairs that count
        towards d, m (inf if none).
    min_pair : int
        Its pair index (-1 if none).
    events : list of CollisionEvent
        Every event so far, in order.
    counters : dict of str -> int
        samples, exact_pairs, pruned_pairs (left out by the broad phase),
        refined_intervals, refine_evaluations, contact_midpoints (intervals whose
        touching pairs were checked at the mid-point), exact_fallbacks.
    """

    def __init__(self, model: Model, collision: CollisionSettings | None = None):
        self.model = model
        self.collision = collision or CollisionSettings()
        self.pairs = np.array(model.collision_pairs, dtype=int).reshape(-1, 2)
        self._a, self._b = (np.ascontiguousarray(self.pairs[:, k], dtype=np.int64) for k in (0, 1))
        self._packed = pack(model)
        self._boxes = BoxSet(model)
        self._scratch = BoxSet(model)
        self._speed = PairSpeedBound(model, self.pairs)
        sp = self._speed
        self._geo = (self._packed, self._boxes.half, self._a, self._b, sp.coords, sp.length, sp.chain_a,
                     sp.chain_b, sp.parents, sp.points, sp.axes, sp.tree, sp.lca, sp.reach_a, sp.reach_b)
        self._stack = stack(16, len(self.pairs), model.n_bodies, model.n_coords)
        self._scratch.set_poses(*self._kinematics(np.zeros(model.n_coords)))
        # A pair whose cheap lower bound exceeds the tolerance cannot touch:
        # FCL only for the others (the slits' neighbours, ~4 a panel), in one batch.
        near = np.flatnonzero(self._scratch.lower_bounds(self.pairs) <= self.collision.tolerance)
        self.flat_contact = np.zeros(len(self.pairs), dtype=bool)
        sd = self._scratch.signed_distances(self._a[near], self._b[near])[0]
        self.flat_contact[near] = sd <= self.collision.tolerance
        self.resting = None
        self._release = np.zeros(len(self.pairs))
        self.package_height = math.nan
        self.colliding = np.zeros(len(self.pairs), dtype=bool)
        self.distances = np.full(len(self.pairs), np.inf)
        self.exact = np.zeros(len(self.pairs), dtype=bool)
        self.min_distance = math.inf
        self.min_pair = -1
        self.events = []
        # The last samples: two, or those Eq. (7) reaches back to (``_prune_history``).
        self._history = deque(maxlen=HISTORY)
        self._count = 0
        self._sample_fallbacks = 0
        self.counters = dict(samples=0, exact_pairs=0, pruned_pairs=0, refined_intervals=0,
                             refine_evaluations=0, contact_midpoints=0)

    @property
    def first_collision(self) -> CollisionEvent | None:
        return self.events[0] if self.events else None

    @property
    def exact_fallbacks(self) -> int:
        """Distances FCL got wrong and that were recomputed exactly (geometry module):
        at the samples and events, as between samples FCL is not used."""
        return self._sample_fallbacks + self._boxes.exact_fallbacks + self._scratch.exact_fallbacks

    def pair_names(self, p: int) -> tuple:
        a, b = self.pairs[p]
        return self.model.bodies[a].name, self.model.bodies[b].name

    def update(self, t, theta, omega=None, poses=None) -> list:
        """Take the state at instant t; return the collisions that began since the last one.

        Parameters
        ----------
        t : float
            s, larger than at the previous update.
        theta : (n_coords,) array_like
            Hinge angles, rad.
        omega : (n_coords,) array_like, optional
            Hinge rates, rad/s. Without them (e.g. encoder angles only) the
            rates are the secant slopes, so the motion between updates is
            taken to be linear in theta.
        poses : (rotation, position), optional
            The bodies' rotations (nb, 3, 3) and centroids (nb, 3), m, at
            ``theta`` when the caller has them (a SimulationResult does),
            saving the forward kinematics.

        Returns
        -------
        list of CollisionEvent
            Ordered by time; also appended to :attr:`events`.
        """
        t = float(t)
        theta = np.asarray(theta, dtype=float)
        if theta.shape != (self.model.n_coords,):
            raise TrajectoryError(f"theta: expected shape ({self.model.n_coords},), got {theta.shape}")
        prev = self._history[-1] if self._history else None
        if prev is not None and not t > prev.t:
            raise TrajectoryError(f"t: updates must move forward in time, got {t} after {prev.t}")
        linear = omega is None
        if linear:
            omega = np.zeros_like(theta) if prev is None else (theta - prev.theta) / (t - prev.t)
        else:
            omega = np.asarray(omega, dtype=float)

        R, p = self._kinematics(theta) if poses is None else poses
        self._boxes.set_poses(R, p)
        D, exact = self._sample_distances()
        if self.resting is None:
            self.package_height = float(np.ptp(p[:, 2]) + max(b.size[2] for b in self.model.bodies))
            self._release = D + self.package_height
            self.resting = D <= self.package_height
        noisy = self.collision.noise > 0
        # The hinge-line radii bound the motion between samples, and what noise does to D.
        radii = self._speed.radii(R, p) if self.collision.refine or noisy else None
        cur = _Sample(t, theta, omega, D, exact, linear, radii)

        tol = self.collision.tolerance
        colliding = D < -tol
        if noisy:
            found, colliding = self._noisy(prev, cur)
        elif prev is not None and self.collision.refine and self.collision.stamps == "header":
            found = self._refine(prev, cur)
        else:
            found = {int(k): (t, None) for k in np.flatnonzero(colliding & ~self.colliding)}
        self._history.append(cur)
        self._prune_history()
        events = [self._event(k, tc, contact, prev, cur) for k, (tc, contact) in found.items()]
        events.sort(key=lambda e: e.t)

        self.colliding = colliding
        self.resting &= ~(D > self._release)
        self.distances, self.exact = D, exact
        counts = np.flatnonzero(exact & ~self.flat_contact & ~self.resting)
        self.min_pair = int(counts[np.argmin(D[counts])]) if counts.size else -1
        self.min_distance = float(D[self.min_pair]) if counts.size else math.inf
        self._count += 1
        self.counters["samples"] += 1
        self.events.extend(events)
        return events

    # --- distances -------------------------------------------------------------------------

    def _kinematics(self, theta, omega=None):
        """:func:`~panel_deploy.kinematics.forward_kinematics` (same shapes, model
        body order, same values to rounding, ~1e-16) by the compiled dynamics
        kernel: every sample and bisection step needs poses, and the numpy
        version costs ~7x as much per call."""
        theta = np.asarray(theta, dtype=float)
        rates = np.zeros_like(theta) if omega is None else np.asarray(omega, dtype=float)
        R, p, v, w = body_states(self._packed, theta, rates)
        return (R, p) if omega is None else (R, p, v, w)

    def _distances_at(self, theta, rows):
        """Exact signed distances of ``rows`` at angles ``theta``, on the scratch boxes."""
        R, p = self._kinematics(theta)
        self._scratch.set_poses(R, p)
        return np.array([self._scratch.signed_distance(*self.pairs[k]) for k in rows])

    def _sample_distances(self):
        """Signed distances of one sample, exact where they can matter (see ``margin``)."""
        b = self._boxes
        lb = b.lower_bounds(self.pairs)
        resting = self.resting if self.resting is not None else np.zeros(len(lb), dtype=bool)
        D, exact, rows, counts = _sample_plan(b.rotation, b.position, b.half, b.radius, self._a, self._b, lb,
                                              np.argsort(lb, kind="stable"), resting, self._release,
                                              self.flat_contact, self.collision.tolerance, self.collision.margin)
        sd, wrong = b.signed_distances(self._a[rows], self._b[rows])
        n = _kept(lb[rows], counts[rows], sd, self.collision.margin)
        D[rows[:n]], exact[rows[:n]] = sd[:n], True
        self._sample_fallbacks += int(np.count_nonzero(wrong[:n]))
        self.counters["exact_pairs"] += int(exact.sum())
        self.counters["pruned_pairs"] += int((~exact).sum())
        return D, exact

    # --- between samples -------------------------------------------------------------------

    def _refine(self, prev: _Sample, cur: _Sample) -> dict:
        """First collision instant (and first touch) in (prev.t, cur.t] of every pair.

        Depth-first bisection, left half first, so mid-points are *visited*
        in time order; a pair is dropped from an interval once its lower
        bound proves sd >= -(tolerance + resolution) there. The search is
        one compiled call, :func:`.refine.refine_interval`; the few pairs it
        finds are then located here.
        """
        s = self.collision
        seg = _segment(prev, cur)
        while True:
            limits = (-s.tolerance, s.resolution, s.time_resolution, s.prune, s.second_order)
            found_t, last_touch, order, pressed, steps, midpoint = refine_interval(
                self._geo, seg.coefficients, limits, cur.t, prev.distances, cur.distances, prev.radii,
                cur.radii, self.colliding, self._stack)
            if steps >= 0:
                break
            depth = len(self._stack[3])
            if depth >= MAX_DEPTH:
                raise TrajectoryError(f"t: the interval ({prev.t:.9g}, {cur.t:.9g}] s is too long to "
                                      f"search to {s.time_resolution:g} s")
            # Deeper than ever before: again, with room for twice as many levels.
            self._stack = stack(min(2 * depth, MAX_DEPTH), len(self.pairs), self.model.n_bodies,
                                self.model.n_coords)
        self.counters["contact_midpoints"] += int(midpoint)
        self.counters["refine_evaluations"] += int(steps)
        self.counters["refined_intervals"] += int(steps > 0)
        found = {}
        for i, k in enumerate(order.tolist()):
            t = float(found_t[k])
            if i < pressed:
                # Touching at both ends, past the tolerance at the mid-point t.
                t = self._bisect(seg, k, prev.t, t, -s.tolerance)[1]
            touch = float(last_touch[k])
            found[k] = (t, None if math.isnan(touch) else self._bisect(seg, k, touch, t, 0.0)[0])
        return found

    def _bisect(self, seg, k, lo, hi, level):
        """(lo, hi) within ``time_resolution`` of where pair k's sd falls below ``level``,
        given sd(lo) >= level > sd(hi); with the search's poses and distances."""
        while hi - lo > self.collision.time_resolution:
            mid = 0.5 * (lo + hi)
            R, p = poses(self._geo, seg.coefficients, mid)
            a, b = self._a[k], self._b[k]
            h = self._boxes.half
            if box_signed_distance(R[a], p[a], h[a], R[b], p[b], h[b]) >= level:
                lo = mid
            else:
                hi = mid
        return lo, hi

    def _noisy(self, prev, cur) -> tuple:
        """Collisions of a noisy stream at sample ``cur``, and the pairs colliding there.

        A pair is deep when sd < -(tolerance + depth), depth the most that
        angle errors of NOISE_SIGMAS standard deviations on every hinge of
        its path can change sd (the speed bound of :mod:`.motion` with the
        rates replaced by those errors); it starts colliding when it is deep
        and its distance fell since the previous sample.
        """
        rows = np.arange(len(self.pairs))
        errors = np.full(self.model.n_coords, NOISE_SIGMAS * self.collision.noise)
        depth = self.collision.tolerance + self._speed(errors, 0.0, cur.radii, cur.radii, rows)
        deep = cur.distances < -depth
        found = {}
        if prev is not None:
            for k in np.flatnonzero(deep & ~self.colliding):
                if self._distance(prev, k) > cur.distances[k]:
                    found[int(k)] = (cur.t, None)
        colliding = deep & self.colliding
        colliding[list(found)] = True
        return found, colliding

    def _prune_history(self) -> None:
        """Keep the samples the next Eq. (7) can need: back to two speed
        intervals before the newest one, and at least two."""
        h, reach = self._history, 2.0 * self.collision.speed_interval
        while len(h) > 3 and h[1].t < h[-1].t - reach - (h[-1].t - h[-2].t):
            h.popleft()

    def _distance(self, sample: _Sample, k: int) -> float:
        """Exact distance of pair k at a stored sample, m."""
        return sample.distances[k] if sample.exact[k] else self._distances_at(sample.theta, [k])[0]

    def _distance_at_time(self, tau: float, k: int) -> float | None:
        """Exact distance of pair k at instant tau (s) on the motion between the
        stored samples, m; None when tau is before the oldest one."""
        h = self._history
        for i in range(len(h) - 1, -1, -1):
            if abs(h[i].t - tau) <= 1e-9 * max(1.0, abs(tau)):
                return self._distance(h[i], k)
            if i and h[i - 1].t < tau < h[i].t:
                return self._distances_at(_segment(h[i - 1], h[i])(tau)[0], [k])[0]
        return None

    # --- events ----------------------------------------------------------------------------

    def _event(self, k, tc, contact_time, prev, cur) -> CollisionEvent:
        if prev is not None:
            theta, omega = _segment(prev, cur)(tc)
        else:
            theta, omega = cur.theta, cur.omega
        R, p, v, w = self._kinematics(theta, omega)
        self._scratch.set_poses(R, p)
        a, b = (int(x) for x in self.pairs[k])
        g: PairGeometry = self._scratch.pair_geometry(a, b)
        x = 0.5 * (g.point_a + g.point_b)
        va = v[a] + np.cross(w[a], x - p[a])
        vb = v[b] + np.cross(w[b], x - p[b])
        return CollisionEvent(
            t=tc, contact_time=contact_time, sample=self._count, pair=int(k), bodies=(a, b),
            names=self.pair_names(k), distance=g.distance, point=x, normal=g.normal,
            approach_speed=self._approach_speed(k, tc), normal_speed=float(-(vb - va) @ g.normal),
            refined=bool(tc < cur.t))

    def _approach_speed(self, k, t) -> float:
        """V_j of Eq. (7) for pair k colliding at instant t (s), m/s (module
        docstring, "Approach speed"); nan without two earlier instants."""
        h, dt = self._history, self.collision.speed_interval
        if dt > 0:
            # t_{j-1}: the last instant of the grid dt, 2 dt, ... strictly before t.
            before = (math.ceil(t / dt - 1e-9) - 1) * dt
            d1, d2 = self._distance_at_time(before, k), self._distance_at_time(before - dt, k)
            if d1 is not None and d2 is not None:
                return float((d2 - d1) / dt)
        if len(h) < 3:
            return math.nan
        older, newer = h[-3], h[-2]
        return float((self._distance(older, k) - self._distance(newer, k)) / (newer.t - older.t))


# --- one sample, compiled: the bounds and the choice of exact pairs around FCL's batch ------

@njit(cache=True)
def _sample_plan(R, c, h, radius, a, b, lb, order, resting, release, flat_contact, tol, margin):
    """Distances of one sample before FCL (:meth:`CollisionMonitor._sample_distances`).

    ``R``, ``c``, ``h`` are the boxes (:func:`.geometry.pair_bounds`),
    ``radius`` (nb,) their bounding spheres' radii (m), ``a``,
    ``b`` (P,) the pairs, ``lb`` (P,) their lower bounds (m) and ``order`` a
    stable sort of them, ``resting`` and ``flat_contact`` (P,) bool,
    ``release`` (P,) the release distances (m), ``tol`` the tolerance (m).

    First the resting pairs that need no exact distance are settled. A
    resting pair does not count towards d, so its distance matters only to
    tell a collision, which the separating-axis depth does exactly, its
    release from the package (``D > release``), which cannot happen while a
    corner of one box is no further than the release distance from the
    other, and whether it touches (``|D| <= tolerance``, for the
    refinement), which the bounds tell unless they straddle the tolerance.
    Those keep a lower bound (``exact`` False). On the paper scene resting
    pairs were 86 % of the exact queries of a locked run. A corner of one
    box lies within its circumradius of its centre, so the corner bound is
    at most the smaller circumradius plus the centres' distance: when that
    already settles the release, the 16 corners are skipped (the same
    decisions and D; half the cost of a resting pair, and in the stowed
    stacks of a large array every pair rests).

    Every other pair is exact if its bound is within ``margin``, or below
    the smallest counted distance of the pairs before it in order of the
    bound. Returns ``(D, exact, rows, counts)``: the distances (m) with the
    settled ones filled in, where they are exact, the pairs to give FCL in
    that order (a batch that holds every pair the rule reaches, see
    :func:`_kept`) and the pairs that count towards d.
    """
    P = lb.shape[0]
    D = lb.copy()
    exact = np.zeros(P, dtype=np.bool_)
    settled = np.zeros(P, dtype=np.bool_)
    for k in range(P):
        if not resting[k]:
            continue
        i, j = a[k], b[k]
        overlap = least_overlap(R[i], c[i], h[i], R[j], c[j], h[j])[0]
        if overlap > tol:
            # Deeper than the tolerance only: a touching pair's overlap can
            # have the wrong sign at ~1e-10 m (near-parallel edge axes are skipped).
            D[k], exact[k], settled[k] = -overlap, True, True
            continue
        # The separating-axis depth where they interfere, else a lower bound.
        lower = -overlap if overlap > 0.0 else (lb[k] if lb[k] >= -overlap else -overlap)
        if lower > tol:
            centres = math.sqrt((c[i, 0] - c[j, 0]) ** 2 + (c[i, 1] - c[j, 1]) ** 2 + (c[i, 2] - c[j, 2]) ** 2)
            if min(radius[i], radius[j]) + centres + _ROUNDING <= release[k]:
                D[k], settled[k] = lower, True
                continue
        upper = corner_bound(R, c, h, i, j)
        # The refinement treats touching pairs (|sd| <= tolerance) apart, so
        # the bounds must also tell touching: both within it, or both beyond.
        if (lower > tol or upper <= tol) and upper <= release[k]:
            D[k], settled[k] = lower, True
    counts = np.empty(P, dtype=np.bool_)
    for k in range(P):
        counts[k] = not flat_contact[k] and not resting[k]
    # Once a counted pair k is reached, the smallest counted distance is at
    # most k's corner upper bound (FCL's certified distance may exceed the
    # true one by CERTIFY_TOL), and every pair with a larger bound comes
    # after k: no pair beyond it gets an exact distance. Bounding by the
    # first four counted pairs, FCL gets ~0.5 pair per sample more than the
    # rule keeps on the paper scene.
    rows = np.empty(P, dtype=np.int64)
    n, seen, reach = 0, 0, np.inf
    for k in order:
        if lb[k] > margin and lb[k] >= reach:
            break
        if settled[k]:
            continue
        rows[n] = k
        n += 1
        if counts[k] and seen < 4:
            reach = min(reach, corner_bound(R, c, h, a[k], b[k]) + 2.0 * CERTIFY_TOL)
            seen += 1
    return D, exact, rows[:n], counts


@njit(cache=True)
def _kept(lb, counts, sd, margin):
    """How many of the pairs given to FCL, in order, the rule of :func:`_sample_plan`
    reaches; ``lb``, ``counts`` and ``sd`` (m) are theirs."""
    best = np.inf
    for i in range(lb.shape[0]):
        if lb[i] > margin and lb[i] >= best:
            return i
        if counts[i]:
            best = min(best, sd[i])
    return lb.shape[0]
