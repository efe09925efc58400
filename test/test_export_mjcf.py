"""The MJCF export is the same multibody system as the Model.

MuJoCo is the independent tool: its forward kinematics, mass matrix and
(constraint-free) forward dynamics must equal ours at random states.
"""

import dataclasses
import math

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco")

from panel_deploy.export import export_mjcf, qpos_index  # noqa: E402
from panel_deploy.export.mjcf import mass_matrix, solref_parameters  # noqa: E402
from panel_deploy.kinematics import forward_kinematics  # noqa: E402
from panel_deploy.model import Body, ClosureParameters, Hinge, Model, box_inertia  # noqa: E402

A, B, T = 0.1, 0.08, 0.005


def _body(name, cell, x, y, mass=0.02, size=(A, B, T), inertia=None):
    return Body(name, (cell,), np.array(size), mass,
                box_inertia(mass, size) if inertia is None else inertia, np.array([x, y, 0.0]))


def _hinge(name, a, b, point, axis, length, k=0.1, c=0.0043, facet="top"):
    return Hinge(name, a, b, np.array(point, float), np.array(axis, float), length, facet,
                 k, c, math.pi, ())


def branched_tree():
    """Ground panel with a chain of two panels to the right and one below it.

    Hinges alternate facets and axis signs, and one body has a full
    (non-diagonal) inertia tensor, so every term of the export is exercised.
    """
    rng = np.random.default_rng(3)
    L = rng.normal(size=(3, 3))
    full = box_inertia(0.03, (A, B, T)) + 1e-6 * (L @ L.T)
    bodies = [_body("g", (1, 1), 0, 0), _body("r1", (1, 2), A, 0, mass=0.03, inertia=full),
              _body("r2", (1, 3), 2 * A, 0, mass=0.05), _body("d1", (2, 1), 0, -B)]
    hinges = [_hinge("g-r1", 0, 1, (A / 2, B / 2, T / 2), (0, -1, 0), B),
              _hinge("r1-r2", 1, 2, (1.5 * A, -B / 2, -T / 2), (0, 1, 0), B, k=0.05, c=0.002,
                     facet="bottom"),
              _hinge("g-d1", 0, 3, (A / 2, -B / 2, T / 2), (-1, 0, 0), A, k=0.2, c=0.008)]
    return Model.build(bodies, hinges, 0, k_s=1000.0, c_s=0.5, gravity=(0.3, -9.81, 1.2))


def collinear_loop():
    """Two panels joined by two collinear hinge segments: a loop whose cut
    hinge stays exactly closed for every angle of the tree hinge."""
    bodies = [_body("g", (1, 1), 0, 0), _body("b", (1, 2), A, 0)]
    hinges = [_hinge("lower", 0, 1, (A / 2, -B / 2, T / 2), (0, 1, 0), B / 2, k=0.1, c=0.004),
              _hinge("upper", 0, 1, (A / 2, 0, T / 2), (0, 1, 0), B / 2, k=0.03, c=0.001)]
    closure = ClosureParameters("penalty", k_M=1e5, c_M=50.0, k_N=1e5, c_N=50.0)
    return Model.build(bodies, hinges, 0, cut_hinges=[1], k_s=1000.0, c_s=0.5,
                       closure=closure, gravity=(0, -9.81, 0))


def ring():
    """A 2 x 2 ring of panels: one loop, general cut-hinge geometry. The cut
    hinge has no spring: away from closure MuJoCo's rotation-vector angle and
    the kernel's atan2 angle differ, and the comparison is of the open tree."""
    bodies = [_body("g", (1, 1), -A / 2, B / 2), _body("r", (1, 2), A / 2, B / 2, mass=0.03),
              _body("d", (2, 2), A / 2, -B / 2, mass=0.025), _body("l", (2, 1), -A / 2, -B / 2)]
    hinges = [_hinge("g-r", 0, 1, (0, 0, T / 2), (0, 1, 0), B),
              _hinge("r-d", 1, 2, (A, 0, -T / 2), (-1, 0, 0), A, k=0.05, c=0.002, facet="bottom"),
              _hinge("d-l", 2, 3, (0, -B, T / 2), (0, 1, 0), B, k=0.15, c=0.006),
              _hinge("l-g", 3, 0, (-A, 0, -T / 2), (1, 0, 0), A, k=0.0, c=0.0, facet="bottom")]
    closure = ClosureParameters("penalty", k_M=1e6, c_M=280.0, k_N=1e6, c_N=280.0)
    return Model.build(bodies, hinges, 0, cut_hinges=[3], k_s=1000.0, c_s=0.5,
                       closure=closure, gravity=(0.5, -9.81, 2.0))


