"""Box-box signed distances against independent exact references.

References (test-only): separated boxes by bounded least squares over the two
boxes' local coordinates (scipy ``lsq_linear``, BVLS: min |c_a + R_a u - c_b -
R_b w| with |u| <= h_a, |w| <= h_b); interfering boxes by the distance from
the origin to the boundary of the Minkowski difference (scipy ConvexHull of
the 64 vertex differences), which is the penetration depth. The compiled
exact distance is also compared with the numpy enumeration it replaced.
"""

import numpy as np
import pytest
from scipy.optimize import lsq_linear
from scipy.spatial import ConvexHull
from scipy.spatial.transform import Rotation

from panel_deploy.boxes import separating_axis
from panel_deploy.collision.geometry import BoxSet, box_distance, least_overlap, pair_bounds
from panel_deploy.model import Body, box_inertia

SIGNS = np.array([(i, j, k) for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], float)


def reference_signed_distance(ha, Ra, ca, hb, Rb, cb):
    A = np.hstack([Ra, -Rb])
    res = lsq_linear(A, cb - ca, bounds=(-np.r_[ha, hb], np.r_[ha, hb]), method="bvls", tol=1e-15)
    d = np.linalg.norm(A @ res.x - (cb - ca))
    if d > 1e-12:
        return d
    va = ca + (SIGNS * ha) @ Ra.T
    vb = cb + (SIGNS * hb) @ Rb.T
    hull = ConvexHull((va[:, None] - vb[None]).reshape(-1, 3))
    # facet equations n.x + off <= 0 inside; depth = min distance origin -> facet plane
    return float(np.max(hull.equations[:, 3]))


class _Two:
    def __init__(self, size_a, size_b):
        self.bodies = [Body(n, (), np.asarray(s, float), 1.0, box_inertia(1.0, s), np.zeros(3))
                       for n, s in (("a", size_a), ("b", size_b))]


def boxes(size_a, size_b, Ra, ca, Rb, cb):
    bs = BoxSet(_Two(size_a, size_b))
    bs.set_poses(np.array([Ra, Rb]), np.array([ca, cb]))
    return bs


UNIT = (0.1, 0.1, 0.005)
LARGE = (0.2, 0.1, 0.005)


def test_random_poses_match_reference_to_1e_9():
    rng = np.random.default_rng(1)
    ha, hb = np.array(UNIT) / 2, np.array(LARGE) / 2
    errors, n_pen = [], 0
    for _ in range(1500):
        Ra, Rb = Rotation.random(2, random_state=rng).as_matrix()
        cb = rng.normal(size=3) * 0.08
        bs = boxes(UNIT, LARGE, Ra, np.zeros(3), Rb, cb)
        ref = reference_signed_distance(ha, Ra, np.zeros(3), hb, Rb, cb)
        n_pen += ref < 0
        errors.append(abs(bs.signed_distance(0, 1) - ref))
    assert 100 < n_pen < 1400          # both regimes are exercised
    assert max(errors) < 1e-9


@pytest.mark.parametrize("gap", [1e-3, 1e-6, 1e-9, 0.0, -1e-6, -1e-4, -2e-3])
def test_face_to_face(gap):
    """Stacked panels offset in-plane: signed distance is the z gap."""
    I = np.eye(3)
    cb = np.array([0.03, -0.02, 0.005 + gap])
    bs = boxes(UNIT, UNIT, I, np.zeros(3), I, cb)
    g = bs.pair_geometry(0, 1)
    assert g.distance == pytest.approx(gap, abs=1e-12)
    if gap != 0.0:
        assert abs(g.normal @ [0, 0, 1]) == pytest.approx(1.0, abs=1e-9)


@pytest.mark.parametrize("gap", [2e-3, 1e-7, 0.0, -3e-4])
def test_edge_to_face(gap):
    """A panel tilted 30 deg about x resting its lower long edge on a flat panel."""
    R = Rotation.from_euler("x", 30, degrees=True).as_matrix()
    hb = np.array(UNIT) / 2
    lowest = np.min(((SIGNS * hb) @ R.T)[:, 2])
    cb = np.array([0.0, 0.0, 0.0025 - lowest + gap])
    bs = boxes(UNIT, UNIT, np.eye(3), np.zeros(3), R, cb)
    ref = reference_signed_distance(np.array(UNIT) / 2, np.eye(3), np.zeros(3), hb, R, cb)
    assert ref == pytest.approx(gap, abs=1e-12)
    assert bs.signed_distance(0, 1) == pytest.approx(gap, abs=1e-9)


def test_side_by_side_touching_is_zero():
    """Two panels of a flat row sharing a slit: touching along the side faces."""
    I = np.eye(3)
    bs = boxes(UNIT, UNIT, I, np.zeros(3), I, np.array([0.1, 0.0, 0.0]))
    assert abs(bs.signed_distance(0, 1)) < 1e-12


