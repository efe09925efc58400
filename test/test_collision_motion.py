"""Between-sample motion bounds (collision.motion) against independent computations.

The radii are checked against the point-to-line distance |r x u| of every
corner, the rate and acceleration bounds against a dense grid of scipy's
Hermite spline, the pair speed bound against finite differences of the exact
signed distance along random motions of the paper's design (it must never be
exceeded), and the second-order bound's pieces against forward kinematics:
each view's speed against central differences of the corners seen from the
other body, its acceleration bound against their second differences. The
pairs' tree paths, compiled, are a plain walk up the tree's to the bit.
"""

import math

import numpy as np
import pytest
from scipy.interpolate import CubicHermiteSpline

from panel_deploy.build import build_model
from panel_deploy.collision.geometry import BoxSet
from panel_deploy.collision.motion import HermiteSegment, PairSpeedBound
from panel_deploy.kinematics import forward_kinematics
from panel_deploy.scene import load_scene, resolve_scene


@pytest.fixture(scope="module")
def paper():
    return build_model(load_scene(resolve_scene("paper_4x4")))


def corner_line_distances(model, R, p):
    """(nb, n_coords) largest corner distance from every hinge line, by |r x u|."""
    out = np.zeros((model.n_bodies, model.n_coords))
    signs = np.array([(i, j, k) for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], float)
    for k, h in enumerate(model.joints):
        hinge = model.hinges[h]
        Rp, pp = R[hinge.body_a], p[hinge.body_a]
        point = pp + Rp @ (hinge.point - model.bodies[hinge.body_a].flat_position)
        axis = Rp @ hinge.axis
        for b, body in enumerate(model.bodies):
            corners = p[b] + (signs * np.asarray(body.size) / 2) @ R[b].T
            out[b, k] = np.linalg.norm(np.cross(corners - point, axis), axis=1).max()
    return out


