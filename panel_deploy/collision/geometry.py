"""Signed distances between the panels' boxes: FCL narrow phase, certified.

Every body is one box of edge lengths ``body.size`` centred on the body frame
(merged panels are one box; thickness included). The signed distance of two
boxes is their Euclidean distance when apart (m, > 0) and minus their
penetration depth when they interfere (m, < 0).

Accuracy. python-fcl 0.7 does not expose FCL's GJK/EPA tolerances (its
``DistanceRequest`` has only ``enable_nearest_points``, ``enable_signed_distance``
and ``gjk_solver_type``). Measured against two exact references on random box
pairs, FCL's distance is exact to ~1e-16 m in about 99.8 % of separated pairs
but over-estimates the rest by up to ~1e-4 m, with either GJK solver.
So each separated distance is certified: FCL's nearest points give an upper
bound |p_b - p_a|, and the separation of the boxes along n = (p_b - p_a)/|.|
(or 0) a lower bound; if the two differ by more than ``CERTIFY_TOL`` the distance is
recomputed exactly by vertex/box and edge/edge enumeration (:func:`box_distance`,
compiled with numba, since on the paper scene about a third of the exact pair
queries need it). When the boxes interfere, the depth is taken from the
separating-axis test, exact for boxes.
(FCL's signed distance agreed with it to 1e-16 m on random pairs, but aborts
the whole process on some near-touching pairs, so it is not used.)

Between samples the monitor needs thousands of distances per second in
compiled code, where FCL cannot be called: :func:`box_signed_distance` gives
them without FCL (separating-axis depth, or the nearest vertex/box pair when
certified like FCL's points, else :func:`box_distance`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import fcl
import numpy as np
from numba import njit

from ..boxes import SIGNS, corners, least_overlap, separation
from ..model import Model

CERTIFY_TOL = 1e-10
"""Largest accepted gap (m) between FCL's distance and its lower bound max(0, separation)."""

_ROUNDING = 1e-12
"""Slack (m) of :func:`box_distance`'s edge pruning, far above the rounding of
coordinates (~1e-16 of their size, for a scene well under 1 km across)."""

_EDGES = np.array([(i, j) for i in range(8) for j in range(i + 1, 8)
                   if np.count_nonzero(SIGNS[i] != SIGNS[j]) == 1])


@dataclass(frozen=True)
class PairGeometry:
    """Signed distance of one pair and where it is attained.

    ``point_a``, ``point_b`` (3,) are the nearest points on each box when apart
    and the centre of FCL's contact manifold (both equal) when interfering, ground frame, m; ``normal`` (3,) is the unit direction from
    box a towards box b along which the signed distance is measured.
    """

    distance: float
    point_a: np.ndarray
    point_b: np.ndarray
    normal: np.ndarray


