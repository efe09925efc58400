"""Compiled (numba) kernels of the deployment dynamics.

State vector ``y`` (shape ``(2 n + 2,)``): ``theta`` (n, rad), ``omega`` (n,
rad/s), the energy dissipated by all dampers and the air drag since t = 0 (J)
and the work done on the system by the exact-closure constraint forces (J,
zero for penalty).

Algorithm (Featherstone, "Rigid Body Dynamics Algorithms", ch. 5-7), with all
spatial vectors in the ground frame about its origin, angular part first:

* forward kinematics down the tree;
* bias forces (velocity product, gravity, air drag, cut-hinge wrenches) by
  recursive Newton-Euler (RNEA) with zero joint acceleration, O(n);
* ``M qdd = Q - b`` solved in O(n) by the articulated-body algorithm
  (:mod:`.articulated`) from ``articulated.MIN_N`` coordinates (the exact
  closure's ``M^-1 J^T`` by one more solve per constraint row, five per cut
  hinge); else the mass matrix by the composite-rigid-body algorithm (CRBA,
  O(n d) for tree depth d) and Cholesky (O(n^3)).

The dense path stays for small n, where its n^3 / 6 flops cost no more than
the articulated path's 6 x 6 algebra (measured: equal at 11 coordinates, the
paper scene).
:func:`observe` (per sample, not per step) keeps the CRBA mass matrix for the
kinetic energy.

Hinge law, Eq. (2)-(4), with the contact elements in parallel with the hinge
spring (paper, text below Eq. 4): ``tau = -k theta - c omega`` plus, past a
limit, ``-k_s (theta - pi) - c_s omega`` (theta > pi) or ``-k_s theta - c_s
omega`` (theta < 0). So the hinge spring keeps acting in contact; the printed
Eq. (4) drops ``-k theta`` for theta > pi, a difference of k pi against the
k_s term, which dominates within the 0.1 % penetration it allows. A scene's
``contact.stop_ramp`` brings k_s and c_s in smoothly over its first radians
past the limit (:func:`stop_engagement`); 0 is the paper's law.

Every kernel that reaches the panel contacts takes their candidate list
``near`` (:func:`near_pairs`) as a required argument: numba compiles a kernel
apart for each way it is called (an omitted argument, None and a tuple are
three types), and a default of None let the install compile the largest
kernels two or three times over for each kind of model.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .._numba_cache import announce_compilation
from ..boxes import contact as contact_of_boxes
from ..boxes import plane_axes
from ..boxes import scratch as box_scratch
from ..boxes import separating_axis
from . import articulated
from ._jit import FLOAT_MATH
from .pack import EXACT, PENALTY, TREE

# Every kernel module imports this one (collision's through dynamics), so the
# notice is in place before anything compiles.
announce_compilation()

PI = math.pi
#: The zero 3-vector, for wrenches without a torque or a force.
ZERO3 = (0.0, 0.0, 0.0)


@njit(cache=True, **FLOAT_MATH)
def hinge_law(theta, omega, k, c, k_s, c_s, ramp):
    """Torque (N m), stored energy (J) and damper power (W) of one hinge, Eq. (2)-(4),
    the stop's spring and damper coming in over the first ``ramp`` rad past a
    limit (:func:`stop_engagement`; 0: at once, the paper's law)."""
    tau = -k * theta - c * omega
    energy = 0.5 * k * theta * theta
    power = c * omega * omega
    if theta > PI or theta < 0.0:
        d = theta - PI if theta > PI else theta
        a = abs(d)
        if a < ramp:
            x = a / ramp
            spring = k_s * ramp * x ** 3 * (1.0 - 0.5 * x)
            energy += k_s * ramp * ramp * x ** 4 * (0.25 - 0.1 * x)
        else:
            spring = k_s * (a - 0.5 * ramp)
            energy += 0.5 * k_s * a * a - k_s * ramp * (0.5 * a - 0.15 * ramp)
        damping = c_s * stop_engagement(a, ramp)
        tau -= math.copysign(spring, d) + damping * omega
        power += damping * omega * omega
    return tau, energy, power


@njit(cache=True, inline="always", **FLOAT_MATH)
def stop_engagement(depth, ramp):
    """The share (0..1) of k_s and c_s acting at ``depth`` rad past a limit:
    ``3 x^2 - 2 x^3`` of ``x = depth / ramp`` within the ramp, 1 beyond it.

    The paper's stop (ramp 0) takes its whole damper at first touch, so its
    torque jumps there by c_s omega and an explicit step that crosses the
    limit errs by O(h); hinges chattering on their stops in a stowed stack
    then cost most of a run's rejected steps (issue 33, 10 x 10). With the
    ramp the spring's torque is twice continuously differentiable in theta
    (its stiffness is k_s times this share) and the damper's once, as Hunt
    and Crossley's impact law removes the jump of a linear dashpot at first
    touch.
    """
    if depth >= ramp:
        return 1.0
    x = depth / ramp
    return x * x * (3.0 - 2.0 * x)


@njit(cache=True, **FLOAT_MATH)
def contact_mode(theta):
    """0 below the flat limit, 1 within [0, pi], 2 past the folded limit."""
    return 0 if theta < 0.0 else (2 if theta > PI else 1)


# --- small vectors ---
# 3-vectors travel as tuples, which numba keeps in registers: an array
# temporary costs a heap allocation, which dominated the kernels' run time.

@njit(cache=True, **FLOAT_MATH)
def _dot(a, b):
    """a . b for 1-d arrays or tuples of equal length."""
    s = 0.0
    for i in range(len(a)):
        s += a[i] * b[i]
    return s


@njit(cache=True, **FLOAT_MATH)
def _mv(A, x):
    """A @ x for small arrays without a BLAS call (whose overhead dominates here)."""
    out = np.zeros(A.shape[0])
    for i in range(A.shape[0]):
        s = 0.0
        for j in range(A.shape[1]):
            s += A[i, j] * x[j]
        out[i] = s
    return out


@njit(cache=True, **FLOAT_MATH)
def _matmul(A, B):
    """A @ B for small arrays, each entry summed in index order."""
    out = np.zeros((A.shape[0], B.shape[1]))
    for i in range(A.shape[0]):
        for k in range(A.shape[1]):
            a = A[i, k]
            for j in range(B.shape[1]):
                out[i, j] += a * B[k, j]
    return out


@njit(cache=True, **FLOAT_MATH)
def _get(A, i, o=0):
    """``A[i, o:o + 3]`` as a tuple."""
    return (A[i, o], A[i, o + 1], A[i, o + 2])


@njit(cache=True, **FLOAT_MATH)
def _put(A, i, v, o=0):
    """``A[i, o:o + 3] = v``."""
    A[i, o] = v[0]
    A[i, o + 1] = v[1]
    A[i, o + 2] = v[2]


@njit(cache=True, **FLOAT_MATH)
def _add(a, b):
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2])


@njit(cache=True, **FLOAT_MATH)
def _sub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


@njit(cache=True, **FLOAT_MATH)
def _scale(a, s):
    return (a[0] * s, a[1] * s, a[2] * s)


@njit(cache=True, **FLOAT_MATH)
def _cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