def paper():
    """The paper scene's model with the cut hinge's spring off (see ring())."""
    from pathlib import Path

    from panel_deploy.build import build_model
    from panel_deploy.scene import load_scene

    model = build_model(load_scene(Path(__file__).resolve().parent.parent
                                   / "config" / "scenes" / "paper_4x4.yaml"))
    k = np.array([0.0 if i in model.cut_hinges else h.k for i, h in enumerate(model.hinges)])
    return model.with_stiffness(k, np.where(k > 0, [h.c for h in model.hinges], 0.0))


def load(model):
    m = mujoco.MjModel.from_xml_string(export_mjcf(model))
    return m, mujoco.MjData(m)


def random_states(model, count, seed):
    rng = np.random.default_rng(seed)
    for _ in range(count):
        yield rng.uniform(0.05, math.pi - 0.05, model.n_coords), rng.normal(0, 3, model.n_coords)


@pytest.mark.parametrize("make", [branched_tree, collinear_loop])
def test_structure_and_stowed_keyframe(make):
    model = make()
    m, d = load(model)
    assert m.nbody == model.n_bodies + 1  # + MuJoCo's world body
    assert m.njnt == m.nq == m.nv == model.n_coords
    assert np.all(m.dof_armature == 0) and np.all(m.dof_frictionloss == 0)
    assert np.all(m.geom_contype == 0) and np.all(m.geom_conaffinity == 0)
    np.testing.assert_allclose(m.opt.gravity, model.gravity)
    idx = qpos_index(model)
    for i in range(model.n_coords):
        h = model.hinges[model.joints[i]]
        j = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, h.name)
        assert m.jnt_qposadr[j] == idx[i]
        assert m.jnt_stiffness[j] == h.k and m.dof_damping[m.jnt_dofadr[j]] == h.c
        assert m.qpos_spring[m.jnt_qposadr[j]] == 0.0
        np.testing.assert_allclose(m.jnt_range[j], [0.0, math.pi])
    for b, body in enumerate(model.bodies):
        j = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, body.name)
        assert m.body_mass[j] == pytest.approx(body.mass, rel=1e-14)
    mujoco.mj_resetDataKeyframe(m, d, 0)
    np.testing.assert_array_equal(d.qpos[idx], model.theta_stowed)


@pytest.mark.parametrize("make", [branched_tree, collinear_loop])
def test_poses_match_forward_kinematics(make):
    model = make()
    m, d = load(model)
    idx = qpos_index(model)
    for theta, omega in random_states(model, 5, seed=1):
        d.qpos[idx] = theta
        d.qvel[idx] = omega
        mujoco.mj_forward(m, d)
        R, p, v, w = forward_kinematics(model, theta, omega)
        for b, body in enumerate(model.bodies):
            j = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, body.name)
            # body frame origin = centroid (MuJoCo's inertial frame is the
            # principal-axis frame, rotated when the inertia is not diagonal)
            np.testing.assert_allclose(d.xpos[j], p[b], atol=1e-14)
            np.testing.assert_allclose(d.xipos[j], p[b], atol=1e-14)
            np.testing.assert_allclose(d.xmat[j].reshape(3, 3), R[b], atol=1e-14)
            vel = np.empty(6)
            mujoco.mj_objectVelocity(m, d, mujoco.mjtObj.mjOBJ_BODY, j, vel, 0)
            np.testing.assert_allclose(vel[:3], w[b], atol=1e-12)
            # object velocity refers to the body frame origin = centroid
            np.testing.assert_allclose(vel[3:], v[b], atol=1e-12)


