"""Compiled (numba) kernels of the deployment dynamics: the right-hand side.

State vector ``y`` (shape ``(2 n + ACCUMULATORS,)``, :func:`state_vector`):
``theta`` (n, rad), ``omega`` (n, rad/s), then three integrals since t = 0
(J): the energy dissipated by all dampers and the air drag, the work done on
the system by the exact-closure constraint forces (zero for penalty), and the
work the bodies did on the panel contacts' springs. The last is there because
a contact law built on the separating axis is not conservative where a pair
changes the features it touches by (the stored energy jumps, the state does
not): the energy balance counts that work, not the stored energy, so that it
checks the integration alone, and the difference says what the law created
(:func:`panel_deploy.dynamics.report.contact_energy_error`).

Algorithm (Featherstone, "Rigid Body Dynamics Algorithms", ch. 5-7), with all
spatial vectors in the ground frame about its origin, angular part first
(:mod:`.spatial`):

* forward kinematics down the tree;
* bias forces (velocity product, gravity, air drag (:mod:`.air`), panel
  contacts (:mod:`.panel_contact`), cut-hinge wrenches (:mod:`.closure`)) by
  recursive Newton-Euler (RNEA) with zero joint acceleration, O(n), and the
  hinge torques (:mod:`.hinges`);
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
"""

from __future__ import annotations

import numpy as np
from numba import njit

from . import articulated
from . import spatial as sp
from ._jit import FLOAT_MATH
from .air import air_drag
from .buffers import allocate
from .closure import (articulated_closure, cholesky, cholesky_solve, closure_jacobian,
                      closure_jacobian_into, constraint_factor, cut_angle, cut_angles, cut_ends,
                      cut_forces, exact_closure, largest_gap)
from .hinges import hinge_law
from .pack import EXACT, TREE
from .panel_contact import near_pairs, panel_contacts, take_onsets

#: Integrals after theta and omega in the state vector (see the module docstring).
ACCUMULATORS = 3


@njit(cache=True, **FLOAT_MATH)
def scratch(P):
    """The mutable scratch of one run of :func:`rhs`, never shared between
    runs: the panel contacts' candidate list
    (:func:`.panel_contact.near_pairs`) and the arrays the O(n) path fills
    (:func:`.buffers.allocate`: none where :func:`articulated.applies` does
    not, the exact closure's only for it)."""
    n = P.n if articulated.applies(P.n) else 0
    mc = 5 * P.cut_a.shape[0] if n > 0 and P.method == EXACT else 0
    return near_pairs(P), allocate(n, mc)


def state_vector(theta, omega):
    """The state vector (2 n + ACCUMULATORS,) of angles theta (n, rad) and rates
    omega (n, rad/s), its integrals at 0 (the start of a run)."""
    return np.concatenate([theta, omega, np.zeros(ACCUMULATORS)])


@njit(cache=True, inline="always", **FLOAT_MATH)
def kinematics(P, theta, omega):
    """Poses, velocities and joint screws of every body, new arrays
    (:func:`kinematics_into`): ``(R, p, w, vo, S)``."""
    n = P.n
    R, p, w, vo = np.empty((n + 1, 3, 3)), np.empty((n + 1, 3)), np.empty((n + 1, 3)), np.empty((n + 1, 3))
    S = np.empty((n, 6))
    kinematics_into(P, theta, omega, R, p, w, vo, S)
    return R, p, w, vo, S


