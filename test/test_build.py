"""Scene -> model: the paper's merged design as bodies, hinges, tree and loop."""

from pathlib import Path

import numpy as np
import pytest

from panel_deploy.build import build_model
from panel_deploy.errors import SceneError
from panel_deploy.kinematics import forward_kinematics, hinge_points
from panel_deploy.model import State
from panel_deploy.scene import load_scene, scene_from_dict

PAPER = Path(__file__).resolve().parent.parent / "config" / "scenes" / "paper_4x4.yaml"


@pytest.fixture(scope="module")
def scene():
    return load_scene(PAPER)


@pytest.fixture(scope="module")
def model(scene):
    return build_model(scene)


def body(model, name):
    return [b.name for b in model.bodies].index(name)


def test_paper_bodies_and_hinges(model):
    assert model.n_bodies == 12 and len(model.hinges) == 12
    assert model.bodies[model.ground].name == "r1c2+r1c3"
    large = [b for b in model.bodies if len(b.cells) == 2]
    assert len(large) == 4
    for b in large:
        assert b.mass == pytest.approx(0.04)
        assert b.size == pytest.approx([0.2, 0.1, 0.005])
        # Uniform box: I_zz = m (a^2 + b^2) / 12.
        assert b.inertia[2, 2] == pytest.approx(0.04 * (0.2**2 + 0.1**2) / 12)
    # One loop of 10 bodies, closed by one cut hinge; the L4-L3 and L3-L2 hinges are
    # two collinear segments each, 0.2 m long.
    assert len(model.cut_hinges) == 1 and model.n_coords == 11
    long = [h for h in model.hinges if len(h.segments) == 2]
    assert len(long) == 2 and all(h.length == pytest.approx(0.2) for h in long)
    # each segment keeps its own spring: the long hinges act with 2 k and 2 c
    assert all(h.springs == len(h.segments) for h in model.hinges)
    assert all(h.k_hinge == pytest.approx(0.2) and h.c_hinge == pytest.approx(0.0086)
               for h in long)
    for h in model.hinges:
        assert np.linalg.norm(h.axis) == pytest.approx(1.0)
        assert h.k == pytest.approx(0.1) and h.c == pytest.approx(0.0043)
        assert abs(h.point[2]) == pytest.approx(0.0025)  # on a facet, t / 2 off the mid-plane
        assert h.theta_stowed == pytest.approx(np.pi)


def test_stowed_state_is_two_stacks_in_paper_order(model):
    R, p = forward_kinematics(model, State.stowed(model).theta)
    t = 0.005
    order = ["r1c2+r1c3", "r1c1", "r2c1", "r3c1", "r4c1", "r4c2+r4c3", "r3c2+r3c3", "r2c2+r2c3"]
    z = [p[body(model, name), 2] for name in order]
    assert np.allclose(z, -t * np.arange(8), atol=1e-12)
    # The right stack mirrors the left one: same layers, on the other footprint cell.
    for left, right in [("r1c1", "r1c4"), ("r2c1", "r2c4"), ("r3c1", "r3c4"), ("r4c1", "r4c4")]:
        pl, pr = p[body(model, left)], p[body(model, right)]
        assert pl[2] == pytest.approx(pr[2]) and pl[0] == pytest.approx(-pr[0])
        assert abs(pl[0]) == pytest.approx(0.05) and pl[1] == pytest.approx(0.15)
    # Every body sits on the ground's footprint, rotated by 0 or pi about x or y.
    for i in range(model.n_bodies):
        assert np.allclose(np.abs(R[i]), np.eye(3), atol=1e-12)


def test_loop_closes_exactly_stowed_and_flat(model):
    for theta in (State.stowed(model).theta, np.zeros(model.n_coords)):
        R, p = forward_kinematics(model, theta)
        for cut in model.cut_hinges:
            M_a, N_a, M_b, N_b = hinge_points(model, R, p, cut)
            assert np.allclose(M_a, M_b, atol=1e-12) and np.allclose(N_a, N_b, atol=1e-12)


def test_flat_state_is_the_array(model):
    R, p = forward_kinematics(model, np.zeros(model.n_coords))
    for i, b in enumerate(model.bodies):
        assert np.allclose(p[i], b.flat_position) and np.allclose(R[i], np.eye(3))


def test_mirror_groups(model):
    names = [h.name for h in model.hinges]
    groups = [sorted(names[i] for i in g) for g in model.hinge_groups]
    assert ["r1c1-r1c2", "r1c3-r1c4"] in groups  # the two top vertical hinges
    assert ["r3c2-r4c2"] in groups               # L4-L3 lies on the mirror line
    assert len(groups) == 7 and sum(map(len, groups)) == 12


def test_collision_pairs_leave_out_hinged_neighbours(model):
    linked = {frozenset((h.body_a, h.body_b)) for h in model.hinges}
    assert len(model.collision_pairs) == 66 - 12
    assert not any(frozenset(p) in linked for p in model.collision_pairs)


