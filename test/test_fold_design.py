"""Merging, Kutzbach DoF, design(), reports, CLI command and plot."""

import json

import pytest

from panel_deploy.cli import main
from panel_deploy.errors import DesignError
import numpy as np

from panel_deploy.fold import (assembly_dof, design, designs, jacobian_mobility,
                              kutzbach_dof, loop_mobility)
from panel_deploy.fold.report import design_dict, design_text

PAPER = [(1, 2), (1, 1), (2, 1), (3, 1), (4, 1), (4, 2), (3, 2), (2, 2),
         (2, 3), (3, 3), (4, 3), (4, 4), (3, 4), (2, 4), (1, 4), (1, 3)]


def test_kutzbach():
    assert kutzbach_dof(16, 16) == 10
    assert kutzbach_dof(12, 12) == 6
    with pytest.raises(DesignError):
        kutzbach_dof(0, 1)


def test_paper_merges_and_dof():
    d = design(4, 4, PAPER)
    assert d.ground == (1, 2)
    assert (d.dof_cells, d.dof_bodies, len(d.bodies)) == (10, 6, 12)
    assert {m.cells for m in d.merges} == {((r, 2), (r, 3)) for r in range(1, 5)}
    kinds = {m.cells: m.reason for m in d.merges}
    assert "flat hinge" in kinds[((1, 2), (1, 3))] and "layer 0" in kinds[((1, 2), (1, 3))]
    assert "slit" in kinds[((3, 2), (3, 3))]
    assert d.refused == ()
    # L4-L3 and L3-L2 are two collinear segments each, counted once.
    assert assembly_dof(d.bodies, d.hinges) == 6


def _twist(axis, point):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    return np.concatenate([-np.cross(axis, point), axis])


def test_loop_mobility_of_linkages_of_known_mobility():
    rng = np.random.default_rng(3)
    ring = [(0, 1), (1, 2), (2, 3), (3, 0)]
    # planar four-bar (parallel axes): 1, where Kutzbach counts -2
    planar = [_twist([0, 0, 1], [*rng.normal(size=2), 0.0]) for _ in range(4)]
    assert loop_mobility(4, ring, planar) == 1 and kutzbach_dof(4, 4) == -2
    # spherical four-bar (axes through one point): 1
    assert loop_mobility(4, ring, [_twist(rng.normal(size=3), [0, 0, 0]) for _ in range(4)]) == 1
    # generic spatial loops: rigid up to 6 hinges, then n - 6, as Kutzbach says
    for n in (4, 6, 7, 8):
        loop = [(i, (i + 1) % n) for i in range(n)]
        twists = [_twist(rng.normal(size=3), rng.normal(size=3)) for _ in range(n)]
        assert loop_mobility(n, loop, twists) == max(0, kutzbach_dof(n, n))
    # an open chain: every hinge free
    assert loop_mobility(3, [(0, 1), (1, 2)], planar[:2]) == 2


def test_jacobian_mobility_beside_kutzbach():
    # 2 x 2 cells: one loop of four hinges on two lines; Kutzbach counts -2, yet the
    # array folds about either line, one at a time: mobility 1
    d = design(2, 2, 0)
    assert (d.dof_cells, d.dof_bodies) == (-2, 1)
    assert jacobian_mobility(d) == (1, 1)
    text = design_text(d)
    assert "Kutzbach DoF -2 (cells) -> 1 (bodies)" in text
    assert "mobility from the loop-closure Jacobian's rank: 1 (cells) -> 1 (bodies)" in text
    js = design_dict(d)
    assert (js["mobility_cells"], js["mobility_bodies"]) == (1, 1)
    # the paper's design: a generic loop of 10 bodies and a chain of 2, as Kutzbach says
    assert jacobian_mobility(design(4, 4, PAPER)) == (10, 6)
    # a design that does not pack has no hinge facets: no rank
    unpacked = next(x for _, x in designs(4, 6) if x.stowed is None)
    assert jacobian_mobility(unpacked) is None and design_dict(unpacked)["mobility_cells"] is None