@njit(cache=True, **FLOAT_MATH)
def _rotate(R, b, x):
    """``R[b] @ x`` for orientations R (k, 3, 3) and a 3-vector x."""
    return (R[b, 0, 0] * x[0] + R[b, 0, 1] * x[1] + R[b, 0, 2] * x[2],
            R[b, 1, 0] * x[0] + R[b, 1, 1] * x[1] + R[b, 1, 2] * x[2],
            R[b, 2, 0] * x[0] + R[b, 2, 1] * x[1] + R[b, 2, 2] * x[2])


@njit(cache=True, **FLOAT_MATH)
def _rotation(axis, angle):
    """Rows of the rotation by ``angle`` (rad) about the unit ``axis`` (Rodrigues)."""
    x, y, z = axis[0], axis[1], axis[2]
    c, s = math.cos(angle), math.sin(angle)
    C = 1.0 - c
    return ((c + x * x * C, x * y * C - z * s, x * z * C + y * s),
            (y * x * C + z * s, c + y * y * C, y * z * C - x * s),
            (z * x * C - y * s, z * y * C + x * s, c + z * z * C))


@njit(cache=True, **FLOAT_MATH)
def _carried(P, R, p, b, x):
    """Current position (m) of body b's material point that sits at x in the flat state."""
    return _add(_get(p, b), _rotate(R, b, _sub(x, _get(P.r0, b))))


@njit(cache=True, **FLOAT_MATH)
def _point_velocity(w, vo, b, x):
    """Velocity (m/s) of body b's material point at x."""
    return _add(_get(vo, b), _cross(_get(w, b), x))


@njit(cache=True, **FLOAT_MATH)
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
    R = np.zeros((n + 1, 3, 3))
    p = np.empty((n + 1, 3))
    w = np.zeros((n + 1, 3))
    vo = np.zeros((n + 1, 3))
    S = np.empty((n, 6))
    for r in range(3):
        R[n, r, r] = 1.0
    _put(p, n, _get(P.r0, n))
    for i in range(n):
        a = P.parent[i]
        rot = _rotation(_get(P.axis, i), theta[i])
        for r in range(3):
            x0, x1, x2 = R[a, r, 0], R[a, r, 1], R[a, r, 2]
            for c in range(3):
                R[i, r, c] = x0 * rot[0][c] + x1 * rot[1][c] + x2 * rot[2][c]
        h = _carried(P, R, p, a, _get(P.point, i))
        u = _rotate(R, a, _get(P.axis, i))
        _put(p, i, _add(h, _rotate(R, i, _sub(_get(P.r0, i), _get(P.point, i)))))
        hu = _cross(h, u)
        _put(S, i, u)
        _put(S, i, hu, 3)
        _put(w, i, _add(_get(w, a), _scale(u, omega[i])))
        _put(vo, i, _add(_get(vo, a), _scale(hu, omega[i])))
    return R, p, w, vo, S


@njit(cache=True, **FLOAT_MATH)
def body_states(P, theta, omega):
    """Pose and velocity of every body in model body order (``P.body``).

    Returns the rotations (nb, 3, 3), centroids (nb, 3) m, centroid
    velocities (nb, 3) m/s and angular velocities (nb, 3) rad/s, in the
    ground frame, from :func:`kinematics`, whose ``vo`` is the velocity of
    the body point at the ground origin, not of the centroid.
    """
    Rk, pk, wk, vo, _ = kinematics(P, theta, omega)
    nb = P.n + 1
    R = np.empty((nb, 3, 3))
    p = np.empty((nb, 3))
    v = np.empty((nb, 3))
    w = np.empty((nb, 3))
    for i in range(nb):
        b = P.body[i]
        R[b] = Rk[i]
        p[b] = pk[i]
        w[b] = wk[i]
        _put(v, b, _add(_get(vo, i), _cross(_get(wk, i), _get(pk, i))))
    return R, p, v, w


# --- spatial inertia ---
# About the ground origin a body of mass m, centroid c, is [[J, [h]x],
# [-[h]x, m 1]] with J = R I R^T - m [c]x^2 and h = m c; a composite body is
# the sum, so (J, h, m) describe both without 6 x 6 matrices.

@njit(cache=True, **FLOAT_MATH)
def _angular_inertia(P, R, p, i, out):
    """Write J of body i (kg m^2, see above) to out[i] (k, 3, 3)."""
    m = P.mass[i]
    c = _get(p, i)
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
def _inertia_times(J, i, h, m, xw, xv):
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
def _dot6(A, i, fw, fv):
    """``A[i, :6] . (fw, fv)``, summed in index order."""
    return (A[i, 0] * fw[0] + A[i, 1] * fw[1] + A[i, 2] * fw[2]
            + A[i, 3] * fv[0] + A[i, 4] * fv[1] + A[i, 5] * fv[2])


@njit(cache=True, **FLOAT_MATH)
def _point_jacobian(P, S, b, x, out, row, sign):
    """Add ``sign`` times d(velocity of body b's material point at x)/d omega
    to out[row:row + 3] (k, n)."""
    while b < P.n:
        v = _add(_get(S, b, 3), _cross(_get(S, b), x))
        for k in range(3):
            out[row + k, b] += sign * v[k]
        b = P.parent[b]


@njit(cache=True, **FLOAT_MATH)
def _angular_jacobian(P, S, b, out, row, sign):
    """Add ``sign`` times d(angular velocity of body b)/d omega to out[row:row + 3] (k, n)."""
    while b < P.n:
        for k in range(3):
            out[row + k, b] += sign * S[b, k]
        b = P.parent[b]


@njit(cache=True, **FLOAT_MATH)
def _point_bias_acceleration(acc, w, vo, b, x):
    """Acceleration of body b's material point at x when qdd = 0 (velocity products only)."""
    wb = _get(w, b)
    return _add(_add(_get(acc, b, 3), _cross(_get(acc, b), x)),
                _cross(wb, _add(_get(vo, b), _cross(wb, x))))


@njit(cache=True, **FLOAT_MATH)
def _cut_angle(P, j, R):
    """Cut-hinge angle (rad, continuous on (-pi/2, 3pi/2]) and its exact rate axis g (3-tuple).

    theta = atan2(e2 . f, e1 . f) with f = R_b e1 and e1, e2 carried by body a;
    d theta / dt = g . (w_b - w_a) for any relative orientation (not only a pure
    rotation about the axis), so torque and energy stay consistent.
    """
    a, b = P.cut_a[j], P.cut_b[j]
    f = _rotate(R, b, _get(P.cut_e1, j))
    e1 = _rotate(R, a, _get(P.cut_e1, j))
    e2 = _rotate(R, a, _get(P.cut_e2, j))
    x = _dot(e1, f)
    y = _dot(e2, f)
    theta = math.atan2(y, x)
    if theta < -0.5 * PI:
        theta += 2.0 * PI
    d = x * x + y * y
    g = _cross(f, _sub(_scale(e2, x), _scale(e1, y)))
    return theta, (g[0] / d, g[1] / d, g[2] / d)