def test_overrides_and_bad_names(scene):
    data = dict(scene.data, hinges={"stiffness": 0.1, "overrides": {"r1c1-r2c1": 0.05}})
    m = build_model(scene_from_dict(data))
    h = next(h for h in m.hinges if h.name == "r1c1-r2c1")
    assert h.k == 0.05 and h.c == pytest.approx(0.043 * 0.05)
    with pytest.raises(SceneError, match=r"^hinges.overrides.r9c9-r9c8: no such hinge"):
        build_model(scene_from_dict(dict(scene.data, hinges={"overrides": {"r9c9-r9c8": 0.1}})))
    with pytest.raises(SceneError, match=r"^closure.cut_hinge\[0\]: \[\[1, 2\], \[2, 2\]\] is not a hinge"):
        build_model(scene_from_dict(dict(scene.data, closure={"cut_hinge": [[[1, 2], [2, 2]]]})))
    with pytest.raises(SceneError, match=r"^hinges.groups\[0\]: no such hinge"):
        build_model(scene_from_dict(dict(scene.data, hinges={"groups": [["nope"]]})))


def test_chosen_cut_hinge(scene):
    m = build_model(scene_from_dict(dict(scene.data, closure={"cut_hinge": [[[1, 1], [2, 1]]]})))
    assert [m.hinges[i].name for i in m.cut_hinges] == ["r1c1-r2c1"]


def test_unpackable_circuit_is_a_scene_error():
    data = {"array": {"rows": 4, "cols": 4, "length": 0.1, "width": 0.1, "thickness": 0.005,
                      "mass": 0.02},
            "fold": {"circuit": [[1, 1], [1, 2], [2, 2], [2, 1]]}}
    with pytest.raises(SceneError, match=r"^fold"):
        build_model(scene_from_dict(data))


def test_a_listed_merge_that_is_refused_is_a_scene_error(scene):
    # (1,1)-(1,2) lie on different stowed layers: fold reports it refused,
    # and a model must not be built without it
    merge = [[[1, 1], [1, 2]], [[1, 2], [1, 3]]]
    with pytest.raises(SceneError, match=r"^fold.merge: \(1,1\)-\(1,2\) refused: they lie on layers"):
        build_model(scene_from_dict(dict(scene.data, fold=dict(scene.data["fold"], merge=merge))))
    m = build_model(scene_from_dict(dict(scene.data, fold=dict(scene.data["fold"], merge=merge[1:]))))
    assert len(m.bodies) == 15


def test_the_model_is_immutable_and_typed(model):
    import dataclasses
    for array in (model.gravity, model.bodies[0].size, model.bodies[0].inertia,
                  model.bodies[0].flat_position, model.hinges[0].point, model.hinges[0].axis):
        with pytest.raises(ValueError, match="read-only"):
            array[0] = 1.0
    with pytest.raises(dataclasses.FrozenInstanceError):
        model.name = "other"
    assert model.name == "paper_4x4" and all(isinstance(g, tuple) for g in model.hinge_groups)
    stiffer = model.with_stiffness(2 * model.stiffness)
    assert (stiffer.name, stiffer.hinge_groups) == (model.name, model.hinge_groups)
    assert np.allclose(stiffer.stiffness, 2 * model.stiffness)
    assert [h.c / h.k for h in stiffer.hinges] == pytest.approx([h.c / h.k for h in model.hinges])


def test_air_parameters_refuse_what_would_feed_energy_in():
    from panel_deploy.errors import ModelError
    from panel_deploy.model import AirParameters

    assert AirParameters(1.2, 1.17).pressure_coefficient == pytest.approx(0.5 * 1.2 * 1.17)
    assert AirParameters().pressure_coefficient == 0.0
    with pytest.raises(ModelError, match=r"^air.density: expected a finite number >= 0, got -1.2"):
        AirParameters(-1.2, 1.17)
    with pytest.raises(ModelError, match=r"^air.drag_coefficient: expected a finite number >= 0"):
        AirParameters(1.2, float("nan"))


def test_a_stop_ramp_is_a_depth_from_the_scene_and_never_negative():
    from panel_deploy.errors import ModelError
    from panel_deploy.model import Model

    model = build_model(load_scene(PAPER, ["contact.stop_ramp=1e-4"]))
    assert model.stop_ramp == 1e-4 and build_model(load_scene(PAPER)).stop_ramp == 0.0
    for bad in (-1e-4, float("nan"), float("inf")):
        with pytest.raises(ModelError, match=r"^stop_ramp: expected a finite depth >= 0 rad"):
            Model.build(model.bodies, model.hinges, model.ground, stop_ramp=bad)
    with pytest.raises(SceneError, match=r"contact.stop_ramp"):
        load_scene(PAPER, ["contact.stop_ramp=-1e-4"])
    with pytest.raises(SceneError, match=r"contact.stop_ramp.*milliradians"):
        load_scene(PAPER, ["contact.stop_ramp=0.1"])