@pytest.mark.parametrize("make", [branched_tree, collinear_loop])
def test_mass_matrix_matches_mujoco(make):
    model = make()
    m, d = load(model)
    idx = qpos_index(model)
    for theta, _ in random_states(model, 5, seed=2):
        d.qpos[idx] = theta
        mujoco.mj_forward(m, d)
        full = np.zeros((m.nv, m.nv))
        mujoco.mj_fullM(m, d, full)
        M, _, _ = mass_matrix(model, theta)
        np.testing.assert_allclose(full[np.ix_(idx, idx)], M, rtol=1e-12, atol=1e-16)


def _open_tree(model):
    """The model without joint-limit contact and penalty springs (Eq. 4-5 off)."""
    return dataclasses.replace(model, k_s=0.0, c_s=0.0,
                               closure=dataclasses.replace(model.closure, k_M=0.0, c_M=0.0,
                                                           k_N=0.0, c_N=0.0))


@pytest.mark.parametrize("make", [branched_tree, collinear_loop, ring, paper])
def test_open_tree_accelerations_match_the_kernel(make):
    """MuJoCo's qacc with constraints off equals our forward dynamics (springs,
    dampers, gravity, cut-hinge spring) at random states inside (0, pi)."""
    from panel_deploy.dynamics.kernels import rhs, scratch, state_vector
    from panel_deploy.dynamics.pack import pack

    model = make()
    m, d = load(model)
    m.opt.disableflags |= (mujoco.mjtDisableBit.mjDSBL_CONSTRAINT | mujoco.mjtDisableBit.mjDSBL_CONTACT
                           | mujoco.mjtDisableBit.mjDSBL_EQUALITY | mujoco.mjtDisableBit.mjDSBL_LIMIT)
    P = pack(_open_tree(model))
    idx = qpos_index(model)
    n = model.n_coords
    for theta, omega in random_states(model, 20, seed=4):
        d.qpos[idx] = theta
        d.qvel[idx] = omega
        mujoco.mj_forward(m, d)
        ours = rhs(P, state_vector(theta, omega), scratch(P))[n:2 * n]
        assert np.all(np.isfinite(ours))
        np.testing.assert_allclose(d.qacc[idx], ours, rtol=1e-9, atol=1e-9 * np.abs(ours).max())