class BoxSet:
    """The boxes of a model's bodies at one configuration.

    Call :meth:`set_poses` with the forward kinematics of a state, then
    :meth:`lower_bounds` (cheap, vectorised, all pairs) and
    :meth:`signed_distance` (exact, one pair) or :meth:`signed_distances`
    (exact, many).
    """

    def __init__(self, model: Model):
        self.half = np.array([np.asarray(b.size, dtype=float) / 2.0 for b in model.bodies])
        self.radius = np.linalg.norm(self.half, axis=1)
        self._objects = [fcl.CollisionObject(fcl.Box(*(2.0 * h)), fcl.Transform()) for h in self.half]
        # No enable_signed_distance: FCL's signed GJK/EPA aborts the process
        # (std::logic_error in validateNearestFeatureOfPolytopeBeingEdge) on
        # near-touching boxes with either solver; depth comes from SAT instead.
        self._request = fcl.DistanceRequest(enable_nearest_points=True)
        self._contact_request = fcl.CollisionRequest(enable_contact=True, num_max_contacts=8)
        self.rotation = np.tile(np.eye(3), (len(self.half), 1, 1))
        self.position = np.zeros((len(self.half), 3))
        self._placed = np.ones(len(self.half), dtype=bool)
        self.exact_fallbacks = 0

    def set_poses(self, rotation, position):
        """Place every box: ``rotation`` (nb, 3, 3), ``position`` (nb, 3) m."""
        self.rotation = np.asarray(rotation, dtype=float)
        self.position = np.asarray(position, dtype=float)
        # FCL's copies are updated when a query needs them (_place): a sample
        # usually needs the exact distance of a few pairs only.
        self._placed[:] = False

    def _place(self, *bodies):
        """Give FCL the poses of the boxes in ``bodies`` (indices or index arrays)
        that it does not have yet."""
        todo = np.zeros(len(self._objects), dtype=bool)
        for x in bodies:
            todo[x] = True
        todo &= ~self._placed
        for i in np.flatnonzero(todo).tolist():
            self._objects[i].setRotation(self.rotation[i])
            self._objects[i].setTranslation(self.position[i])
        self._placed |= todo

    def lower_bounds(self, pairs: np.ndarray) -> np.ndarray:
        """A lower bound (m) on the distance of every pair, shape (P,).

        The larger of the gap between the two axis-aligned bounding boxes and
        the gap between the two bounding spheres; <= 0 says nothing.
        """
        half_aabb = np.einsum("bij,bj->bi", np.abs(self.rotation), self.half)
        a, b = (np.ascontiguousarray(pairs[:, k], dtype=np.int64) for k in (0, 1))
        return _lower_bounds(half_aabb, self.position, self.radius, a, b)

    def separation(self, i: int, j: int, n) -> float:
        """Gap (m) between the projections of boxes i and j on the unit vector n."""
        return separation(self.rotation[i], self.position[i], self.half[i],
                          self.rotation[j], self.position[j], self.half[j], n)

    def signed_distance(self, i: int, j: int) -> float:
        """Signed distance (m) of boxes i and j: distance, or minus penetration depth."""
        return self.pair_geometry(i, j).distance

    def signed_distances(self, a, b) -> tuple:
        """Signed distances of the box pairs (a[k], b[k]), with one compiled call
        for the certificates, depths and exact fallbacks instead of one per pair.

        Returns ``(sd, wrong)``, each (K,): ``sd`` each pair's
        :meth:`signed_distance` (m, to the bit) and ``wrong`` where FCL got it
        wrong and it was recomputed exactly. These are not added to
        :attr:`exact_fallbacks`: a caller may compute more than it keeps.
        """
        a, b = np.asarray(a, dtype=np.int64), np.asarray(b, dtype=np.int64)
        self._place(a, b)
        fcl_d = np.empty(len(a))
        near = np.zeros((len(a), 2, 3))
        objects, request = self._objects, self._request
        for k, (i, j) in enumerate(zip(a.tolist(), b.tolist())):
            result = fcl.DistanceResult()
            fcl_d[k] = d = fcl.distance(objects[i], objects[j], request, result)
            if d > 0.0:
                near[k] = result.nearest_points
        return _certified(self.rotation, self.position, self.half, a, b, fcl_d, near)

    def pair_geometry(self, i: int, j: int) -> PairGeometry:
        """Signed distance of boxes i and j with nearest points and normal."""
        self._place(i, j)
        result = fcl.DistanceResult()
        d = fcl.distance(self._objects[i], self._objects[j], self._request, result)
        if d <= 0.0:
            return self._penetration(i, j)
        pa, pb = result.nearest_points
        n = (pb - pa) / d
        if d - max(self.separation(i, j, n), 0.0) > CERTIFY_TOL:
            self.exact_fallbacks += 1
            d, pa, pb = self._exact_distance(i, j)
            n = (pb - pa) / d if d > 0 else np.zeros(3)
        return PairGeometry(float(d), pa, pb, n)

    def _penetration(self, i, j):
        """Exact depth by the separating-axis test: for two boxes the face
        normals and the 9 edge cross products contain the direction of least
        overlap, so the smallest overlap over those 15 axes is the depth.
        The point is the centre of FCL's box-box contact manifold."""
        overlap, axis, along = least_overlap(self.rotation[i], self.position[i], self.half[i],
                                             self.rotation[j], self.position[j], self.half[j])
        axis = np.array(axis)
        if overlap < 0.0:
            # FCL said "in contact" but an axis separates them: apart by a hair.
            self.exact_fallbacks += 1
            d, pa, pb = self._exact_distance(i, j)
            return PairGeometry(d, pa, pb, axis * np.sign(along))
        n = axis * (1.0 if along >= 0 else -1.0)
        result = fcl.CollisionResult()
        fcl.collide(self._objects[i], self._objects[j], self._contact_request, result)
        if result.contacts:
            x = np.mean([c.pos for c in result.contacts], axis=0)
        else:
            x = 0.5 * (self.corners(i)[np.argmax(self.corners(i) @ n)]
                       + self.corners(j)[np.argmin(self.corners(j) @ n)])
        return PairGeometry(float(-overlap), x, x, n)

    def corners(self, i: int) -> np.ndarray:
        """The 8 corners (8, 3) of box i, m."""
        return self.position[i] + (SIGNS * self.half[i]) @ self.rotation[i].T

    def _exact_distance(self, i, j):
        """Distance (m) of apart boxes i and j and its nearest points: :func:`box_distance`."""
        return box_distance(self.rotation[i], self.position[i], self.half[i],
                            self.rotation[j], self.position[j], self.half[j])


