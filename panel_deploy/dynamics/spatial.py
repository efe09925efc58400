"""Small-vector and spatial-inertia helpers of the compiled dynamics kernels.

3-vectors travel as tuples, which numba keeps in registers: an array
temporary costs a heap allocation, which dominated the kernels' run time.
Spatial vectors are in the ground frame about its origin, angular part first
(:mod:`.kernels`). Callers import the module (``from . import spatial as
sp``): its short names (``sp.add``, ``sp.get``) would shadow locals.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ._jit import FLOAT_MATH

#: The zero 3-vector, for wrenches without a torque or a force.
ZERO3 = (0.0, 0.0, 0.0)


@njit(cache=True, **FLOAT_MATH)
def dot(a, b):
    """a . b for 1-d arrays or tuples of equal length."""
    s = 0.0
    for i in range(len(a)):
        s += a[i] * b[i]
    return s


@njit(cache=True, **FLOAT_MATH)
def mv(A, x):
    """A @ x for small arrays without a BLAS call (whose overhead dominates here)."""
    out = np.zeros(A.shape[0])
    for i in range(A.shape[0]):
        s = 0.0
        for j in range(A.shape[1]):
            s += A[i, j] * x[j]
        out[i] = s
    return out


@njit(cache=True, **FLOAT_MATH)
def matmul(A, B):
    """A @ B for small arrays, each entry summed in index order."""
    out = np.zeros((A.shape[0], B.shape[1]))
    for i in range(A.shape[0]):
        for k in range(A.shape[1]):
            a = A[i, k]
            for j in range(B.shape[1]):
                out[i, j] += a * B[k, j]
    return out


@njit(cache=True, **FLOAT_MATH)
def get(A, i, o=0):
    """``A[i, o:o + 3]`` as a tuple."""
    return (A[i, o], A[i, o + 1], A[i, o + 2])


@njit(cache=True, **FLOAT_MATH)
def put(A, i, v, o=0):
    """``A[i, o:o + 3] = v``."""
    A[i, o] = v[0]
    A[i, o + 1] = v[1]
    A[i, o + 2] = v[2]


@njit(cache=True, **FLOAT_MATH)
def add(a, b):
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2])


@njit(cache=True, **FLOAT_MATH)
def sub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


@njit(cache=True, **FLOAT_MATH)
def scale(a, s):
    return (a[0] * s, a[1] * s, a[2] * s)


@njit(cache=True, **FLOAT_MATH)
def cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


@njit(cache=True, **FLOAT_MATH)
def rotate(R, b, x):
    """``R[b] @ x`` for orientations R (k, 3, 3) and a 3-vector x."""
    return (R[b, 0, 0] * x[0] + R[b, 0, 1] * x[1] + R[b, 0, 2] * x[2],
            R[b, 1, 0] * x[0] + R[b, 1, 1] * x[1] + R[b, 1, 2] * x[2],
            R[b, 2, 0] * x[0] + R[b, 2, 1] * x[1] + R[b, 2, 2] * x[2])


@njit(cache=True, **FLOAT_MATH)
def rotation(axis, angle):
    """Rows of the rotation by ``angle`` (rad) about the unit ``axis`` (Rodrigues)."""
    x, y, z = axis[0], axis[1], axis[2]
    c, s = math.cos(angle), math.sin(angle)
    C = 1.0 - c
    return ((c + x * x * C, x * y * C - z * s, x * z * C + y * s),
            (y * x * C + z * s, c + y * y * C, y * z * C - x * s),
            (z * x * C - y * s, z * y * C + x * s, c + z * z * C))


@njit(cache=True, inline="always", **FLOAT_MATH)
def carried(P, R, p, b, x):
    """Current position (m) of body b's material point that sits at x in the flat state."""
    return add(get(p, b), rotate(R, b, sub(x, get(P.r0, b))))


@njit(cache=True, **FLOAT_MATH)
def point_velocity(w, vo, b, x):
    """Velocity (m/s) of body b's material point at x."""
    return add(get(vo, b), cross(get(w, b), x))


# --- spatial inertia ---
# About the ground origin a body of mass m, centroid c, is [[J, [h]x],
# [-[h]x, m 1]] with J = R I R^T - m [c]x^2 and h = m c; a composite body is
# the sum, so (J, h, m) describe both without 6 x 6 matrices.

