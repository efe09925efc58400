"""Boxes: the panels' geometry shared by the contact model and the collision check.

Every body is one box: rotation R (3, 3), centre c (3,) and half edges h (3,),
ground frame, m. The separating-axis test here gives the collision check its
exact penetration depths (:mod:`panel_deploy.collision.geometry`) and the
panel contacts of the dynamics their depth and normal; :func:`contact`
adds where the contact acts. Plain numba functions, callable from both;
those a contact evaluation calls for every touching pair are
``inline='always'``, so that numba's reference counts of their array
arguments do not cost a dozen calls' atomic operations a pair (see
:mod:`panel_deploy.dynamics._jit`).
"""

from __future__ import annotations

import math
from itertools import product

import numpy as np
from numba import njit

#: Corner signs of a box, in the order of :func:`corners`.
SIGNS = np.array(list(product((-1.0, 1.0), repeat=3)))
#: A box's support feature along a contact normal (a vertex, an edge or a face)
#: holds its corners within this fraction of its smallest half edge of the
#: extreme: so faces tilted by up to about FEATURE * thickness / length (5 mrad
#: for the paper's 100 x 100 x 5 mm panels) still press as faces.
FEATURE = 0.1
#: A corner this close (m) to the other feature's outline is on it: on up to
#: rounding (the stowed stacks' coincident edges), nothing wider. With the
#: FEATURE band here a corner joined the contact while still outside the other
#: panel's face, at a depth of its own, and the push jumped: two side-by-side
#: panels meeting edge on near flat (8 x 8, issue 33) went from 0.2 N to 14 N
#: within 1e-9 rad, and the integrator stalled on the jump at steps of 1e-8 s.
#: With the outline exact a corner joins where an edge crossing already stood.
#: Points closer than this to one found before are that one. Points within
#: the FEATURE band of one found before press with a part of a point's share
#: (:func:`_add_point`): near-coplanar faces have clusters of corners and
#: crossings microns apart, which must press about once, not two to eight
#: times by turns as the separating axis flips between the faces.
COINCIDENT = 1e-9


@njit(cache=True)
def corners(R, c, h):
    """The 8 corners (8, 3) of a box, m, in the order of ``SIGNS``."""
    return corners_into(R, c, h, np.empty((8, 3)))


@njit(cache=True, inline='always')
def corners_into(R, c, h, out):
    """:func:`corners`, written to out (8, 3) and returned."""
    for k in range(8):
        for m in range(3):
            out[k, m] = c[m] + (SIGNS[k, 0] * h[0] * R[m, 0] + SIGNS[k, 1] * h[1] * R[m, 1]
                                + SIGNS[k, 2] * h[2] * R[m, 2])
    return out


@njit(cache=True)
def radius(R, h, n):
    """Half-extent (m) along the unit vector n (3,) of a box of rotation R (3, 3) and half edges h (3,)."""
    r = 0.0
    for k in range(3):
        r += abs(n[0] * R[0, k] + n[1] * R[1, k] + n[2] * R[2, k]) * h[k]
    return r


@njit(cache=True)
def separation(Ra, ca, ha, Rb, cb, hb, n):
    """Gap (m) between the projections on the unit vector ``n`` (3,) of the boxes
    (R (3, 3), centre c (3,), half edges h (3,), ground frame, m) a and b."""
    along = n[0] * (cb[0] - ca[0]) + n[1] * (cb[1] - ca[1]) + n[2] * (cb[2] - ca[2])
    return along - radius(Ra, ha, n) - radius(Rb, hb, n)


