"""The two-stack packing check: does a circuit design fold into two equal stacks?

Model
-----
The ground cell stays at the identity. Walking the circuit from the ground,
each hinge is either flat (angle 0) or folded by pi about its hinge line, which
runs along the cells' shared edge on the top facet (z = +t/2) or on the bottom
facet (z = -t/2) of the flat array. The stowed placement of a cell is the
product of exponentials

    g_k = M_1 M_2 ... M_k

of the hinge motions between the ground and the cell, each ``M_i`` a half turn
about hinge i's line as it lies in the flat array (or the identity when flat).
A half turn about a line at the top facet lands the next cell on top of the
previous one, so the facet of a folded hinge is the side its two cells meet on.

All motions are diagonal rotations (entries +-1) and translations, so the
search uses exact integers in units of (a/2, b/2, t/2).

Rules of a two-stack package (every one is checked):

* every cell's centroid lands on one of two footprint positions: the ground's
  own cell and one of its four neighbours (possibly outside the array);
* the cells occupy ``N/2`` consecutive layers, each (stack, layer) slot exactly
  once, so both stacks are full and equal (no voids);
* a folded hinge joins cells on adjacent layers of one stack and a flat hinge
  two cells side by side on one layer (both follow from the motions above);
* no two hinge lines (folded or flat) lie on the same stowed segment, i.e. the
  same edge of a stack at the same layer interface;
* the closing hinge of the circuit brings the walk back to the identity at the
  ground (loop closure).

The verdict does not depend on the ground: re-rooting a package at another
cell ``h`` is the rigid motion ``g_h^-1`` of the whole package, which keeps
every rule and maps the footprint onto ``h`` and one of its neighbours. The
placements (and which layer the ground is on) do depend on it.

Choice of package
-----------------
When several packages exist, the search order decides: hinges are taken in
walking order from the ground along the given circuit order, each trying flat,
then folded on the top facet, then folded on the bottom facet; facets of flat
hinges are then assigned in walking order, trying the top facet first. The first
complete package in that order is returned, searching first among packages
with the ground on the top layer (layer 0) and only then among all packages.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Iterator, Sequence

from ..errors import DesignError
from .circuits import validate_circuit
from .design import Cell, CellPlacement, HingeState, StowedState
from .grid import check_cell, edge

#: Default cap on search nodes per pass; packages of up to 36 cells need far fewer.
DEFAULT_MAX_NODES = 2_000_000

_IDENTITY = (1, 1, 1, 0, 0, 0)

# Pruning rules, in the words used in the reasons.
_REASONS = {
    "footprint": "a cell would land off the two-cell footprint",
    "span": "the layers would span more than N/2",
    "slot": "a cell would land on an occupied (stack, layer) slot",
    "hinge": "two hinge lines would share one stack edge at one layer interface",
    "closure": "the closing hinge does not bring the loop back to the ground",
    "flat-facet": "the flat hinges' lines cannot all get a free stack edge",
    "ground-top": "the ground would not be on the top layer",
}


def _compose(g, m):
    """g followed by m in the moving frame: p -> g(m(p))."""
    gx, gy, gz, tx, ty, tz = g
    mx, my, mz, ux, uy, uz = m
    return (gx * mx, gy * my, gz * mz, gx * ux + tx, gy * uy + ty, gz * uz + tz)


def _apply(g, p):
    return (g[0] * p[0] + g[3], g[1] * p[1] + g[4], g[2] * p[2] + g[5])


class _Geometry:
    """Doubled-unit coordinates of cells and hinge lines of one array."""

    def __init__(self, rows: int, cols: int):
        self.rows, self.cols = rows, cols

    def centre(self, cell: Cell) -> tuple[int, int, int]:
        r, c = cell
        return (2 * c - self.cols - 1, self.rows + 1 - 2 * r, 0)

    def cell_at(self, x: int, y: int) -> Cell:
        return ((self.rows + 1 - y) // 2, (x + self.cols + 1) // 2)

    def hinge_line(self, u: Cell, v: Cell, z: int):
        """(axis, midpoint) of the shared edge of u and v at doubled height z."""
        pu, pv = self.centre(u), self.centre(v)
        mid = ((pu[0] + pv[0]) // 2, (pu[1] + pv[1]) // 2, z)
        axis = "y" if u[0] == v[0] else "x"
        return axis, mid

    def fold(self, u: Cell, v: Cell, z: int):
        """Half turn about the shared edge of u and v at doubled height z."""
        axis, (mx, my, mz) = self.hinge_line(u, v, z)
        if axis == "y":
            return (-1, 1, -1, 2 * mx, 0, 2 * mz)
        return (1, -1, -1, 0, 2 * my, 2 * mz)


def _segment(g, axis, mid):
    return (axis,) + _apply(g, mid)


def _search(geo, walk, ground_on_top, max_nodes, stats) -> Iterator[tuple]:
    """Yield (motions, choices, flat facets) of every package in search order."""
    n = len(walk)
    half = n // 2
    root = geo.centre(walk[0])
    neighbour_pos = {
        (root[0] + dx, root[1] + dy) for dx, dy in ((2, 0), (-2, 0), (0, 2), (0, -2))
    }
    motions = [_IDENTITY] + [None] * (n - 1)
    choices = [None] * n  # choices[k]: hinge between walk[k-1] and walk[k]; [0]: closing
    occupied = {(root[0], root[1], 0)}
    segments = set()
    state = {"other": None, "zmin": 0, "zmax": 0, "nodes": 0}
    options = (("flat", None), ("fold", 1), ("fold", -1))

    def assign_flat_facets(k, flats, result):
        if k == len(flats):
            yield tuple(result)
            return
        g, u, v = flats[k]
        for z, name in ((1, "top"), (-1, "bottom")):
            seg = _segment(g, *geo.hinge_line(u, v, z))
            if seg in segments:
                continue
            segments.add(seg)
            result.append(name)
            yield from assign_flat_facets(k + 1, flats, result)
            result.pop()
            segments.discard(seg)

    def close():
        g = motions[n - 1]
        u, v = walk[n - 1], walk[0]
        for kind, z in options:
            m = _IDENTITY if kind == "flat" else geo.fold(u, v, z)
            if _compose(g, m) != _IDENTITY:
                stats["closure"] += 1
                continue
            seg = None
            if kind == "fold":
                seg = _segment(g, *geo.hinge_line(u, v, z))
                if seg in segments:
                    stats["hinge"] += 1
                    continue
                segments.add(seg)
            choices[0] = (kind, z)
            flats = [
                (motions[k - 1], walk[k - 1], walk[k])
                for k in range(1, n)
                if choices[k][0] == "flat"
            ]
            if kind == "flat":
                flats.append((g, u, v))
            found = False
            for facets in assign_flat_facets(0, flats, []):
                found = True
                yield list(motions), list(choices), facets
            if not found:
                stats["flat-facet"] += 1
            if seg is not None:
                segments.discard(seg)

    def extend(k):
        state["nodes"] += 1
        if state["nodes"] > max_nodes:
            raise _BudgetExceeded
        if k == n:
            yield from close()
            return
        g = motions[k - 1]
        u, v = walk[k - 1], walk[k]
        centre = geo.centre(v)
        for kind, z in options:
            if kind == "flat":
                m, seg = _IDENTITY, None
            else:
                m = geo.fold(u, v, z)
                seg = _segment(g, *geo.hinge_line(u, v, z))
            h = _compose(g, m)
            x, y, zc = _apply(h, centre)
            other = state["other"]
            if (x, y) != (root[0], root[1]):
                if other is None:
                    if (x, y) not in neighbour_pos:
                        stats["footprint"] += 1
                        continue
                elif (x, y) != other:
                    stats["footprint"] += 1
                    continue
            zmin, zmax = min(state["zmin"], zc), max(state["zmax"], zc)
            if ground_on_top and zc > 0:
                stats["ground-top"] += 1
                continue
            if (zmax - zmin) // 2 + 1 > half:
                stats["span"] += 1
                continue
            if (x, y, zc) in occupied:
                stats["slot"] += 1
                continue
            if seg is not None and seg in segments:
                stats["hinge"] += 1
                continue
            saved = (state["other"], state["zmin"], state["zmax"])
            if (x, y) != (root[0], root[1]) and other is None:
                state["other"] = (x, y)
            state["zmin"], state["zmax"] = zmin, zmax
            occupied.add((x, y, zc))
            if seg is not None:
                segments.add(seg)
            motions[k] = h
            choices[k] = (kind, z)
            yield from extend(k + 1)
            if seg is not None:
                segments.discard(seg)
            occupied.discard((x, y, zc))
            state["other"], state["zmin"], state["zmax"] = saved

    yield from extend(1)


class _BudgetExceeded(Exception):
    pass


def _build_state(geo, walk, motions, choices, facets) -> StowedState:
    n = len(walk)
    root = geo.centre(walk[0])
    centres = {walk[k]: _apply(motions[k], geo.centre(walk[k])) for k in range(n)}
    other = next((x, y) for x, y, _ in centres.values() if (x, y) != (root[0], root[1]))
    foot = sorted([geo.cell_at(root[0], root[1]), geo.cell_at(*other)])
    foot_pos = [geo.centre(c)[:2] for c in foot]
    zmax = max(p[2] for p in centres.values())
    placements = {}
    for k, cell in enumerate(walk):
        g = motions[k]
        x, y, z = centres[cell]
        placements[cell] = CellPlacement(
            cell=cell,
            stack=foot_pos.index((x, y)),
            layer=(zmax - z) // 2,
            face_up=g[2] == 1,
            rotation=(g[0], g[1], g[2]),
            offset=(g[3] // 2, g[4] // 2, g[5] // 2),
        )
    hinges = {}
    flat_facets = iter(facets)
    # Hinge k joins walk[k-1] and walk[k]; the closing hinge (choices[0]) comes last,
    # matching the order in which flat facets were assigned.
    for k in list(range(1, n)) + [0]:
        u, v = walk[k - 1], walk[k]
        kind, z = choices[k]
        if kind == "flat":
            hinges[edge(u, v)] = HingeState(edge(u, v), 0.0, next(flat_facets))
        else:
            hinges[edge(u, v)] = HingeState(edge(u, v), math.pi, "top" if z == 1 else "bottom")
    return StowedState(
        footprint=(foot[0], foot[1]), layers=n // 2, placements=placements, hinges=hinges
    )


def _walk(circuit: Sequence[Cell], ground: Cell) -> list[Cell]:
    k = circuit.index(ground)
    return list(circuit[k:]) + list(circuit[:k])


def stowed_states(
    rows: int, cols: int, circuit, ground=None, *, max_nodes: int = DEFAULT_MAX_NODES
) -> Iterator[StowedState]:
    """Yield every two-stack package of a circuit design, in search order.

    Parameters
    ----------
    rows, cols : int
    circuit : sequence of (row, col)
        A Hamiltonian circuit of the array (validated), in visiting order.
    ground : (row, col), optional
        The cell held at the identity; the first cell of `circuit` by default.
    max_nodes : int, optional
        Cap on search nodes.

    Yields
    ------
    StowedState
        Packages in the order described in the module docstring (without the
        ground-on-top preference).

    Raises
    ------
    DesignError
        If the circuit or ground is invalid, or the search exceeds `max_nodes`.
    """
    circuit = validate_circuit(rows, cols, circuit)
    ground = circuit[0] if ground is None else check_cell(ground, rows, cols)
    geo = _Geometry(rows, cols)
    walk = _walk(circuit, ground)
    try:
        for motions, choices, facets in _search(geo, walk, False, max_nodes, Counter()):
            yield _build_state(geo, walk, motions, choices, facets)
    except _BudgetExceeded:
        raise DesignError(f"packing search exceeded {max_nodes} nodes") from None


def find_stowed_state(
    rows: int, cols: int, circuit, ground=None, *, max_nodes: int = DEFAULT_MAX_NODES
) -> tuple[StowedState | None, str]:
    """Decide whether a circuit design packs into two equal stacks, and how.

    Parameters
    ----------
    rows, cols : int
    circuit : sequence of (row, col)
        A Hamiltonian circuit of the array, in visiting order.
    ground : (row, col), optional
        The cell held at the identity (the ground panel); the first cell of
        `circuit` by default. It does not change the verdict, only the placements.
    max_nodes : int, optional
        Cap on search nodes per pass. If it is reached, no package is returned
        and the reason says the search was cut short (undecided).

    Returns
    -------
    stowed : StowedState or None
        The package chosen by the rule of the module docstring, or None.
    reason : str
        "" when a package exists, else why none does: odd cell count, or the
        pruning rules that cut every branch with how often each fired.

    Raises
    ------
    DesignError
        If the circuit is not a Hamiltonian circuit of the array or the ground
        is not one of its cells.
    """
    circuit = validate_circuit(rows, cols, circuit)
    ground = circuit[0] if ground is None else check_cell(ground, rows, cols)
    n = len(circuit)
    if n % 2:
        return None, f"{n} cells cannot fill two equal stacks (odd cell count)"
    geo = _Geometry(rows, cols)
    walk = _walk(circuit, ground)
    stats = Counter()
    for ground_on_top in (True, False):
        try:
            for motions, choices, facets in _search(geo, walk, ground_on_top, max_nodes, stats):
                return _build_state(geo, walk, motions, choices, facets), ""
        except _BudgetExceeded:
            return None, (
                f"undecided: the packing search exceeded {max_nodes} nodes "
                "(raise max_nodes)"
            )
    del stats["ground-top"]
    if not stats:
        return None, "no two-stack package: no branch of the search survives"
    ranked = ", ".join(f"{_REASONS[k]} ({v}x)" for k, v in stats.most_common())
    main = stats.most_common(1)[0][0]
    return None, f"no two-stack package: {_REASONS[main]}; every branch cut by: {ranked}"
