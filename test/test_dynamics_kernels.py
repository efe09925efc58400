"""Compiled kernels against an independent numpy computation: Lagrange's equations
with the mass matrix, Coriolis terms and potential all from finite differences of
the reference kinematics (panel_deploy.kinematics)."""

import dataclasses

import numpy as np
import pytest

from panel_deploy.dynamics import kernels
from panel_deploy.dynamics.pack import pack
from panel_deploy.kinematics import forward_kinematics, hinge_points
from panel_deploy.model import AirParameters

from test_dynamics_helpers import near, plate_on_hinge, random_branched


def law(theta, omega, k, c, k_s, c_s):
    """Eq. (2)-(4) with the contact in parallel with the hinge spring."""
    tau, energy = -k * theta - c * omega, 0.5 * k * theta**2
    for over in (theta - np.pi if theta > np.pi else 0.0, theta if theta < 0 else 0.0):
        if over:
            tau += -k_s * over - c_s * omega
            energy += 0.5 * k_s * over**2
    return tau, energy


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
    V += sum(law(th, 0.0, model.hinges[h].k_hinge, 0, model.k_s, 0)[1] for th, h in zip(theta, model.joints))
    cl = model.closure
    for j, hc in enumerate(model.cut_hinges):
        h = model.hinges[hc]
        V += law(cut_angle(model, R, j), 0.0, h.k_hinge, 0, model.k_s, 0)[1]
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
    qdd = kernels.rhs(P, y, near(P))[model.n_coords:2 * model.n_coords]
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
    c, J, gamma = kernels.closure_jacobian(P, R, p, w, vo, S, acc)
    assert np.allclose(c, constraint(theta), atol=1e-14)
    J_ref = fd(constraint, theta)
    assert np.allclose(J, J_ref, atol=1e-8)
    hh = 1e-5
    gamma_ref = (fd(constraint, theta + hh * omega) - fd(constraint, theta - hh * omega)) / (2 * hh) @ omega
    assert np.allclose(gamma, gamma_ref, rtol=1e-4, atol=1e-6 * np.abs(gamma_ref).max())
    qdd = kernels.rhs(P, np.concatenate([theta, omega, [0, 0]]), near(P))[n:2 * n]
    T = model.closure.baumgarte
    residual = J @ qdd + gamma + 2 / T * (J @ omega) + c / T**2
    # a random 4-hinge spatial loop is over-constrained (J is 5 x 4 on the loop), so
    # the stabilised constraint holds in the least-squares sense: on the range of J
    U, sv, _ = np.linalg.svd(J)
    rank = int(np.sum(sv > 1e-8 * sv[0]))
    assert rank == 4
    assert np.abs(U[:, :rank].T @ residual).max() < 1e-6 * np.abs(c / T**2).max()
    assert np.abs(residual).max() > 1e-3 * np.abs(c / T**2).max()  # the loop cannot close


def face_drag_reference(v0, a, b, A, B, n=1500):
    """|u| u, s |u| u, r |u| u summed over an n x n midpoint grid of the face
    (error O(1/n^2), and O(1/n) only in the cells the kink u = 0 crosses)."""
    s = (np.arange(n) + 0.5) / n * 2 * A - A
    r = (np.arange(n) + 0.5) / n * 2 * B - B
    S, R = np.meshgrid(s, r, indexing="ij")
    g = np.abs(v0 + a * S + b * R) * (v0 + a * S + b * R) * (4 * A * B / n**2)
    return np.array([g.sum(), (S * g).sum(), (R * g).sum()])


@pytest.mark.parametrize("seed", range(4))
def test_face_drag_integral_matches_a_fine_grid(seed):
    # the zero line u = 0 crosses the face for most draws: the kink is inside
    rng = np.random.default_rng(seed)
    v0, a, b = rng.normal(size=3) * (1.0, 20.0, 20.0)
    A, B = rng.uniform(0.02, 0.1, 2)
    got = np.array(kernels.face_drag(v0, a, b, A, B))
    assert np.abs(got - face_drag_reference(v0, a, b, A, B)).max() < 1e-6 * np.abs(got).max()
    assert np.allclose(kernels.face_drag(-v0, -a, -b, A, B), -got, rtol=1e-12, atol=0)


def test_face_drag_closed_forms():
    A, B = 0.1, 0.05
    area = 4 * A * B
    # pure translation along the normal: the flat-plate drag 1/2 rho C_d A |v| v, no moment
    assert kernels.face_drag(-3.0, 0.0, 0.0, A, B) == pytest.approx((-9.0 * area, 0.0, 0.0))
    # spin about the body's x axis (b = w_x): int r |b r| b r dA = 2A b|b| B^4 / 2, no force
    I0, Is, Ir = kernels.face_drag(0.0, 0.0, 4.0, A, B)
    assert (I0, Is) == pytest.approx((0.0, 0.0), abs=1e-15)
    assert Ir == pytest.approx(2 * A * 16.0 * B**4 / 2, rel=1e-12)
    # a tiny rotation on a translation: no 1 / a cancellation (u keeps its sign)
    assert kernels.face_drag(1.0, 1e-14, 0.0, A, B) == pytest.approx((area, 0.0, 0.0), abs=1e-15)