@njit(cache=True)
def _lower_bounds(half_aabb, c, radius, a, b):
    """:meth:`BoxSet.lower_bounds` of the pairs (a[k], b[k]) from the boxes'
    axis-aligned half extents (nb, 3), centres (nb, 3) and bounding radii
    (nb,), m; as its numpy form computed them, to the bit."""
    out = np.empty(a.shape[0])
    for k in range(a.shape[0]):
        i, j = a[k], b[k]
        gap2, centre2 = 0.0, 0.0
        for m in range(3):
            d = c[j, m] - c[i, m]
            g = max(abs(d) - half_aabb[i, m] - half_aabb[j, m], 0.0)
            gap2 += g * g
            centre2 += d * d
        out[k] = max(math.sqrt(gap2), math.sqrt(centre2) - radius[i] - radius[j])
    return out


@njit(cache=True)
def _certified(R, c, h, a, b, fcl_d, near):
    """The rest of :meth:`BoxSet.pair_geometry`'s distance for many pairs.

    ``fcl_d`` (K,) is FCL's distance of each pair (a[k], b[k]) and ``near``
    (K, 2, 3) its nearest points where that is > 0, m. Returns the signed
    distances (K,), m, and where FCL got them wrong (K,) bool (exact fallbacks).
    """
    sd = np.empty(a.shape[0])
    wrong = np.zeros(a.shape[0], dtype=np.bool_)
    n = np.empty(3)
    for k in range(a.shape[0]):
        i, j = a[k], b[k]
        d = fcl_d[k]
        if d <= 0.0:
            overlap = least_overlap(R[i], c[i], h[i], R[j], c[j], h[j])[0]
            if overlap >= 0.0:
                sd[k] = -overlap
                continue
        else:
            for m in range(3):
                n[m] = (near[k, 1, m] - near[k, 0, m]) / d
            if d - max(separation(R[i], c[i], h[i], R[j], c[j], h[j], n), 0.0) <= CERTIFY_TOL:
                sd[k] = d
                continue
        wrong[k] = True
        sd[k] = _box_distance(R[i], c[i], h[i], R[j], c[j], h[j], -np.inf)[0]
    return sd, wrong


@njit(cache=True)
def pair_bounds(R, c, h, a, b):
    """Separating-axis overlap and a corner upper bound of many box pairs, m.

    ``R`` (nb, 3, 3), ``c`` (nb, 3) and ``h`` (nb, 3) are the boxes as in
    :func:`separation`, ``a`` and ``b`` (P,) the pairs' box indices.
    Returns ``(overlap, upper)``, each (P,): ``overlap`` is
    :func:`least_overlap`'s (> 0 the depth of an interfering pair, exact for
    boxes; < 0 minus a lower bound on the distance of an apart one), and
    ``upper`` the smallest distance of a corner of either box from the
    other box, an upper bound on the pair's distance.
    """
    overlap = np.empty(len(a))
    upper = np.empty(len(a))
    for k in range(len(a)):
        i, j = a[k], b[k]
        overlap[k] = least_overlap(R[i], c[i], h[i], R[j], c[j], h[j])[0]
        upper[k] = corner_bound(R, c, h, i, j)
    return overlap, upper


@njit(cache=True)
def corner_bound(R, c, h, i, j):
    """:func:`pair_bounds`' ``upper`` of the one pair of boxes i and j, m."""
    q = np.empty(3)
    best = np.inf
    for x, y in ((i, j), (j, i)):
        vx = corners(R[x], c[x], h[x])
        for m in range(8):
            _clamp_to_box(vx[m], R[y], c[y], h[y], q)
            best = min(best, _distance(vx[m], q))
    return best