def test_radii_are_the_corner_distances_from_each_hinge_line(paper):
    bound = PairSpeedBound(paper, paper.collision_pairs)
    rng = np.random.default_rng(3)
    for theta in (np.zeros(paper.n_coords), np.full(paper.n_coords, math.pi),
                  *(rng.uniform(0, math.pi, paper.n_coords) for _ in range(5))):
        R, p = forward_kinematics(paper, theta)
        np.testing.assert_allclose(bound.radii(R, p), corner_line_distances(paper, R, p),
                                   rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("order", [1, 2])
def test_rate_and_acceleration_bounds_are_the_largest_on_a_dense_grid(order):
    rng = np.random.default_rng(4 + order)
    for _ in range(20):
        th0, th1, w0, w1 = (rng.normal(size=6) for _ in range(4))
        seg = HermiteSegment(0.2, th0, w0, 0.25, th1, w1)
        spline = CubicHermiteSpline([0.2, 0.25], [th0, th1], [w0, w1])
        ta, tb = np.sort(rng.uniform(0.2, 0.25, 2))
        grid = np.linspace(ta, tb, 20001)
        dense = np.abs(spline(grid, order)).max(axis=0)
        got = (seg.rate_bound if order == 1 else seg.accel_bound)(ta, tb)
        assert np.all(got >= dense * (1 - 1e-12))
        np.testing.assert_allclose(got, dense, rtol=1e-6)


def test_pair_speed_bound_is_never_exceeded_along_random_motions(paper):
    """|sd(t + dt) - sd(t)| / dt <= L on every pair, over Hermite motions at up to 20 rad/s;
    and L is not vacuous: for some pair the measured rate reaches a tenth of it."""
    pairs = np.asarray(paper.collision_pairs)
    bound = PairSpeedBound(paper, pairs)
    boxes = BoxSet(paper)
    rows = np.arange(len(pairs))
    rng = np.random.default_rng(11)
    ratios = []
    for _ in range(6):
        th0, th1 = rng.uniform(0.3, 2.8, (2, paper.n_coords))
        w0, w1 = rng.uniform(-20, 20, (2, paper.n_coords))
        seg = HermiteSegment(0.0, th0, w0, 0.05, th1, w1)
        ta, tb = 0.01, 0.03
        L = bound(seg.rate_bound(ta, tb), tb - ta, bound.radii(*forward_kinematics(paper, seg(ta)[0])),
                  bound.radii(*forward_kinematics(paper, seg(tb)[0])), rows)
        sd = []
        for t in np.linspace(ta, tb, 81):
            boxes.set_poses(*forward_kinematics(paper, seg(t)[0]))
            sd.append([boxes.signed_distance(a, b) for a, b in pairs])
        rate = np.abs(np.diff(sd, axis=0)).max(axis=0) / ((tb - ta) / 80)
        assert np.all(rate <= L * (1 + 1e-9) + 1e-12)
        ratios.append((rate / L).max())
    assert max(ratios) > 0.1


def seen_from(model, R, p, x, y):
    """The 8 corners (..., 8, 3) of body y in body x's frame, m, the bodies at
    poses R (..., nb, 3, 3), p (..., nb, 3)."""
    signs = np.array([(i, j, k) for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], float)
    offsets = np.einsum("...ij,cj->...ci", R[..., y, :, :], signs * np.asarray(model.bodies[y].size) / 2)
    return np.einsum("...ci,...ij->...cj", p[..., y, None, :] + offsets - p[..., x, None, :], R[..., x, :, :])


def random_segments(model, rng, count, rate=20.0):
    for _ in range(count):
        th0, th1 = rng.uniform(0.3, 2.8, (2, model.n_coords))
        w0, w1 = rng.uniform(-rate, rate, (2, model.n_coords))
        yield HermiteSegment(0.0, th0, w0, 0.05, th1, w1)


def test_pair_speeds_are_the_corners_speeds_seen_from_each_body(paper):
    """V of each view is the largest speed of the corners of one body in the
    other's frame, by central differences of forward kinematics."""
    from panel_deploy.dynamics.kernels import body_states
    from panel_deploy.dynamics.pack import pack

    pairs = np.asarray(paper.collision_pairs)
    bound, rows = PairSpeedBound(paper, pairs), np.arange(len(pairs))
    packed, dt = pack(paper), 1e-6
    for seg in random_segments(paper, np.random.default_rng(13), 3):
        theta, omega = seg(0.02)
        V = bound.speeds(*body_states(packed, theta, omega), rows)
        after, before = (forward_kinematics(paper, seg(0.02 + sign * dt)[0]) for sign in (1, -1))
        for view, (x, y) in enumerate((pairs.T, pairs.T[::-1])):
            fd = [np.linalg.norm(seen_from(paper, *after, i, j) - seen_from(paper, *before, i, j),
                                 axis=1).max() / (2 * dt) for i, j in zip(x, y)]
            np.testing.assert_allclose(V[view], fd, rtol=1e-6, atol=1e-9)


def test_acceleration_bound_is_never_exceeded_along_random_motions(paper):
    """The corners of one body seen from the other accelerate (second
    differences over a dense grid) no faster than the bound of that view,
    over Hermite motions at up to 20 rad/s; and the bound is not vacuous."""
    pairs = np.asarray(paper.collision_pairs)
    bound, rows = PairSpeedBound(paper, pairs), np.arange(len(pairs))
    ta, tb, steps = 0.01, 0.03, 400
    dt = (tb - ta) / steps
    ratios = []
    for seg in random_segments(paper, np.random.default_rng(17), 4):
        radii = [bound.radii(*forward_kinematics(paper, seg(t)[0])) for t in (ta, tb)]
        A = bound.acceleration(seg.rate_bound(ta, tb), seg.accel_bound(ta, tb), tb - ta, *radii, rows)
        poses = [forward_kinematics(paper, seg(t)[0]) for t in np.linspace(ta, tb, steps + 1)]
        R, p = np.array([pose[0] for pose in poses]), np.array([pose[1] for pose in poses])
        for view, (x, y) in enumerate((pairs.T, pairs.T[::-1])):
            for k, (i, j) in enumerate(zip(x, y)):
                path = seen_from(paper, R, p, i, j)
                measured = np.linalg.norm(np.diff(path, 2, axis=0), axis=2).max() / dt ** 2
                assert measured <= A[view, k] * (1 + 1e-6), (view, (i, j), measured, A[view, k])
                ratios.append(measured / A[view, k])
    assert max(ratios) > 0.1


def plain_path(model, a, b):
    """Bodies b_0 = a .. b_m = b and the coordinates of the joints between them, by lists."""
    def up(x):
        chain = [x]
        while model.parent[chain[-1]] >= 0:
            chain.append(model.parent[chain[-1]])
        return chain

    ua, ub = up(a), up(b)
    common = next(x for x in ua if x in set(ub))
    side_a, side_b = ua[:ua.index(common) + 1], ub[:ub.index(common)][::-1]
    coords = [model.body_joint[x] for x in side_a[:-1]] + [model.body_joint[x] for x in side_b]
    return side_a + side_b, coords, common


@pytest.mark.parametrize("sets", [[], ["array.rows=10", "array.cols=10", "fold.circuit=8", "fold.ground=null"]])
def test_pair_paths_are_the_plain_walk_to_the_bit(sets):
    model = build_model(load_scene(resolve_scene("paper_4x4"), sets))
    sp = PairSpeedBound(model, model.collision_pairs)
    diag = 2.0 * np.linalg.norm(sp.half, axis=1)
    for p, (a, b) in enumerate(model.collision_pairs):
        bodies, coords, common = plain_path(model, a, b)
        m = len(coords)
        d = diag[bodies]
        assert list(sp.coords[p, :m]) == coords and sp.lca[p] == common
        assert sp.length[p] == m and np.all(sp.coords[p, m:] == 0) and np.all(sp.chain_a[p, m:] == 0.0)
        np.testing.assert_array_equal(sp.chain_a[p, :m], np.cumsum(d[::-1])[::-1][1:])
        np.testing.assert_array_equal(sp.chain_b[p, :m], np.cumsum(d)[:-1])
        assert sp.reach_a[p] == sp.chain_a[p, 0] and sp.reach_b[p] == sp.chain_b[p, m - 1]
    assert not sets or sp.coords.shape[1] > 10   # long paths on the large array
