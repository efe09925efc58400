"""Hamiltonian circuits of the grid graph of an R x C array.

A circuit visits every cell once and returns to its first cell; it is an
undirected cycle, so each one is listed once whatever its start and direction.

Canonical form and order
------------------------
Every circuit passes through the corner cell (1, 1) using both of its edges, to
(1, 2) and to (2, 1). The *canonical sequence* of a circuit starts at (1, 1),
goes to (1, 2) first and ends at (2, 1). :func:`circuits` yields the canonical
sequences in increasing lexicographic order (cells compared as ``(row, col)``
tuples), and the *circuit index* ``i`` of a circuit is its 0-based position in
that order. The order depends only on the array size, so a scene can name a
circuit as ``circuit: {index: i}``.

Grid graphs are bipartite (chessboard colouring), so an array with an odd
number of cells, or with a single row or column, has no circuit.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence

from ..errors import DesignError, shown
from .design import Cell
from .grid import are_adjacent, check_cell, check_size, edge

#: Largest array, in cells, whose circuits reports enumerate and check in full
#: (orbit and packable counts); larger arrays are counted by the DP only.
ENUMERATION_LIMIT = 36


def _has_no_circuit(rows: int, cols: int) -> bool:
    return rows < 2 or cols < 2 or (rows * cols) % 2 == 1


def circuits(rows: int, cols: int) -> Iterator[tuple[Cell, ...]]:
    """Yield every Hamiltonian circuit of the array, lazily, in index order.

    Depth-first search over canonical sequences (see the module docstring),
    trying neighbours in sorted order, with these prunings:

    * a cell left with fewer than two usable neighbours (one for the final
      cell (2, 1), which is already joined to (1, 1)) ends the branch;
    * a neighbour of the current cell that has just one other usable neighbour
      must be entered next (its two circuit edges are forced), and two such
      neighbours end the branch;
    * the unvisited cells must stay connected to the current cell.

    Parameters
    ----------
    rows, cols : int

    Yields
    ------
    tuple of Cell
        The canonical sequence of one circuit (closing edge implied).

    Raises
    ------
    DesignError
        If the size is invalid.
    """
    rows, cols = check_size(rows, cols)
    if _has_no_circuit(rows, cols):
        return
    n = rows * cols
    nbrs = []
    for i in range(n):
        r, c = divmod(i, cols)
        lst = []
        if r > 0:
            lst.append(i - cols)
        if c > 0:
            lst.append(i - 1)
        if c < cols - 1:
            lst.append(i + 1)
        if r < rows - 1:
            lst.append(i + cols)
        nbrs.append(lst)
    start, first, last = 0, 1, cols
    cell_of = [(i // cols + 1, i % cols + 1) for i in range(n)]

    # Bit-parallel flood fill for the connectivity pruning.
    full = (1 << n) - 1
    not_first_col = 0
    not_last_col = 0
    for i in range(n):
        if i % cols != 0:
            not_first_col |= 1 << i
        if i % cols != cols - 1:
            not_last_col |= 1 << i

    def connected(region: int, seed: int) -> bool:
        reach = seed
        while True:
            grow = (
                reach
                | (reach << cols)
                | (reach >> cols)
                | ((reach << 1) & not_first_col)
                | ((reach >> 1) & not_last_col)
            ) & region
            if grow == reach:
                return reach == region
            reach = grow

    visited = [False] * n
    free = [len(nbrs[i]) for i in range(n)]
    unvisited = full
    path = []

    def visit(i):
        nonlocal unvisited
        visited[i] = True
        unvisited &= ~(1 << i)
        for w in nbrs[i]:
            free[w] -= 1
        path.append(i)

    def unvisit(i):
        nonlocal unvisited
        visited[i] = False
        unvisited |= 1 << i
        for w in nbrs[i]:
            free[w] += 1
        path.pop()

    def search(head: int) -> Iterator[tuple[Cell, ...]]:
        if head == last:
            if len(path) == n:
                yield tuple(cell_of[i] for i in path)
            return
        cand = [u for u in nbrs[head] if not visited[u]]
        forced = [u for u in cand if u != last and free[u] == 1]
        if len(forced) > 1:
            return
        if forced:
            cand = forced
        for u in cand:
            visit(u)
            # The old head is now interior, so its other unvisited neighbours
            # lost a usable neighbour (they are not adjacent to u: bipartite).
            ok = all(
                free[x] >= (1 if x == last else 2)
                for x in nbrs[head]
                if not visited[x]
            )
            if ok and (unvisited == 0 or connected(unvisited | (1 << u), 1 << u)):
                yield from search(u)
            unvisit(u)

    visit(start)
    visit(first)
    yield from search(first)


def _frontier_count(rows: int, cols: int) -> int:
    """Count circuits with a frontier ("plug") dynamic programme.

    Cells are processed row-major. The frontier has ``cols + 1`` plug positions;
    before cell (i, j) (0-based) position ``k < j`` holds the down plug of cell
    (i, k), position ``j`` the right plug of cell (i, j - 1) and position
    ``k > j`` the down plug of cell (i - 1, k - 1). A plug is 0 (none), 1 or 2,
    the left and right end of a path segment; left-to-right order along the
    frontier is geometric, so the ends nest like brackets. Every cell takes
    exactly two edges and the loop may close only at the last cell.
    """
    width = cols + 1
    states = {0: 1}

    def get(s, k):
        return (s >> (2 * k)) & 3

    def put(s, k, v):
        return (s & ~(3 << (2 * k))) | (v << (2 * k))

    def partner(s, k, step):
        """Position of the bracket matching the one at ``k``, searching along ``step``."""
        opening = get(s, k)
        depth = 0
        while True:
            v = get(s, k)
            if v == opening:
                depth += 1
            elif v:
                depth -= 1
                if depth == 0:
                    return k
            k += step

    total = 0
    for i in range(rows):
        for j in range(cols):
            can_down = i < rows - 1
            can_right = j < cols - 1
            final = i == rows - 1 and j == cols - 1
            new = {}
            for s, cnt in states.items():
                left, up = get(s, j), get(s, j + 1)
                base = put(put(s, j, 0), j + 1, 0)
                outs = []
                if left == 0 and up == 0:
                    if can_down and can_right:
                        outs.append(put(put(base, j, 1), j + 1, 2))
                elif left == 0 or up == 0:
                    x = left or up
                    if can_down:
                        outs.append(put(base, j, x))
                    if can_right:
                        outs.append(put(base, j + 1, x))
                elif left == 1 and up == 1:
                    # Joining two opening ends: the partner of `up` opens now.
                    outs.append(put(base, partner(s, j + 1, 1), 1))
                elif left == 2 and up == 2:
                    outs.append(put(base, partner(s, j, -1), 2))
                elif left == 2 and up == 1:
                    outs.append(base)
                else:  # left == 1, up == 2: the two ends of one segment meet.
                    if final and base == 0:
                        total += cnt
                    continue
                for o in outs:
                    new[o] = new.get(o, 0) + cnt
            states = new
        # Next row: the right plug past the last column is empty; shift.
        states = {(s << 2) & ((1 << (2 * width)) - 1): v for s, v in states.items()}
    return total


def count_circuits(rows: int, cols: int) -> int:
    """Number of Hamiltonian circuits of the array, without enumerating them.

    Uses a frontier (transfer-matrix) dynamic programme over the cells, so
    8 x 8 (4,638,576 circuits) counts in about a second.

    Parameters
    ----------
    rows, cols : int

    Returns
    -------
    int
        Number of undirected Hamiltonian cycles of the grid graph.

    Raises
    ------
    DesignError
        If the size is invalid.
    """
    rows, cols = check_size(rows, cols)
    if _has_no_circuit(rows, cols):
        return 0
    # The frontier is one plug wider than the row, so run along the short side.
    if cols > rows:
        rows, cols = cols, rows
    return _frontier_count(rows, cols)


def symmetries(rows: int, cols: int) -> list:
    """The symmetry group of the rectangle as functions on cells.

    Returns
    -------
    list of callable
        4 maps (identity, flip rows, flip columns, half turn), plus the 4
        diagonal reflections and quarter turns when ``rows == cols``.
    """
    rows, cols = check_size(rows, cols)
    R, C = rows + 1, cols + 1
    group = [
        lambda p: p,
        lambda p: (R - p[0], p[1]),
        lambda p: (p[0], C - p[1]),
        lambda p: (R - p[0], C - p[1]),
    ]
    if rows == cols:
        group += [
            lambda p: (p[1], p[0]),
            lambda p: (C - p[1], R - p[0]),
            lambda p: (p[1], R - p[0]),
            lambda p: (C - p[1], p[0]),
        ]
    return group


def circuit_edges(circuit: Sequence[Cell]) -> tuple[tuple[Cell, Cell], ...]:
    """Sorted cell pairs of the edges a circuit crosses, closing edge included."""
    n = len(circuit)
    return tuple(sorted(edge(circuit[k], circuit[(k + 1) % n]) for k in range(n)))


def canonical_form(rows: int, cols: int, circuit: Sequence[Cell]) -> tuple:
    """A key equal for two circuits exactly when a symmetry maps one onto the other.

    The key is the lexicographically smallest sorted edge list over the
    symmetry group of the rectangle.
    """
    edges = circuit_edges(circuit)
    return min(
        tuple(sorted(edge(g(u), g(v)) for u, v in edges)) for g in symmetries(rows, cols)
    )


def circuits_up_to_symmetry(rows: int, cols: int) -> Iterator[tuple[int, tuple[Cell, ...]]]:
    """Yield one circuit per orbit under the symmetries of the rectangle.

    The representative of an orbit is its member of smallest circuit index.
    This enumerates every circuit (exhaustive; practical up to 6 x 6).

    Parameters
    ----------
    rows, cols : int

    Yields
    ------
    (int, tuple of Cell)
        Circuit index and canonical sequence of each representative.

    Raises
    ------
    DesignError
        If the size is invalid.
    """
    seen = set()
    for i, circ in enumerate(circuits(rows, cols)):
        key = canonical_form(rows, cols, circ)
        if key not in seen:
            seen.add(key)
            yield i, circ


def count_circuits_up_to_symmetry(rows: int, cols: int) -> int:
    """Number of orbits of circuits under the symmetry group (by enumeration)."""
    return sum(1 for _ in circuits_up_to_symmetry(rows, cols))


def circuit_by_index(rows: int, cols: int, index: int) -> tuple[Cell, ...]:
    """The canonical sequence of circuit number `index` (see the module docstring).

    Raises
    ------
    DesignError
        If `index` is not an integer in ``0 .. count_circuits(rows, cols) - 1``.
    """
    rows, cols = check_size(rows, cols)
    if isinstance(index, bool) or not isinstance(index, int) or index < 0:
        raise DesignError(f"circuit index: expected an integer >= 0, got {shown(index)}")
    for i, circ in enumerate(circuits(rows, cols)):
        if i == index:
            return circ
    if _has_no_circuit(rows, cols):
        raise DesignError(
            f"the {rows} x {cols} array has no Hamiltonian circuit: "
            + ("it has a single row or column" if min(rows, cols) < 2 else
               "its cell count is odd, and a circuit of a chessboard alternates colours")
        )
    raise DesignError(
        f"circuit index {index} out of range: the {rows} x {cols} array has "
        f"{count_circuits(rows, cols)} circuits (indices 0..{count_circuits(rows, cols) - 1})"
    )


def canonical_sequence(circuit: Sequence[Cell]) -> tuple[Cell, ...]:
    """Rotate and orient a valid circuit to start at (1, 1) and go to (1, 2) first."""
    k = list(circuit).index((1, 1))
    seq = tuple(circuit[k:]) + tuple(circuit[:k])
    if seq[1] != (1, 2):
        seq = (seq[0],) + tuple(reversed(seq[1:]))
    return seq


def circuit_index(rows: int, cols: int, circuit: Sequence[Cell]) -> int:
    """Index of a valid circuit in the order of :func:`circuits` (enumerates)."""
    target = canonical_sequence(circuit)
    for i, circ in enumerate(circuits(rows, cols)):
        if circ == target:
            return i
    raise DesignError("circuit not found among the array's circuits")


def validate_circuit(rows: int, cols: int, circuit) -> tuple[Cell, ...]:
    """Check that a cell list is a Hamiltonian circuit of the array.

    Parameters
    ----------
    rows, cols : int
    circuit : sequence of (row, col)
        The cells in visiting order, each once; the edge from the last cell back
        to the first is implied (repeating the first cell at the end is accepted).

    Returns
    -------
    tuple of Cell
        The circuit in the given order and start.

    Raises
    ------
    DesignError
        If a cell is malformed or outside the array, a cell is missing or
        repeated, or two consecutive cells (including last and first) do not
        share an edge.
    """
    rows, cols = check_size(rows, cols)
    try:
        seq = [check_cell(p, rows, cols) for p in circuit]
    except TypeError:
        raise DesignError(f"circuit: expected a sequence of (row, col) cells, got {shown(circuit)}") from None
    if len(seq) > 1 and seq[0] == seq[-1]:
        seq = seq[:-1]
    n = rows * cols
    if len(set(seq)) != len(seq):
        dup = sorted({p for p in seq if seq.count(p) > 1})
        raise DesignError(f"circuit visits cell(s) {dup} more than once")
    if len(seq) != n:
        missing = sorted(set((r, c) for r in range(1, rows + 1) for c in range(1, cols + 1)) - set(seq))
        raise DesignError(
            f"circuit has {len(seq)} cells, the {rows} x {cols} array has {n}; missing {missing}"
        )
    for k in range(n):
        u, v = seq[k], seq[(k + 1) % n]
        if not are_adjacent(u, v):
            raise DesignError(
                f"circuit is not a Hamiltonian circuit: consecutive cells {u} and {v} "
                "do not share an edge"
            )
    return tuple(seq)