@pytest.mark.parametrize("theta", [0.3, 1.2, 2.8])
@pytest.mark.parametrize("omega", [3.0, -5.0])
def test_drag_torque_on_a_swinging_panel_is_the_closed_form(theta, omega):
    """Plate of width w, length L on a hinge at its edge: 1/2 rho C_d w omega |omega|
    times the integral of r^3 from 0 to L = rho C_d w omega |omega| L^4 / 8, opposing omega."""
    rho, cd = 1.2, 1.17
    still = plate_on_hinge(k=0.0, c=0.0)
    air = dataclasses.replace(still, air=AirParameters(rho, cd))
    th, om = np.array([theta]), np.array([omega])
    P_air, P_still = pack(air), pack(still)
    _, Q_air, *_, diss_air, _ = kernels.mass_and_bias(P_air, th, om, near(P_air))
    _, Q_still, *_, diss_still, _ = kernels.mass_and_bias(P_still, th, om, near(P_still))
    w, L = still.hinges[0].length, still.bodies[1].size[0]
    closed = -rho * cd * w * omega * abs(omega) * L**4 / 8
    assert Q_air[0] - Q_still[0] == pytest.approx(closed, rel=1e-12)
    # the power the drag takes is its torque times the rate, counted as dissipation
    assert diss_air - diss_still == pytest.approx(-closed * omega, rel=1e-12)


def test_hinge_law_without_a_ramp_is_the_paper_law():
    rng = np.random.default_rng(3)
    for theta in np.concatenate([rng.uniform(-0.1, np.pi + 0.1, 200), [0.0, np.pi, -1e-9, np.pi + 1e-9]]):
        omega, k, c = rng.normal(), rng.uniform(0.01, 1), rng.uniform(0, 0.01)
        tau, energy, _ = kernels.hinge_law(theta, omega, k, c, 1000.0, 0.5, 0.0)
        assert (tau, energy) == pytest.approx(law(theta, omega, k, c, 1000.0, 0.5), rel=1e-14, abs=1e-300)


@pytest.mark.parametrize("limit, side", [(0.0, -1.0), (np.pi, 1.0)])
def test_a_ramped_stop_is_smooth_conservative_and_fully_in_past_its_ramp(limit, side):
    k_s, c_s, ramp, k = 1000.0, 0.5, 1e-3, 0.1
    depths = np.linspace(0.0, 3 * ramp, 301)[1:]
    theta = limit + side * depths

    def stop(th, om=0.0, r=ramp):
        tau, e, pw = kernels.hinge_law(th, om, k, 0.0, k_s, c_s, r)
        return tau + k * th, e - 0.5 * k * th * th, pw    # the stop's share alone

    tau = np.array([stop(t)[0] for t in theta])
    energy = np.array([stop(t)[1] for t in theta])
    # the torque is minus the slope of the stored energy (a spring, not a source)
    h = 1e-8
    slope = np.array([(stop(t + h)[1] - stop(t - h)[1]) / (2 * h) for t in theta])
    assert np.abs(tau + slope).max() < 1e-6 * k_s * ramp
    # no jump at first touch: torque, stiffness and damping all start from zero
    first = limit + side * 1e-9
    assert abs(stop(first)[0]) < 1e-12 and stop(first, 1.0)[2] < 1e-9
    # stiffness continuous where the ramp ends (one-sided slopes agree)
    edge, d = limit + side * ramp, 1e-7
    inner = (stop(edge)[0] - stop(edge - side * d)[0]) / d
    outer = (stop(edge + side * d)[0] - stop(edge)[0]) / d
    assert inner == pytest.approx(outer, rel=1e-3) and abs(outer) == pytest.approx(k_s, rel=1e-3)
    # past the ramp: the paper's stop moved ramp / 2 deeper, with its full damper
    beyond = depths > ramp
    assert np.allclose(tau[beyond], -side * k_s * (depths[beyond] - ramp / 2), rtol=1e-12)
    for t, dep in zip(theta[beyond][::20], depths[beyond][::20]):
        assert stop(t, 2.0)[0] - stop(t)[0] == pytest.approx(-c_s * 2.0, rel=1e-12)
        assert stop(t, 2.0)[2] == pytest.approx(c_s * 4.0, rel=1e-12)
    # the engagement's share: half at mid-ramp, all from its end
    assert kernels.stop_engagement(ramp / 2, ramp) == 0.5
    assert kernels.stop_engagement(ramp, ramp) == kernels.stop_engagement(1.0, ramp) == 1.0
    assert energy.min() >= 0.0 and np.all(np.diff(energy) > 0)
