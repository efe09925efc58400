"""Air drag on the panel faces, in the compiled dynamics.

A point of a body's mid-plane at (s, r) from the centroid along the body's x
and y axes moves along the face normal n at u = v0 + a s + b r: v0 = n . v_c,
a = -w . e_y, b = w . e_x. The pressure -q |u| u (q = 1/2 rho C_d) acts once
per point: the two large faces meet the air on opposite sides, so their net
is one face area with the signed u. It is -q u^2 where u > 0 and q u^2 where
u < 0, a polynomial on each side of the line u = 0. Split along a diagonal,
the face is two triangles, and the line cuts each into a triangle and a
quadrilateral (the triangle less a corner): integrated exactly (to
round-off) on those, there is no quadrature error at the kink and no
division by a or b (a closed form in corner values of |u|^3 u / (a b)
cancels catastrophically as a, b -> 0).
"""

from __future__ import annotations

from numba import njit

from . import spatial as sp
from ._jit import FLOAT_MATH


#: A triangle rule of degree 3 (exact for the cubic integrands u^2 s, u^2 r):
#: weights of each vertex, each edge midpoint and the centroid, times the area.
_W_VERTEX, _W_MID, _W_CENTRE = 1.0 / 20.0, 2.0 / 15.0, 9.0 / 20.0


@njit(cache=True, **FLOAT_MATH)
def _u2_moments(v0, a, b, s, r):
    """u^2, s u^2 and r u^2 at the face point (s, r)."""
    u = v0 + a * s + b * r
    u2 = u * u
    return (u2, s * u2, r * u2)


@njit(cache=True, **FLOAT_MATH)
def _triangle_u2(v0, a, b, p, q, t):
    """Integrals of u^2, s u^2, r u^2 over the triangle p, q, t ((s, r) pairs, m)."""
    area = 0.5 * abs((q[0] - p[0]) * (t[1] - p[1]) - (t[0] - p[0]) * (q[1] - p[1]))
    corners = sp.add(sp.add(_u2_moments(v0, a, b, p[0], p[1]), _u2_moments(v0, a, b, q[0], q[1])),
                   _u2_moments(v0, a, b, t[0], t[1]))
    mids = sp.add(sp.add(_u2_moments(v0, a, b, 0.5 * (p[0] + q[0]), 0.5 * (p[1] + q[1])),
                     _u2_moments(v0, a, b, 0.5 * (q[0] + t[0]), 0.5 * (q[1] + t[1]))),
                _u2_moments(v0, a, b, 0.5 * (t[0] + p[0]), 0.5 * (t[1] + p[1])))
    centre = _u2_moments(v0, a, b, (p[0] + q[0] + t[0]) / 3.0, (p[1] + q[1] + t[1]) / 3.0)
    return sp.scale(sp.add(sp.add(sp.scale(corners, _W_VERTEX), sp.scale(mids, _W_MID)),
                       sp.scale(centre, _W_CENTRE)), area)


@njit(cache=True, **FLOAT_MATH)
def _u(v0, a, b, x):
    return v0 + a * x[0] + b * x[1]


@njit(cache=True, **FLOAT_MATH)
def _towards(x, y, f):
    """The point a fraction f of the way from x to y."""
    return (x[0] + f * (y[0] - x[0]), x[1] + f * (y[1] - x[1]))


@njit(cache=True, **FLOAT_MATH)
def _positive_part(v0, a, b, x, y, z):
    """Integrals of u^2, s u^2, r u^2 over the part of triangle x, y, z where u >= 0."""
    ux, uy, uz = _u(v0, a, b, x), _u(v0, a, b, y), _u(v0, a, b, z)
    count = (ux >= 0.0) + (uy >= 0.0) + (uz >= 0.0)
    if count == 0:
        return sp.ZERO3
    whole = _triangle_u2(v0, a, b, x, y, z)
    if count == 3:
        return whole
    # the vertex alone on its side of u = 0 first
    if (ux >= 0.0) != (uy >= 0.0) and (ux >= 0.0) != (uz >= 0.0):
        p, q, t, up, uq, ut = x, y, z, ux, uy, uz
    elif (uy >= 0.0) != (ux >= 0.0):  # then x is on z's side
        p, q, t, up, uq, ut = y, z, x, uy, uz, ux
    else:
        p, q, t, up, uq, ut = z, x, y, uz, ux, uy
    corner = _triangle_u2(v0, a, b, p, _towards(p, q, up / (up - uq)),
                          _towards(p, t, up / (up - ut)))
    return corner if count == 1 else sp.sub(whole, corner)