@njit(cache=True, inline='always')
def axis_overlap(Ra, ca, ha, Rb, cb, hb, k):
    """Overlap (m) of boxes a and b (given as in :func:`separation`) along
    candidate axis k of :func:`least_overlap` (0-14, in its order): returns
    ``(overlap, axis, along)`` as it does for one axis, with an infinite
    overlap for a skipped (near-parallel) edge pair."""
    if k < 3:
        u0, u1, u2 = Ra[0, k], Ra[1, k], Ra[2, k]
    elif k < 6:
        u0, u1, u2 = Rb[0, k - 3], Rb[1, k - 3], Rb[2, k - 3]
    else:
        i, j = (k - 6) // 3, (k - 6) % 3
        u0 = Ra[1, i] * Rb[2, j] - Ra[2, i] * Rb[1, j]
        u1 = Ra[2, i] * Rb[0, j] - Ra[0, i] * Rb[2, j]
        u2 = Ra[0, i] * Rb[1, j] - Ra[1, i] * Rb[0, j]
    norm = math.sqrt(u0 * u0 + u1 * u1 + u2 * u2)
    if norm <= 1e-9:
        return np.inf, (0.0, 0.0, 0.0), 0.0
    u0, u1, u2 = u0 / norm, u1 / norm, u2 / norm
    along = u0 * (cb[0] - ca[0]) + u1 * (cb[1] - ca[1]) + u2 * (cb[2] - ca[2])
    ra = rb = 0.0
    for m in range(3):
        ra += abs(u0 * Ra[0, m] + u1 * Ra[1, m] + u2 * Ra[2, m]) * ha[m]
        rb += abs(u0 * Rb[0, m] + u1 * Rb[1, m] + u2 * Rb[2, m]) * hb[m]
    return ra + rb - abs(along), (u0, u1, u2), along


@njit(cache=True)
def least_overlap(Ra, ca, ha, Rb, cb, hb, stop_below=-np.inf):
    """Separating-axis test of boxes a and b (given as in :func:`separation`).

    Over the 15 candidate axes (the 3 + 3 face normals, then the 9 edge cross
    products a_i x b_j, in that order; near-parallel edge pairs skipped), the
    axis of least overlap: returns ``(overlap, axis, along)`` with the overlap
    (m, < 0 if that axis separates the boxes), the unit axis (a 3-tuple) and
    the centre offset ``(c_b - c_a) . axis`` (m) that gives its direction. The
    first of equal overlaps wins. It returns at the first axis whose overlap
    is below ``stop_below`` (m): that axis proves the boxes further apart.
    No allocation: the contact model calls it in every evaluation of the
    dynamics.
    """
    best = np.inf
    axis = (0.0, 0.0, 0.0)
    along_best = 0.0
    for k in range(15):
        overlap, u, along = axis_overlap(Ra, ca, ha, Rb, cb, hb, k)
        if overlap < best:
            best = overlap
            axis = u
            along_best = along
            if best < stop_below:
                break
    return best, axis, along_best