@njit(cache=True)
def box_distance(Ra, ca, ha, Rb, cb, hb):
    """Distance of two apart boxes by enumerating vertex/box and edge/edge pairs.

    Each box is given by its rotation ``R`` (3, 3), centre ``c`` (3,) and half
    edge lengths ``h`` (3,), ground frame, m. Returns ``(distance, point_a,
    point_b)``: the distance (m) and the nearest points (3,) on a and b, m.

    For convex polyhedra the nearest points lie on a vertex of one and a
    face of the other, or on two edges; so the minimum over all vertices'
    distances to the other box and all edge pairs' distances is exact.
    Where faces or edges are parallel the nearest points are not unique (their
    difference is): the first candidate found wins, in the order a's
    vertices, b's vertices, edge pairs, so rounding picks among the ties.
    An edge pair is skipped when either edge is farther than the best
    candidate so far (plus ``_ROUNDING``) from the other box, along one of
    that box's axes: it could not have won, so the result is the full
    enumeration's, to the bit, at about a third of its cost on the paper
    scene (the monitor's between-sample search runs it at every bisection
    step).
    """
    return _box_distance(Ra, ca, ha, Rb, cb, hb, -np.inf)


@njit(cache=True)
def _box_distance(Ra, ca, ha, Rb, cb, hb, lower):
    """:func:`box_distance`, stopping after the vertices when ``lower`` (m), a
    lower bound on the distance, or the separation along the best vertex
    pair's direction is within ``_ROUNDING`` of it (-inf: never)."""
    va = corners(Ra, ca, ha)
    vb = corners(Rb, cb, hb)
    ua = np.empty((8, 3))  # a's corners in b's frame
    ub = np.empty((8, 3))
    best = np.inf
    pa = np.empty(3)
    pb = np.empty(3)
    q = np.empty(3)
    for k in range(8):
        ua[k, 0], ua[k, 1], ua[k, 2] = _clamp_to_box(va[k], Rb, cb, hb, q)
        dist = _distance(va[k], q)
        if dist < best:
            best = dist
            pa[:] = va[k]
            pb[:] = q
    for k in range(8):
        ub[k, 0], ub[k, 1], ub[k, 2] = _clamp_to_box(vb[k], Ra, ca, ha, q)
        dist = _distance(q, vb[k])
        if dist < best:
            best = dist
            pa[:] = q
            pb[:] = vb[k]
    if lower > -np.inf:
        if best > 0.0:
            for m in range(3):
                q[m] = (pb[m] - pa[m]) / best
            lower = max(lower, separation(Ra, ca, ha, Rb, cb, hb, q))
        if best - lower <= _ROUNDING:
            return best, pa, pb
    gap_a = _edge_gaps(ua, hb)
    gap_b = _edge_gaps(ub, ha)
    sa, da = _edge_vectors(va)
    sb, db = _edge_vectors(vb)
    for e in range(sa.shape[0]):
        for f in range(sb.shape[0]):
            if max(gap_a[e], gap_b[f]) > best + _ROUNDING:
                continue
            s, t = _segment_parameters(sa[e], da[e], sb[f], db[f])
            dist = 0.0
            for m in range(3):
                g = (sb[f, m] + t * db[f, m]) - (sa[e, m] + s * da[e, m])
                dist += g * g
            dist = math.sqrt(dist)
            if dist < best:
                best = dist
                for m in range(3):
                    pa[m] = sa[e, m] + s * da[e, m]
                    pb[m] = sb[f, m] + t * db[f, m]
    return best, pa, pb


@njit(cache=True)
def box_signed_distance(Ra, ca, ha, Rb, cb, hb):
    """Signed distance (m) of two boxes (given as in :func:`box_distance`),
    without FCL: minus the separating-axis depth when they interfere, else
    their distance to ``_ROUNDING``. As the certified FCL path of
    :meth:`BoxSet.signed_distance` it is exact to far below any tolerance,
    and differs from it by at most ``CERTIFY_TOL`` (a pair FCL calls apart
    by less than that but the separating axes call interfering can differ
    in sign at that level).

    The nearest vertex/box pair is taken, like FCL's points, when the
    boxes' separation along its direction (or the separating-axis gap) is
    within ``_ROUNDING`` of it: a lower bound that close certifies it, and
    spares the edge pairs for most near pairs (72 % on the paper scene).
    """
    overlap = least_overlap(Ra, ca, ha, Rb, cb, hb)[0]
    if overlap > 0.0:
        return -overlap
    return _box_distance(Ra, ca, ha, Rb, cb, hb, -overlap)[0]


