"""Compiled kernels against an independent numpy computation: Lagrange's equations
with the mass matrix, Coriolis terms and potential all from finite differences of
the reference kinematics (panel_deploy.kinematics)."""

import numpy as np
import pytest

from panel_deploy.dynamics import closure, kernels
from panel_deploy.dynamics.pack import pack
from panel_deploy.kinematics import forward_kinematics, hinge_points

from test_dynamics_helpers import near, paper_hinge_law, random_branched, scratch


def skew_vec(W):
    return np.array([W[2, 1], W[0, 2], W[1, 0]])


def cut_angle(model, R, j):
    """Rotation of body b relative to body a about the cut axis, from R_a^T R_b.

    Off a closed loop R_a^T R_b is not a pure rotation about the axis and the
    angle depends on the reference normal e1, so it uses the kernels' e1."""
    h = model.hinges[model.cut_hinges[j]]
    Rrel = R[h.body_a].T @ R[h.body_b]
    e1 = pack(model).cut_e1[j]
    f = Rrel @ e1
    ang = np.arctan2(np.cross(h.axis, e1) @ f, e1 @ f)
    return ang + 2 * np.pi if ang < -np.pi / 2 else ang


def potential(model, theta):
    R, p = forward_kinematics(model, theta)
    V = -sum(b.mass * model.gravity @ (p[i] - b.flat_position) for i, b in enumerate(model.bodies))
    V += sum(paper_hinge_law(th, 0.0, model.hinges[h].k_hinge, 0, model.k_s, 0)[1] for th, h in zip(theta, model.joints))
    cl = model.closure
    for j, hc in enumerate(model.cut_hinges):
        h = model.hinges[hc]
        V += paper_hinge_law(cut_angle(model, R, j), 0.0, h.k_hinge, 0, model.k_s, 0)[1]
        if cl.method == "penalty":
            Ma, Na, Mb, Nb = hinge_points(model, R, p, hc)
            u = R[h.body_a] @ h.axis
            dN = Nb - Na
            V += 0.5 * cl.k_M * np.sum((Mb - Ma) ** 2) + 0.5 * cl.k_N * np.sum((dN - u * (u @ dN)) ** 2)
    return V


def fd(f, x, h=1e-6):
    cols = []
    for j in range(len(x)):
        e = np.zeros_like(x)
        e[j] = h
        cols.append((np.asarray(f(x + e)) - np.asarray(f(x - e))) / (2 * h))
    return np.stack(cols, axis=-1)


def mass_matrix(model, theta):
    R, p = forward_kinematics(model, theta)
    M = np.zeros((len(theta),) * 2)
    for i, b in enumerate(model.bodies):
        if i == model.ground:
            continue
        Jv = fd(lambda q: forward_kinematics(model, q)[1][i], theta)
        dR = fd(lambda q: forward_kinematics(model, q)[0][i], theta)
        Jw = np.stack([skew_vec(dR[:, :, j] @ R[i].T) for j in range(len(theta))], axis=1)
        M += b.mass * Jv.T @ Jv + Jw.T @ (R[i] @ b.inertia @ R[i].T) @ Jw
    return M


def reference_qdd(model, theta, omega):
    """Lagrange: M qdd = -(dM/dt) omega + 1/2 d(omega^T M omega)/dq - dV/dq + Q_damping."""
    M = mass_matrix(model, theta)
    dM = fd(lambda q: mass_matrix(model, q), theta, 1e-4)  # (n, n, n): d M / d q_k
    coriolis = np.einsum("ijk,k,j->i", dM, omega, omega) - 0.5 * np.einsum("jki,j,k->i", dM, omega, omega)
    Q = -fd(lambda q: potential(model, q), theta)
    Q -= np.array([(model.hinges[h].c_hinge + (model.c_s if not 0 <= th <= np.pi else 0.0)) * w
                   for th, w, h in zip(theta, omega, model.joints)])
    cl = model.closure
    for j, hc in enumerate(model.cut_hinges):
        h = model.hinges[hc]
        G = fd(lambda q: cut_angle(model, forward_kinematics(model, q)[0], j), theta)
        th_c = cut_angle(model, forward_kinematics(model, theta)[0], j)
        c_tot = h.c_hinge + (model.c_s if not 0 <= th_c <= np.pi else 0.0)
        Q -= c_tot * (G @ omega) * G
        if cl.method == "penalty":
            def ends(q):
                R, p = forward_kinematics(model, q)
                Ma, Na, Mb, Nb = hinge_points(model, R, p, hc)
                return np.concatenate([Mb - Ma, Nb - Na])
            Jd = fd(ends, theta)
            u = forward_kinematics(model, theta)[0][h.body_a] @ h.axis
            Pn = np.eye(3) - np.outer(u, u)
            Q -= cl.c_M * Jd[:3].T @ (Jd[:3] @ omega) + cl.c_N * Jd[3:].T @ Pn @ (Jd[3:] @ omega)
    return np.linalg.solve(M, Q - coriolis), M