@njit(cache=True, inline='always')
def separating_axis(Ra, ca, ha, Rb, cb, hb, first):
    """A candidate axis of :func:`least_overlap` (0-14) along which boxes a and
    b (given as in :func:`separation`) do not overlap, trying ``first`` before
    the others: returns ``(k, overlap, axis, along)``, the axis and the overlap
    along it (m, <= 0) (and a zero axis and along), or if there is none k = -1
    and what :func:`least_overlap` returns (to rounding: here the axes of a
    pair that interferes come from b's rotation in a's frame, there from
    :func:`axis_overlap`'s dot products): then, and only then,
    the boxes interfere, and :func:`interference` takes that axis of least
    overlap from here, not from a second pass over the 15. Moving bodies keep
    their separating axis for many evaluations, so the axis that separated a
    pair last time settles it at the cost of one axis in place of up to 15."""
    overlap0 = axis_overlap(Ra, ca, ha, Rb, cb, hb, first)[0]
    if overlap0 <= 0.0:
        return first, overlap0, (0.0, 0.0, 0.0), 0.0
    # All 15 from b's rotation in a's frame, C[i][j] = a_i . b_j, as
    # Gottschalk's OBB test has them: a box's extent along a face normal or
    # an edge product is a sum of |C| entries (a's edges right-handed
    # orthonormal), not three dot products a box: 10.7 us against 14.9 us
    # for the stowed stacks' touching pairs of 10 x 10, whose 15 axes all
    # overlap.
    d = (cb[0] - ca[0], cb[1] - ca[1], cb[2] - ca[2])
    C = ((Ra[0, 0] * Rb[0, 0] + Ra[1, 0] * Rb[1, 0] + Ra[2, 0] * Rb[2, 0],
          Ra[0, 0] * Rb[0, 1] + Ra[1, 0] * Rb[1, 1] + Ra[2, 0] * Rb[2, 1],
          Ra[0, 0] * Rb[0, 2] + Ra[1, 0] * Rb[1, 2] + Ra[2, 0] * Rb[2, 2]),
         (Ra[0, 1] * Rb[0, 0] + Ra[1, 1] * Rb[1, 0] + Ra[2, 1] * Rb[2, 0],
          Ra[0, 1] * Rb[0, 1] + Ra[1, 1] * Rb[1, 1] + Ra[2, 1] * Rb[2, 1],
          Ra[0, 1] * Rb[0, 2] + Ra[1, 1] * Rb[1, 2] + Ra[2, 1] * Rb[2, 2]),
         (Ra[0, 2] * Rb[0, 0] + Ra[1, 2] * Rb[1, 0] + Ra[2, 2] * Rb[2, 0],
          Ra[0, 2] * Rb[0, 1] + Ra[1, 2] * Rb[1, 1] + Ra[2, 2] * Rb[2, 1],
          Ra[0, 2] * Rb[0, 2] + Ra[1, 2] * Rb[1, 2] + Ra[2, 2] * Rb[2, 2]))
    # the least overlap in least_overlap's order (the first of equal ones
    # wins), every axis by the same formulas, ``first`` too: what a pair
    # that touches gets may not depend on which axis was tried first
    best, axis, along_best = np.inf, (0.0, 0.0, 0.0), 0.0
    for k in range(15):
        if k < 3:
            u = (Ra[0, k], Ra[1, k], Ra[2, k])
            along = u[0] * d[0] + u[1] * d[1] + u[2] * d[2]
            extent = ha[k] + abs(C[k][0]) * hb[0] + abs(C[k][1]) * hb[1] + abs(C[k][2]) * hb[2]
        elif k < 6:
            j = k - 3
            u = (Rb[0, j], Rb[1, j], Rb[2, j])
            along = u[0] * d[0] + u[1] * d[1] + u[2] * d[2]
            extent = hb[j] + abs(C[0][j]) * ha[0] + abs(C[1][j]) * ha[1] + abs(C[2][j]) * ha[2]
        else:
            i, j = (k - 6) // 3, (k - 6) % 3
            u0 = Ra[1, i] * Rb[2, j] - Ra[2, i] * Rb[1, j]
            u1 = Ra[2, i] * Rb[0, j] - Ra[0, i] * Rb[2, j]
            u2 = Ra[0, i] * Rb[1, j] - Ra[1, i] * Rb[0, j]
            norm = math.sqrt(u0 * u0 + u1 * u1 + u2 * u2)
            u, along, extent = (0.0, 0.0, 0.0), 0.0, np.inf  # near-parallel edges: no axis
            if norm > 1e-9:
                u = (u0 / norm, u1 / norm, u2 / norm)
                along = u[0] * d[0] + u[1] * d[1] + u[2] * d[2]
                i1, i2, j1, j2 = (i + 1) % 3, (i + 2) % 3, (j + 1) % 3, (j + 2) % 3
                extent = (ha[i1] * abs(C[i2][j]) + ha[i2] * abs(C[i1][j])
                          + hb[j1] * abs(C[i][j2]) + hb[j2] * abs(C[i][j1])) / norm
        overlap = extent - abs(along)
        if overlap <= 0.0:
            return k, overlap, (0.0, 0.0, 0.0), 0.0
        if overlap < best:
            best, axis, along_best = overlap, u, along
    return -1, best, axis, along_best


@njit(cache=True, inline='always')
def _feature(V, n, sign, eps, out):
    """Write to out the corners of V (8, 3) within eps of the largest sign * (n . v);
    returns their number and that extreme, m."""
    top = -np.inf
    for k in range(8):
        top = max(top, sign * (n[0] * V[k, 0] + n[1] * V[k, 1] + n[2] * V[k, 2]))
    m = 0
    for k in range(8):
        if sign * (n[0] * V[k, 0] + n[1] * V[k, 1] + n[2] * V[k, 2]) >= top - eps:
            out[m, :] = V[k]
            m += 1
    return m, sign * top


@njit(cache=True, inline='always')
def _pseudo_angle(x, y):
    """A number in (-2, 2] that orders directions (x, y) as ``atan2(y, x)``
    does (-2 just above -pi, 2 at pi; 0 for (0, 0)), without its cost: the
    "diamond angle" y / (|x| + |y|), unrolled over the four quadrants. The
    faces' corners are put in order by it in every contact evaluation."""
    s = abs(x) + abs(y)
    if s == 0.0:
        return 0.0
    if y >= 0.0:
        return y / s if x >= 0.0 else 2.0 - y / s
    return y / s if x >= 0.0 else -2.0 - y / s