@njit(cache=True, inline="always", **FLOAT_MATH)
def kinematics_into(P, theta, omega, R, p, w, vo, S):
    """Poses, velocities and joint screws of every body, into (overwritten):

    Parameters
    ----------
    R : (n + 1, 3, 3)   orientations, ground last
    p : (n + 1, 3)      centroids, m
    w : (n + 1, 3)      angular velocities, rad/s
    vo : (n + 1, 3)     velocity of the body point at the ground origin, m/s
                        (centroid velocity = vo + w x p)
    S : (n, 6)          joint screws (axis, hinge point x axis)
    """
    n = P.n
    for r in range(3):
        for c in range(3):
            R[n, r, c] = 1.0 if r == c else 0.0
        w[n, r] = 0.0
        vo[n, r] = 0.0
    sp.put(p, n, sp.get(P.r0, n))
    for i in range(n):
        a = P.parent[i]
        rot = sp.rotation(sp.get(P.axis, i), theta[i])
        for r in range(3):
            x0, x1, x2 = R[a, r, 0], R[a, r, 1], R[a, r, 2]
            for c in range(3):
                R[i, r, c] = x0 * rot[0][c] + x1 * rot[1][c] + x2 * rot[2][c]
        h = sp.carried(P, R, p, a, sp.get(P.point, i))
        u = sp.rotate(R, a, sp.get(P.axis, i))
        sp.put(p, i, sp.add(h, sp.rotate(R, i, sp.sub(sp.get(P.r0, i), sp.get(P.point, i)))))
        hu = sp.cross(h, u)
        sp.put(S, i, u)
        sp.put(S, i, hu, 3)
        sp.put(w, i, sp.add(sp.get(w, a), sp.scale(u, omega[i])))
        sp.put(vo, i, sp.add(sp.get(vo, a), sp.scale(hu, omega[i])))


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
        sp.put(v, b, sp.add(sp.get(vo, i), sp.cross(sp.get(wk, i), sp.get(pk, i))))
    return R, p, v, w


@njit(cache=True, **FLOAT_MATH)
def loop_residual(P, theta):
    """How far tree angles ``theta`` (rad) are from closing every loop: per cut
    hinge j, row j holds M_b - M_a and N_b - N_a (m, the gaps of its two ends,
    :func:`.closure.cut_ends`) and its angle (rad, :func:`.closure.cut_angle`); (m, 7)."""
    R, p, _, _, _ = kinematics(P, theta, np.zeros(theta.shape[0]))
    out = np.empty((P.cut_a.shape[0], 7))
    for j in range(P.cut_a.shape[0]):
        Ma, Na, Mb, Nb = cut_ends(P, j, R, p)
        for i in range(3):
            out[j, i] = Mb[i] - Ma[i]
            out[j, 3 + i] = Nb[i] - Na[i]
        out[j, 6] = cut_angle(P, j, R)[0]
    return out


@njit(cache=True, inline="always", **FLOAT_MATH)
def body_inertias(P, R, p):
    """Angular inertias J (n, 3, 3, kg m^2, see above) and first moments h = m c
    (n, 3, kg m) of the bodies about the ground origin, new arrays."""
    Jb, hb = np.empty((P.n, 3, 3)), np.empty((P.n, 3))
    body_inertias_into(P, R, p, Jb, hb)
    return Jb, hb


@njit(cache=True, inline="always", **FLOAT_MATH)
def body_inertias_into(P, R, p, Jb, hb):
    """:func:`body_inertias` into Jb and hb (overwritten)."""
    for i in range(P.n):
        sp.angular_inertia(P, R, p, i, Jb)
        sp.put(hb, i, sp.scale(sp.get(p, i), P.mass[i]))


@njit(cache=True, **FLOAT_MATH)
def mass_matrix(P, S, Jb, hb):
    """The mass matrix (n, n) from :func:`body_inertias`' (J, h)."""
    n = P.n
    # composite bodies (Jc, hc, mc), accumulated leaves first; h and m share
    # one array (an allocation costs the paper scene's rhs ~1 %)
    Jc = Jb.copy()
    hm = np.empty((n, 4))
    for i in range(n):
        sp.put(hm, i, sp.get(hb, i))
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
        Fw, Fv = sp.inertia_times(Jc, i, sp.get(hm, i), hm[i, 3], sp.get(S, i), sp.get(S, i, 3))
        M[i, i] = sp.dot6(S, i, Fw, Fv)
        j = P.parent[i]
        while j < n:
            M[i, j] = M[j, i] = sp.dot6(S, j, Fw, Fv)
            j = P.parent[j]
    return M


@njit(cache=True, **FLOAT_MATH)
def contact_onsets(P, y, t, record, near):
    """The fastest arriving panel contact at y (:func:`.panel_contact.panel_contacts`' onsets)
    into ``record`` (9,) at time t (s), as :func:`.panel_contact.take_onsets`, for a caller
    whose last evaluation was not at y (scipy's integrators).
    ``near``: the run's candidate list (:func:`.panel_contact.near_pairs`)."""
    if P.contact.shape[0] == 0:
        return
    n = P.n
    R, p, w, vo, _ = kinematics(P, y[:n], y[n:2 * n])
    panel_contacts(P, R, p, w, vo, np.zeros((n + 1, 6)), near)
    take_onsets(near, t, record)