@pytest.mark.parametrize("seed", [0, 1])
def test_forward_dynamics_matches_lagrange_reference(seed):
    model = random_branched(seed)
    P = pack(model)
    rng = np.random.default_rng(10 + seed)
    theta = rng.uniform(0.2, 2.5, model.n_coords)
    theta[0] = np.pi + 0.01     # one tree hinge in contact
    omega = rng.normal(0, 2.0, model.n_coords)
    qdd_ref, M_ref = reference_qdd(model, theta, omega)
    y = np.concatenate([theta, omega, [0, 0]])
    M, *_ = kernels.mass_and_bias(P, theta, omega, near(P))
    assert np.allclose(M, M_ref, rtol=1e-6, atol=1e-12 * np.abs(M_ref).max())
    qdd = kernels.rhs(P, y, scratch(P))[model.n_coords:2 * model.n_coords]
    assert np.allclose(qdd, qdd_ref, rtol=1e-4, atol=1e-5 * np.abs(qdd_ref).max())


def test_exact_closure_jacobian_and_acceleration():
    """J and dJ/dt omega against finite differences of the numpy constraint function,
    and the solved acceleration obeys the Baumgarte-stabilised constraint."""
    model = random_branched(3, closure="exact")
    P = pack(model)
    n = model.n_coords
    rng = np.random.default_rng(4)
    theta = rng.uniform(0.2, 2.5, n)
    omega = rng.normal(0, 2.0, n)
    h = model.hinges[model.cut_hinges[0]]
    e1 = P.cut_e1[0]
    e2 = P.cut_e2[0]

    def constraint(q):
        R, p = forward_kinematics(model, q)
        Ma, Na, Mb, Nb = hinge_points(model, R, p, model.cut_hinges[0])
        Ra = R[h.body_a]
        return np.concatenate([Mb - Ma, [(Ra @ e1) @ (Nb - Na), (Ra @ e2) @ (Nb - Na)]])

    R, p, w, vo, S = kernels.kinematics(P, theta, omega)
    M, Q, kin, acc, *_ = kernels.mass_and_bias(P, theta, omega, near(P))
    c, J, gamma = closure.closure_jacobian(P, R, p, w, vo, S, acc)
    assert np.allclose(c, constraint(theta), atol=1e-14)
    J_ref = fd(constraint, theta)
    assert np.allclose(J, J_ref, atol=1e-8)
    hh = 1e-5
    gamma_ref = (fd(constraint, theta + hh * omega) - fd(constraint, theta - hh * omega)) / (2 * hh) @ omega
    assert np.allclose(gamma, gamma_ref, rtol=1e-4, atol=1e-6 * np.abs(gamma_ref).max())
    qdd = kernels.rhs(P, kernels.state_vector(theta, omega), scratch(P))[n:2 * n]
    T = model.closure.baumgarte
    residual = J @ qdd + gamma + 2 / T * (J @ omega) + c / T**2
    # a random 4-hinge spatial loop is over-constrained (J is 5 x 4 on the loop), so
    # the stabilised constraint holds in the least-squares sense: on the range of J
    U, sv, _ = np.linalg.svd(J)
    rank = int(np.sum(sv > 1e-8 * sv[0]))
    assert rank == 4
    assert np.abs(U[:, :rank].T @ residual).max() < 1e-6 * np.abs(c / T**2).max()
    assert np.abs(residual).max() > 1e-3 * np.abs(c / T**2).max()  # the loop cannot close
