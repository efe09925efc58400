"""The grid graph of an R x C panel array.

Cells are ``(row, col)`` tuples, 1-based (see :mod:`panel_deploy.fold.design`);
two cells are adjacent when they share an edge of the flat array.
"""

from __future__ import annotations

import numbers

import networkx as nx

from ..errors import DesignError, shown
from .design import Cell


def check_size(rows, cols) -> tuple[int, int]:
    """Validate an array size.

    Parameters
    ----------
    rows, cols : int
        Number of rows and columns of the array.

    Returns
    -------
    (int, int)
        The size as plain ints.

    Raises
    ------
    DesignError
        If either is not an integer >= 1.
    """
    for name, value in (("rows", rows), ("cols", cols)):
        if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < 1:
            raise DesignError(f"{name}: expected an integer >= 1, got {shown(value)}")
    return int(rows), int(cols)


def check_cell(cell, rows: int, cols: int) -> Cell:
    """Validate one cell of an R x C array.

    Parameters
    ----------
    cell : pair of int
        ``(row, col)``, 1-based.
    rows, cols : int

    Returns
    -------
    Cell
        The cell as a tuple of plain ints.

    Raises
    ------
    DesignError
        If `cell` is not a pair of integers inside the array.
    """
    try:
        r, c = cell
    except (TypeError, ValueError):
        raise DesignError(f"cell {shown(cell)}: expected a (row, col) pair") from None
    for v in (r, c):
        if isinstance(v, bool) or not isinstance(v, numbers.Integral):
            raise DesignError(f"cell {shown(cell)}: row and column must be integers")
    if not (1 <= r <= rows and 1 <= c <= cols):
        raise DesignError(
            f"cell {shown(cell)} is outside the {rows} x {cols} array "
            f"(rows 1..{rows}, columns 1..{cols})"
        )
    return (int(r), int(c))


def cells(rows: int, cols: int) -> list[Cell]:
    """All cells of the array in row-major order (row 1 first)."""
    rows, cols = check_size(rows, cols)
    return [(r, c) for r in range(1, rows + 1) for c in range(1, cols + 1)]


def neighbours(cell: Cell, rows: int, cols: int) -> list[Cell]:
    """Cells sharing an edge with `cell`, in sorted order."""
    r, c = cell
    out = [(r - 1, c), (r, c - 1), (r, c + 1), (r + 1, c)]
    return [(i, j) for i, j in out if 1 <= i <= rows and 1 <= j <= cols]


def are_adjacent(u: Cell, v: Cell) -> bool:
    """True if cells `u` and `v` share an edge (Manhattan distance 1)."""
    return abs(u[0] - v[0]) + abs(u[1] - v[1]) == 1


def edge(u: Cell, v: Cell) -> tuple[Cell, Cell]:
    """The sorted pair naming the shared edge of `u` and `v`."""
    return (u, v) if u <= v else (v, u)


def shared_edges(rows: int, cols: int) -> list[tuple[Cell, Cell]]:
    """Every shared edge of the array as a sorted cell pair, in sorted order.

    There are ``rows (cols - 1) + cols (rows - 1)`` of them.
    """
    rows, cols = check_size(rows, cols)
    out = []
    for r in range(1, rows + 1):
        for c in range(1, cols + 1):
            if c < cols:
                out.append(((r, c), (r, c + 1)))
            if r < rows:
                out.append(((r, c), (r + 1, c)))
    return sorted(out)


def grid_graph(rows: int, cols: int) -> nx.Graph:
    """The grid graph of the array: one node per cell, one edge per shared edge.

    Parameters
    ----------
    rows, cols : int

    Returns
    -------
    networkx.Graph
        Nodes are the cells ``(r, c)`` (1-based), edges the shared edges.

    Raises
    ------
    DesignError
        If the size is invalid.
    """
    g = nx.Graph()
    g.add_nodes_from(cells(rows, cols))
    g.add_edges_from(shared_edges(rows, cols))
    return g