@njit(cache=True, inline='always')
def _plane(F, m, n, e1, e2, out, angle):
    """The m points F in the contact frame, written to out (m, 3): coordinates
    along e1, e2, then the height along n; ordered counter-clockwise around
    their mean (a convex polygon when m >= 3). angle (>= m,) is scratch."""
    cx = cy = 0.0
    for k in range(m):
        out[k, 0] = F[k, 0] * e1[0] + F[k, 1] * e1[1] + F[k, 2] * e1[2]
        out[k, 1] = F[k, 0] * e2[0] + F[k, 1] * e2[1] + F[k, 2] * e2[2]
        out[k, 2] = F[k, 0] * n[0] + F[k, 1] * n[1] + F[k, 2] * n[2]
        cx += out[k, 0] / m
        cy += out[k, 1] / m
    for k in range(m):
        angle[k] = _pseudo_angle(out[k, 0] - cx, out[k, 1] - cy)
    for k in range(1, m):  # insertion sort: m <= 8
        j = k
        while j > 0 and angle[j - 1] > angle[j]:
            angle[j - 1], angle[j] = angle[j], angle[j - 1]
            for q in range(3):
                out[j - 1, q], out[j, q] = out[j, q], out[j - 1, q]
            j -= 1


@njit(cache=True, inline='always')
def _covers(P, m, x, y, tol):
    """Whether the point (x, y) lies in the convex hull of P[:m] (2-d, ordered
    as :func:`_plane` leaves them), to within tol, m."""
    if m == 1:
        dx, dy = x - P[0, 0], y - P[0, 1]
        return dx * dx + dy * dy <= tol * tol
    if m == 2:
        ax, ay = P[0, 0], P[0, 1]
        ux, uy = P[1, 0] - ax, P[1, 1] - ay
        length = math.sqrt(ux * ux + uy * uy)
        if length == 0.0:
            return True
        cross = (ux * (y - ay) - uy * (x - ax)) / length
        along = (ux * (x - ax) + uy * (y - ay)) / length
        return abs(cross) <= tol and -tol <= along <= length + tol
    # outside an edge by more than tol: cross < -tol |edge|, squared, so that
    # no edge needs its length (a face pressed on a face tests 32 edges)
    for k in range(m):
        ax, ay = P[k, 0], P[k, 1]
        ux, uy = P[(k + 1) % m, 0] - ax, P[(k + 1) % m, 1] - ay
        cross = ux * (y - ay) - uy * (x - ax)
        if cross < 0.0 and cross * cross > tol * tol * (ux * ux + uy * uy):
            return False
    return True


@njit(cache=True, inline='always')
def _height(P, m, plane, x, y):
    """Height along the normal (m) of the feature P[:m] (ordered by
    :func:`_plane`) over the point (x, y): its vertex, its face's plane
    ``plane`` (:func:`_affine_height` of P, taken once for all its points),
    or where that is NaN (a face seen edge on) or m == 2 its edge's line
    (nearest point)."""
    if m == 1:
        return P[0, 2]
    if m >= 3 and not math.isnan(plane[0]):
        return plane[0] + plane[1] * x + plane[2] * y
    # an edge (or a face seen edge on): along the line through its first two points
    ux, uy = P[1, 0] - P[0, 0], P[1, 1] - P[0, 1]
    length2 = ux * ux + uy * uy
    t = 0.0 if length2 == 0.0 else min(1.0, max(0.0, ((x - P[0, 0]) * ux + (y - P[0, 1]) * uy) / length2))
    return P[0, 2] + t * (P[1, 2] - P[0, 2])


@njit(cache=True, inline='always')
def _add_point(out, count, x, y, band):
    """Append the point (x, y) to out[:count] and return the new count; its
    part of a point's share in out[count, 2]: 3 u^2 - 2 u^3 (a smoothstep),
    u its distance (the larger of |dx| and |dy|, m) to the nearest point
    there over ``band`` (m), 1 from ``band`` on. A point within COINCIDENT of
    one there, or past out's end, is left out. Two points that part press as
    one at first and as two once ``band`` apart, with no jump between: a
    point left out until ``band`` apart joined with its whole share at once,
    and the integrator shrank its steps onto each such jump (issue 33)."""
    nearest = np.inf
    for k in range(count):
        nearest = min(nearest, max(abs(out[k, 0] - x), abs(out[k, 1] - y)))
    if nearest <= COINCIDENT or count == out.shape[0]:
        return count
    u = min(1.0, nearest / band)
    out[count, 0], out[count, 1], out[count, 2] = x, y, u * u * (3.0 - 2.0 * u)
    return count + 1