@njit(cache=True, **FLOAT_MATH)
def _cut_ends(P, j, R, p):
    """Ends (M_a, N_a, M_b, N_b) of cut hinge j as carried by its bodies a and b, m."""
    M = _get(P.cut_point, j)
    N = _add(M, _scale(_get(P.cut_axis, j), P.cut_length[j]))
    a, b = P.cut_a[j], P.cut_b[j]
    return (_carried(P, R, p, a, M), _carried(P, R, p, a, N),
            _carried(P, R, p, b, M), _carried(P, R, p, b, N))


@njit(cache=True, **FLOAT_MATH)
def largest_gap(P, R, p):
    """Largest loop-closure gap |M_b - M_a| or |N_b - N_a| over the cut hinges, m."""
    out = 0.0
    for j in range(P.cut_a.shape[0]):
        Ma, Na, Mb, Nb = _cut_ends(P, j, R, p)
        dM, dN = _sub(Mb, Ma), _sub(Nb, Na)
        out = max(out, math.sqrt(_dot(dM, dM)), math.sqrt(_dot(dN, dN)))
    return out


@njit(cache=True, **FLOAT_MATH)
def loop_residual(P, theta):
    """How far tree angles ``theta`` (rad) are from closing every loop: per cut
    hinge j, row j holds M_b - M_a and N_b - N_a (m, the gaps of its two ends,
    :func:`_cut_ends`) and its angle (rad, :func:`_cut_angle`); (m, 7)."""
    R, p, _, _, _ = kinematics(P, theta, np.zeros(theta.shape[0]))
    out = np.empty((P.cut_a.shape[0], 7))
    for j in range(P.cut_a.shape[0]):
        Ma, Na, Mb, Nb = _cut_ends(P, j, R, p)
        for i in range(3):
            out[j, i] = Mb[i] - Ma[i]
            out[j, 3 + i] = Nb[i] - Na[i]
        out[j, 6] = _cut_angle(P, j, R)[0]
    return out


@njit(cache=True, **FLOAT_MATH)
def _add_wrench(F, body, torque, force, point):
    """Add a force applied at ``point`` plus a torque to body's wrench about the origin."""
    t = _add(torque, _cross(point, force))
    for k in range(3):
        F[body, k] += t[k]
        F[body, 3 + k] += force[k]


@njit(cache=True, **FLOAT_MATH)
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
    for j in range(P.cut_a.shape[0]):
        a, b = P.cut_a[j], P.cut_b[j]
        theta, g = _cut_angle(P, j, R)
        omega = _dot(g, _sub(_get(w, b), _get(w, a)))
        tau, e, pw = hinge_law(theta, omega, P.cut_k[j], P.cut_c[j], P.k_s, P.c_s, P.stop_ramp)
        energy += e
        power += pw
        _add_wrench(F, b, _scale(g, tau), ZERO3, ZERO3)
        _add_wrench(F, a, _scale(g, -tau), ZERO3, ZERO3)
        if P.method != PENALTY:
            continue
        Ma, Na, Mb, Nb = _cut_ends(P, j, R, p)
        dM = _sub(Mb, Ma)
        vM = _sub(_point_velocity(w, vo, b, Mb), _point_velocity(w, vo, a, Ma))
        fM = _sub(_scale(dM, -P.k_M), _scale(vM, P.c_M))
        energy += 0.5 * P.k_M * _dot(dM, dM)
        power += P.c_M * _dot(vM, vM)
        _add_wrench(F, b, ZERO3, fM, Mb)
        _add_wrench(F, a, ZERO3, _scale(fM, -1.0), Ma)
        u = _rotate(R, a, _get(P.cut_axis, j))
        dN = _sub(Nb, Na)
        vN = _sub(_point_velocity(w, vo, b, Nb), _point_velocity(w, vo, a, Na))
        dNp = _sub(dN, _scale(u, _dot(u, dN)))
        vNp = _sub(vN, _scale(u, _dot(u, vN)))
        fN = _sub(_scale(dNp, -P.k_N), _scale(vNp, P.c_N))
        energy += 0.5 * P.k_N * _dot(dNp, dNp)
        power += P.c_N * _dot(vNp, vNp)
        _add_wrench(F, b, ZERO3, fN, Nb)
        _add_wrench(F, a, _scale(_cross(u, dN), P.k_N * _dot(u, dN)), _scale(fN, -1.0), Na)
    return F, energy, power


@njit(cache=True, **FLOAT_MATH)
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
    # rows 0-2: d(N_b - N_a)/d omega, rows 3-5: d(w_a)/d omega, of one cut
    work = np.empty((6, n))
    with_gamma = acc.shape[0] > 0
    for j in range(m):
        a, b = P.cut_a[j], P.cut_b[j]
        r = 5 * j
        Ma, Na, Mb, Nb = _cut_ends(P, j, R, p)
        dM = _sub(Mb, Ma)
        for k in range(3):
            c[r + k] = dM[k]
        _point_jacobian(P, S, b, Mb, J, r, 1.0)
        _point_jacobian(P, S, a, Ma, J, r, -1.0)
        work[:] = 0.0
        _point_jacobian(P, S, b, Nb, work, 0, 1.0)
        _point_jacobian(P, S, a, Na, work, 0, -1.0)
        _angular_jacobian(P, S, a, work, 3, 1.0)
        dN = _sub(Nb, Na)
        vN = _sub(_point_velocity(w, vo, b, Nb), _point_velocity(w, vo, a, Na))
        if with_gamma:
            gM = _sub(_point_bias_acceleration(acc, w, vo, b, Mb),
                      _point_bias_acceleration(acc, w, vo, a, Ma))
            for k in range(3):
                gamma[r + k] = gM[k]
            aN = _sub(_point_bias_acceleration(acc, w, vo, b, Nb),
                      _point_bias_acceleration(acc, w, vo, a, Na))
        for k in range(2):
            e = _rotate(R, a, _get(P.cut_e1 if k == 0 else P.cut_e2, j))
            c[r + 3 + k] = _dot(e, dN)
            t = _cross(e, dN)
            for col in range(n):
                JN = e[0] * work[0, col] + e[1] * work[1, col] + e[2] * work[2, col]
                Jw = t[0] * work[3, col] + t[1] * work[4, col] + t[2] * work[5, col]
                J[r + 3 + k, col] = JN + Jw
            if with_gamma:
                wa = _get(w, a)
                edot = _cross(wa, e)
                eddot = _add(_cross(_get(acc, a), e), _cross(wa, edot))
                gamma[r + 3 + k] = _dot(e, aN) + 2.0 * _dot(edot, vN) + _dot(eddot, dN)
    return c, J, gamma


@njit(cache=True, **FLOAT_MATH)
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


@njit(cache=True, **FLOAT_MATH)
def _cholesky_solve(L, X):
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
def _constraint_factor(L, J, regularisation):
    """Y = M^-1 J^T and the Cholesky factor of the regularised J M^-1 J^T
    (:func:`_regularised_cholesky`); ``L`` is the Cholesky factor of M. Returns ``(Y, LA, ok)``."""
    Y = J.T.copy()
    _cholesky_solve(L, Y)
    LA, ok = _regularised_cholesky(_matmul(J, Y), regularisation)
    return Y, LA, ok


