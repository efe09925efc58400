"""The cut hinges that close the array's loops, in the compiled dynamics.

Each cut hinge joins bodies a and b outside the tree. Its angle and ends
(:func:`cut_angle`, :func:`cut_ends`), its own spring, damper and stops, and
for the penalty closure the springs that hold its two ends together
(:func:`cut_forces`); for the exact closure the constraint rows
``J qdd = gamma`` (five per cut hinge, :func:`closure_jacobian`) and the
multipliers that enforce them, on the articulated (O(n)) or the dense path.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from . import articulated
from . import spatial as sp
from ._jit import FLOAT_MATH
from .hinges import hinge_law
from .pack import PENALTY


@njit(cache=True, inline="always", **FLOAT_MATH)
def cut_angle(P, j, R):
    """Cut-hinge angle (rad, continuous on (-pi/2, 3pi/2]) and its exact rate axis g (3-tuple).

    theta = atan2(e2 . f, e1 . f) with f = R_b e1 and e1, e2 carried by body a;
    d theta / dt = g . (w_b - w_a) for any relative orientation (not only a pure
    rotation about the axis), so torque and energy stay consistent.
    """
    a, b = P.cut_a[j], P.cut_b[j]
    f = sp.rotate(R, b, sp.get(P.cut_e1, j))
    e1 = sp.rotate(R, a, sp.get(P.cut_e1, j))
    e2 = sp.rotate(R, a, sp.get(P.cut_e2, j))
    x = sp.dot(e1, f)
    y = sp.dot(e2, f)
    theta = math.atan2(y, x)
    if theta < -0.5 * math.pi:
        theta += 2.0 * math.pi
    d = x * x + y * y
    g = sp.cross(f, sp.sub(sp.scale(e2, x), sp.scale(e1, y)))
    return theta, (g[0] / d, g[1] / d, g[2] / d)


@njit(cache=True, inline="always", **FLOAT_MATH)
def cut_ends(P, j, R, p):
    """Ends (M_a, N_a, M_b, N_b) of cut hinge j as carried by its bodies a and b, m."""
    M = sp.get(P.cut_point, j)
    N = sp.add(M, sp.scale(sp.get(P.cut_axis, j), P.cut_length[j]))
    a, b = P.cut_a[j], P.cut_b[j]
    return (sp.carried(P, R, p, a, M), sp.carried(P, R, p, a, N),
            sp.carried(P, R, p, b, M), sp.carried(P, R, p, b, N))


@njit(cache=True, **FLOAT_MATH)
def largest_gap(P, R, p):
    """Largest loop-closure gap |M_b - M_a| or |N_b - N_a| over the cut hinges, m."""
    out = 0.0
    for j in range(P.cut_a.shape[0]):
        Ma, Na, Mb, Nb = cut_ends(P, j, R, p)
        dM, dN = sp.sub(Mb, Ma), sp.sub(Nb, Na)
        out = max(out, math.sqrt(sp.dot(dM, dM)), math.sqrt(sp.dot(dN, dN)))
    return out


@njit(cache=True, inline="always", **FLOAT_MATH)
def cut_forces(P, R, p, w, vo, F):
    """Wrenches of the cut hinges on their bodies into F (n + 1, 6, overwritten),
    with energy and damper power.

    The cut hinge's own spring, damper and contact (Eq. 2-4 about its axis) for
    every closure method; for PENALTY also the five springs and dampers of
    Eq. (5): M-M' along x_M, y_M, z_M and N-N' along the two directions normal
    to the axis (the projection ``I - u u^T`` with u carried by body a). The
    N springs' energy 0.5 k_N |P dN|^2 depends on u, so body a also gets the
    torque ``k_N (u . dN) u x dN`` that makes the force its exact gradient.

    F holds the wrenches about the ground origin. Returns (energy, power), J and W.
    """
    F[:] = 0.0
    energy = 0.0
    power = 0.0
    for j in range(P.cut_a.shape[0]):
        a, b = P.cut_a[j], P.cut_b[j]
        theta, g = cut_angle(P, j, R)
        omega = sp.dot(g, sp.sub(sp.get(w, b), sp.get(w, a)))
        tau, e, pw = hinge_law(theta, omega, P.cut_k[j], P.cut_c[j], P.k_s, P.c_s, P.stop_ramp)
        energy += e
        power += pw
        sp.add_wrench(F, b, sp.scale(g, tau), sp.ZERO3, sp.ZERO3)
        sp.add_wrench(F, a, sp.scale(g, -tau), sp.ZERO3, sp.ZERO3)
        if P.method != PENALTY:
            continue
        Ma, Na, Mb, Nb = cut_ends(P, j, R, p)
        dM = sp.sub(Mb, Ma)
        vM = sp.sub(sp.point_velocity(w, vo, b, Mb), sp.point_velocity(w, vo, a, Ma))
        fM = sp.sub(sp.scale(dM, -P.k_M), sp.scale(vM, P.c_M))
        energy += 0.5 * P.k_M * sp.dot(dM, dM)
        power += P.c_M * sp.dot(vM, vM)
        sp.add_wrench(F, b, sp.ZERO3, fM, Mb)
        sp.add_wrench(F, a, sp.ZERO3, sp.scale(fM, -1.0), Ma)
        u = sp.rotate(R, a, sp.get(P.cut_axis, j))
        dN = sp.sub(Nb, Na)
        vN = sp.sub(sp.point_velocity(w, vo, b, Nb), sp.point_velocity(w, vo, a, Na))
        dNp = sp.sub(dN, sp.scale(u, sp.dot(u, dN)))
        vNp = sp.sub(vN, sp.scale(u, sp.dot(u, vN)))
        fN = sp.sub(sp.scale(dNp, -P.k_N), sp.scale(vNp, P.c_N))
        energy += 0.5 * P.k_N * sp.dot(dNp, dNp)
        power += P.c_N * sp.dot(vNp, vNp)
        sp.add_wrench(F, b, sp.ZERO3, fN, Nb)
        sp.add_wrench(F, a, sp.scale(sp.cross(u, dN), P.k_N * sp.dot(u, dN)), sp.scale(fN, -1.0), Na)
    return energy, power


@njit(cache=True, inline="always", **FLOAT_MATH)
def closure_jacobian(P, R, p, w, vo, S, acc):
    """:func:`closure_jacobian_into` new arrays: ``(c, J, gamma)``."""
    m5, n = 5 * P.cut_a.shape[0], P.n
    c, J, gamma = np.empty(m5), np.empty((m5, n)), np.empty(m5)
    closure_jacobian_into(P, R, p, w, vo, S, acc, c, J, gamma, np.empty((6, n)))
    return c, J, gamma


@njit(cache=True, inline="always", **FLOAT_MATH)
def closure_jacobian_into(P, R, p, w, vo, S, acc, c, J, gamma, work):
    """Exact-closure constraints of Eq. (5) kept as equalities, into c, J and
    gamma (overwritten); work is (6, n) scratch.

    Five per cut hinge: M_b - M_a = 0 (3) and e_k . (N_b - N_a) = 0 for the two
    unit normals e_1, e_2 of the axis carried by body a.

    Parameters
    ----------
    acc : (n + 1, 6) or None-like (shape (0, 6))
        Velocity-product spatial accelerations; when empty, ``gamma`` is zeros.

    c : (5 m,) constraint values, m
    J : (5 m, n) Jacobian dc/dtheta, m/rad
    gamma : (5 m,) dJ/dt omega, m/s^2
    """
    n = P.n
    m = P.cut_a.shape[0]
    J[:] = 0.0
    gamma[:] = 0.0
    # work rows 0-2: d(N_b - N_a)/d omega, rows 3-5: d(w_a)/d omega, of one cut
    with_gamma = acc.shape[0] > 0
    for j in range(m):
        a, b = P.cut_a[j], P.cut_b[j]
        r = 5 * j
        Ma, Na, Mb, Nb = cut_ends(P, j, R, p)
        dM = sp.sub(Mb, Ma)
        for k in range(3):
            c[r + k] = dM[k]
        sp.point_jacobian(P, S, b, Mb, J, r, 1.0)
        sp.point_jacobian(P, S, a, Ma, J, r, -1.0)
        work[:] = 0.0
        sp.point_jacobian(P, S, b, Nb, work, 0, 1.0)
        sp.point_jacobian(P, S, a, Na, work, 0, -1.0)
        sp.angular_jacobian(P, S, a, work, 3, 1.0)
        dN = sp.sub(Nb, Na)
        vN = sp.sub(sp.point_velocity(w, vo, b, Nb), sp.point_velocity(w, vo, a, Na))
        if with_gamma:
            gM = sp.sub(sp.point_bias_acceleration(acc, w, vo, b, Mb),
                      sp.point_bias_acceleration(acc, w, vo, a, Ma))
            for k in range(3):
                gamma[r + k] = gM[k]
            aN = sp.sub(sp.point_bias_acceleration(acc, w, vo, b, Nb),
                      sp.point_bias_acceleration(acc, w, vo, a, Na))
        for k in range(2):
            e = sp.rotate(R, a, sp.get(P.cut_e1 if k == 0 else P.cut_e2, j))
            c[r + 3 + k] = sp.dot(e, dN)
            t = sp.cross(e, dN)
            for col in range(n):
                JN = e[0] * work[0, col] + e[1] * work[1, col] + e[2] * work[2, col]
                Jw = t[0] * work[3, col] + t[1] * work[4, col] + t[2] * work[5, col]
                J[r + 3 + k, col] = JN + Jw
            if with_gamma:
                wa = sp.get(w, a)
                edot = sp.cross(wa, e)
                eddot = sp.add(sp.cross(sp.get(acc, a), e), sp.cross(wa, edot))
                gamma[r + 3 + k] = sp.dot(e, aN) + 2.0 * sp.dot(edot, vN) + sp.dot(eddot, dN)


@njit(cache=True, **FLOAT_MATH)
def cholesky(A):
    """The lower Cholesky factor L of A (n, n): ``(L, ok)``, ok False where A
    is not positive definite."""
    L = np.empty_like(A)
    return L, cholesky_into(A, L)


@njit(cache=True, inline="always", **FLOAT_MATH)
def cholesky_into(A, L):
    """:func:`cholesky` into L (n, n, overwritten); returns ok."""
    n = A.shape[0]
    L[:] = 0.0
    for j in range(n):
        s = A[j, j]
        for k in range(j):
            s -= L[j, k] * L[j, k]
        if not s > 0.0:
            return False
        L[j, j] = math.sqrt(s)
        for i in range(j + 1, n):
            s = A[i, j]
            for k in range(j):
                s -= L[i, k] * L[j, k]
            L[i, j] = s / L[j, j]
    return True


@njit(cache=True, **FLOAT_MATH)
def cholesky_solve(L, X):
    """Overwrite X (n, k) with the solution of ``L L^T X = X``.

    The innermost loop runs over the k right-hand sides, which are independent:
    one column at a time, every operation waits on the one before.
    """
    n, m = X.shape
    for i in range(n):
        for k in range(i):
            l = L[i, k]
            for c in range(m):
                X[i, c] -= l * X[k, c]
        d = L[i, i]
        for c in range(m):
            X[i, c] /= d
    for i in range(n - 1, -1, -1):
        for k in range(i + 1, n):
            l = L[k, i]
            for c in range(m):
                X[i, c] -= l * X[k, c]
        d = L[i, i]
        for c in range(m):
            X[i, c] /= d


@njit(cache=True, **FLOAT_MATH)
def constraint_factor(L, J, regularisation):
    """Y = M^-1 J^T and the Cholesky factor of the regularised J M^-1 J^T
    (:func:`_regularised_cholesky`); ``L`` is the Cholesky factor of M. Returns ``(Y, LA, ok)``."""
    Y = J.T.copy()
    cholesky_solve(L, Y)
    A = sp.matmul(J, Y)
    LA = np.empty_like(A)
    return Y, LA, _regularised_cholesky(A, regularisation, LA)


@njit(cache=True, inline="always", **FLOAT_MATH)
def articulated_closure(P, S, UA, D, Q, c, J, gamma, omega, qdd, buffers):
    """Write to qdd (n,) the exact closure's joint accelerations
    (:func:`exact_closure`'s) with M factored by the articulated-body
    algorithm (:func:`articulated.factor`'s (UA, D)), no n x n matrix:
    Q and the rows of J (mc, n) go up the tree in one pass
    (:func:`articulated.up_rows`); J M^-1 J^T and J M^-1 Q are sums over
    their innovations, and only ``Q + J^T lam`` goes back down, in place of
    1 + mc rows. ``buffers``: :class:`.buffers.Buffers`' closure (its items 4 on).
    Returns (the constraint forces' power (W), ok); ok is False
    where the regularised J M^-1 J^T is not positive definite."""
    n, mc = P.n, J.shape[0]
    rows, E, work, inv, A, b, LA, lam, cdot = buffers[4:]
    rows[0] = Q
    rows[1:] = J
    articulated.up_rows(P, S, UA, D, rows, E, work)
    for i in range(n):
        inv[i] = 1.0 / D[i]
    for r in range(mc):
        b[r] = _weighted_dot(E[1 + r], E[0], inv)
        for s in range(r + 1):
            A[r, s] = A[s, r] = _weighted_dot(E[1 + r], E[1 + s], inv)
    if not _regularised_cholesky(A, P.regularisation, LA):
        return 0.0, False
    _multipliers(P, c, J, gamma, omega, b, LA, lam, cdot)
    qdd[:] = E[0]
    for r in range(mc):
        for i in range(n):
            qdd[i] += lam[r] * E[1 + r, i]
    articulated.down_rows(P, S, UA, D, qdd.reshape((1, n)), work[:1])
    return sp.dot(lam, cdot), True


@njit(cache=True, inline="always", **FLOAT_MATH)
def _weighted_dot(x, y, w):
    """sum x_i y_i w_i over the (n,) arrays, in four interleaved partial sums:
    one sum waits on each add before it (no reassociation, ``FLOAT_MATH``),
    four keep the multipliers busy (10 x 10's J M^-1 J^T: 0.95 us against
    1.3 us a term at a time into A)."""
    n = x.shape[0]
    s0 = s1 = s2 = s3 = 0.0
    i = 0
    while i + 4 <= n:
        s0 += x[i] * y[i] * w[i]
        s1 += x[i + 1] * y[i + 1] * w[i + 1]
        s2 += x[i + 2] * y[i + 2] * w[i + 2]
        s3 += x[i + 3] * y[i + 3] * w[i + 3]
        i += 4
    while i < n:
        s0 += x[i] * y[i] * w[i]
        i += 1
    return (s0 + s1) + (s2 + s3)


@njit(cache=True, inline="always", **FLOAT_MATH)
def _regularised_cholesky(A, regularisation, LA):
    """Cholesky factor into LA of A = J M^-1 J^T (mc, mc, overwritten) + a
    Tikhonov term, relative to its largest diagonal entry, which keeps it
    defined through rank loss of the closure Jacobian (the stowed and
    flat-aligned singular states); returns ok (:func:`cholesky_into`)."""
    mc = A.shape[0]
    scale = 0.0
    for r in range(mc):
        scale = max(scale, A[r, r])
    for r in range(mc):
        A[r, r] += regularisation * scale + 1e-300
    return cholesky_into(A, LA)


@njit(cache=True, inline="always", **FLOAT_MATH)
def _multipliers(P, c, J, gamma, omega, Jqdd, LA, lam, cdot):
    """The exact closure's Lagrange multipliers (Baumgarte-stabilised, time
    constant ``P.baumgarte``) into lam (mc,), and J omega into cdot (mc,),
    from :func:`closure_jacobian`'s (c, J, gamma), J times the tree's qdd,
    ``Jqdd`` (mc,), and the factor LA of the regularised J M^-1 J^T."""
    T = P.baumgarte
    for r in range(J.shape[0]):
        s = 0.0
        for i in range(J.shape[1]):
            s += J[r, i] * omega[i]
        cdot[r] = s
        lam[r] = (-gamma[r] - (2.0 / T) * s - c[r] / (T * T)) - Jqdd[r]
    cholesky_solve(LA, lam.reshape((lam.shape[0], 1)))


@njit(cache=True, inline="always", **FLOAT_MATH)
def exact_closure(P, c, J, gamma, Y, LA, omega, qdd):
    """Add to the tree's qdd (n,) the exact closure's Lagrange multiplier term
    (:func:`_multipliers`) from :func:`closure_jacobian`'s (c, J, gamma) and
    :func:`constraint_factor`'s (Y, LA) of the dense M. Returns the
    constraint forces' power, W."""
    n, mc = P.n, J.shape[0]
    lam, cdot = np.empty(mc), np.empty(mc)
    _multipliers(P, c, J, gamma, omega, sp.mv(J, qdd), LA, lam, cdot)
    for i in range(n):
        s = 0.0
        for r in range(J.shape[0]):
            s += Y[i, r] * lam[r]
        qdd[i] += s
    return sp.dot(lam, cdot)


@njit(cache=True, **FLOAT_MATH)
def cut_angles(P, R):
    """Angle of every cut hinge (rad) for body orientations R (n + 1, 3, 3)."""
    m = P.cut_a.shape[0]
    out = np.empty(m)
    for j in range(m):
        out[j] = cut_angle(P, j, R)[0]
    return out


@njit(cache=True, **FLOAT_MATH)
def cut_rates(P, R, w):
    """Rate of every cut hinge (rad/s) for body orientations R (n + 1, 3, 3) and
    angular velocities w (n + 1, 3), rad/s, both in kernel body order."""
    m = P.cut_a.shape[0]
    out = np.empty(m)
    for j in range(m):
        g = cut_angle(P, j, R)[1]
        a, b = P.cut_a[j], P.cut_b[j]
        out[j] = g[0] * (w[b, 0] - w[a, 0]) + g[1] * (w[b, 1] - w[a, 1]) + g[2] * (w[b, 2] - w[a, 2])
    return out
