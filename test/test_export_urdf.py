"""The URDF export is the same kinematic tree as the Model.

yourdfpy is the independent URDF library: it parses the document, and its
forward kinematics, composed with each link's visual origin, must put every
panel box where :func:`forward_kinematics` puts the body, at random angles.
"""

import io
import math
import xml.etree.ElementTree as ET

import numpy as np
import pytest

yourdfpy = pytest.importorskip("yourdfpy")

from panel_deploy.build import build_model  # noqa: E402
from panel_deploy.export import link_poses, model_urdf  # noqa: E402
from panel_deploy.kinematics import forward_kinematics  # noqa: E402
from panel_deploy.model import Body, Hinge, Model, box_inertia  # noqa: E402
from panel_deploy.scene import load_scene, resolve_scene  # noqa: E402

A, B, T = 0.1, 0.08, 0.005
N_STATES = 20
TOL = 1e-9


def _body(name, x, y, mass=0.02, inertia=None):
    size = (A, B, T)
    return Body(name, (), np.array(size), mass,
                box_inertia(mass, size) if inertia is None else inertia, np.array([x, y, 0.0]))


def _hinge(name, a, b, point, axis, length, k=0.1, facet="top"):
    return Hinge(name, a, b, np.array(point, float), np.array(axis, float), length, facet,
                 k, 0.043 * k, math.pi, ())


def branched_tree():
    """A tree (no cut hinge): ground with a chain of two panels to the right
    and one below it, alternating facets and axis signs, one full inertia
    tensor, a '+' in a body name, a ground that is not body 0, and one hinge
    given child -> parent so that Model.build reverses it."""
    rng = np.random.default_rng(3)
    L = rng.normal(size=(3, 3))
    full = box_inertia(0.03, (A, B, T)) + 1e-6 * (L @ L.T)
    bodies = [_body("r1+r2", A, 0, mass=0.03, inertia=full), _body("g", 0, 0),
              _body("far", 2 * A, 0, mass=0.05), _body("d1", 0, -B)]
    hinges = [_hinge("g-r1", 1, 0, (A / 2, B / 2, T / 2), (0, -1, 0), B),
              _hinge("r1-far", 2, 0, (1.5 * A, B / 2, -T / 2), (0, -1, 0), B, k=0.05,
                     facet="bottom"),
              _hinge("g-d1", 1, 3, (A / 2, -B / 2, T / 2), (-1, 0, 0), A, k=0.2)]
    return Model.build(bodies, hinges, 1, name="tree<&>")


@pytest.fixture(scope="module")
def paper():
    return build_model(load_scene(resolve_scene("paper_4x4")))


@pytest.fixture(scope="module")
def tree():
    return branched_tree()


def _load(text):
    return yourdfpy.URDF.load(io.StringIO(text), build_scene_graph=True, load_meshes=False)


def _comments(text):
    root = ET.fromstring(text, parser=ET.XMLParser(target=ET.TreeBuilder(insert_comments=True)))
    return [e.text for e in root.iter() if e.tag is ET.Comment]


@pytest.mark.parametrize("which", ["paper", "tree"])
def test_structure(which, request):
    model = request.getfixturevalue(which)
    text = model_urdf(model)
    ET.fromstring(text)  # well-formed XML
    assert text == model_urdf(model)  # deterministic
    urdf = _load(text)
    assert urdf.robot.name == model.name
    names = [b.name for b in model.bodies]
    assert sorted(urdf.link_map) == sorted(names + ["world"])
    assert urdf.base_link == "world"

    revolute = [j for j in urdf.robot.joints if j.type == "revolute"]
    fixed = [j for j in urdf.robot.joints if j.type == "fixed"]
    assert [j.name for j in revolute] == [model.hinges[h].name for h in model.joints]
    assert len(urdf.robot.joints) == len(revolute) + 1
    assert (fixed[0].parent, fixed[0].child) == ("world", model.bodies[model.ground].name)
    assert np.array_equal(fixed[0].origin[:3, 3], model.bodies[model.ground].flat_position)
    for j, h_index in zip(revolute, model.joints):
        h = model.hinges[h_index]
        assert j.parent == model.bodies[h.body_a].name
        assert j.child == model.bodies[h.body_b].name
        assert np.array_equal(j.axis, h.axis)
        assert j.limit.lower == 0.0 and j.limit.upper == math.pi
        assert j.limit.effort == h.k_hinge * math.pi and j.limit.velocity > 0

    for body in model.bodies:
        link = urdf.link_map[body.name]
        for geom in (link.visuals[0], link.collisions[0]):
            assert np.array_equal(geom.geometry.box.size, body.size)
        assert link.inertial.mass == body.mass
        assert np.array_equal(link.inertial.inertia, body.inertia)
        # the box and the inertia share one frame: centred on the centroid
        assert np.array_equal(link.inertial.origin, link.visuals[0].origin)
        assert np.array_equal(link.collisions[0].origin, link.visuals[0].origin)