@njit(cache=True, **FLOAT_MATH)
def _articulated_closure(P, S, UA, D, Q, c, J, gamma, omega, qdd):
    """Write to qdd (n,) the exact closure's joint accelerations
    (:func:`_exact_closure`'s) with M factored by the articulated-body
    algorithm (:func:`articulated.factor`'s (UA, D)), no n x n matrix:
    Q and the rows of J (mc, n) go up the tree in one pass
    (:func:`articulated.up_rows`); J M^-1 J^T and J M^-1 Q are sums over
    their innovations, and only ``Q + J^T lam`` goes back down, in place of
    1 + mc rows. Returns (the constraint forces' power (W), ok); ok is False
    where the regularised J M^-1 J^T is not positive definite."""
    n, mc = P.n, J.shape[0]
    rows = np.empty((1 + mc, n))
    rows[0] = Q
    rows[1:] = J
    E = np.empty((1 + mc, n))
    work = np.empty((1 + mc, n + 1, 6))
    articulated.up_rows(P, S, UA, D, rows, E, work)
    A = np.zeros((mc, mc))
    b = np.zeros(mc)
    for i in range(n):
        inv = 1.0 / D[i]
        for r in range(mc):
            er = E[1 + r, i] * inv
            b[r] += er * E[0, i]
            for s in range(r + 1):
                A[r, s] += er * E[1 + s, i]
    for r in range(mc):
        for s in range(r):
            A[s, r] = A[r, s]
    LA, ok = _regularised_cholesky(A, P.regularisation)
    if not ok:
        return 0.0, False
    lam, cdot = _multipliers(P, c, J, gamma, omega, b, LA)
    qdd[:] = E[0]
    for r in range(mc):
        for i in range(n):
            qdd[i] += lam[r] * E[1 + r, i]
    articulated.down_rows(P, S, UA, D, qdd.reshape((1, n)), work[:1])
    return _dot(lam, cdot), True


@njit(cache=True, inline="always", **FLOAT_MATH)
def _regularised_cholesky(A, regularisation):
    """Cholesky factor of A = J M^-1 J^T (mc, mc, overwritten) + a Tikhonov
    term, relative to its largest diagonal entry, which keeps it defined
    through rank loss of the closure Jacobian (the stowed and flat-aligned
    singular states): ``(LA, ok)``."""
    mc = A.shape[0]
    scale = 0.0
    for r in range(mc):
        scale = max(scale, A[r, r])
    for r in range(mc):
        A[r, r] += regularisation * scale + 1e-300
    return _cholesky(A)


@njit(cache=True, inline="always", **FLOAT_MATH)
def _multipliers(P, c, J, gamma, omega, Jqdd, LA):
    """The exact closure's Lagrange multipliers (Baumgarte-stabilised, time
    constant ``P.baumgarte``) from :func:`closure_jacobian`'s (c, J, gamma),
    J times the tree's qdd, ``Jqdd`` (mc,), and the factor LA of the
    regularised J M^-1 J^T: ``(lam, J omega)``."""
    T = P.baumgarte
    cdot = _mv(J, omega)
    lam = np.empty(J.shape[0])
    for r in range(J.shape[0]):
        lam[r] = (-gamma[r] - (2.0 / T) * cdot[r] - c[r] / (T * T)) - Jqdd[r]
    _cholesky_solve(LA, lam.reshape((lam.shape[0], 1)))
    return lam, cdot


@njit(cache=True, inline="always", **FLOAT_MATH)
def _exact_closure(P, c, J, gamma, Y, LA, omega, qdd):
    """Add to the tree's qdd (n,) the exact closure's Lagrange multiplier term
    (:func:`_multipliers`) from :func:`closure_jacobian`'s (c, J, gamma) and
    :func:`_constraint_factor`'s (Y, LA) of the dense M. Returns the
    constraint forces' power, W."""
    n = P.n
    lam, cdot = _multipliers(P, c, J, gamma, omega, _mv(J, qdd), LA)
    for i in range(n):
        s = 0.0
        for r in range(J.shape[0]):
            s += Y[i, r] * lam[r]
        qdd[i] += s
    return _dot(lam, cdot)


@njit(cache=True, inline="always", **FLOAT_MATH)
def body_inertias(P, R, p):
    """Angular inertias J (n, 3, 3, kg m^2, see above) and first moments h = m c
    (n, 3, kg m) of the bodies about the ground origin."""
    n = P.n
    Jb = np.empty((n, 3, 3))
    hb = np.empty((n, 3))
    for i in range(n):
        _angular_inertia(P, R, p, i, Jb)
        _put(hb, i, _scale(_get(p, i), P.mass[i]))
    return Jb, hb


@njit(cache=True, **FLOAT_MATH)
def mass_matrix(P, S, Jb, hb):
    """The mass matrix (n, n) from :func:`body_inertias`' (J, h)."""
    n = P.n
    # composite bodies (Jc, hc, mc), accumulated leaves first; h and m share
    # one array (an allocation costs the paper scene's rhs ~1 %)
    Jc = Jb.copy()
    hm = np.empty((n, 4))
    for i in range(n):
        _put(hm, i, _get(hb, i))
        hm[i, 3] = P.mass[i]
    for i in range(n - 1, -1, -1):
        a = P.parent[i]
        if a < n:
            for r in range(3):
                for q in range(3):
                    Jc[a, r, q] += Jc[i, r, q]
            for k in range(4):
                hm[a, k] += hm[i, k]
    M = np.zeros((n, n))
    for i in range(n):
        Fw, Fv = _inertia_times(Jc, i, _get(hm, i), hm[i, 3], _get(S, i), _get(S, i, 3))
        M[i, i] = _dot6(S, i, Fw, Fv)
        j = P.parent[i]
        while j < n:
            M[i, j] = M[j, i] = _dot6(S, j, Fw, Fv)
            j = P.parent[j]
    return M


# --- air drag on the panel faces ---
# A point of a body's mid-plane at (s, r) from the centroid along the body's x
# and y axes moves along the face normal n at u = v0 + a s + b r: v0 = n . v_c,
# a = -w . e_y, b = w . e_x. The pressure -q |u| u (q = 1/2 rho C_d) acts once
# per point: the two large faces meet the air on opposite sides, so their net
# is one face area with the signed u. It is -q u^2 where u > 0 and q u^2 where
# u < 0, a polynomial on each side of the line u = 0. Split along a diagonal,
# the face is two triangles, and the line cuts each into a triangle and a
# quadrilateral (the triangle less a corner): integrated exactly (to
# round-off) on those, there is no quadrature error at the kink and no
# division by a or b (a closed form in corner values of |u|^3 u / (a b)
# cancels catastrophically as a, b -> 0).

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
    corners = _add(_add(_u2_moments(v0, a, b, p[0], p[1]), _u2_moments(v0, a, b, q[0], q[1])),
                   _u2_moments(v0, a, b, t[0], t[1]))
    mids = _add(_add(_u2_moments(v0, a, b, 0.5 * (p[0] + q[0]), 0.5 * (p[1] + q[1])),
                     _u2_moments(v0, a, b, 0.5 * (q[0] + t[0]), 0.5 * (q[1] + t[1]))),
                _u2_moments(v0, a, b, 0.5 * (t[0] + p[0]), 0.5 * (t[1] + p[1])))
    centre = _u2_moments(v0, a, b, (p[0] + q[0] + t[0]) / 3.0, (p[1] + q[1] + t[1]) / 3.0)
    return _scale(_add(_add(_scale(corners, _W_VERTEX), _scale(mids, _W_MID)),
                       _scale(centre, _W_CENTRE)), area)


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
        return ZERO3
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
    return corner if count == 1 else _sub(whole, corner)


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
        return _scale(whole, -1.0)
    c0, c1, c2, c3 = (-A, -B), (A, -B), (A, B), (-A, B)
    positive = _add(_positive_part(v0, a, b, c0, c1, c2), _positive_part(v0, a, b, c0, c2, c3))
    # |u| u is u^2 where u > 0 and -u^2 elsewhere
    return _sub(_scale(positive, 2.0), whole)


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
    v0 = _dot(n, v)
    a = -_dot(w, e2)
    b = _dot(w, e1)
    I0, Is, Ir = face_drag(v0, a, b, air[i, 0], air[i, 1])
    q = air[i, 2]
    # (s e1 + r e2) x n = r e1 - s e2, times the pressure -q |u| u
    torque = _scale(_sub(_scale(e2, Is), _scale(e1, Ir)), q)
    return _scale(n, -q * I0), torque, q * (v0 * I0 + a * Is + b * Ir)