@njit(cache=True, inline="always", **FLOAT_MATH)
def angular_inertia(P, R, p, i, out):
    """Write J of body i (kg m^2, see above) to out[i] (k, 3, 3)."""
    m = P.mass[i]
    c = get(p, i)
    # diagonal of [c]x^2 (off it, c_r c_q)
    d = (-c[2] * c[2] - c[1] * c[1], -c[2] * c[2] - c[0] * c[0], -c[1] * c[1] - c[0] * c[0])
    I = P.inertia[i]
    for r in range(3):
        t0 = R[i, r, 0] * I[0, 0] + R[i, r, 1] * I[1, 0] + R[i, r, 2] * I[2, 0]
        t1 = R[i, r, 0] * I[0, 1] + R[i, r, 1] * I[1, 1] + R[i, r, 2] * I[2, 1]
        t2 = R[i, r, 0] * I[0, 2] + R[i, r, 1] * I[1, 2] + R[i, r, 2] * I[2, 2]
        for q in range(3):
            cc = d[r] if r == q else c[r] * c[q]
            out[i, r, q] = (t0 * R[i, q, 0] + t1 * R[i, q, 1] + t2 * R[i, q, 2]) - m * cc


@njit(cache=True, **FLOAT_MATH)
def inertia_times(J, i, h, m, xw, xv):
    """Spatial inertia (J[i], h, m) times the spatial vector (xw, xv): (angular, linear)."""
    h0, h1, h2 = h[0], h[1], h[2]
    fw = (J[i, 0, 0] * xw[0] + J[i, 0, 1] * xw[1] + J[i, 0, 2] * xw[2] - h2 * xv[1] + h1 * xv[2],
          J[i, 1, 0] * xw[0] + J[i, 1, 1] * xw[1] + J[i, 1, 2] * xw[2] + h2 * xv[0] - h0 * xv[2],
          J[i, 2, 0] * xw[0] + J[i, 2, 1] * xw[1] + J[i, 2, 2] * xw[2] - h1 * xv[0] + h0 * xv[1])
    fv = (h2 * xw[1] - h1 * xw[2] + m * xv[0],
          -h2 * xw[0] + h0 * xw[2] + m * xv[1],
          h1 * xw[0] - h0 * xw[1] + m * xv[2])
    return fw, fv


@njit(cache=True, **FLOAT_MATH)
def dot6(A, i, fw, fv):
    """``A[i, :6] . (fw, fv)``, summed in index order."""
    return (A[i, 0] * fw[0] + A[i, 1] * fw[1] + A[i, 2] * fw[2]
            + A[i, 3] * fv[0] + A[i, 4] * fv[1] + A[i, 5] * fv[2])


@njit(cache=True, inline="always", **FLOAT_MATH)
def point_jacobian(P, S, b, x, out, row, sign):
    """Add ``sign`` times d(velocity of body b's material point at x)/d omega
    to out[row:row + 3] (k, n)."""
    while b < P.n:
        v = add(get(S, b, 3), cross(get(S, b), x))
        for k in range(3):
            out[row + k, b] += sign * v[k]
        b = P.parent[b]


@njit(cache=True, inline="always", **FLOAT_MATH)
def angular_jacobian(P, S, b, out, row, sign):
    """Add ``sign`` times d(angular velocity of body b)/d omega to out[row:row + 3] (k, n)."""
    while b < P.n:
        for k in range(3):
            out[row + k, b] += sign * S[b, k]
        b = P.parent[b]


@njit(cache=True, **FLOAT_MATH)
def point_bias_acceleration(acc, w, vo, b, x):
    """Acceleration of body b's material point at x when qdd = 0 (velocity products only)."""
    wb = get(w, b)
    return add(add(get(acc, b, 3), cross(get(acc, b), x)),
                cross(wb, add(get(vo, b), cross(wb, x))))


@njit(cache=True, **FLOAT_MATH)
def add_wrench(F, body, torque, force, point):
    """Add a force applied at ``point`` plus a torque to body's wrench about the origin."""
    t = add(torque, cross(point, force))
    for k in range(3):
        F[body, k] += t[k]
        F[body, 3 + k] += force[k]