@njit(cache=True, inline="always", **FLOAT_MATH)
def _bias(P, theta, omega, kin, Jb, hb, near, f, acc, Q):
    """Generalised force minus bias by recursive Newton-Euler with zero joint
    acceleration, for the kinematics ``kin`` and :func:`body_inertias`' (J, h),
    and the panel contacts' candidate list ``near`` (:func:`.panel_contact.near_pairs`);
    into f (n + 1, 6, the bodies' wrenches, scratch), acc and Q (overwritten).

    Returns Q (n,) N m (``M qdd = Q`` for the tree), the velocity-product
    spatial accelerations acc (n + 1, 6), the spring energy (J, the panel
    contacts' included), the panel contacts' part of it (J) and the power
    their springs take (W), the dissipation (W: dampers and air drag) and the
    gravity energy (J).
    """
    n = P.n
    R, p, w, vo, S = kin
    if P.method != TREE:
        spring, dissipation = cut_forces(P, R, p, w, vo, f)
        for i in range(n + 1):
            for k in range(6):
                f[i, k] = -f[i, k]
    else:
        f[:] = 0.0
        spring = 0.0
        dissipation = 0.0
    acc[n, :] = 0.0
    gravity_energy = 0.0
    for i in range(n):
        a = P.parent[i]
        sw, sv = sp.get(S, i), sp.get(S, i, 3)
        wa = sp.get(w, a)
        sp.put(acc, i, sp.add(sp.get(acc, a), sp.scale(sp.cross(wa, sw), omega[i])))
        sp.put(acc, i, sp.add(sp.get(acc, a, 3),
                          sp.scale(sp.add(sp.cross(wa, sv), sp.cross(sp.get(vo, a), sw)), omega[i])), 3)
        m = P.mass[i]
        pi, wi, voi = sp.get(p, i), sp.get(w, i), sp.get(vo, i)
        hi = sp.get(hb, i)
        hw, hv = sp.inertia_times(Jb, i, hi, m, wi, voi)
        fw, fv = sp.inertia_times(Jb, i, hi, m, sp.get(acc, i), sp.get(acc, i, 3))
        fw = sp.add(fw, sp.add(sp.cross(wi, hw), sp.cross(voi, hv)))
        fv = sp.add(fv, sp.cross(wi, hv))
        if P.has_gravity:
            fg = sp.scale((P.gravity[0], P.gravity[1], P.gravity[2]), m)
            fw = sp.sub(fw, sp.cross(pi, fg))
            fv = sp.sub(fv, fg)
            gravity_energy -= sp.dot(fg, sp.sub(pi, sp.get(P.r0, i)))
        sp.put(f, i, sp.add(sp.get(f, i), fw))
        sp.put(f, i, sp.add(sp.get(f, i, 3), fv), 3)
    dissipation += air_drag(P, R, p, w, vo, f)
    contact, pw, contact_power = panel_contacts(P, R, p, w, vo, f, near)
    spring += contact
    dissipation += pw
    for i in range(n - 1, -1, -1):
        tau, e, pw = hinge_law(theta[i], omega[i], P.k[i], P.c[i], P.k_s, P.c_s, P.stop_ramp)
        spring += e
        dissipation += pw
        Q[i] = tau - sp.dot6(S, i, sp.get(f, i), sp.get(f, i, 3))
        a = P.parent[i]
        if a < n:
            for k in range(6):
                f[a, k] += f[i, k]
    return Q, acc, spring, contact, contact_power, dissipation, gravity_energy


@njit(cache=True, **FLOAT_MATH)
def mass_and_bias(P, theta, omega, near):
    """Mass matrix, generalised force and everything the energy needs, with
    the panel contacts' candidate list ``near`` (:func:`.panel_contact.near_pairs`).

    Returns
    -------
    M : (n, n) kg m^2
    Q : (n,) generalised force minus bias, ``M qdd = Q`` for the tree, N m
    kin : tuple (R, p, w, vo, S)
    acc : (n + 1, 6) velocity-product spatial accelerations
    spring, contact, contact_power, dissipation, gravity_energy : float
        J (the panel contacts' included), J (theirs), W (taken by their
        springs), W (dampers and air drag), J
    """
    n = P.n
    kin = kinematics(P, theta, omega)
    R, p, _, _, S = kin
    Jb, hb = body_inertias(P, R, p)
    M = mass_matrix(P, S, Jb, hb)
    Q, acc, spring, contact, contact_power, dissipation, gravity_energy = _bias(
        P, theta, omega, kin, Jb, hb, near, np.empty((n + 1, 6)), np.empty((n + 1, 6)), np.empty(n))
    return M, Q, kin, acc, spring, contact, contact_power, dissipation, gravity_energy