@njit(cache=True, **FLOAT_MATH)
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
        pi, wi = _get(p, i), _get(w, i)
        force, torque, pw = body_drag(air, R, i, _add(_get(vo, i), _cross(wi, pi)), wi)
        _put(f, i, _sub(_get(f, i), _add(torque, _cross(pi, force))))
        _put(f, i, _sub(_get(f, i, 3), force), 3)
        power += pw
    return power


#: Depth (m) over which a panel contact comes in: below it the spring force
#: is k d^2 / (2 D) and the damping c d / D, so that the push and its
#: stiffness grow from zero at first touch. A contact in full at once makes
#: the push (and the Jacobian) jump, and a step across it must shrink to
#: where the jump no longer matters. A face pressed with up to 50 N (k_p =
#: 1e7 N/m) sits on the ramp, a tenth of the collision tolerance deep at most.
CONTACT_RAMP = 1e-5


@njit(cache=True, **FLOAT_MATH)
def _contact_law(depth, speed, k, c):
    """One contact point at depth > 0 (m) approaching at speed (m/s), see
    ``CONTACT_RAMP``: its push (N, never a pull), the spring's share of it
    (N) and energy (J), and d spring / d depth (N/m) and the damping (N s/m)
    at that depth; k and c are the full stiffness (N/m) and damping (N s/m)."""
    D = CONTACT_RAMP
    if depth < D:
        spring, energy, stiffness, damping = (0.5 * k * depth * depth / D, k * depth ** 3 / (6.0 * D),
                                              k * depth / D, c * depth / D)
    else:
        spring, stiffness, damping = k * (depth - 0.5 * D), k, c
        energy = k * (0.5 * depth * depth - 0.5 * D * depth + D * D / 6.0)
    return max(0.0, spring + damping * speed), spring, energy, stiffness, damping


@njit(cache=True, **FLOAT_MATH)
def _boxes(P, R, p):
    """The axis-aligned box around every body at poses (R, p): (n + 1, 2, 3),
    its lower and upper corners (m), once per call for :func:`_pair_apart`."""
    out = np.empty((P.n + 1, 2, 3))
    for i in range(P.n + 1):
        for k in range(3):
            e = (abs(R[i, k, 0]) * P.half[i, 0] + abs(R[i, k, 1]) * P.half[i, 1]
                 + abs(R[i, k, 2]) * P.half[i, 2])
            out[i, 0, k] = p[i, k] - e
            out[i, 1, k] = p[i, k] + e
    return out


@njit(cache=True, inline="always", **FLOAT_MATH)
def _box_gap(contact, r, box):
    """The gap (m) between the :func:`_boxes` of pair r of ``P.contact``
    along the ground axis that parts them most (< 0: they overlap)."""
    a, b = int(contact[r, 0]), int(contact[r, 1])
    gap = -np.inf
    for k in range(3):
        gap = max(gap, box[a, 0, k] - box[b, 1, k], box[b, 0, k] - box[a, 1, k])
    return gap


@njit(cache=True, inline="always", **FLOAT_MATH)
def _pair_apart(contact, r, box, margin=0.0):
    """Whether the :func:`_boxes` of pair r of ``P.contact`` are apart by at
    least ``margin`` (m; boxes that only touch are apart, a contact needs
    some depth): the test that spares most pairs of a large array the
    separating axes."""
    return _box_gap(contact, r, box) >= margin


#: Margin of the candidate list of panel contact pairs (:func:`near_pairs`),
#: m: a pair is listed while its boxes are less than this apart, and the list
#: is rebuilt once any box corner has moved half of it. Measured on the 10 x
#: 10 array (3569 pairs, panels 0.1 m): 5 mm lists 30-330 pairs and is rebuilt
#: every ~10 right-hand sides in the stowed stacks.
NEAR_MARGIN = 0.005


@njit(cache=True, **FLOAT_MATH)
def near_pairs(P):
    """An empty candidate list of the pairs of ``P.contact`` for
    :func:`rhs`, a tuple:

    0. the :func:`_boxes` it was built at (n + 1, 2, 3), NaN until its first use;
    1. the listed pairs' rows (q,) and 2. their count (1,);
    3. each pair's last separating axis (q,) (:func:`boxes.separating_axis`);
    4. the bodies' rotations (n + 1, 3, 3) and 5. centres (n + 1, 3), m, when
       it was built, and 6. how far any point of each body has moved since (n + 1,), m;
    7. each pair's slack (q,), m: how much further its two bodies may move
       together (by 6.) and stay apart, as the last test of the pair found it;
    8. the fastest contact onset the last :func:`panel_contacts` call met
       (9,), laid out as ``result.ONSET_COLUMNS``, its time NaN (the call
       does not know it) and its speed 0 for none: the step loops take the
       onsets of an accepted step from its last evaluation
       (:func:`take_onsets`), which was at the step's end.

    Mutable scratch of one run, never shared between runs: 0.-7. only spare
    :func:`panel_contacts` the tests of pairs that cannot touch, so a run
    gives the same result to the bit with it as without."""
    q = P.contact.shape[0]
    return (np.full((P.n + 1, 2, 3), np.nan), np.empty(q, np.int64), np.zeros(1, np.int64),
            np.zeros(q, np.int64), np.empty((P.n + 1, 3, 3)), np.empty((P.n + 1, 3)),
            np.empty(P.n + 1), np.full(q, -np.inf), np.zeros(9))


#: Rounding allowance of a pair's slack (:func:`near_pairs`), m: a pair skipped
#: on its slack is apart by more than this, far beyond the separating-axis
#: test's rounding (~1e-16 m on panels of 0.1-1 m), so that test would find it
#: apart too.
SLACK_ROUNDING = 1e-9


