"""Two-stack packing: verdicts, the paper's package, an independent verifier."""

import math

import numpy as np
import pytest

from panel_deploy.errors import DesignError
from panel_deploy.fold import circuits, design, find_stowed_state, stowed_states

PAPER = [(1, 2), (1, 1), (2, 1), (3, 1), (4, 1), (4, 2), (3, 2), (2, 2),
         (2, 3), (3, 3), (4, 3), (4, 4), (3, 4), (2, 4), (1, 4), (1, 3)]
A, B, T = 1.0, 0.7, 0.1  # deliberately non-square panel, thin


def centroid(cell, rows, cols):
    r, c = cell
    return np.array([(c - (cols + 1) / 2) * A, ((rows + 1) / 2 - r) * B, 0.0])


def hinge_motion(u, v, facet, angle, rows, cols):
    """Homogeneous 4x4 rotation by `angle` about the hinge line (Rodrigues)."""
    p = (centroid(u, rows, cols) + centroid(v, rows, cols)) / 2
    p[2] = T / 2 if facet == "top" else -T / 2
    axis = np.array([0.0, 1.0, 0.0]) if u[0] == v[0] else np.array([1.0, 0.0, 0.0])
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    rot = np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * k @ k
    m = np.eye(4)
    m[:3, :3] = rot
    m[:3, 3] = p - rot @ p
    return m


