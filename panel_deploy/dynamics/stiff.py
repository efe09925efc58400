"""The stiff terms of the compiled dynamics in joint space, for the Rosenbrock
integrator (:mod:`.rosenbrock`): the hinge stops, the panel contacts pressed
in and the penalty closure's springs, as ``K`` and ``C``, and the Jacobian of
the right-hand side they give.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..boxes import plane_axes
from ..boxes import scratch as box_scratch
from . import spatial as sp
from ._jit import FLOAT_MATH
from .closure import cholesky, cholesky_solve, closure_jacobian, constraint_factor, cut_angle
from .hinges import contact_mode, stop_engagement
from .kernels import body_inertias, kinematics, mass_matrix
from .pack import EXACT, PENALTY
from .panel_contact import contact_law, pair_points, touching


@njit(cache=True, **FLOAT_MATH)
def _outer_add(out, scale, u):
    for i in range(u.shape[0]):
        for j in range(u.shape[0]):
            out[i, j] += scale * u[i] * u[j]


@njit(cache=True, **FLOAT_MATH)
def _pressed_points(P, R, p, near):
    """The panel contact points pressed (depth > 0) at poses (R, p): (count,
    rows), row i < count ``[pair, normal (3), point (3, m), depth (m), weight]``,
    so that the separating axes run once a call, not once to count and again
    to fill. ``near``: the run's candidate list (:func:`.panel_contact.near_pairs`)."""
    rows = np.empty((64, 9))
    count = 0
    if P.contact.shape[0] == 0:
        return count, rows
    work = box_scratch()
    points, depths, weights = work[-3], work[-2], work[-1]
    touched, least = touching(P, R, p, near)
    for j in range(touched.shape[0]):
        r = touched[j]
        found, normal = pair_points(P, r, R, p, least[j], work)
        if count + found > rows.shape[0]:
            grown = np.empty((2 * rows.shape[0] + found, 9))
            grown[:count] = rows[:count]
            rows = grown
        for q in range(found):
            rows[count, 0] = r
            rows[count, 1], rows[count, 2], rows[count, 3] = normal
            rows[count, 4], rows[count, 5], rows[count, 6] = points[q, 0], points[q, 1], points[q, 2]
            rows[count, 7], rows[count, 8] = depths[q], weights[q]
            count += 1
    return count, rows


@njit(cache=True, **FLOAT_MATH)
def _contact_row_count(P, pressed):
    """Rows of U that :func:`_contact_rows` writes: one per pressed point, two
    more where its pair has friction."""
    contact = P.contact
    if contact.shape[0] == 0:
        return 0
    count, rows = pressed
    out = count
    for i in range(count):
        if contact[int(rows[i, 0]), 10] > 0.0:
            out += 2
    return out


@njit(cache=True, **FLOAT_MATH)
def _contact_rows(P, pressed, S, U, kk, cc, start):
    """Write from row ``start`` of U, kk, cc the pressed panel contact points
    (:func:`_pressed_points`' (count, rows)): G, the row of -d(depth)/d theta,
    and the stiffness and damping of :func:`.panel_contact.contact_law` at its depth, so that K
    gains ``k G^T G`` (C likewise); then, for a point with friction, its two
    slip directions with :func:`.panel_contact._friction`'s damping at zero slip, mu times
    the spring's push over the friction speed."""
    contact = P.contact
    if contact.shape[0] == 0:
        return
    count, rows = pressed
    Jp = np.empty((3, P.n))
    extra = start + count
    for i in range(count):
        r = int(rows[i, 0])
        weight = rows[i, 8]
        push, _, _, k, c = contact_law(rows[i, 7], 0.0, weight * contact[r, 8], weight * contact[r, 9])
        kk[start + i], cc[start + i] = k, c
        x = (rows[i, 4], rows[i, 5], rows[i, 6])
        Jp[:] = 0.0
        sp.point_jacobian(P, S, int(contact[r, 1]), x, Jp, 0, 1.0)
        sp.point_jacobian(P, S, int(contact[r, 0]), x, Jp, 0, -1.0)
        normal = (rows[i, 1], rows[i, 2], rows[i, 3])
        _direction_row(P, Jp, normal, U[start + i])
        if contact[r, 10] > 0.0:
            for e in plane_axes(normal):
                _direction_row(P, Jp, e, U[extra])
                kk[extra], cc[extra] = 0.0, contact[r, 10] * push / contact[r, 11]
                extra += 1


@njit(cache=True, inline="always", **FLOAT_MATH)
def _direction_row(P, Jp, e, out):
    """Write ``e . Jp`` (n,) to out: the rate along the unit vector e
    (3-tuple) of the relative velocity (of a point, or angular) whose
    Jacobian is Jp (3, n)."""
    for col in range(P.n):
        out[col] = e[0] * Jp[0, col] + e[1] * Jp[1, col] + e[2] * Jp[2, col]


@njit(cache=True, inline="always", **FLOAT_MATH)
def _stop_share(P, theta):
    """:func:`.hinges.stop_engagement` of a hinge at theta (0 within its limits)."""
    if contact_mode(theta) == 1:
        return 0.0
    return stop_engagement(theta - math.pi if theta > math.pi else -theta, P.stop_ramp)