@njit(cache=True)
def _edge_vectors(corners):
    """Start points and edge vectors, each (12, 3), m, of a box's 12 edges from its corners (8, 3)."""
    start = np.empty((_EDGES.shape[0], 3))
    vector = np.empty((_EDGES.shape[0], 3))
    for e in range(_EDGES.shape[0]):
        for m in range(3):
            start[e, m] = corners[_EDGES[e, 0], m]
            vector[e, m] = corners[_EDGES[e, 1], m] - start[e, m]
    return start, vector


@njit(cache=True)
def _clamp_to_box(v, R, c, h, out):
    """Write into ``out`` (3,) the point of the box (R, c, h) nearest to ``v``
    (3,), m; return v's coordinates in the box's frame (a tuple of 3), m."""
    u0 = (v[0] - c[0]) * R[0, 0] + (v[1] - c[1]) * R[1, 0] + (v[2] - c[2]) * R[2, 0]
    u1 = (v[0] - c[0]) * R[0, 1] + (v[1] - c[1]) * R[1, 1] + (v[2] - c[2]) * R[2, 1]
    u2 = (v[0] - c[0]) * R[0, 2] + (v[1] - c[1]) * R[1, 2] + (v[2] - c[2]) * R[2, 2]
    l0, l1, l2 = min(max(u0, -h[0]), h[0]), min(max(u1, -h[1]), h[1]), min(max(u2, -h[2]), h[2])
    for m in range(3):
        out[m] = c[m] + (l0 * R[m, 0] + l1 * R[m, 1] + l2 * R[m, 2])
    return u0, u1, u2


@njit(cache=True)
def _edge_gaps(local, h):
    """A lower bound (m) on the distance of each of a box's 12 edges (order
    of ``_EDGES``) from another box of half edges ``h`` (3,), given the first
    box's corners (8, 3) in the other's frame: the largest gap along one of
    the other box's axes, which the edge, linear in each coordinate, spans
    from end to end."""
    out = np.empty(_EDGES.shape[0])
    for e in range(_EDGES.shape[0]):
        i, j = _EDGES[e, 0], _EDGES[e, 1]
        gap = 0.0
        for m in range(3):
            lo, hi = min(local[i, m], local[j, m]), max(local[i, m], local[j, m])
            gap = max(gap, lo - h[m], -h[m] - hi)
        out[e] = gap
    return out


@njit(cache=True)
def _distance(x, y):
    """|y - x| (m) of two points (3,)."""
    dx, dy, dz = y[0] - x[0], y[1] - x[1], y[2] - x[2]
    return math.sqrt(dx * dx + dy * dy + dz * dz)


@njit(cache=True)
def _segment_parameters(p1, d1, p2, d2):
    """Parameters (s, t) in [0, 1] of the closest points p1 + s d1, p2 + t d2 of two segments.

    ``p1``, ``p2`` (3,) start points and ``d1``, ``d2`` (3,) nonzero edge
    vectors, m. Ericson, Real-Time Collision Detection, 5.1.9; parallel
    segments start from the point of the second nearest to p1 (exact, since
    for parallel segments an endpoint is always among the nearest).
    """
    r0, r1, r2 = p1[0] - p2[0], p1[1] - p2[1], p1[2] - p2[2]
    a = d1[0] * d1[0] + d1[1] * d1[1] + d1[2] * d1[2]
    e = d2[0] * d2[0] + d2[1] * d2[1] + d2[2] * d2[2]
    b = d1[0] * d2[0] + d1[1] * d2[1] + d1[2] * d2[2]
    c = d1[0] * r0 + d1[1] * r1 + d1[2] * r2
    f = d2[0] * r0 + d2[1] * r1 + d2[2] * r2
    denom = a * e - b * b
    s = 0.0 if denom <= 1e-12 * a * e else min(max((b * f - c * e) / denom, 0.0), 1.0)
    t = (b * s + f) / e
    if t < 0.0:
        s = min(max(-c / a, 0.0), 1.0)
        t = 0.0
    elif t > 1.0:
        s = min(max((b - c) / a, 0.0), 1.0)
        t = 1.0
    return s, t