@njit(cache=True, **FLOAT_MATH)
def rhs(P, y, scratch):
    """dy/dt of the state vector (see the module docstring); NaN if M is not positive definite.
    ``scratch``: the run's :func:`scratch`; on the O(n) path its arrays hold
    this evaluation's kinematics and factors until the next.

    Solves ``M qdd = Q`` by the articulated-body algorithm (O(n)) where
    :func:`articulated.applies`, else by CRBA and Cholesky.
    """
    n = P.n
    theta = y[:n]
    omega = y[n:2 * n]
    dy = np.empty(2 * n + ACCUMULATORS)
    dy[:n] = omega
    dy[2 * n + 1] = 0.0
    near = scratch[0]
    if articulated.applies(P.n):
        _articulated_rhs(P, theta, omega, near, scratch[1], dy)
        return dy
    M, qdd, kin, acc, _, _, contact_power, dissipation, _ = mass_and_bias(P, theta, omega, near)
    dy[2 * n] = dissipation
    dy[2 * n + 2] = contact_power
    L, ok = cholesky(M)
    if not ok:
        dy[:] = np.nan
        return dy
    cholesky_solve(L, qdd.reshape((n, 1)))
    if P.method == EXACT:
        R, p, w, vo, S = kin
        c, J, gamma = closure_jacobian(P, R, p, w, vo, S, acc)
        Y, LA, ok = constraint_factor(L, J, P.regularisation)
        if not ok:
            dy[:] = np.nan
            return dy
        dy[2 * n + 1] = exact_closure(P, c, J, gamma, Y, LA, omega, qdd)
    dy[n:2 * n] = qdd
    return dy


@njit(cache=True, **FLOAT_MATH)
def rhs_apart(P, y, near, buffers):
    """:func:`rhs` with the :func:`scratch`'s two parts as arguments of their
    own, for calls from Python (scipy's solvers): numba types a tuple that
    holds a :class:`.buffers.Buffers` in Python, array by array (the paper
    scene's DOP853 reference ran 5 x slower so), and each part apart by its
    fingerprint."""
    return rhs(P, y, (near, buffers))


@njit(cache=True, **FLOAT_MATH)
def _articulated_rhs(P, theta, omega, near, b, dy):
    """:func:`rhs`'s O(n) path: dy[n:] from dy[:n] = omega, into the
    :class:`.buffers.Buffers` b."""
    n = P.n
    R, p, w, vo, S, Jb, hb, f, acc, Q = b.R, b.p, b.w, b.vo, b.S, b.Jb, b.hb, b.f, b.acc, b.Q
    IA, U, D, closure = b.IA, b.U, b.D, b.closure
    kinematics_into(P, theta, omega, R, p, w, vo, S)
    body_inertias_into(P, R, p, Jb, hb)
    _, _, _, _, contact_power, dissipation, _ = _bias(P, theta, omega, (R, p, w, vo, S), Jb, hb,
                                                      near, f, acc, Q)
    dy[2 * n] = dissipation
    dy[2 * n + 2] = contact_power
    if not articulated.factor_into(P, S, Jb, hb, b.armature, IA, U, D):
        dy[:] = np.nan
        return
    qdd = dy[n:2 * n]
    if P.method != EXACT:
        articulated.solve(P, S, U, D, Q, qdd, f)  # f is spent: the solve's scratch
        return
    c, J, gamma, jwork = closure[:4]
    closure_jacobian_into(P, R, p, w, vo, S, acc, c, J, gamma, jwork)
    dy[2 * n + 1], ok = articulated_closure(P, S, U, D, Q, c, J, gamma, omega, qdd, closure)
    if not ok:
        dy[:] = np.nan