def test_robot_name_default(tree):
    model = Model.build(tree.bodies, tree.hinges, tree.ground)
    assert _load(model_urdf(model)).robot.name == "panel_array"


@pytest.mark.parametrize("which", ["paper", "tree"])
def test_forward_kinematics(which, request):
    """Box poses from yourdfpy's FK equal the model's body poses; link_poses
    equals yourdfpy's link transforms."""
    model = request.getfixturevalue(which)
    urdf = _load(model_urdf(model))
    names = [model.hinges[h].name for h in model.joints]
    rng = np.random.default_rng(20240607)
    worst_p = worst_R = worst_link = 0.0
    thetas = [np.zeros(model.n_coords), model.theta_stowed]
    thetas += [rng.uniform(0.0, math.pi, model.n_coords) for _ in range(N_STATES)]
    for theta in thetas:
        urdf.update_cfg(dict(zip(names, theta)))
        R, p = forward_kinematics(model, theta)
        R_link, p_link = link_poses(model, R, p)
        for b, body in enumerate(model.bodies):
            T_link = urdf.get_transform(body.name, "world")
            T_box = T_link @ urdf.link_map[body.name].visuals[0].origin
            worst_R = max(worst_R, np.abs(T_box[:3, :3] - R[b]).max())
            worst_p = max(worst_p, np.abs(T_box[:3, 3] - p[b]).max())
            worst_link = max(worst_link, np.abs(T_link[:3, :3] - R_link[b]).max(),
                             np.abs(T_link[:3, 3] - p_link[b]).max())
    assert worst_R < TOL and worst_p < TOL and worst_link < TOL, (worst_R, worst_p, worst_link)


def test_link_poses_flat(paper):
    """At theta = 0 every link frame is the flat frame translated to its origin."""
    R, p = forward_kinematics(paper, np.zeros(paper.n_coords))
    R_link, p_link = link_poses(paper, R, p)
    assert np.allclose(R_link, np.eye(3), atol=0)
    g = paper.ground
    assert np.array_equal(p_link[g], paper.bodies[g].flat_position)
    for b in paper.order[1:]:
        h = paper.hinges[paper.joints[paper.body_joint[b]]]
        assert np.allclose(p_link[b], h.point, atol=1e-15)


def test_cut_hinge_comment(paper, tree):
    assert paper.cut_hinges
    comments = _comments(model_urdf(paper))
    for h_index in paper.cut_hinges:
        h = paper.hinges[h_index]
        hits = [c for c in comments if f'cut hinge "{h.name}"' in c]
        assert len(hits) == 1
        assert f'"{paper.bodies[h.body_a].name}"' in hits[0]
        assert f'"{paper.bodies[h.body_b].name}"' in hits[0]
        assert "/joint_states" in hits[0]
    # a cut hinge is not a joint
    joints = {j.name for j in _load(model_urdf(paper)).robot.joints}
    assert not joints & {paper.hinges[h].name for h in paper.cut_hinges}

    assert not tree.cut_hinges
    assert not [c for c in _comments(model_urdf(tree)) if "cut hinge" in c]