@njit(cache=True, **FLOAT_MATH)
def _near_rows(P, box, R, p, near):
    """The rows of ``P.contact`` whose :func:`_boxes` ``box`` may overlap, from
    the candidate list ``near`` (:func:`near_pairs`), rebuilt first if a box
    corner moved more than NEAR_MARGIN / 2 since it was built, and each
    body's motion since then at poses (R, p). A pair left out was
    NEAR_MARGIN apart along some axis then, and each of its boxes has moved
    at most half of that since: it is apart now, as :func:`_pair_apart`
    (``>=``) would find it."""
    contact = P.contact
    built, rows, count, R0, p0, moved, slack = near[0], near[1], near[2], near[4], near[5], near[6], near[7]
    half = 0.5 * NEAR_MARGIN
    stale = False
    for x, x0 in zip(box.ravel(), built.ravel()):
        if not abs(x - x0) <= half:  # NaN: not built yet
            stale = True
            break
    if stale:
        built[:] = box
        R0[:] = R
        p0[:] = p
        slack[:] = -np.inf
        m = 0
        for r in range(contact.shape[0]):
            if not _pair_apart(contact, r, box, NEAR_MARGIN):
                rows[m] = r
                m += 1
        count[0] = m
    for i in range(P.n + 1):
        # |dp| + |dR|_F |h| bounds the motion of every point p + R u, |u| <= |h|
        dp, dR = 0.0, 0.0
        for k in range(3):
            dp += (p[i, k] - p0[i, k]) ** 2
            for m in range(3):
                dR += (R[i, k, m] - R0[i, k, m]) ** 2
        h = P.half[i]
        moved[i] = math.sqrt(dp) + math.sqrt(dR) * math.sqrt(h[0] * h[0] + h[1] * h[1] + h[2] * h[2])
    return rows[:count[0]]


@njit(cache=True, **FLOAT_MATH)
def _touching(P, R, p, near):
    """The rows of ``P.contact`` whose pairs may touch at poses
    (R, p): every other pair is apart, and :func:`_pair_points` would find
    no point of it.

    Of the pairs on the candidate list ``near`` (:func:`near_pairs`): those
    whose bodies have moved less than their slack since their last test are
    apart; the rest get the box test, then the separating axes, the one that separated
    the pair last first (while an array deploys, most pairs whose boxes
    overlap are apart: 221 of 222 on 10 x 10 at 0.1 s), and the gap found
    sets the slack. One loop here, not a call a pair: passing the list to a
    function costs ~60 ns a call in reference counts, more than the test.
    """
    contact = P.contact
    box = _boxes(P, R, p)
    rows = _near_rows(P, box, R, p, near)
    axes, moved, slack = near[3], near[6], near[7]
    out = np.empty(rows.shape[0], np.int64)
    m = 0
    for r in rows:
        a, b = int(contact[r, 0]), int(contact[r, 1])
        if moved[a] + moved[b] < slack[r]:
            continue
        gap = _box_gap(contact, r, box)
        if not gap >= 0.0:  # NaN poses as well: the contact is left to find them
            k, overlap = separating_axis(R[a], p[a], contact[r, 2:5], R[b], p[b], contact[r, 5:8], axes[r])
            if k < 0:
                out[m] = r
                m += 1
                continue
            axes[r], gap = k, -overlap
        # apart by gap now, so by gap - (moved now + moved later) later
        slack[r] = gap - moved[a] - moved[b] - SLACK_ROUNDING
    return out[:m]


@njit(cache=True, **FLOAT_MATH)
def _pair_points(P, r, R, p, work):
    """Contact points of pair r of ``P.contact`` (:func:`boxes.contact`): their
    number and the normal from the pair's first body towards its second;
    points, depths and weights are left in work; callers first skip the
    pairs :func:`_touching` rules out."""
    contact = P.contact
    a, b = int(contact[r, 0]), int(contact[r, 1])
    return contact_of_boxes(R[a], p[a], contact[r, 2:5], R[b], p[b], contact[r, 5:8], work,
                            contact[r, 12] != 0.0)


@njit(cache=True, **FLOAT_MATH)
def panel_contacts(P, R, p, w, vo, f, near):
    """Subtract the panel-contact wrenches from f (n + 1, 6), the bias wrenches
    about the ground origin; returns the contact energy (J) and the power its
    dampers dissipate (W).

    Per contact point of a pair of ``P.contact`` (:mod:`panel_deploy.contacts`,
    :func:`panel_deploy.boxes.contact`) at depth d > 0, approaching at s (the
    normal speed of the pair's first body's point there relative to the
    second's), a push ``max(0, k d + c s)`` along the normal on the two
    bodies, k and c its weight's share of k_p and c_p: a spring and damper that never
    pulls (one that pulled would glue parting panels together), both coming
    in over the first ``CONTACT_RAMP`` of depth (:func:`_contact_law`). The
    spring stores its energy; the rest of the push's work, (push - spring) s
    >= 0, is dissipated (s is d's rate up to the motion of the point).
    With a friction coefficient mu (``contact[r, 10]``) > 0, the point's
    :func:`_friction` opposes the slip, and dissipates all its work.
    0, 0 where ``P.contact`` has no rows (no panel contact);
    ``near`` is the run's candidate list (:func:`near_pairs`), which also
    gets the fastest onset met (its item 8).

    An onset is a contact point shallower than CONTACT_RAMP (where the
    force is not yet in full), its speed the approach speed there: a
    contact stops an impact within a step or two, so the speed of its
    shallow points at the steps' ends is the impact's (the samples would
    miss it: the contact absorbed a 4.2 m/s impact between two samples,
    issue 33). Every shallow point, not a pair's first: a face coming down
    may touch first at one slow point, its fast corners a step later (the
    paper scene's r1c2+r1c3 on r2c4, 50 us samples: one point at 0.000 m/s,
    the next sample another at 0.097 m/s; r4c1 on r4c4 was missed so, one
    point pressing a step before its four), and a pair resting in light
    contact can still be struck.
    """
    contact = P.contact
    if contact.shape[0] == 0:
        return 0.0, 0.0
    energy = 0.0
    power = 0.0
    work = box_scratch()
    points, depths, weights = work[-3], work[-2], work[-1]
    onset = near[8]
    onset[0], onset[1] = np.nan, 0.0
    for r in _touching(P, R, p, near):
        count, normal = _pair_points(P, r, R, p, work)
        a, b = int(contact[r, 0]), int(contact[r, 1])
        mu, v_f = contact[r, 10], contact[r, 11]
        for q in range(count):
            depth = depths[q]
            x = (points[q, 0], points[q, 1], points[q, 2])
            relative = _sub(_point_velocity(w, vo, a, x), _point_velocity(w, vo, b, x))
            speed = _dot(normal, relative)
            if depth < CONTACT_RAMP and speed > onset[1]:
                onset[1], onset[2] = speed, r
                onset[3], onset[4], onset[5] = x
                onset[6], onset[7], onset[8] = normal
            push, spring, e, _, _ = _contact_law(depth, speed, weights[q] * contact[r, 8],
                                                 weights[q] * contact[r, 9])
            energy += e
            power += (push - spring) * speed
            force = _scale(normal, push)  # on b, as the friction: f holds minus the force on a
            if mu > 0.0:
                friction, loss = _friction(_sub(relative, _scale(normal, speed)), mu * push, v_f)
                force = _add(force, friction)
                power += loss
            _add_wrench(f, a, ZERO3, force, x)
            _add_wrench(f, b, ZERO3, _scale(force, -1.0), x)
    return energy, power