@njit(cache=True, **FLOAT_MATH)
def rhs_jacobian(P, y, f0, scratch):
    """Forward-difference Jacobian d rhs / dy, (N, N) for y (N,), given f0 =
    rhs(P, y, scratch) (``scratch``: the run's :func:`scratch`)."""
    N = y.shape[0]
    Jac = np.zeros((N, N))
    yp = y.copy()
    for j in range(2 * P.n):
        h = 1.4901161193847656e-08 * max(1.0, abs(y[j]))
        yp[j] = y[j] + h
        Jac[:, j] = (rhs(P, yp, scratch) - f0) / h
        yp[j] = y[j]
    return Jac


@njit(cache=True, **FLOAT_MATH)
def rhs_jacobian_apart(P, y, near, buffers):
    """:func:`rhs_jacobian` at y with the :func:`scratch`'s two parts apart,
    for calls from Python (see :func:`rhs_apart`)."""
    scratch = (near, buffers)
    return rhs_jacobian(P, y, rhs(P, y, scratch), scratch)


@njit(cache=True, **FLOAT_MATH)
def observe(P, y, scratch):
    """Energies and closure gap at one state, with the run's ``scratch``
    (:func:`scratch`); from Python, :func:`observe_samples` (numba types the
    scratch anew at each call from Python, ~0.2 ms).

    Returns kinetic, spring (the panel contacts' included), the panel
    contacts' and gravity energy (J), largest gap (m) and the closure
    Jacobian (5 m, n) for its singular values. On the O(n) path
    (:func:`articulated.applies`) the kinetic energy is summed over the
    bodies, with no mass matrix (O(n^2) to build).
    """
    n = P.n
    theta = y[:n]
    omega = y[n:2 * n]
    near, b = scratch
    if articulated.applies(n):
        R, p, w, vo, S, Jb, hb = b.R, b.p, b.w, b.vo, b.S, b.Jb, b.hb
        kinematics_into(P, theta, omega, R, p, w, vo, S)
        body_inertias_into(P, R, p, Jb, hb)
        kin = (R, p, w, vo, S)
        _, _, spring, contact, _, _, gravity_energy = _bias(P, theta, omega, kin, Jb, hb, near,
                                                            b.f, b.acc, b.Q)
        kinetic = 0.0
        for i in range(n):
            wi, voi = sp.get(w, i), sp.get(vo, i)
            hw, hv = sp.inertia_times(Jb, i, sp.get(hb, i), P.mass[i], wi, voi)
            kinetic += 0.5 * (sp.dot(wi, hw) + sp.dot(voi, hv))
    else:
        M, _, kin, _, spring, contact, _, _, gravity_energy = mass_and_bias(P, theta, omega, near)
        kinetic = 0.5 * sp.dot(omega, sp.mv(M, omega))
        R, p, w, vo, S = kin
    gap = 0.0
    if P.method != TREE:
        gap = largest_gap(P, R, p)
        c, J, gamma = closure_jacobian(P, R, p, w, vo, S, np.zeros((0, 6)))
    else:
        J = np.zeros((0, n))
    return kinetic, spring, contact, gravity_energy, gap, J


@njit(cache=True, **FLOAT_MATH)
def observe_samples(P, Y):
    """What a result holds of each sample, the rows y of Y (s, N), in one pass:
    :func:`body_states` (rotations (s, nb, 3, 3), centroids, centroid and
    angular velocities (s, nb, 3), model body order), :func:`observe`'s
    energies (s, 4: kinetic, spring, contact, gravity; J), largest gaps
    (s,) m and closure Jacobians (s, 5 m, n), and the cut hinges' angles
    (s, m) rad. One call from Python, not four a sample (10 x 10's 41
    samples took 5 ms of a 0.41 s run so)."""
    n, s, nb, m = P.n, Y.shape[0], P.n + 1, P.cut_a.shape[0]
    R = np.empty((s, nb, 3, 3))
    p = np.empty((s, nb, 3))
    v = np.empty((s, nb, 3))
    w = np.empty((s, nb, 3))
    energy = np.empty((s, 4))
    gaps = np.empty(s)
    Js = np.empty((s, 5 * m if P.method != TREE else 0, n))
    cut = np.empty((s, m))
    run = scratch(P)
    for j in range(s):
        y = Y[j]
        R[j], p[j], v[j], w[j] = body_states(P, y[:n], y[n:2 * n])
        energy[j, 0], energy[j, 1], energy[j, 2], energy[j, 3], gaps[j], Js[j] = observe(P, y, run)
        if m:
            cut[j] = cut_angles(P, R[j][P.body])  # kernel body order
    return R, p, v, w, energy, gaps, Js, cut
