"""Box-box signed distances against independent exact references.

References (test-only): separated boxes by bounded least squares over the two
boxes' local coordinates (scipy ``lsq_linear``, BVLS: min |c_a + R_a u - c_b -
R_b w| with |u| <= h_a, |w| <= h_b); interfering boxes by the distance from
the origin to the boundary of the Minkowski difference (scipy ConvexHull of
the 64 vertex differences), which is the penetration depth.
"""

import numpy as np
import pytest
from scipy.optimize import lsq_linear
from scipy.spatial import ConvexHull
from scipy.spatial.transform import Rotation

from panel_deploy.collision.geometry import BoxSet
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