@njit(cache=True, inline="always", **FLOAT_MATH)
def _friction(slip, limit, v_f):
    """Regularised Coulomb friction at a contact point slipping at ``slip``
    (3-tuple, m/s: the first body's point relative to the second's, in the
    contact plane) under a normal push of mu times ``limit`` (N): the force
    on the second body, ``limit slip / sqrt(|slip|^2 + v_f^2)`` (N), and the
    power it dissipates (W). Below the slip speed v_f (m/s) it is a damper
    of ``limit / v_f`` (N s/m), so that sticking is a slow creep and the
    force is smooth: Coulomb's law jumps at zero slip, and a step that
    crosses it errs by O(h)."""
    v2 = _dot(slip, slip)
    scale = limit / math.sqrt(v2 + v_f * v_f)
    return _scale(slip, scale), scale * v2


@njit(cache=True, **FLOAT_MATH)
def take_onsets(near, t, record):
    """Into ``record`` (9,), laid out as ``result.ONSET_COLUMNS``, the fastest
    contact onset of the last :func:`panel_contacts` call with the candidate
    list ``near`` (:func:`near_pairs`), at time t (s), if faster than the one
    already there (record[1]; 0 for none)."""
    onset = near[8]
    if onset[1] > record[1]:
        record[:] = onset
        record[0] = t


@njit(cache=True, **FLOAT_MATH)
def contact_onsets(P, y, t, record, near):
    """The fastest arriving panel contact at y (:func:`panel_contacts`' onsets)
    into ``record`` (9,) at time t (s), as :func:`take_onsets`, for a caller
    whose last evaluation was not at y (scipy's integrators).
    ``near``: the run's candidate list (:func:`near_pairs`)."""
    if P.contact.shape[0] == 0:
        return
    n = P.n
    R, p, w, vo, _ = kinematics(P, y[:n], y[n:2 * n])
    panel_contacts(P, R, p, w, vo, np.zeros((n + 1, 6)), near)
    take_onsets(near, t, record)


@njit(cache=True, inline="always", **FLOAT_MATH)
def _bias(P, theta, omega, kin, Jb, hb, near):
    """Generalised force minus bias by recursive Newton-Euler with zero joint
    acceleration, for the kinematics ``kin`` and :func:`body_inertias`' (J, h),
    and the panel contacts' candidate list ``near`` (:func:`near_pairs`).

    Returns Q (n,) N m (``M qdd = Q`` for the tree), the velocity-product
    spatial accelerations (n + 1, 6), and the spring energy, dissipation and
    gravity energy (J, W: dampers and air drag, J).
    """
    n = P.n
    R, p, w, vo, S = kin
    if P.method != TREE:
        f, spring, dissipation = cut_forces(P, R, p, w, vo)
        for i in range(n + 1):
            for k in range(6):
                f[i, k] = -f[i, k]
    else:
        f = np.zeros((n + 1, 6))
        spring = 0.0
        dissipation = 0.0
    acc = np.zeros((n + 1, 6))
    gravity_energy = 0.0
    for i in range(n):
        a = P.parent[i]
        sw, sv = _get(S, i), _get(S, i, 3)
        wa = _get(w, a)
        _put(acc, i, _add(_get(acc, a), _scale(_cross(wa, sw), omega[i])))
        _put(acc, i, _add(_get(acc, a, 3),
                          _scale(_add(_cross(wa, sv), _cross(_get(vo, a), sw)), omega[i])), 3)
        m = P.mass[i]
        pi, wi, voi = _get(p, i), _get(w, i), _get(vo, i)
        hi = _get(hb, i)
        hw, hv = _inertia_times(Jb, i, hi, m, wi, voi)
        fw, fv = _inertia_times(Jb, i, hi, m, _get(acc, i), _get(acc, i, 3))
        fw = _add(fw, _add(_cross(wi, hw), _cross(voi, hv)))
        fv = _add(fv, _cross(wi, hv))
        if P.has_gravity:
            fg = _scale((P.gravity[0], P.gravity[1], P.gravity[2]), m)
            fw = _sub(fw, _cross(pi, fg))
            fv = _sub(fv, fg)
            gravity_energy -= _dot(fg, _sub(pi, _get(P.r0, i)))
        _put(f, i, _add(_get(f, i), fw))
        _put(f, i, _add(_get(f, i, 3), fv), 3)
    dissipation += air_drag(P, R, p, w, vo, f)
    e, pw = panel_contacts(P, R, p, w, vo, f, near)
    spring += e
    dissipation += pw
    Q = np.empty(n)
    for i in range(n - 1, -1, -1):
        tau, e, pw = hinge_law(theta[i], omega[i], P.k[i], P.c[i], P.k_s, P.c_s, P.stop_ramp)
        spring += e
        dissipation += pw
        Q[i] = tau - _dot6(S, i, _get(f, i), _get(f, i, 3))
        a = P.parent[i]
        if a < n:
            for k in range(6):
                f[a, k] += f[i, k]
    return Q, acc, spring, dissipation, gravity_energy


@njit(cache=True, **FLOAT_MATH)
def mass_and_bias(P, theta, omega, near):
    """Mass matrix, generalised force and everything the energy needs, with
    the panel contacts' candidate list ``near`` (:func:`near_pairs`).

    Returns
    -------
    M : (n, n) kg m^2
    Q : (n,) generalised force minus bias, ``M qdd = Q`` for the tree, N m
    kin : tuple (R, p, w, vo, S)
    acc : (n + 1, 6) velocity-product spatial accelerations
    spring, dissipation, gravity_energy : float  J, W (dampers and air drag), J
    """
    kin = kinematics(P, theta, omega)
    R, p, _, _, S = kin
    Jb, hb = body_inertias(P, R, p)
    M = mass_matrix(P, S, Jb, hb)
    Q, acc, spring, dissipation, gravity_energy = _bias(P, theta, omega, kin, Jb, hb, near)
    return M, Q, kin, acc, spring, dissipation, gravity_energy


@njit(cache=True, **FLOAT_MATH)
def rhs(P, y, near):
    """dy/dt of the state vector (see the module docstring); NaN if M is not positive definite.
    ``near``: the run's candidate list of panel contact pairs (:func:`near_pairs`).

    Solves ``M qdd = Q`` by the articulated-body algorithm (O(n)) where
    :func:`articulated.applies`, else by CRBA and Cholesky.
    """
    n = P.n
    theta = y[:n]
    omega = y[n:2 * n]
    dy = np.empty(2 * n + 2)
    dy[:n] = omega
    dy[2 * n + 1] = 0.0
    if articulated.applies(P.n):
        kin = kinematics(P, theta, omega)
        R, p, _, _, S = kin
        Jb, hb = body_inertias(P, R, p)
        Q, acc, _, dissipation, _ = _bias(P, theta, omega, kin, Jb, hb, near)
        dy[2 * n] = dissipation
        U, D, ok = articulated.factor(P, S, articulated.inertias(P, Jb, hb), np.zeros(n))
        if not ok:
            dy[:] = np.nan
            return dy
        qdd = dy[n:2 * n]
        if P.method != EXACT:
            articulated.solve(P, S, U, D, Q, qdd, np.empty((n + 1, 6)))
        else:
            c, J, gamma = closure_jacobian(P, R, p, kin[2], kin[3], S, acc)
            dy[2 * n + 1], ok = _articulated_closure(P, S, U, D, Q, c, J, gamma, omega, qdd)
            if not ok:
                dy[:] = np.nan
                return dy
        return dy
    M, qdd, kin, acc, _, dissipation, _ = mass_and_bias(P, theta, omega, near)
    dy[2 * n] = dissipation
    L, ok = _cholesky(M)
    if not ok:
        dy[:] = np.nan
        return dy
    _cholesky_solve(L, qdd.reshape((n, 1)))
    if P.method == EXACT:
        R, p, w, vo, S = kin
        c, J, gamma = closure_jacobian(P, R, p, w, vo, S, acc)
        Y, LA, ok = _constraint_factor(L, J, P.regularisation)
        if not ok:
            dy[:] = np.nan
            return dy
        dy[2 * n + 1] = _exact_closure(P, c, J, gamma, Y, LA, omega, qdd)
    dy[n:2 * n] = qdd
    return dy


