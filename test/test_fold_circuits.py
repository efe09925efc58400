"""Circuits of the grid graph: enumeration, DP count, symmetry, validation."""

import itertools

import networkx as nx
import pytest

from panel_deploy.errors import DesignError
from panel_deploy.fold import (
    canonical_form,
    circuit_by_index,
    circuit_edges,
    circuit_index,
    circuits,
    circuits_up_to_symmetry,
    count_circuits,
    count_circuits_up_to_symmetry,
    grid_graph,
    validate_circuit,
)
from panel_deploy.fold.circuits import symmetries

PAPER = [(1, 2), (1, 1), (2, 1), (3, 1), (4, 1), (4, 2), (3, 2), (2, 2),
         (2, 3), (3, 3), (4, 3), (4, 4), (3, 4), (2, 4), (1, 4), (1, 3)]


def test_grid_graph():
    g = grid_graph(3, 4)
    assert g.number_of_nodes() == 12
    assert g.number_of_edges() == 3 * 3 + 4 * 2
    assert set(g[(2, 2)]) == {(1, 2), (3, 2), (2, 1), (2, 3)}


@pytest.mark.parametrize("rows,cols,expected", [
    (2, 2, 1), (2, 3, 1), (2, 7, 1), (3, 4, 2), (4, 4, 6), (4, 5, 14), (4, 6, 37),
    (5, 6, 154), (6, 6, 1072), (3, 3, 0), (5, 5, 0), (1, 4, 0),
])
def test_enumeration_counts(rows, cols, expected):
    assert sum(1 for _ in circuits(rows, cols)) == expected


def test_dp_agrees_with_enumeration_up_to_6x6():
    for rows, cols in itertools.product(range(1, 7), repeat=2):
        assert count_circuits(rows, cols) == sum(1 for _ in circuits(rows, cols)), (rows, cols)


def test_dp_8x8():
    assert count_circuits(8, 8) == 4638576


def test_circuits_are_valid_distinct_and_ordered():
    seqs = list(circuits(4, 6))
    assert seqs == sorted(seqs)
    edge_sets = {circuit_edges(s) for s in seqs}
    assert len(edge_sets) == len(seqs)
    g = grid_graph(4, 6)
    for s in seqs:
        assert s[0] == (1, 1) and s[1] == (1, 2) and s[-1] == (2, 1)
        assert validate_circuit(4, 6, s) == s
        h = nx.Graph(circuit_edges(s))
        assert all(g.has_edge(u, v) for u, v in h.edges)
        assert all(d == 2 for _, d in h.degree) and nx.is_connected(h)


def test_every_cell_has_two_hinges():
    for s in circuits(6, 6):
        deg = {}
        for u, v in circuit_edges(s):
            deg[u] = deg.get(u, 0) + 1
            deg[v] = deg.get(v, 0) + 1
        assert len(deg) == 36 and set(deg.values()) == {2}


def test_index_round_trip():
    paper_index = circuit_index(4, 4, PAPER)
    assert paper_index == 2
    assert circuit_edges(circuit_by_index(4, 4, paper_index)) == circuit_edges(PAPER)
    with pytest.raises(DesignError, match="out of range"):
        circuit_by_index(4, 4, 6)


@pytest.mark.parametrize("rows,cols", [(4, 4), (4, 6), (5, 6), (6, 6)])
def test_orbits_burnside(rows, cols):
    seqs = list(circuits(rows, cols))
    group = symmetries(rows, cols)
    fixed = 0
    for g in group:
        for s in seqs:
            e = set(circuit_edges(s))
            if {tuple(sorted((g(u), g(v)))) for u, v in e} == e:
                fixed += 1
    orbits = count_circuits_up_to_symmetry(rows, cols)
    assert fixed % len(group) == 0
    assert orbits == fixed // len(group)
    reps = list(circuits_up_to_symmetry(rows, cols))
    assert len({canonical_form(rows, cols, s) for _, s in reps}) == orbits


def test_orbit_counts():
    assert count_circuits_up_to_symmetry(4, 4) == 2
    assert count_circuits_up_to_symmetry(2, 5) == 1
    assert count_circuits_up_to_symmetry(6, 6) == 149


@pytest.mark.parametrize("cells,match", [
    (PAPER[:-1], "missing"),
    (PAPER[:-1] + [(2, 2)], "more than once"),
    (PAPER[:1] + PAPER[2:] + PAPER[1:2], "do not share an edge"),
    (PAPER[:-1] + [(5, 1)], "outside"),
    ([(1, 1), "ab"], "row"),
    (42, "sequence"),
])
def test_validation_errors(cells, match):
    with pytest.raises(DesignError, match=match):
        validate_circuit(4, 4, cells)


def test_bad_sizes():
    for rows, cols in [(0, 4), (4, -1), (2.5, 2), (True, 3)]:
        with pytest.raises(DesignError):
            count_circuits(rows, cols)
    assert validate_circuit(4, 4, PAPER + [PAPER[0]]) == tuple(PAPER)