@njit(cache=True, inline='always')
def _overlap_corners(A, ma, B, mb, on, band, out):
    """Corners of the intersection of the convex hulls of A[:ma] and B[:mb]
    (2-d, their first two columns), written to out (its first two columns,
    and in its third each one's part of a point's share, by
    :func:`_add_point` over ``band``, m); returns their number: each one's
    points inside the other (or within ``on`` of its outline, m) and their
    edges' crossings. Without any, the one point half way between the two
    hulls' means."""
    count = 0
    for P, mp, Q, mq in ((A, ma, B, mb), (B, mb, A, ma)):
        for k in range(mp):
            if _covers(Q, mq, P[k, 0], P[k, 1], on):
                count = _add_point(out, count, P[k, 0], P[k, 1], band)
    ea = 0 if ma == 1 else (1 if ma == 2 else ma)
    eb = 0 if mb == 1 else (1 if mb == 2 else mb)
    for i in range(ea):
        px, py = A[i, 0], A[i, 1]
        rx, ry = A[(i + 1) % ma, 0] - px, A[(i + 1) % ma, 1] - py
        for j in range(eb):
            qx, qy = B[j, 0], B[j, 1]
            wx, wy = B[(j + 1) % mb, 0] - qx, B[(j + 1) % mb, 1] - qy
            denom = rx * wy - ry * wx
            if abs(denom) <= 1e-12 * math.sqrt((rx * rx + ry * ry) * (wx * wx + wy * wy)):
                continue  # parallel: their overlap is in the corners above
            s = ((qx - px) * wy - (qy - py) * wx) / denom
            u = ((qx - px) * ry - (qy - py) * rx) / denom
            if 0.0 <= s <= 1.0 and 0.0 <= u <= 1.0:
                count = _add_point(out, count, px + s * rx, py + s * ry, band)
    if count == 0:
        out[0, 0] = out[0, 1] = 0.0
        out[0, 2] = 1.0
        for P, mp in ((A, ma), (B, mb)):
            for k in range(mp):
                out[0, 0] += 0.5 * P[k, 0] / mp
                out[0, 1] += 0.5 * P[k, 1] / mp
        count = 1
    return count


#: Share of k_p and c_p of each point of a corner contact: a face pressed flat
#: on another presses at the four corners of their overlap.
FACE_POINTS = 4


@njit(cache=True)
def _clip(P, m, c0, cx, cy, out):
    """The part of the convex polygon P[:m] (2-d, in order) where
    c0 + cx x + cy y >= 0, written to out in the same order; returns its
    vertex count (one step of Sutherland and Hodgman's clipping)."""
    count = 0
    for k in range(m):
        x0, y0 = P[k, 0], P[k, 1]
        x1, y1 = P[(k + 1) % m, 0], P[(k + 1) % m, 1]
        g0 = c0 + cx * x0 + cy * y0
        g1 = c0 + cx * x1 + cy * y1
        if g0 >= 0.0:
            out[count, 0], out[count, 1] = x0, y0
            count += 1
        if (g0 >= 0.0) != (g1 >= 0.0):
            s = g0 / (g0 - g1)
            out[count, 0], out[count, 1] = x0 + s * (x1 - x0), y0 + s * (y1 - y0)
            count += 1
    return count


@njit(cache=True)
def _area(P, m):
    """Signed area of the polygon P[:m] (2-d; > 0 counter-clockwise), m^2."""
    twice = 0.0
    for k in range(m):
        twice += P[k, 0] * P[(k + 1) % m, 1] - P[(k + 1) % m, 0] * P[k, 1]
    return 0.5 * twice