@njit(cache=True, **FLOAT_MATH)
def rhs_jacobian(P, y, f0, near):
    """Forward-difference Jacobian d rhs / dy, (2n + 2, 2n + 2), given f0 = rhs(P, y, near)."""
    N = y.shape[0]
    Jac = np.zeros((N, N))
    yp = y.copy()
    for j in range(2 * P.n):
        h = 1.4901161193847656e-08 * max(1.0, abs(y[j]))
        yp[j] = y[j] + h
        Jac[:, j] = (rhs(P, yp, near) - f0) / h
        yp[j] = y[j]
    return Jac


@njit(cache=True, **FLOAT_MATH)
def observe(P, y):
    """Energies and closure gap at one state.

    Returns kinetic, spring, gravity energy (J), largest gap (m) and the
    closure Jacobian (5 m, n) for its singular values.
    """
    n = P.n
    theta = y[:n]
    omega = y[n:2 * n]
    M, Q, kin, acc, spring, dissipation, gravity_energy = mass_and_bias(
        P, theta, omega, near_pairs(P))
    kinetic = 0.5 * _dot(omega, _mv(M, omega))
    R, p, w, vo, S = kin
    gap = 0.0
    if P.method != TREE:
        gap = largest_gap(P, R, p)
        c, J, gamma = closure_jacobian(P, R, p, w, vo, S, np.zeros((0, 6)))
    else:
        J = np.zeros((0, n))
    return kinetic, spring, gravity_energy, gap, J


@njit(cache=True, **FLOAT_MATH)
def cut_angles(P, R):
    """Angle of every cut hinge (rad) for body orientations R (n + 1, 3, 3)."""
    m = P.cut_a.shape[0]
    out = np.empty(m)
    for j in range(m):
        out[j] = _cut_angle(P, j, R)[0]
    return out


@njit(cache=True, **FLOAT_MATH)
def cut_rates(P, R, w):
    """Rate of every cut hinge (rad/s) for body orientations R (n + 1, 3, 3) and
    angular velocities w (n + 1, 3), rad/s, both in kernel body order."""
    m = P.cut_a.shape[0]
    out = np.empty(m)
    for j in range(m):
        g = _cut_angle(P, j, R)[1]
        a, b = P.cut_a[j], P.cut_b[j]
        out[j] = g[0] * (w[b, 0] - w[a, 0]) + g[1] * (w[b, 1] - w[a, 1]) + g[2] * (w[b, 2] - w[a, 2])
    return out


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
    to fill. ``near``: the run's candidate list (:func:`near_pairs`)."""
    rows = np.empty((64, 9))
    count = 0
    if P.contact.shape[0] == 0:
        return count, rows
    work = box_scratch()
    points, depths, weights = work[-3], work[-2], work[-1]
    for r in _touching(P, R, p, near):
        found, normal = _pair_points(P, r, R, p, work)
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
    and the stiffness and damping of :func:`_contact_law` at its depth, so that K
    gains ``k G^T G`` (C likewise); then, for a point with friction, its two
    slip directions with :func:`_friction`'s damping at zero slip, mu times
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
        push, _, _, k, c = _contact_law(rows[i, 7], 0.0, weight * contact[r, 8], weight * contact[r, 9])
        kk[start + i], cc[start + i] = k, c
        x = (rows[i, 4], rows[i, 5], rows[i, 6])
        Jp[:] = 0.0
        _point_jacobian(P, S, int(contact[r, 1]), x, Jp, 0, 1.0)
        _point_jacobian(P, S, int(contact[r, 0]), x, Jp, 0, -1.0)
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
    """:func:`stop_engagement` of a hinge at theta (0 within its limits)."""
    if contact_mode(theta) == 1:
        return 0.0
    return stop_engagement(theta - PI if theta > PI else -theta, P.stop_ramp)


@njit(cache=True, inline="always", **FLOAT_MATH)
def stiff_terms(P, y, near):
    """The stiff springs and dampers in joint space, ``K = diag(Kd) + U^T
    diag(kk) U`` and ``C = diag(Cd) + U^T diag(cc) U`` (N m/rad, N m s/rad),
    at the current configuration.

    ``Kd = k + k_s e`` on tree hinges past a limit (Eq. 2-4; e the stop's
    :func:`stop_engagement`), likewise Cd; one
    row of U per cut hinge, its angle Jacobian (its own spring and contact),
    and for PENALTY five per cut hinge, the closure Jacobian of Eq. (5) with
    weights k_M, k_M, k_M, k_N, k_N (c likewise); then one per panel contact
    point pressed now and two more where it has friction (:func:`_contact_rows`).
    Returns (kin, Kd, Cd, U, kk, cc), kin the :func:`kinematics` tuple; U is
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
        th, g = _cut_angle(P, j, R)
        Jw[:] = 0.0
        _angular_jacobian(P, S, P.cut_b[j], Jw, 0, 1.0)
        _angular_jacobian(P, S, P.cut_a[j], Jw, 0, -1.0)
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
    L, ok = _cholesky(M)
    A = np.zeros((n, n))
    B = np.zeros((n, n))
    if not ok:
        return A, B, False
    A[:] = Kq
    B[:] = Cq
    _cholesky_solve(L, A)
    _cholesky_solve(L, B)
    for i in range(n):
        for col in range(n):
            A[i, col] = -A[i, col]
            B[i, col] = -B[i, col]
    if P.method == EXACT:
        _, J, _ = closure_jacobian(P, R, p, w, vo, S, np.zeros((0, 6)))
        Y, LA, ok = _constraint_factor(L, J, P.regularisation)
        if not ok:
            return A, B, False
        T = P.baumgarte
        # lambda's response to a unit change of theta[col] / omega[col]
        Ra = _matmul(J, A)
        Rb = _matmul(J, B)
        for r in range(J.shape[0]):
            for col in range(n):
                Ra[r, col] = -Ra[r, col] - J[r, col] / (T * T)
                Rb[r, col] = -Rb[r, col] - J[r, col] * (2.0 / T)
        _cholesky_solve(LA, Ra)
        _cholesky_solve(LA, Rb)
        A += _matmul(Y, Ra)
        B += _matmul(Y, Rb)
    return A, B, True