def test_merge_none_and_explicit():
    d = design(4, 4, PAPER, merge="none")
    assert len(d.bodies) == 16 and d.dof_bodies == 10 and d.merges == ()
    d = design(4, 4, PAPER, merge=[((3, 3), (3, 2)), ((1, 1), (1, 2))])
    assert [m.cells for m in d.merges] == [((3, 2), (3, 3))]
    assert len(d.refused) == 1 and "layers 1 and 0" in d.refused[0].reason
    assert len(d.bodies) == 15
    with pytest.raises(DesignError, match="share an edge"):
        design(4, 4, PAPER, merge=[((1, 1), (2, 2))])
    with pytest.raises(DesignError):
        design(4, 4, PAPER, merge="all")


def test_merged_hinges_are_single_lines():
    for _, d in designs(4, 6):
        if d.stowed is None:
            assert len(d.bodies) == 24 and d.reason
            continue
        owner = {c: i for i, b in enumerate(d.bodies) for c in b}
        lines = {}
        for u, v in d.hinges:
            i, j = owner[u], owner[v]
            if i == j:
                assert d.stowed.hinges[(u, v)].angle == 0
                continue
            h = d.stowed.hinges[(u, v)]
            line = ("v", min(u[1], v[1])) if u[0] == v[0] else ("h", min(u[0], v[0]))
            lines.setdefault((min(i, j), max(i, j)), set()).add((line, h.facet, h.angle))
        assert all(len(s) == 1 for s in lines.values())
        assert d.dof_bodies == kutzbach_dof(len(d.bodies), len(lines))
        for b in d.bodies:
            motions = {(d.stowed.placements[c].rotation, d.stowed.placements[c].offset) for c in b}
            assert len(motions) == 1


def test_design_errors():
    with pytest.raises(DesignError, match="out of range"):
        design(4, 4, 6)
    with pytest.raises(DesignError, match="odd"):
        design(3, 3, 0)
    with pytest.raises(DesignError, match="do not share an edge"):
        design(4, 4, PAPER[::2] + PAPER[1::2])
    with pytest.raises(DesignError):
        design(4, 4, "abc")


def test_reports():
    d = design(4, 4, PAPER)
    js = design_dict(d, 2)
    assert json.loads(json.dumps(js)) == js  # plain JSON types only
    assert js["stacks"][0][0] == [1, 2] and js["stacks"][0][-1] == [2, 2]
    assert js["dof_cells"] == 10 and js["dof_bodies"] == 6 and js["packs"]
    folded = [h for h in js["hinges"] if h["folded"]]
    assert len(folded) == 14 and {h["facet"] for h in folded} == {"top", "bottom"}
    text = design_text(d, 2)
    assert "stack 0: (1,2) (1,1)" in text and "DoF 10 (cells) -> 6 (bodies)" in text


def test_fold_command(capsys, tmp_path):
    assert main(["fold", "--rows", "4", "--cols", "4"]) == 0
    out = capsys.readouterr().out
    assert "6 Hamiltonian circuits" in out and "6 pack" in out
    assert main(["fold", "--rows", "4", "--cols", "6", "--json", "--limit", "3"]) == 0
    js = json.loads(capsys.readouterr().out)
    assert js["circuits"] == 37 and js["packable"] == 29 and len(js["listed"]) == 3
    png = tmp_path / "d.png"
    assert main(["fold", "--rows", "4", "--cols", "4", "--circuit", "2", "--plot", str(png)]) == 0
    assert png.stat().st_size > 10000
    assert "verdict: packs into two stacks" in capsys.readouterr().out
    assert main(["fold", "--rows", "4", "--cols", "4", "--circuit", "99"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("panel-deploy: error: --circuit: ") and "out of range" in err
    assert main(["fold", "--rows", "4", "--cols", "6", "--circuit", "5"]) == 1
    capsys.readouterr()
    assert main(["fold", "--rows", "8", "--cols", "8", "--limit", "2", "--json"]) == 0
    js = json.loads(capsys.readouterr().out)
    assert js["circuits"] == 4638576 and js["packable"] is None and len(js["listed"]) == 2