def verify(rows, cols, circuit, ground, st):
    """Recompute every placement from the hinge states and check all the rules."""
    n = len(circuit)
    assert st.layers == n // 2
    k0 = circuit.index(ground)
    walk = list(circuit[k0:]) + list(circuit[:k0])
    key = lambda u, v: (min(u, v), max(u, v))
    g = {walk[0]: np.eye(4)}
    for a, b in zip(walk, walk[1:]):
        h = st.hinges[key(a, b)]
        g[b] = g[a] @ hinge_motion(a, b, h.facet, h.angle, rows, cols)
    h = st.hinges[key(walk[-1], walk[0])]
    closing = g[walk[-1]] @ hinge_motion(walk[-1], walk[0], h.facet, h.angle, rows, cols)
    assert np.allclose(closing, np.eye(4)), "loop does not close"
    foot = [centroid(f, rows, cols)[:2] for f in st.footprint]
    assert abs(foot[0] - foot[1]).sum() in (pytest.approx(A), pytest.approx(B))
    z_top = max((g[c] @ np.append(centroid(c, rows, cols), 1))[2] for c in walk)
    slots = set()
    for c in walk:
        p = st.placements[c]
        m = g[c]
        assert np.allclose(m[:3, :3], np.diag(p.rotation))
        assert np.allclose(m[:3, 3], np.array(p.offset) * [A, B, T])
        assert p.face_up == (m[2, 2] > 0)
        x = (m @ np.append(centroid(c, rows, cols), 1))[:3]
        assert np.allclose(x[:2], foot[p.stack]), f"{c} off its stack"
        assert x[2] == pytest.approx(z_top - p.layer * T)
        slots.add((p.stack, p.layer))
    assert slots == {(s, l) for s in (0, 1) for l in range(n // 2)}, "voids or overlaps"
    segments = []
    for (u, v), h in st.hinges.items():
        pu, pv = st.placements[u], st.placements[v]
        if h.angle == 0:
            assert pu.layer == pv.layer and pu.stack != pv.stack
        else:
            assert h.angle == pytest.approx(math.pi)
            assert pu.stack == pv.stack and abs(pu.layer - pv.layer) == 1
        mid = (centroid(u, rows, cols) + centroid(v, rows, cols)) / 2
        mid[2] = T / 2 if h.facet == "top" else -T / 2
        seg = (g[u] @ np.append(mid, 1))[:3]
        if h.angle:
            # A folded hinge sits on the interface between its two layers.
            assert seg[2] == pytest.approx(z_top - (max(pu.layer, pv.layer) - 0.5) * T)
        segments.append(tuple(np.round(seg, 9)) + (u[0] == v[0],))
    assert len(set(segments)) == len(segments), "two hinges share a stack edge"
    assert len(st.hinges) == n


def test_paper_design_stowed_state():
    st, reason = find_stowed_state(4, 4, PAPER, (1, 2))
    assert reason == ""
    verify(4, 4, PAPER, (1, 2), st)
    assert st.footprint == ((1, 2), (1, 3))
    assert st.stack_order(0) == [(1, 2), (1, 1), (2, 1), (3, 1), (4, 1), (4, 2), (3, 2), (2, 2)]
    assert st.stack_order(1) == [(1, 3), (1, 4), (2, 4), (3, 4), (4, 4), (4, 3), (3, 3), (2, 3)]
    flat = {k for k, h in st.hinges.items() if h.angle == 0}
    assert flat == {((1, 2), (1, 3)), ((2, 2), (2, 3))}
    # Zig-zag: consecutive hinges down a column alternate facets.
    for col in (1, 4):
        facets = [st.hinges[((r, col), (r + 1, col))].facet for r in (1, 2, 3)]
        assert facets[0] != facets[1] != facets[2]
    # Mirror symmetry of the two stacks.
    for (r, c), p in st.placements.items():
        q = st.placements[(r, 5 - c)]
        assert (q.layer, q.stack) == (p.layer, 1 - p.stack)


def test_all_paper_packages_share_the_stacks():
    found = list(stowed_states(4, 4, PAPER, (1, 2)))
    assert found
    for st in found:
        verify(4, 4, PAPER, (1, 2), st)
        assert {tuple(st.stack_order(s)) for s in (0, 1)} <= {
            tuple(x) for x in (
                [(1, 2), (1, 1), (2, 1), (3, 1), (4, 1), (4, 2), (3, 2), (2, 2)],
                [(1, 3), (1, 4), (2, 4), (3, 4), (4, 4), (4, 3), (3, 3), (2, 3)],
            )
        } | {tuple(reversed(x)) for x in (
            [(1, 2), (1, 1), (2, 1), (3, 1), (4, 1), (4, 2), (3, 2), (2, 2)],
            [(1, 3), (1, 4), (2, 4), (3, 4), (4, 4), (4, 3), (3, 3), (2, 3)],
        )}


@pytest.mark.parametrize("rows,cols", [(2, 2), (2, 5), (3, 4), (4, 4), (4, 6)])
def test_verdict_independent_of_ground(rows, cols):
    for circ in circuits(rows, cols):
        verdicts = set()
        for ground in circ[:: 1 if rows * cols <= 16 else 5]:
            st, reason = find_stowed_state(rows, cols, circ, ground)
            verdicts.add(st is not None)
            if st is not None:
                verify(rows, cols, circ, ground, st)
            else:
                assert reason.startswith("no two-stack package")
        assert len(verdicts) == 1


def test_ground_on_top_preferred():
    for ground in PAPER:
        st, _ = find_stowed_state(4, 4, PAPER, ground)
        tops = [x.placements[ground].layer == 0 for x in stowed_states(4, 4, PAPER, ground)]
        assert (st.placements[ground].layer == 0) == any(tops)


def test_4x6_verdicts_and_reasons():
    results = [find_stowed_state(4, 6, c) for c in circuits(4, 6)]
    bad = [r for st, r in results if st is None]
    assert len(results) == 37 and len(bad) == 8
    for r in bad:
        assert r.startswith("no two-stack package: ") and "x)" in r
    # 2 x C: a single strip folds as a zig-zag.
    st, r = find_stowed_state(2, 6, next(circuits(2, 6)))
    assert r == ""


def test_30_panels_pack_into_two_stacks_of_15():
    for rows, cols in ((5, 6), (6, 5)):
        packed = 0
        for circ in circuits(rows, cols):
            st, _ = find_stowed_state(rows, cols, circ)
            if st is not None:
                packed += 1
                if packed == 1:
                    verify(rows, cols, circ, circ[0], st)
                    assert st.layers == 15
        assert packed == 90


def test_6x6_packable_count():
    # The first package in search order decides the verdict (one search pass).
    count = 0
    for i, circ in enumerate(circuits(6, 6)):
        st = next(stowed_states(6, 6, circ), None)
        if st is not None:
            count += 1
            if i % 97 == 0:
                verify(6, 6, circ, circ[0], st)
    assert count == 832


def test_odd_and_errors():
    with pytest.raises(DesignError):
        find_stowed_state(4, 4, PAPER[:-1])
    with pytest.raises(DesignError, match="outside"):
        find_stowed_state(4, 4, PAPER, (0, 1))
    d = design(4, 4, PAPER)
    assert d.stowed is not None and d.reason == ""


def test_budget_makes_search_undecided():
    st, reason = find_stowed_state(6, 6, next(circuits(6, 6)), max_nodes=5)
    assert st is None and reason.startswith("undecided")