@njit(cache=True, inline='always')
def _affine_height(P):
    """(h0, hx, hy): the plane h = h0 + hx x + hy y through the first three
    points of P (x, y, height); NaNs where they are in line (a face seen
    edge on)."""
    ux, uy, uz = P[1, 0] - P[0, 0], P[1, 1] - P[0, 1], P[1, 2] - P[0, 2]
    vx, vy, vz = P[2, 0] - P[0, 0], P[2, 1] - P[0, 1], P[2, 2] - P[0, 2]
    det = ux * vy - uy * vx
    if abs(det) <= 1e-12 * (ux * ux + uy * uy + vx * vx + vy * vy):
        return np.nan, np.nan, np.nan
    hx = (uz * vy - vz * uy) / det
    hy = (vz * ux - uz * vx) / det
    return P[0, 2] - hx * P[0, 0] - hy * P[0, 1], hx, hy


@njit(cache=True, inline='always')
def _fan_area(P, t):
    """Area of the triangle (0, t, t + 1) of the polygon P (counter-clockwise)."""
    return 0.5 * ((P[t, 0] - P[0, 0]) * (P[t + 1, 1] - P[0, 1])
                  - (P[t + 1, 0] - P[0, 0]) * (P[t, 1] - P[0, 1]))


@njit(cache=True)
def _pressure_points(A, ma, B, mb, e1, e2, n, poly, spare, points, depths, weights):
    """Faces A[:ma] and B[:mb] (ordered by :func:`_plane`, 3 points or more
    each) pressed together by a pressure in proportion to the depth: the
    quadrature points of the part of their overlap where a reaches past b,
    written to points, depths and weights; returns their number, or -1 when
    a face is seen edge on.

    The depth d = h_a - h_b is affine over the plane, so the overlap clipped
    to d >= 0 is a convex polygon (Sutherland and Hodgman: against each edge
    of B, then d >= 0). Each triangle of its fan from corner 0 takes the
    midpoints of its edges, each a third of its area (exact for a quadratic:
    the push, the integral of d, and its moment, of x d); a diagonal's
    midpoint serves both its triangles. A point's weight is its area as a
    share of the smaller face's, so the weights sum to 1 over a face pressed
    whole on one as large. Where the overlap gains or loses a corner, its
    triangle comes or goes with no area, so the push is continuous in the
    pose, where springs at the overlap's corners jump."""
    ha0, hax, hay = _affine_height(A)
    hb0, hbx, hby = _affine_height(B)
    reference = min(abs(_area(A, ma)), abs(_area(B, mb)))
    if not (math.isfinite(ha0) and math.isfinite(hb0)) or reference <= 0.0:
        return -1
    m = ma
    for k in range(ma):
        poly[k, 0], poly[k, 1] = A[k, 0], A[k, 1]
    for k in range(mb):  # the left of each edge of B, counter-clockwise
        ax, ay = B[k, 0], B[k, 1]
        cx, cy = ay - B[(k + 1) % mb, 1], B[(k + 1) % mb, 0] - ax
        m = _clip(poly, m, -(cx * ax + cy * ay), cx, cy, spare)
        poly, spare = spare, poly
        if m < 3:
            return 0
    m = _clip(poly, m, ha0 - hb0, hax - hbx, hay - hby, spare)
    poly = spare
    if m < 3:
        return 0
    count = 0
    # edges (i, j) of the fan: its outline, then the diagonals (0, t)
    for k in range(2 * m - 3):
        if k < m:
            i, j = k, (k + 1) % m
            area = _fan_area(poly, min(max(k, 1), m - 2))
        else:
            i, j = 0, k - m + 2
            area = _fan_area(poly, j - 1) + _fan_area(poly, j)
        x, y = 0.5 * (poly[i, 0] + poly[j, 0]), 0.5 * (poly[i, 1] + poly[j, 1])
        top, bottom = ha0 + hax * x + hay * y, hb0 + hbx * x + hby * y
        if top - bottom <= 0.0 or area <= 0.0:
            continue
        z = 0.5 * (top + bottom)
        for q in range(3):
            points[count, q] = x * e1[q] + y * e2[q] + z * n[q]
        depths[count] = top - bottom
        weights[count] = area / (3.0 * reference)
        count += 1
    return count