def test_lower_bounds_never_exceed_distance():
    rng = np.random.default_rng(2)
    for _ in range(300):
        Ra, Rb = Rotation.random(2, random_state=rng).as_matrix()
        cb = rng.normal(size=3) * 0.2
        bs = boxes(UNIT, LARGE, Ra, np.zeros(3), Rb, cb)
        lb = bs.lower_bounds(np.array([[0, 1]]))[0]
        assert lb <= max(bs.signed_distance(0, 1), 0.0) + 1e-15


def numpy_box_distance(ha, Ra, ca, hb, Rb, cb):
    """The vectorised numpy enumeration that box_distance compiles: vertex/box
    clamps, then all 144 edge pairs by Ericson 5.1.9; first minimum wins."""
    va, vb = ca + (SIGNS * ha) @ Ra.T, cb + (SIGNS * hb) @ Rb.T
    near_b = cb + np.clip((va - cb) @ Rb, -hb, hb) @ Rb.T
    near_a = ca + np.clip((vb - ca) @ Ra, -ha, ha) @ Ra.T
    edges = np.array([(i, j) for i in range(8) for j in range(i + 1, 8)
                      if np.count_nonzero(SIGNS[i] != SIGNS[j]) == 1])
    p1, d1 = va[edges[:, 0], None], (va[edges[:, 1]] - va[edges[:, 0]])[:, None]
    p2, d2 = vb[edges[None, :, 0]], vb[edges[None, :, 1]] - vb[edges[None, :, 0]]
    p1, d1, p2, d2 = np.broadcast_arrays(p1, d1, p2, d2)
    dot = lambda x, y: np.einsum("...i,...i", x, y)  # noqa: E731
    a, e, b, c, f = dot(d1, d1), dot(d2, d2), dot(d1, d2), dot(d1, p1 - p2), dot(d2, p1 - p2)
    denom = a * e - b * b
    parallel = denom <= 1e-12 * a * e
    s = np.where(parallel, 0.0, np.clip((b * f - c * e) / np.where(parallel, 1.0, denom), 0.0, 1.0))
    t = (b * s + f) / e
    s = np.where(t < 0.0, np.clip(-c / a, 0.0, 1.0), np.where(t > 1.0, np.clip((b - c) / a, 0.0, 1.0), s))
    t = np.clip(t, 0.0, 1.0)
    pa = np.concatenate([va, near_a, (p1 + s[..., None] * d1).reshape(-1, 3)])
    pb = np.concatenate([near_b, vb, (p2 + t[..., None] * d2).reshape(-1, 3)])
    k = np.argmin(np.linalg.norm(pb - pa, axis=1))
    return np.linalg.norm(pb[k] - pa[k]), pa[k], pb[k]


def separated_pairs(rng):
    """Apart box pairs (ha, Ra, ca, hb, Rb, cb), m: random poses, parallel faces
    stacked with in-plane offsets, and edges crossing or parallel at a gap."""
    ha, hb = np.array(UNIT) / 2, np.array(LARGE) / 2
    out = []
    while len(out) < 200:
        Ra, Rb = Rotation.random(2, random_state=rng).as_matrix()
        cb = rng.normal(size=3) * 0.1
        if reference_signed_distance(ha, Ra, np.zeros(3), hb, Rb, cb) > 1e-9:
            out.append((ha, Ra, np.zeros(3), hb, Rb, cb))
    for k in range(100):
        # face to face: same orientation, z gap, overlapping (k = 0: aligned) in plane
        Q = Rotation.random(random_state=rng).as_matrix()
        offset = rng.uniform(-0.14, 0.14) * (k > 0), rng.uniform(-0.09, 0.09) * (k > 0)
        local = np.r_[offset, ha[2] + hb[2] + 10.0 ** rng.uniform(-9, -2)]
        c = rng.normal(size=3) * 0.1
        out.append((ha, Q, c, hb, Q, c + Q @ local))
    y, n = np.array([0.0, 1.0, 0.0]), np.array([1.0, 0.0, 1.0]) / np.sqrt(2)
    for k in range(100):
        # a's edge along y at (ha_x, ., ha_z), outward normal n inside its cone;
        # b's edge (local x, at local y = -hb_y, z = -hb_z) along u normal to n,
        # crossing it at a gap g along n, with -n strictly inside b's edge cone
        # (no face of b faces a). Every other one parallel: u = y.
        phi = np.pi / 2 if k % 2 else rng.uniform(-1.4, 1.4)
        u = np.cos(phi) * np.array([1.0, 0.0, -1.0]) / np.sqrt(2) + np.sin(phi) * y
        w, alpha = np.cross(n, u), rng.uniform(0.3, 1.2)
        Rb = np.column_stack([u, np.cos(alpha) * n + np.sin(alpha) * w,
                              np.sin(alpha) * n - np.cos(alpha) * w])
        crossing = np.array([ha[0], rng.uniform(-ha[1], ha[1]), ha[2]]) + 10.0 ** rng.uniform(-9, -2) * n
        cb = crossing - Rb @ [rng.uniform(-hb[0], hb[0]), -hb[1], -hb[2]]
        Q, c = Rotation.random(random_state=rng).as_matrix(), rng.normal(size=3) * 0.1
        out.append((ha, Q, c, hb, Q @ Rb, c + Q @ cb))
    return out


