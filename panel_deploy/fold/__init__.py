"""Fold design: Hamiltonian circuits, two-stack packing, merging and mobility.

The pipeline for an R x C array of identical panels (paper, section 2):

1. choose a Hamiltonian circuit of the grid graph (:mod:`.circuits`); hinges go
   on the edges it crosses, every other shared edge is a slit;
2. decide whether it folds into two equal stacks without voids, and how
   (:mod:`.packing`);
3. merge cells that stay side by side with the same stowed motion into rigid
   bodies (:mod:`.merge`) and count the mobility (:mod:`.kutzbach`), and find
   it from the rank of the loop-closure Jacobian (:mod:`.mobility`).

:func:`design` does all three for one circuit, :func:`designs` for every
circuit of an array.
"""

from __future__ import annotations

import numbers
from collections.abc import Iterator

from ..errors import DesignError, shown
from .circuits import (
    canonical_form,
    circuit_by_index,
    circuit_edges,
    circuit_index,
    circuits,
    circuits_up_to_symmetry,
    count_circuits,
    count_circuits_up_to_symmetry,
    validate_circuit,
)
from .design import Cell, CellPlacement, FoldDesign, HingeState, Merge, StowedState
from .grid import check_cell, check_size, grid_graph, shared_edges
from .kutzbach import assembly_dof, kutzbach_dof
from .merge import merge_cells
from .mobility import jacobian_mobility, loop_mobility
from .packing import find_stowed_state, stowed_states

__all__ = [
    "Cell",
    "CellPlacement",
    "FoldDesign",
    "HingeState",
    "Merge",
    "StowedState",
    "assembly_dof",
    "canonical_form",
    "circuit_by_index",
    "circuit_edges",
    "circuit_index",
    "circuits",
    "circuits_up_to_symmetry",
    "count_circuits",
    "count_circuits_up_to_symmetry",
    "design",
    "designs",
    "find_stowed_state",
    "grid_graph",
    "jacobian_mobility",
    "kutzbach_dof",
    "loop_mobility",
    "merge_cells",
    "shared_edges",
    "stowed_states",
    "validate_circuit",
]


def _design_of(rows, cols, circ, ground, merge) -> FoldDesign:
    ground = circ[0] if ground is None else check_cell(ground, rows, cols)
    hinges = circuit_edges(circ)
    hinge_set = set(hinges)
    slits = tuple(e for e in shared_edges(rows, cols) if e not in hinge_set)
    stowed, reason = find_stowed_state(rows, cols, circ, ground)
    bodies, merges, refused = merge_cells(rows, cols, hinges, stowed, merge)
    cells = [(r, c) for r in range(1, rows + 1) for c in range(1, cols + 1)]
    return FoldDesign(
        rows=rows,
        cols=cols,
        circuit=circ,
        hinges=hinges,
        slits=slits,
        stowed=stowed,
        reason=reason,
        bodies=bodies,
        merges=merges,
        dof_cells=assembly_dof([(c,) for c in cells], hinges),
        dof_bodies=assembly_dof(bodies, hinges),
        ground=ground,
        refused=refused,
    )


def design(rows: int, cols: int, circuit=0, ground=None, merge="auto") -> FoldDesign:
    """Design the folding of an R x C array along one Hamiltonian circuit.

    Parameters
    ----------
    rows, cols : int
        Size of the array.
    circuit : int or sequence of (row, col), optional
        A circuit index (position in :func:`circuits` order, see
        :mod:`panel_deploy.fold.circuits`) or the cells of a circuit in visiting
        order. Default 0.
    ground : (row, col), optional
        The ground panel, held at the identity in the stowed state. Default:
        the circuit's first cell ((1, 1) for an index). It changes the stowed
        placements, never the verdict.
    merge : "auto", "none" or sequence of cell pairs, optional
        Which adjacent cells to merge into rigid bodies (see :mod:`.merge`).

    Returns
    -------
    FoldDesign
        With the stowed package (or the reason none exists), bodies, merges
        and Kutzbach mobility before and after merging. A design that does not
        pack is returned too (``stowed is None``), with one body per cell.

    Raises
    ------
    DesignError
        For an invalid size, circuit index out of range, a cell list that is
        not a Hamiltonian circuit of the array, a ground outside the array, or
        an invalid `merge`.

    Examples
    --------
    >>> d = design(4, 4, [(1, 2), (1, 1), (2, 1), (3, 1), (4, 1), (4, 2), (3, 2), (2, 2),
    ...                   (2, 3), (3, 3), (4, 3), (4, 4), (3, 4), (2, 4), (1, 4), (1, 3)])
    >>> len(d.bodies), d.dof_cells, d.dof_bodies
    (12, 10, 6)
    """
    rows, cols = check_size(rows, cols)
    if isinstance(circuit, numbers.Integral) and not isinstance(circuit, bool):
        circ = circuit_by_index(rows, cols, int(circuit))
    elif isinstance(circuit, (str, bytes)) or circuit is None or isinstance(circuit, bool):
        raise DesignError(f"circuit: expected an index or a list of cells, got {shown(circuit)}")
    else:
        circ = validate_circuit(rows, cols, circuit)
    return _design_of(rows, cols, circ, ground, merge)


def designs(rows: int, cols: int, merge="auto") -> Iterator[tuple[int, FoldDesign]]:
    """Yield ``(index, design)`` for every circuit of the array, lazily, in index order.

    Each design uses the circuit's canonical sequence with ground (1, 1).

    Raises
    ------
    DesignError
        If the size or `merge` is invalid.
    """
    rows, cols = check_size(rows, cols)
    for i, circ in enumerate(circuits(rows, cols)):
        yield i, _design_of(rows, cols, circ, None, merge)