@njit(cache=True)
def _facing_face(R, V, n, sign, out):
    """The face of a box (rotation R (3, 3), corners V (8, 3) in the order of
    ``SIGNS``) whose outward normal is nearest sign * n (n a unit 3-tuple):
    its four corners, written to out[:4] in their order in V (out may be V:
    a corner is never written past where it is read), and that outward
    normal (a 3-tuple)."""
    k, best = 0, -1.0
    for axis in range(3):
        along = abs(R[0, axis] * n[0] + R[1, axis] * n[1] + R[2, axis] * n[2])
        if along > best:
            k, best = axis, along
    side = 1.0 if sign * (R[0, k] * n[0] + R[1, k] * n[1] + R[2, k] * n[2]) >= 0.0 else -1.0
    m = 0
    for c in range(8):
        if SIGNS[c, k] == side:
            out[m, :] = V[c]
            m += 1
    return side * R[0, k], side * R[1, k], side * R[2, k]


@njit(cache=True)
def _face_pressure(Va, Ra, Vb, Rb, n, work):
    """Two boxes pressed together (see :func:`contact`, ``pressure``): the
    face of each box that faces the other along n, whole,
    and as the normal the bisector of their outward normals, not n. So the
    push does not jump where the least-overlap axis passes from one face's
    normal to the other's (near-parallel faces, 10 x 10 at 0.03-0.06 s: the
    push turned by 4-25 mrad at once) or to an edge product that equals
    them, nor where a tilted face's corners leave the FEATURE band (a face of
    3 corners in place of 4 pressed with twice the push; an edge pushed at
    its corners, about 20x the pressure's push there). Returns (count, normal) as
    :func:`contact`; count -1 when a face is seen edge on. The faces' corners
    replace Va and Vb (8, 3), the boxes' corners."""
    _, _, _, _, A, B, angle, _, poly, spare, points, depths, weights = work
    ua = _facing_face(Ra, Va, n, 1.0, Va)
    ub = _facing_face(Rb, Vb, n, -1.0, Vb)
    m0, m1, m2 = ua[0] - ub[0], ua[1] - ub[1], ua[2] - ub[2]
    norm = math.sqrt(m0 * m0 + m1 * m1 + m2 * m2)
    normal = (m0 / norm, m1 / norm, m2 / norm)
    e1, e2 = plane_axes(normal)
    _plane(Va, 4, normal, e1, e2, A, angle)
    _plane(Vb, 4, normal, e1, e2, B, angle)
    return _pressure_points(A, 4, B, 4, e1, e2, normal, poly, spare, points, depths, weights), normal


@njit(cache=True, inline='always')
def plane_axes(n):
    """Unit vectors (e1, e2) (3-tuples) that make (e1, e2, n) a right-handed
    frame for the unit normal n (3-tuple): e1 from the frame axis least
    aligned with n."""
    k = 0 if abs(n[0]) <= min(abs(n[1]), abs(n[2])) else (1 if abs(n[1]) <= abs(n[2]) else 2)
    t = (1.0 - n[k] * n[0] if k == 0 else -n[k] * n[0],
         1.0 - n[k] * n[1] if k == 1 else -n[k] * n[1],
         1.0 - n[k] * n[2] if k == 2 else -n[k] * n[2])
    norm = math.sqrt(t[0] * t[0] + t[1] * t[1] + t[2] * t[2])
    e1 = (t[0] / norm, t[1] / norm, t[2] / norm)
    return e1, (n[1] * e1[2] - n[2] * e1[1], n[2] * e1[0] - n[0] * e1[2], n[0] * e1[1] - n[1] * e1[0])


#: Most contact points of one pair: 8 corners inside plus 8 edge crossings;
#: 2 m - 3 edges of the fan of a pressed overlap of m <= 9 corners.
MAX_POINTS = 16


@njit(cache=True)
def scratch():
    """The work space :func:`contact` takes, allocated once by its caller;
    the contact points, their depths and their weights are left in its last
    three arrays."""
    return (np.empty((8, 3)), np.empty((8, 3)), np.empty((8, 3)), np.empty((8, 3)),
            np.empty((8, 3)), np.empty((8, 3)), np.empty(8), np.empty((MAX_POINTS, 3)),
            np.empty((MAX_POINTS, 2)), np.empty((MAX_POINTS, 2)),
            np.empty((MAX_POINTS, 3)), np.empty(MAX_POINTS), np.empty(MAX_POINTS))


