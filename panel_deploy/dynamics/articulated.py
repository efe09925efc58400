"""Mass-matrix operations in O(n) on the kinematic tree: Featherstone's
articulated-body algorithm (ABA; "Rigid Body Dynamics Algorithms", ch. 7)
as a factorisation of ``H = M + diag(armature)`` reused for many right-hand
sides, and the product ``M x`` by one pass down and one up the tree.

All spatial quantities are in the ground frame about its origin, angular part
first, as in :mod:`.kernels`: the articulated inertias of a child and its
parent then add without coordinate transforms. ``S`` (n, 6) are the joint
screws of :func:`kernels.kinematics`; :func:`factor` takes the bodies'
angular inertias and first moments of :func:`kernels.body_inertias`,
:func:`times` their spatial inertias ``I6`` (n, 6, 6, :func:`inertias`),
kg m^2, kg m, kg.

The dense path (CRBA, Cholesky, LU of n x n matrices) costs O(n^3) per step;
these are O(n) per solve. Below :data:`MIN_N` coordinates the dense path is
as fast or faster (fixed costs of the 6 x 6 algebra against n^3 / 6 flops),
so :func:`applies` keeps it there.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ._jit import FLOAT_MATH

#: Coordinates from which the O(n) path is taken. Measured, stiff Jacobian plus
#: one ROS34PW2 step (3 rhs calls), compiled loops: 16 us dense against 20 us
#: O(n) on the paper scene (11 coordinates), 40 against 33 us on the 5 x 6
#: packing (26), 480 against 84 us on 10 x 10 (85).
MIN_N = 20


@njit(cache=True, **FLOAT_MATH)
def applies(n):
    """Whether the rhs and the W-solves of a model of n coordinates
    (``Packed.n``) take the O(n) path: at least MIN_N. (A scalar, not the
    Packed tuple: passing that to a function costs a reference count per array.)"""
    return n >= MIN_N


@njit(cache=True, inline="always", **FLOAT_MATH)
def inertias(P, Jb, hb):
    """Spatial inertias ``[[J, [h]x], [-[h]x, m 1]]`` (n, 6, 6) about the ground
    origin from the angular inertias J (n, 3, 3, kg m^2) and first moments
    h = m c (n, 3, kg m) of :func:`kernels.body_inertias`."""
    n = P.n
    out = np.zeros((n, 6, 6))
    for i in range(n):
        h0, h1, h2 = hb[i, 0], hb[i, 1], hb[i, 2]
        m = P.mass[i]
        for r in range(3):
            for c in range(3):
                out[i, r, c] = Jb[i, r, c]
            out[i, 3 + r, 3 + r] = m
        # [h]x in the upper right, its transpose -[h]x in the lower left
        out[i, 0, 4] = -h2
        out[i, 0, 5] = h1
        out[i, 1, 3] = h2
        out[i, 1, 5] = -h0
        out[i, 2, 3] = -h1
        out[i, 2, 4] = h0
        for r in range(3):
            for c in range(3):
                out[i, 3 + r, c] = out[i, c, 3 + r]
    return out


#: Index of entry (r, c) of a symmetric 6 x 6 matrix in its upper triangle
#: packed row by row (21 entries, the order of ``np.triu_indices``): the
#: articulated inertias of :func:`factor`.
PACKED = np.zeros((6, 6), dtype=np.int64)
PACKED[np.triu_indices(6)] = np.arange(21)
PACKED.T[np.triu_indices(6)] = np.arange(21)


@njit(cache=True, inline="always", **FLOAT_MATH)
def factor(P, S, Jb, hb, armature):
    """:func:`factor_into` new arrays: ``(U, D, ok)``."""
    n = P.n
    U, D = np.empty((n, 6)), np.empty(n)
    return U, D, factor_into(P, S, Jb, hb, armature, np.empty((n, 21)), U, D)


@njit(cache=True, inline="always", **FLOAT_MATH)
def factor_into(P, S, Jb, hb, armature, IA, U, D):
    """Factor ``H = M + diag(armature)`` (armature (n,), kg m^2) by the
    articulated-body inertias, leaves first, from the bodies' angular
    inertias Jb (n, 3, 3, kg m^2) and first moments hb (n, 3, kg m) of
    :func:`kernels.body_inertias`.

    Writes ``U[i] = I^A_i S_i`` to U (n, 6) and ``D[i] = S_i . U[i] +
    armature[i]`` to D (n,), the articulated inertias to IA (n, 21, scratch);
    returns ok, False if some D is not positive (H not positive definite), as
    the Cholesky of the dense path fails.

    The articulated inertias are symmetric, so each is kept as its upper
    triangle (``PACKED``), built straight from (Jb, hb, mass): 21 updates a
    body in place of 36 and no (n, 6, 6) spatial inertias
    (:func:`inertias`) to fill and copy first (10 x 10: 2.4 us against 4.3).
    """
    n = P.n
    for i in range(n):
        h0, h1, h2 = hb[i, 0], hb[i, 1], hb[i, 2]
        m = P.mass[i]
        # the rows of [[J, [h]x], [-[h]x, m 1]] from the diagonal on
        IA[i, 0], IA[i, 1], IA[i, 2] = Jb[i, 0, 0], Jb[i, 0, 1], Jb[i, 0, 2]
        IA[i, 3], IA[i, 4], IA[i, 5] = 0.0, -h2, h1
        IA[i, 6], IA[i, 7] = Jb[i, 1, 1], Jb[i, 1, 2]
        IA[i, 8], IA[i, 9], IA[i, 10] = h2, 0.0, -h0
        IA[i, 11] = Jb[i, 2, 2]
        IA[i, 12], IA[i, 13], IA[i, 14] = -h1, h0, 0.0
        IA[i, 15], IA[i, 16], IA[i, 17] = m, 0.0, 0.0
        IA[i, 18], IA[i, 19] = m, 0.0
        IA[i, 20] = m
    for i in range(n - 1, -1, -1):
        d = armature[i]
        for r in range(6):
            s = 0.0
            for c in range(6):
                s += IA[i, PACKED[r, c]] * S[i, c]
            U[i, r] = s
            d += S[i, r] * s
        if not d > 0.0:
            return False
        D[i] = d
        a = P.parent[i]
        if a < n:
            inv = 1.0 / d
            k = 0
            for r in range(6):
                ur = U[i, r] * inv
                for c in range(r, 6):
                    IA[a, k] += IA[i, k] - ur * U[i, c]
                    k += 1
    return True


@njit(cache=True, inline="always", **FLOAT_MATH)
def solve(P, S, U, D, tau, out, work):
    """Write ``H^-1 tau`` to out (n,) from :func:`factor`'s (U, D); work is
    (n + 1, 6) scratch. tau (n,) is not changed and may not be out."""
    n = P.n
    solve_rows(P, S, U, D, tau.reshape((1, n)), out.reshape((1, n)), work.reshape((1, n + 1, 6)))


@njit(cache=True, inline="always", **FLOAT_MATH)
def solve_rows(P, S, U, D, T, out, work):
    """Write ``(H^-1 T^T)^T`` to out (m, n): :func:`solve` of each row of T
    (m, n) in one pass over the tree, each row's arithmetic as solve's
    (the W-solve's contact rows, :mod:`.rosenbrock`: half the time of m passes).
    work is (m, n + 1, 6) scratch; T is not changed and may not be out."""
    up_rows(P, S, U, D, T, out, work)
    down_rows(P, S, U, D, out, work)


@njit(cache=True, inline="always", **FLOAT_MATH)
def up_rows(P, S, U, D, T, out, work):
    """The pass up the tree of :func:`solve_rows`: write to out (m, n) the
    innovations ``e = L^-1 t`` of each row t of T (m, n), where ``H = L
    diag(D) L^T`` is the factorisation the articulated-body recursion makes
    (Rodriguez, Jain & Kreutz-Delgado's innovations factorisation). So
    ``a . H^-1 b = sum_i e_a[i] e_b[i] / D[i]`` for any two rows a, b: the
    quadratic forms of H^-1 need no pass down. work is (m, n + 1, 6)
    scratch; T is not changed and may not be out."""
    n = P.n
    m = T.shape[0]
    work[:] = 0.0
    # out holds u_i, work the articulated bias forces passed to the parent
    for i in range(n - 1, -1, -1):
        a = P.parent[i]
        inv = 1.0 / D[i]  # one division a body, not a row (10 x 10's closure: 6 rows)
        for r in range(m):
            u = T[r, i]
            for k in range(6):
                u -= S[i, k] * work[r, i, k]
            out[r, i] = u
            if a < n:
                c = u * inv
                for k in range(6):
                    work[r, a, k] += work[r, i, k] + U[i, k] * c


@njit(cache=True, inline="always", **FLOAT_MATH)
def down_rows(P, S, U, D, out, work):
    """The pass down the tree of :func:`solve_rows`: overwrite the innovations
    in out (m, n) (:func:`up_rows`) with ``H^-1 t`` of their rows t.
    work is (m, n + 1, 6) scratch."""
    n = P.n
    m = out.shape[0]
    # joint and body accelerations (the ground's row n stays 0)
    work[:] = 0.0
    for i in range(n):
        a = P.parent[i]
        for r in range(m):
            x = out[r, i]
            for k in range(6):
                x -= U[i, k] * work[r, a, k]
            x /= D[i]
            out[r, i] = x
            for k in range(6):
                work[r, i, k] = work[r, a, k] + S[i, k] * x


@njit(cache=True, inline="always", **FLOAT_MATH)
def times(P, S, I6, x, out, work):
    """Write ``M x`` to out (n,): body accelerations ``a_i = a_parent + S_i
    x_i`` down the tree, their inertia forces summed up it and projected on the
    joint screws. work is (2, n + 1, 6) scratch; x (n,) may not be out."""
    n = P.n
    a = work[0]
    f = work[1]
    a[n, :] = 0.0
    f[:] = 0.0
    for i in range(n):
        b = P.parent[i]
        for k in range(6):
            a[i, k] = a[b, k] + S[i, k] * x[i]
    for i in range(n - 1, -1, -1):
        s = 0.0
        for r in range(6):
            v = f[i, r]
            for c in range(6):
                v += I6[i, r, c] * a[i, c]
            f[i, r] = v
            s += S[i, r] * v
        out[i] = s
        b = P.parent[i]
        if b < n:
            for r in range(6):
                f[b, r] += f[i, r]