def test_compiled_box_distance_matches_numpy_enumeration():
    """Same distance as the numpy formulation and the lsq reference. Where
    faces or edges are parallel the nearest points are not unique and rounding
    decides which tie wins, so there the points are only checked to lie on
    their boxes with the same p_b - p_a (unique for convex sets); the random
    pairs and crossing edges have unique points."""
    for k, (ha, Ra, ca, hb, Rb, cb) in enumerate(separated_pairs(np.random.default_rng(3))):
        d, pa, pb = box_distance(Ra, ca, ha, Rb, cb, hb)
        d0, pa0, pb0 = numpy_box_distance(ha, Ra, ca, hb, Rb, cb)
        assert abs(d - d0) < 1e-12
        assert abs(reference_signed_distance(ha, Ra, ca, hb, Rb, cb) - d) < 1e-12
        assert np.abs((pb - pa) - (pb0 - pa0)).max() < 1e-12
        assert np.all(np.abs((pa - ca) @ Ra) <= ha + 1e-12)
        assert np.all(np.abs((pb - cb) @ Rb) <= hb + 1e-12)
        if k < 200 or (k >= 300 and k % 2 == 0):
            assert np.abs(pa - pa0).max() < 1e-12 and np.abs(pb - pb0).max() < 1e-12


def test_pair_bounds_give_the_depth_and_bracket_the_distance():
    # Batched: the separating-axis overlap of every pair (the depth of an
    # interfering one) and, for an apart one, -overlap <= distance <= upper.
    rng = np.random.default_rng(4)
    ha, hb = np.array(UNIT) / 2, np.array(LARGE) / 2
    n = 400
    R = Rotation.random(2 * n, random_state=rng).as_matrix()
    c = np.zeros((2 * n, 3))
    c[1::2] = rng.normal(size=(n, 3)) * 0.06
    h = np.tile(np.array([ha, hb]), (n, 1))
    a, b = np.arange(0, 2 * n, 2), np.arange(1, 2 * n, 2)
    overlap, upper = pair_bounds(R, c, h, a, b)
    apart = 0
    for k in range(n):
        i, j = a[k], b[k]
        assert overlap[k] == least_overlap(R[i], c[i], h[i], R[j], c[j], h[j])[0]
        ref = reference_signed_distance(h[i], R[i], c[i], h[j], R[j], c[j])
        if overlap[k] > 0:
            assert overlap[k] == pytest.approx(-ref, abs=1e-12)
        else:
            apart += 1
            assert -overlap[k] <= ref + 1e-12 and ref <= upper[k] + 1e-12
    assert 50 < apart < n


def test_a_separating_axis_exists_exactly_when_the_boxes_are_apart():
    # Whatever axis is tried first, separating_axis finds one exactly when
    # least_overlap says the boxes do not interfere (overlap <= 0) and the
    # independent reference says they are apart, and the axis it returns
    # does separate them; the contact model relies on this to skip a pair.
    rng = np.random.default_rng(5)
    ha, hb = np.array(UNIT) / 2, np.array(LARGE) / 2
    apart = 0
    for k in range(300):
        Ra, Rb = Rotation.random(2, random_state=rng).as_matrix()
        ca, cb = np.zeros(3), rng.normal(size=3) * 0.06
        overlap = least_overlap(Ra, ca, ha, Rb, cb, hb)[0]
        ref = reference_signed_distance(ha, Ra, ca, hb, Rb, cb)
        for first in (0, 5, 14, int(rng.integers(15))):
            axis, overlap_axis, least_axis, least_along = separating_axis(Ra, ca, ha, Rb, cb, hb, first)
            assert (axis >= 0) == (overlap <= 0.0) == (ref > 0.0), (k, first, overlap, ref)
            if axis >= 0:
                # the returned axis alone separates: the projections on it do not overlap
                i, j = (axis - 6) // 3, (axis - 6) % 3
                u = Ra[:, axis] if axis < 3 else Rb[:, axis - 3] if axis < 6 else np.cross(Ra[:, i], Rb[:, j])
                u = u / np.linalg.norm(u)
                ra, rb = np.abs(Ra.T @ u) @ ha, np.abs(Rb.T @ u) @ hb
                assert abs((cb - ca) @ u) >= ra + rb - 1e-15, (k, first, axis)
                assert overlap_axis == pytest.approx(ra + rb - abs((cb - ca) @ u), abs=1e-15)
            else:  # least_overlap's answer (to rounding: compiled apart), whatever axis went first
                least = least_overlap(Ra, ca, ha, Rb, cb, hb)
                assert overlap_axis == pytest.approx(least[0], rel=1e-12)
                np.testing.assert_allclose(least_axis, least[1], rtol=0, atol=1e-12)
                assert least_along == pytest.approx(least[2], rel=1e-12, abs=1e-15)
        apart += overlap <= 0.0
    assert 50 < apart < 300