@njit(cache=True, inline="always", **FLOAT_MATH)
def stiff_terms(P, y, near):
    """The stiff springs and dampers in joint space, ``K = diag(Kd) + U^T
    diag(kk) U`` and ``C = diag(Cd) + U^T diag(cc) U`` (N m/rad, N m s/rad),
    at the current configuration.

    ``Kd = k + k_s e`` on tree hinges past a limit (Eq. 2-4; e the stop's
    :func:`.hinges.stop_engagement`), likewise Cd; one
    row of U per cut hinge, its angle Jacobian (its own spring and contact),
    and for PENALTY five per cut hinge, the closure Jacobian of Eq. (5) with
    weights k_M, k_M, k_M, k_N, k_N (c likewise); then one per panel contact
    point pressed now and two more where it has friction (:func:`_contact_rows`).
    Returns (kin, Kd, Cd, U, kk, cc), kin the :func:`.kernels.kinematics` tuple; U is
    (r, n), r = 6 m (PENALTY) or m plus the contact rows, so K, C are
    diagonal plus rank r.
    """
    n = P.n
    theta = y[:n]
    kin = kinematics(P, theta, y[n:2 * n])
    R, p, w, vo, S = kin
    Kd = np.empty(n)
    Cd = np.empty(n)
    for i in range(n):
        share = _stop_share(P, theta[i])
        Kd[i] = P.k[i] + P.k_s * share
        Cd[i] = P.c[i] + P.c_s * share
    m = P.cut_a.shape[0]
    closure = 6 * m if P.method == PENALTY else m
    pressed = _pressed_points(P, R, p, near)
    rows = closure + _contact_row_count(P, pressed)
    U = np.zeros((rows, n))
    kk = np.empty(rows)
    cc = np.empty(rows)
    _contact_rows(P, pressed, S, U, kk, cc, closure)
    Jw = np.empty((3, n))
    for j in range(m):
        th, g = cut_angle(P, j, R)
        Jw[:] = 0.0
        sp.angular_jacobian(P, S, P.cut_b[j], Jw, 0, 1.0)
        sp.angular_jacobian(P, S, P.cut_a[j], Jw, 0, -1.0)
        _direction_row(P, Jw, g, U[j])
        share = _stop_share(P, th)
        kk[j] = P.cut_k[j] + P.k_s * share
        cc[j] = P.cut_c[j] + P.c_s * share
    if P.method == PENALTY:
        _, J, _ = closure_jacobian(P, R, p, w, vo, S, np.zeros((0, 6)))
        for r in range(J.shape[0]):
            on_M = r % 5 < 3
            U[m + r] = J[r]
            kk[m + r] = P.k_M if on_M else P.k_N
            cc[m + r] = P.c_M if on_M else P.c_N
    return kin, Kd, Cd, U, kk, cc


@njit(cache=True, **FLOAT_MATH)
def stiff_jacobian(P, y, near):
    """The stiff linear part of ``A = d qdd / d theta`` and ``B = d qdd / d omega``, (n, n).

    Keeps only the springs and dampers of :func:`stiff_terms`, at the current
    configuration: ``A = -M^-1 K``, ``B = -M^-1 C``. For EXACT the same is
    projected onto the constraint (``M^-1 -> M^-1 - Y (J Y)^-1 J M^-1``, ``Y =
    M^-1 J^T``) and the Baumgarte terms ``-Y (J Y)^-1 J / T^2`` (A) and ``2 /
    T`` (B) are added. Velocity products, gravity, air drag and the terms of
    order gap x stiffness are left out: they are not stiff, and a W-method
    does not need them.
    Costs about one RHS call, against 2 n for the finite-difference Jacobian.
    Returns (A, B, ok); ok is False if M is not positive definite.
    """
    n = P.n
    kin, Kd, Cd, U, kk, cc = stiff_terms(P, y, near)
    R, p, w, vo, S = kin
    Jb, hb = body_inertias(P, R, p)
    M = mass_matrix(P, S, Jb, hb)
    Kq = np.zeros((n, n))
    Cq = np.zeros((n, n))
    for i in range(n):
        Kq[i, i] = Kd[i]
        Cq[i, i] = Cd[i]
    for r in range(U.shape[0]):
        _outer_add(Kq, kk[r], U[r])
        _outer_add(Cq, cc[r], U[r])
    L, ok = cholesky(M)
    A = np.zeros((n, n))
    B = np.zeros((n, n))
    if not ok:
        return A, B, False
    A[:] = Kq
    B[:] = Cq
    cholesky_solve(L, A)
    cholesky_solve(L, B)
    for i in range(n):
        for col in range(n):
            A[i, col] = -A[i, col]
            B[i, col] = -B[i, col]
    if P.method == EXACT:
        _, J, _ = closure_jacobian(P, R, p, w, vo, S, np.zeros((0, 6)))
        Y, LA, ok = constraint_factor(L, J, P.regularisation)
        if not ok:
            return A, B, False
        T = P.baumgarte
        # lambda's response to a unit change of theta[col] / omega[col]
        Ra = sp.matmul(J, A)
        Rb = sp.matmul(J, B)
        for r in range(J.shape[0]):
            for col in range(n):
                Ra[r, col] = -Ra[r, col] - J[r, col] / (T * T)
                Rb[r, col] = -Rb[r, col] - J[r, col] * (2.0 / T)
        cholesky_solve(LA, Ra)
        cholesky_solve(LA, Rb)
        A += sp.matmul(Y, Ra)
        B += sp.matmul(Y, Rb)
    return A, B, True
