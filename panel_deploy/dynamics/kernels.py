"""Compiled (numba) kernels of the deployment dynamics.

State vector ``y`` (shape ``(2 n + 2,)``): ``theta`` (n, rad), ``omega`` (n,
rad/s), the energy dissipated by all dampers since t = 0 (J) and the work done
on the system by the exact-closure constraint forces (J, zero for penalty).

Algorithm (Featherstone, "Rigid Body Dynamics Algorithms", ch. 5-6), with all
spatial vectors in the ground frame about its origin, angular part first:

* forward kinematics down the tree;
* mass matrix by the composite-rigid-body algorithm (CRBA), bias forces
  (velocity product, gravity, cut-hinge wrenches) by recursive Newton-Euler
  (RNEA) with zero joint acceleration;
* ``M qdd = Q - b`` solved by Cholesky.

CRBA is O(n d) for tree depth d and the Cholesky O(n^3), against O(n) for the
articulated-body algorithm. With n = 11 that is a few hundred flops, below the
kernel's fixed costs, and the exact closure needs ``M^-1 J^T`` anyway, which
ABA does not give; the factored mass matrix also yields the kinetic energy.

Hinge law, Eq. (2)-(4), with the contact elements in parallel with the hinge
spring (paper, text below Eq. 4): ``tau = -k theta - c omega`` plus, past a
limit, ``-k_s (theta - pi) - c_s omega`` (theta > pi) or ``-k_s theta - c_s
omega`` (theta < 0). So the hinge spring keeps acting in contact; the printed
Eq. (4) drops ``-k theta`` for theta > pi, a difference of k pi against the
k_s term, which dominates within the 0.1 % penetration it allows.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .pack import EXACT, PENALTY, TREE

PI = math.pi


@njit(cache=True)
def hinge_law(theta, omega, k, c, k_s, c_s):
    """Torque (N m), stored energy (J) and damper power (W) of one hinge, Eq. (2)-(4)."""
    tau = -k * theta - c * omega
    energy = 0.5 * k * theta * theta
    power = c * omega * omega
    if theta > PI:
        d = theta - PI
        tau -= k_s * d + c_s * omega
        energy += 0.5 * k_s * d * d
        power += c_s * omega * omega
    elif theta < 0.0:
        tau -= k_s * theta + c_s * omega
        energy += 0.5 * k_s * theta * theta
        power += c_s * omega * omega
    return tau, energy, power


@njit(cache=True)
def contact_mode(theta):
    """0 below the flat limit, 1 within [0, pi], 2 past the folded limit."""
    return 0 if theta < 0.0 else (2 if theta > PI else 1)


@njit(cache=True)
def _dot(a, b):
    s = 0.0
    for i in range(a.shape[0]):
        s += a[i] * b[i]
    return s


@njit(cache=True)
def _mv(A, x):
    """A @ x for small arrays without a BLAS call (whose overhead dominates here)."""
    out = np.zeros(A.shape[0])
    for i in range(A.shape[0]):
        s = 0.0
        for j in range(A.shape[1]):
            s += A[i, j] * x[j]
        out[i] = s
    return out


@njit(cache=True)
def _vm(x, A):
    """x @ A for small arrays."""
    out = np.zeros(A.shape[1])
    for i in range(A.shape[0]):
        for j in range(A.shape[1]):
            out[j] += x[i] * A[i, j]
    return out


@njit(cache=True)
def _mm(A, B):
    out = np.zeros((A.shape[0], B.shape[1]))
    for i in range(A.shape[0]):
        for k in range(A.shape[1]):
            a = A[i, k]
            for j in range(B.shape[1]):
                out[i, j] += a * B[k, j]
    return out


@njit(cache=True)
def _cross(a, b):
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                     a[0] * b[1] - a[1] * b[0]])


@njit(cache=True)
def _rotation(axis, angle):
    x, y, z = axis[0], axis[1], axis[2]
    c, s = math.cos(angle), math.sin(angle)
    C = 1.0 - c
    out = np.empty((3, 3))
    out[0, 0] = c + x * x * C
    out[0, 1] = x * y * C - z * s
    out[0, 2] = x * z * C + y * s
    out[1, 0] = y * x * C + z * s
    out[1, 1] = c + y * y * C
    out[1, 2] = y * z * C - x * s
    out[2, 0] = z * x * C - y * s
    out[2, 1] = z * y * C + x * s
    out[2, 2] = c + z * z * C
    return out


@njit(cache=True)
def kinematics(P, theta, omega):
    """Poses, velocities and joint screws of every body.

    Returns
    -------
    R : (n + 1, 3, 3)   orientations, ground last
    p : (n + 1, 3)      centroids, m
    w : (n + 1, 3)      angular velocities, rad/s
    vo : (n + 1, 3)     velocity of the body point at the ground origin, m/s
                        (centroid velocity = vo + w x p)
    S : (n, 6)          joint screws (axis, hinge point x axis)
    """
    n = P.n
    R = np.empty((n + 1, 3, 3))
    p = np.empty((n + 1, 3))
    w = np.zeros((n + 1, 3))
    vo = np.zeros((n + 1, 3))
    S = np.empty((n, 6))
    R[n] = np.eye(3)
    p[n] = P.r0[n]
    for i in range(n):
        a = P.parent[i]
        Ra = R[a]
        R[i] = _mm(Ra, _rotation(P.axis[i], theta[i]))
        h = p[a] + _mv(Ra, P.point[i] - P.r0[a])
        u = _mv(Ra, P.axis[i])
        p[i] = h + _mv(R[i], P.r0[i] - P.point[i])
        S[i, :3] = u
        S[i, 3:] = _cross(h, u)
        w[i] = w[a] + u * omega[i]
        vo[i] = vo[a] + S[i, 3:] * omega[i]
    return R, p, w, vo, S


@njit(cache=True)
def _spatial_inertia(m, Ic, c):
    """6x6 spatial inertia about the ground origin of a body of mass m, centroid c."""
    C = np.array([[0.0, -c[2], c[1]], [c[2], 0.0, -c[0]], [-c[1], c[0], 0.0]])
    out = np.empty((6, 6))
    out[:3, :3] = Ic - m * _mm(C, C)
    out[:3, 3:] = m * C
    out[3:, :3] = -m * C
    out[3:, 3:] = m * np.eye(3)
    return out


@njit(cache=True)
def _point_jacobian(P, S, b, x, out, sign):
    """Add ``sign`` times d(velocity of body b's material point at x)/d omega to out (3, n)."""
    while b < P.n:
        out[:, b] += sign * (S[b, 3:] + _cross(S[b, :3], x))
        b = P.parent[b]


@njit(cache=True)
def _angular_jacobian(P, S, b, out, sign):
    while b < P.n:
        out[:, b] += sign * S[b, :3]
        b = P.parent[b]


@njit(cache=True)
def _point_bias_acceleration(a6, w, vo, x):
    """Acceleration of a material point at x when qdd = 0 (velocity products only)."""
    return a6[3:] + _cross(a6[:3], x) + _cross(w, vo + _cross(w, x))


@njit(cache=True)
def _cut_angle(P, j, R):
    """Cut-hinge angle (rad, continuous on (-pi/2, 3pi/2]) and its exact rate axis g.

    theta = atan2(e2 . f, e1 . f) with f = R_b e1 and e1, e2 carried by body a;
    d theta / dt = g . (w_b - w_a) for any relative orientation (not only a pure
    rotation about the axis), so torque and energy stay consistent.
    """
    a, b = P.cut_a[j], P.cut_b[j]
    f = _mv(R[b], P.cut_e1[j])
    e1 = _mv(R[a], P.cut_e1[j])
    e2 = _mv(R[a], P.cut_e2[j])
    x = _dot(e1, f)
    y = _dot(e2, f)
    theta = math.atan2(y, x)
    if theta < -0.5 * PI:
        theta += 2.0 * PI
    g = _cross(f, x * e2 - y * e1) / (x * x + y * y)
    return theta, g


@njit(cache=True)
def cut_geometry(P, R, p, w, vo):
    """Ends and gaps of every cut hinge.

    Returns (m, 4, 3) points (M_a, N_a, M_b, N_b) and (m, 2, 3) gaps
    (M_b - M_a, N_b - N_a) with their rates (m, 2, 3), m and m/s.
    """
    m = P.cut_a.shape[0]
    pts = np.empty((m, 4, 3))
    gap = np.empty((m, 2, 3))
    rate = np.empty((m, 2, 3))
    for j in range(m):
        for s in range(2):
            body = P.cut_a[j] if s == 0 else P.cut_b[j]
            for e in range(2):
                end = P.cut_point[j] + e * P.cut_length[j] * P.cut_axis[j]
                x = p[body] + _mv(R[body], end - P.r0[body])
                pts[j, 2 * s + e] = x
        for e in range(2):
            gap[j, e] = pts[j, 2 + e] - pts[j, e]
            a, b = P.cut_a[j], P.cut_b[j]
            xa, xb = pts[j, e], pts[j, 2 + e]
            rate[j, e] = (vo[b] + _cross(w[b], xb)) - (vo[a] + _cross(w[a], xa))
    return pts, gap, rate


@njit(cache=True)
def _add_wrench(F, body, torque, force, point):
    """Add a force applied at ``point`` plus a torque to body's wrench about the origin."""
    F[body, :3] += torque + _cross(point, force)
    F[body, 3:] += force


@njit(cache=True)
def cut_forces(P, R, p, w, vo):
    """Wrenches of the cut hinges on their bodies, with energy and damper power.

    The cut hinge's own spring, damper and contact (Eq. 2-4 about its axis) for
    every closure method; for PENALTY also the five springs and dampers of
    Eq. (5): M-M' along x_M, y_M, z_M and N-N' along the two directions normal
    to the axis (the projection ``I - u u^T`` with u carried by body a). The
    N springs' energy 0.5 k_N |P dN|^2 depends on u, so body a also gets the
    torque ``k_N (u . dN) u x dN`` that makes the force its exact gradient.

    Returns
    -------
    F : (n + 1, 6) wrenches about the ground origin
    energy, power : float   J, W
    """
    n = P.n
    F = np.zeros((n + 1, 6))
    energy = 0.0
    power = 0.0
    pts, gap, rate = cut_geometry(P, R, p, w, vo)
    zero = np.zeros(3)
    for j in range(P.cut_a.shape[0]):
        a, b = P.cut_a[j], P.cut_b[j]
        theta, g = _cut_angle(P, j, R)
        omega = _dot(g, w[b] - w[a])
        tau, e, pw = hinge_law(theta, omega, P.cut_k[j], P.cut_c[j], P.k_s, P.c_s)
        energy += e
        power += pw
        _add_wrench(F, b, tau * g, zero, zero)
        _add_wrench(F, a, -tau * g, zero, zero)
        if P.method != PENALTY:
            continue
        dM, vM = gap[j, 0], rate[j, 0]
        fM = -P.k_M * dM - P.c_M * vM
        energy += 0.5 * P.k_M * _dot(dM, dM)
        power += P.c_M * _dot(vM, vM)
        _add_wrench(F, b, zero, fM, pts[j, 2])
        _add_wrench(F, a, zero, -fM, pts[j, 0])
        u = _mv(R[a], P.cut_axis[j])
        dN, vN = gap[j, 1], rate[j, 1]
        dNp = dN - u * _dot(u, dN)
        vNp = vN - u * _dot(u, vN)
        fN = -P.k_N * dNp - P.c_N * vNp
        energy += 0.5 * P.k_N * _dot(dNp, dNp)
        power += P.c_N * _dot(vNp, vNp)
        _add_wrench(F, b, zero, fN, pts[j, 3])
        _add_wrench(F, a, P.k_N * _dot(u, dN) * _cross(u, dN), -fN, pts[j, 1])
    return F, energy, power


@njit(cache=True)
def closure_jacobian(P, R, p, w, vo, S, acc):
    """Exact-closure constraints of Eq. (5) kept as equalities.

    Five per cut hinge: M_b - M_a = 0 (3) and e_k . (N_b - N_a) = 0 for the two
    unit normals e_1, e_2 of the axis carried by body a.

    Parameters
    ----------
    acc : (n + 1, 6) or None-like (shape (0, 6))
        Velocity-product spatial accelerations; when empty, ``gamma`` is zeros.

    Returns
    -------
    c : (5 m,) constraint values, m
    J : (5 m, n) Jacobian dc/dtheta, m/rad
    gamma : (5 m,) dJ/dt omega, m/s^2
    """
    n = P.n
    m = P.cut_a.shape[0]
    c = np.empty(5 * m)
    J = np.zeros((5 * m, n))
    gamma = np.zeros(5 * m)
    pts, gap, rate = cut_geometry(P, R, p, w, vo)
    with_gamma = acc.shape[0] > 0
    for j in range(m):
        a, b = P.cut_a[j], P.cut_b[j]
        r = 5 * j
        c[r:r + 3] = gap[j, 0]
        JM = np.zeros((3, n))
        _point_jacobian(P, S, b, pts[j, 2], JM, 1.0)
        _point_jacobian(P, S, a, pts[j, 0], JM, -1.0)
        J[r:r + 3] = JM
        JN = np.zeros((3, n))
        _point_jacobian(P, S, b, pts[j, 3], JN, 1.0)
        _point_jacobian(P, S, a, pts[j, 1], JN, -1.0)
        Jw = np.zeros((3, n))
        _angular_jacobian(P, S, a, Jw, 1.0)
        dN, vN = gap[j, 1], rate[j, 1]
        if with_gamma:
            gamma[r:r + 3] = (_point_bias_acceleration(acc[b], w[b], vo[b], pts[j, 2])
                              - _point_bias_acceleration(acc[a], w[a], vo[a], pts[j, 0]))
            aN = (_point_bias_acceleration(acc[b], w[b], vo[b], pts[j, 3])
                  - _point_bias_acceleration(acc[a], w[a], vo[a], pts[j, 1]))
        for k in range(2):
            e = _mv(R[a], P.cut_e1[j] if k == 0 else P.cut_e2[j])
            c[r + 3 + k] = _dot(e, dN)
            J[r + 3 + k] = _vm(e, JN) + _vm(_cross(e, dN), Jw)
            if with_gamma:
                edot = _cross(w[a], e)
                eddot = _cross(acc[a, :3], e) + _cross(w[a], edot)
                gamma[r + 3 + k] = _dot(e, aN) + 2.0 * _dot(edot, vN) + _dot(eddot, dN)
    return c, J, gamma


@njit(cache=True)
def _cholesky(A):
    n = A.shape[0]
    L = np.zeros_like(A)
    for j in range(n):
        s = A[j, j]
        for k in range(j):
            s -= L[j, k] * L[j, k]
        if not s > 0.0:
            return L, False
        L[j, j] = math.sqrt(s)
        for i in range(j + 1, n):
            s = A[i, j]
            for k in range(j):
                s -= L[i, k] * L[j, k]
            L[i, j] = s / L[j, j]
    return L, True


@njit(cache=True)
def _cholesky_solve(L, b):
    n = L.shape[0]
    x = b.copy()
    for i in range(n):
        for k in range(i):
            x[i] -= L[i, k] * x[k]
        x[i] /= L[i, i]
    for i in range(n - 1, -1, -1):
        for k in range(i + 1, n):
            x[i] -= L[k, i] * x[k]
        x[i] /= L[i, i]
    return x


@njit(cache=True)
def _constraint_factor(L, J, regularisation):
    """Y = M^-1 J^T and the Cholesky factor of the regularised J M^-1 J^T.

    ``L`` is the Cholesky factor of M; the Tikhonov term, relative to the
    largest diagonal entry, keeps the factorisation defined through rank loss
    of the closure Jacobian (the stowed and flat-aligned singular states).
    Returns ``(Y, LA, ok)``.
    """
    n, mc = L.shape[0], J.shape[0]
    Y = np.empty((n, mc))
    for r in range(mc):
        Y[:, r] = _cholesky_solve(L, J[r].copy())
    A = _mm(J, Y)
    scale = 0.0
    for r in range(mc):
        scale = max(scale, A[r, r])
    for r in range(mc):
        A[r, r] += regularisation * scale + 1e-300
    LA, ok = _cholesky(A)
    return Y, LA, ok


@njit(cache=True)
def _crba(P, R, p, S):
    """Spatial inertias (n, 6, 6) about the ground origin and the mass matrix (n, n)."""
    n = P.n
    I6 = np.empty((n, 6, 6))
    for i in range(n):
        Ic = _mm(_mm(R[i], P.inertia[i]), R[i].T)
        I6[i] = _spatial_inertia(P.mass[i], Ic, p[i])
    comp = I6.copy()
    for i in range(n - 1, -1, -1):
        if P.parent[i] < n:
            comp[P.parent[i]] += comp[i]
    M = np.zeros((n, n))
    for i in range(n):
        Fi = _mv(comp[i], S[i])
        M[i, i] = _dot(S[i], Fi)
        j = P.parent[i]
        while j < n:
            M[i, j] = M[j, i] = _dot(S[j], Fi)
            j = P.parent[j]
    return I6, M


@njit(cache=True)
def mass_and_bias(P, theta, omega):
    """Mass matrix, generalised force and everything the energy needs.

    Returns
    -------
    M : (n, n) kg m^2
    Q : (n,) generalised force minus bias, ``M qdd = Q`` for the tree, N m
    kin : tuple (R, p, w, vo, S)
    acc : (n + 1, 6) velocity-product spatial accelerations
    spring, dissipation, gravity_energy : float  J, W, J
    """
    n = P.n
    R, p, w, vo, S = kinematics(P, theta, omega)
    I6, M = _crba(P, R, p, S)
    if P.method != TREE:
        f, spring, dissipation = cut_forces(P, R, p, w, vo)
        f = -f
    else:
        f = np.zeros((n + 1, 6))
        spring = 0.0
        dissipation = 0.0
    acc = np.zeros((n + 1, 6))
    gravity_energy = 0.0
    V = np.empty(6)
    for i in range(n):
        a = P.parent[i]
        s = S[i]
        acc[i, :3] = acc[a, :3] + _cross(w[a], s[:3]) * omega[i]
        acc[i, 3:] = acc[a, 3:] + (_cross(w[a], s[3:]) + _cross(vo[a], s[:3])) * omega[i]
        V[:3] = w[i]
        V[3:] = vo[i]
        h = _mv(I6[i], V)
        fi = _mv(I6[i], acc[i])
        fi[:3] += _cross(w[i], h[:3]) + _cross(vo[i], h[3:])
        fi[3:] += _cross(w[i], h[3:])
        if P.has_gravity:
            fg = P.mass[i] * P.gravity
            fi[:3] -= _cross(p[i], fg)
            fi[3:] -= fg
            gravity_energy -= _dot(fg, p[i] - P.r0[i])
        f[i] += fi
    Q = np.empty(n)
    for i in range(n - 1, -1, -1):
        tau, e, pw = hinge_law(theta[i], omega[i], P.k[i], P.c[i], P.k_s, P.c_s)
        spring += e
        dissipation += pw
        Q[i] = tau - _dot(S[i], f[i])
        if P.parent[i] < n:
            f[P.parent[i]] += f[i]
    return M, Q, (R, p, w, vo, S), acc, spring, dissipation, gravity_energy


@njit(cache=True)
def rhs(P, y):
    """dy/dt of the state vector (see the module docstring); NaN if M is not positive definite."""
    n = P.n
    theta = y[:n]
    omega = y[n:2 * n]
    M, Q, kin, acc, spring, dissipation, _ = mass_and_bias(P, theta, omega)
    dy = np.empty(2 * n + 2)
    dy[:n] = omega
    dy[2 * n] = dissipation
    dy[2 * n + 1] = 0.0
    L, ok = _cholesky(M)
    if not ok:
        dy[:] = np.nan
        return dy
    qdd = _cholesky_solve(L, Q)
    if P.method == EXACT:
        R, p, w, vo, S = kin
        c, J, gamma = closure_jacobian(P, R, p, w, vo, S, acc)
        cdot = _mv(J, omega)
        T = P.baumgarte
        target = -gamma - (2.0 / T) * cdot - c / (T * T)
        Y, LA, ok = _constraint_factor(L, J, P.regularisation)
        if not ok:
            dy[:] = np.nan
            return dy
        lam = _cholesky_solve(LA, target - _mv(J, qdd))
        qdd = qdd + _mv(Y, lam)
        dy[2 * n + 1] = _dot(lam, cdot)
    dy[n:2 * n] = qdd
    return dy


@njit(cache=True)
def rhs_jacobian(P, y, f0):
    """Forward-difference Jacobian d rhs / dy, (2n + 2, 2n + 2), given f0 = rhs(P, y)."""
    N = y.shape[0]
    Jac = np.zeros((N, N))
    yp = y.copy()
    for j in range(2 * P.n):
        h = 1.4901161193847656e-08 * max(1.0, abs(y[j]))
        yp[j] = y[j] + h
        Jac[:, j] = (rhs(P, yp) - f0) / h
        yp[j] = y[j]
    return Jac


@njit(cache=True)
def observe(P, y):
    """Energies and closure gap at one state.

    Returns kinetic, spring, gravity energy (J), largest gap (m) and the
    closure Jacobian (5 m, n) for its singular values.
    """
    n = P.n
    theta = y[:n]
    omega = y[n:2 * n]
    M, Q, kin, acc, spring, dissipation, gravity_energy = mass_and_bias(P, theta, omega)
    kinetic = 0.5 * _dot(omega, _mv(M, omega))
    R, p, w, vo, S = kin
    gap = 0.0
    if P.method != TREE:
        pts, d, rate = cut_geometry(P, R, p, w, vo)
        for j in range(d.shape[0]):
            for e in range(2):
                gap = max(gap, math.sqrt(_dot(d[j, e], d[j, e])))
        c, J, gamma = closure_jacobian(P, R, p, w, vo, S, np.zeros((0, 6)))
    else:
        J = np.zeros((0, n))
    return kinetic, spring, gravity_energy, gap, J


@njit(cache=True)
def cut_angles(P, R):
    """Angle of every cut hinge (rad) for body orientations R (n + 1, 3, 3)."""
    m = P.cut_a.shape[0]
    out = np.empty(m)
    for j in range(m):
        out[j] = _cut_angle(P, j, R)[0]
    return out


@njit(cache=True)
def _outer_add(out, scale, u):
    for i in range(u.shape[0]):
        for j in range(u.shape[0]):
            out[i, j] += scale * u[i] * u[j]


@njit(cache=True)
def stiff_jacobian(P, y):
    """The stiff linear part of ``A = d qdd / d theta`` and ``B = d qdd / d omega``, (n, n).

    Keeps only the springs and dampers, at the current configuration: ``A =
    -M^-1 K``, ``B = -M^-1 C`` with ``K = diag(k) + k_s`` on hinges in contact
    (Eq. 2-4), the cut hinges' own spring and contact through their angle
    Jacobian, and for PENALTY ``J^T diag(k_M, k_M, k_M, k_N, k_N) J`` (likewise
    c) with J the closure Jacobian of Eq. (5). For EXACT the same is projected
    onto the constraint (``M^-1 -> M^-1 - Y (J Y)^-1 J M^-1``, ``Y = M^-1 J^T``)
    and the Baumgarte terms ``-Y (J Y)^-1 J / T^2`` (A) and ``2 / T`` (B) are
    added. Velocity products, gravity and the terms of order gap x stiffness
    are left out: they are not stiff, and a W-method does not need them.
    Costs about one RHS call, against 2 n for the finite-difference Jacobian.
    Returns (A, B, ok); ok is False if M is not positive definite.
    """
    n = P.n
    theta = y[:n]
    R, p, w, vo, S = kinematics(P, theta, y[n:2 * n])
    _, M = _crba(P, R, p, S)
    Kq = np.zeros((n, n))
    Cq = np.zeros((n, n))
    for i in range(n):
        contact = contact_mode(theta[i]) != 1
        Kq[i, i] = P.k[i] + (P.k_s if contact else 0.0)
        Cq[i, i] = P.c[i] + (P.c_s if contact else 0.0)
    for j in range(P.cut_a.shape[0]):
        th, g = _cut_angle(P, j, R)
        Jw = np.zeros((3, n))
        _angular_jacobian(P, S, P.cut_b[j], Jw, 1.0)
        _angular_jacobian(P, S, P.cut_a[j], Jw, -1.0)
        G = _vm(g, Jw)
        contact = contact_mode(th) != 1
        _outer_add(Kq, P.cut_k[j] + (P.k_s if contact else 0.0), G)
        _outer_add(Cq, P.cut_c[j] + (P.c_s if contact else 0.0), G)
    if P.method != TREE:
        c, J, _ = closure_jacobian(P, R, p, w, vo, S, np.zeros((0, 6)))
    else:
        J = np.zeros((0, n))
    if P.method == PENALTY:
        for r in range(J.shape[0]):
            on_M = r % 5 < 3
            _outer_add(Kq, P.k_M if on_M else P.k_N, J[r])
            _outer_add(Cq, P.c_M if on_M else P.c_N, J[r])
    L, ok = _cholesky(M)
    A = np.zeros((n, n))
    B = np.zeros((n, n))
    if not ok:
        return A, B, False
    for col in range(n):
        A[:, col] = -_cholesky_solve(L, Kq[:, col].copy())
        B[:, col] = -_cholesky_solve(L, Cq[:, col].copy())
    if P.method == EXACT:
        Y, LA, ok = _constraint_factor(L, J, P.regularisation)
        if not ok:
            return A, B, False
        T = P.baumgarte
        for col in range(n):
            # lambda's response to a unit change of theta[col] / omega[col]
            ra = -_mv(J, A[:, col]) - J[:, col] / (T * T)
            rb = -_mv(J, B[:, col]) - J[:, col] * (2.0 / T)
            A[:, col] += _mv(Y, _cholesky_solve(LA, ra))
            B[:, col] += _mv(Y, _cholesky_solve(LA, rb))
    return A, B, True