@njit(cache=True)
def contact(Ra, ca, ha, Rb, cb, hb, work, pressure=False):
    """Where and how deep boxes a and b (given as in :func:`separation`) interfere.

    The separating-axis test gives the normal n (from a towards b) of least
    overlap; each box's support feature along it (a's corners furthest
    towards b, b's furthest towards a, see ``FEATURE``: a corner, an edge or
    a face) is projected on the plane normal to n, and the corners of their
    overlap are the contact points: for faces pressed flat the corners of
    the overlap, for crossing edges the crossing, for a corner the corner.
    A point's depth is how far a's feature reaches past b's there, along n,
    so a tilted face presses deeper at one edge; the point itself is half
    way between the two.

    Each point has a weight, its share of the pair's stiffness and damping:
    1 / FACE_POINTS at a corner, less within the FEATURE band of a point
    found before (:func:`_add_point`). With ``pressure`` the two boxes' faces that
    face each other push instead, whole, whatever the features, by a
    pressure in proportion to the depth over their overlap, along the
    bisector of their normals (:func:`_face_pressure`, which returns that
    normal in place of n), at the quadrature points of
    :func:`_pressure_points`, each weighted by its share of the smaller
    face's area: a face tilted past the band, whose feature is an edge,
    presses on with its whole face, and so do two faces whose edges cross,
    so the push is continuous where the features turn from faces to edges
    or the least-overlap axis passes between the faces' normals and their
    edges' products. It still changes at once where a box's facing face
    does (n half way between two of its faces' normals: a corner or edge
    struck at 45 degrees, an impact), and the corners push where a face is
    seen edge on.

    Returns ``(count, normal)``: the number of points that interfere (0 when
    the separating-axis test finds the boxes apart) and n (a 3-tuple). The
    points (m), their depths (m, > 0) and weights are ``work[-3][:count]``,
    ``work[-2][:count]`` and ``work[-1][:count]``; ``work`` is :func:`scratch`.
    """
    depth, axis, along = least_overlap(Ra, ca, ha, Rb, cb, hb, 0.0)
    if depth <= 0.0:
        return 0, (0.0, 0.0, 0.0)
    return interference(Ra, ca, ha, Rb, cb, hb, axis, along, work, pressure)


@njit(cache=True, inline='always')
def interference(Ra, ca, ha, Rb, cb, hb, axis, along, work, pressure):
    """:func:`contact` of boxes that interfere, given their axis of least
    overlap (a unit 3-tuple) and the centre offset along it, m (both as
    :func:`least_overlap` returns them, or :func:`separating_axis` where it
    finds no separating axis)."""
    s = 1.0 if along >= 0.0 else -1.0
    n = (s * axis[0], s * axis[1], s * axis[2])
    eps = FEATURE * min(min(ha[0], ha[1], ha[2]), min(hb[0], hb[1], hb[2]))
    Va, Vb, Fa, Fb, A, B, angle, corners2, poly, spare, points, depths, weights = work
    if pressure:
        count, normal = _face_pressure(corners_into(Ra, ca, ha, Va), Ra, corners_into(Rb, cb, hb, Vb), Rb,
                                       n, work)
        if count >= 0:
            return count, normal
    ma, _ = _feature(corners_into(Ra, ca, ha, Va), n, 1.0, eps, Fa)
    mb, _ = _feature(corners_into(Rb, cb, hb, Vb), n, -1.0, eps, Fb)
    e1, e2 = plane_axes(n)
    _plane(Fa, ma, n, e1, e2, A, angle)
    _plane(Fb, mb, n, e1, e2, B, angle)
    found = _overlap_corners(A, ma, B, mb, COINCIDENT, eps, corners2)
    plane_a = _affine_height(A) if ma >= 3 else (np.nan, np.nan, np.nan)
    plane_b = _affine_height(B) if mb >= 3 else (np.nan, np.nan, np.nan)
    count = 0
    for q in range(found):
        x, y = corners2[q, 0], corners2[q, 1]
        top, bottom = _height(A, ma, plane_a, x, y), _height(B, mb, plane_b, x, y)
        if top - bottom <= 0.0:
            continue
        z = 0.5 * (top + bottom)
        for m in range(3):
            points[count, m] = x * e1[m] + y * e2[m] + z * n[m]
        depths[count] = top - bottom
        weights[count] = corners2[q, 2] / FACE_POINTS
        count += 1
    return count, n