def test_cut_hinge_closes_and_its_spring_acts_about_the_axis():
    model = collinear_loop()
    m, d = load(model)
    cut = model.hinges[model.cut_hinges[0]]
    tree = model.hinges[model.joints[0]]
    for theta in np.linspace(0.0, math.pi, 7):
        d.qpos[0] = theta
        d.qvel[0] = 0.7
        mujoco.mj_forward(m, d)
        # both connect equalities are satisfied exactly on a collinear loop
        eq_rows = d.efc_type == mujoco.mjtConstraint.mjCNSTR_EQUALITY
        np.testing.assert_allclose(d.efc_pos[eq_rows], 0.0, atol=1e-15)
        np.testing.assert_allclose(d.actuator_length[0], theta - math.pi / 2, atol=1e-12)
        np.testing.assert_allclose(d.actuator_velocity[0], 0.7, atol=1e-12)
        # spring + damper of the cut hinge add to the tree joint's own
        expected = -cut.k * theta - cut.c * 0.7
        np.testing.assert_allclose(d.qfrc_actuator[0], expected, rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(d.qfrc_spring[0] + d.qfrc_damper[0],
                                   -tree.k * theta - tree.c * 0.7, rtol=1e-12)


def test_limit_and_closure_solref_follow_the_stated_mapping():
    model = collinear_loop()
    m, _ = load(model)
    p = solref_parameters(model)
    M, _, _ = mass_matrix(model, model.theta_stowed)
    # one coordinate: the row's inverse effective inertia is 1 / M
    np.testing.assert_allclose(p["limit"][0], [model.k_s / M[0, 0], model.c_s / M[0, 0]])
    np.testing.assert_allclose(-m.jnt_solref[0], p["limit"][0])
    # the point M lies on the hinge line: it does not move, zero effective mass
    np.testing.assert_allclose(p[("connect", 1, "M")], 0.0, atol=1e-12)
    np.testing.assert_allclose(-m.eq_solref[0], p[("connect", 1, "M")], atol=1e-12)


def test_limit_row_stiffness_and_damping_as_mapped():
    """Pushed past its limit with nothing else acting, the row accelerates as
    the paper's -k_s r - c_s v would make it."""
    bodies = [_body("g", (1, 1), 0, 0), _body("b", (1, 2), A, 0)]
    hinges = [_hinge("h", 0, 1, (A / 2, -B / 2, T / 2), (0, 1, 0), B, k=0.0, c=0.0)]
    model = Model.build(bodies, hinges, 0, k_s=1000.0, c_s=0.5)
    m, d = load(model)
    # at the stowed state: the mapping is exact there
    d.qpos[0] = math.pi + 1e-3
    d.qvel[0] = 0.2
    mujoco.mj_forward(m, d)
    M, _, _ = mass_matrix(model, d.qpos)
    paper = (-model.k_s * 1e-3 - model.c_s * 0.2) / M[0, 0]
    np.testing.assert_allclose(d.qacc[0], paper, rtol=2e-4)  # 1 - impedance leaks


def test_paper_stowed_keyframe_closes_the_loop():
    """At the stowed keyframe the cut hinge's ends coincide on both sides and
    its angle, as MuJoCo measures it, is pi (folded)."""
    from pathlib import Path

    from panel_deploy.build import build_model
    from panel_deploy.scene import load_scene

    model = build_model(load_scene(Path(__file__).resolve().parent.parent
                                   / "config" / "scenes" / "paper_4x4.yaml"))
    cut = model.hinges[model.cut_hinges[0]]
    assert cut.theta_stowed == pytest.approx(math.pi)
    m, d = load(model)
    mujoco.mj_resetDataKeyframe(m, d, 0)
    mujoco.mj_forward(m, d)
    eq_rows = d.efc_type == mujoco.mjtConstraint.mjCNSTR_EQUALITY
    assert eq_rows.sum() == 6
    np.testing.assert_allclose(d.efc_pos[eq_rows], 0.0, atol=1e-12)
    np.testing.assert_allclose(d.actuator_length[0] + math.pi / 2, math.pi, atol=1e-9)


def test_air_maps_to_the_inertia_box_fluid_model():
    """density = rho C_d and no viscosity; on a panel swinging about its edge hinge
    MuJoCo's fluid torque is the inertia-box formula, 5/8 of our pressure integral
    rho C_d w L^4 omega |omega| / 8 (the difference the module doc states)."""
    from panel_deploy.dynamics import kernels, panel_contact
    from panel_deploy.dynamics.pack import pack
    from panel_deploy.model import AirParameters

    still = collinear_loop()
    assert "density" not in export_mjcf(still) and "viscosity" not in export_mjcf(still)
    bodies = [_body("g", (1, 1), 0, 0), _body("b", (1, 2), A, 0)]
    hinges = [_hinge("h", 0, 1, (A / 2, -B / 2, T / 2), (0, 1, 0), B, k=0.0, c=0.0)]
    rho, cd = 1.2, 1.17
    model = Model.build(bodies, hinges, 0, air=AirParameters(rho, cd))
    m, d = load(model)
    assert (m.opt.density, m.opt.viscosity) == (pytest.approx(rho * cd), 0.0)
    rx, ry, rz = A / 2, B / 2, T / 2  # the equivalent inertia box is the panel
    for theta, omega in ((0.4, 3.0), (2.0, -4.0)):
        d.qpos[0], d.qvel[0] = theta, omega
        mujoco.mj_forward(m, d)
        # centroid drag (normal and edge-on) times its lever about the hinge, plus the spin term
        box = -rho * cd * (2 * rx * ry * (A / 2) ** 3 + 2 * ry * rz * (T / 2) ** 3
                           + 0.5 * ry * (rx**4 + rz**4)) * omega * abs(omega)
        assert d.qfrc_fluid[0] == pytest.approx(box, rel=1e-9)
        P = pack(model)
        ours = kernels.mass_and_bias(P, np.array([theta]), np.array([omega]),
                                     panel_contact.near_pairs(P))[1][0]
        assert ours == pytest.approx(-rho * cd * B * A**4 * omega * abs(omega) / 8, rel=1e-12)
        assert d.qfrc_fluid[0] / ours == pytest.approx(5 / 8, rel=1e-4)