@njit(cache=True, **FLOAT_MATH)
def face_drag(v0, a, b, half_length, half_width):
    """Integrals of |u| u, s |u| u and r |u| u over the face, u = v0 + a s + b r.

    The face is s in [-half_length, half_length], r in [-half_width,
    half_width] (m); v0 in m/s, a and b in 1/s. Exact to round-off (see
    above). Returns (m^4/s^2, m^5/s^2, m^5/s^2).
    """
    A, B = half_length, half_width
    area = 4.0 * A * B
    # u^2 over the whole face; its terms odd in s or r vanish
    whole = (area * (v0 * v0 + (a * a * A * A + b * b * B * B) / 3.0),
             area * 2.0 * v0 * a * A * A / 3.0,
             area * 2.0 * v0 * b * B * B / 3.0)
    reach = abs(a) * A + abs(b) * B
    if v0 >= reach:
        return whole
    if v0 <= -reach:
        return sp.scale(whole, -1.0)
    c0, c1, c2, c3 = (-A, -B), (A, -B), (A, B), (-A, B)
    positive = sp.add(_positive_part(v0, a, b, c0, c1, c2), _positive_part(v0, a, b, c0, c2, c3))
    # |u| u is u^2 where u > 0 and -u^2 elsewhere
    return sp.sub(sp.scale(positive, 2.0), whole)


@njit(cache=True, **FLOAT_MATH)
def body_drag(air, R, i, v, w):
    """Air drag on body i with centroid velocity v (m/s) and angular velocity
    w (rad/s), ground frame: force (N), torque about the centroid (N m) and
    the power it dissipates (W, >= 0: ``q * integral |u|^3``).

    ``air`` is ``Packed.air`` and R the orientations (n + 1, 3, 3). A
    quasi-steady pressure ``-q |u| u`` (q = ``air[i, 2]``) on the large faces
    only: the edges (thickness t), any shielding between stacked or nearby
    panels and the added mass of the air are left out, and the air is still.
    """
    e1 = (R[i, 0, 0], R[i, 1, 0], R[i, 2, 0])
    e2 = (R[i, 0, 1], R[i, 1, 1], R[i, 2, 1])
    n = (R[i, 0, 2], R[i, 1, 2], R[i, 2, 2])
    v0 = sp.dot(n, v)
    a = -sp.dot(w, e2)
    b = sp.dot(w, e1)
    I0, Is, Ir = face_drag(v0, a, b, air[i, 0], air[i, 1])
    q = air[i, 2]
    # (s e1 + r e2) x n = r e1 - s e2, times the pressure -q |u| u
    torque = sp.scale(sp.sub(sp.scale(e2, Is), sp.scale(e1, Ir)), q)
    return sp.scale(n, -q * I0), torque, q * (v0 * I0 + a * Is + b * Ir)


@njit(cache=True, inline="always", **FLOAT_MATH)
def air_drag(P, R, p, w, vo, f):
    """Subtract the air drag wrench of every body from its row of f (n + 1, 6),
    the bias wrenches about the ground origin; returns the power dissipated, W
    (0 where ``P.air`` has no rows: no air).
    """
    air = P.air
    if air.shape[0] == 0:
        return 0.0
    power = 0.0
    for i in range(P.n):
        pi, wi = sp.get(p, i), sp.get(w, i)
        force, torque, pw = body_drag(air, R, i, sp.add(sp.get(vo, i), sp.cross(wi, pi)), wi)
        sp.put(f, i, sp.sub(sp.get(f, i), sp.add(torque, sp.cross(pi, force))))
        sp.put(f, i, sp.sub(sp.get(f, i, 3), force), 3)
        power += pw
    return power
