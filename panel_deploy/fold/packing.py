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
    "reach": "the walk would cut off empty slots it must still fill",
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
    # Occupancy per stack (0: the ground's, 1: the other) as bit sets over
    # layer levels, level = z / 2 + half, so the ground sits at bit `half`.
    occ = [1 << half, 0]
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

    ground_bit = 1 << half

    def reachable(stack, bit, lo, hi):
        """Can a walk from the new cell still fill every slot it must fill?

        The walk moves between ladder neighbours (a fold: the adjacent layer of
        the same stack; a flat hinge: the other stack, same layer) through empty
        slots, must fill every empty slot between the lowest and highest layer
        used so far, and must end next to the ground to close the loop.
        """
        # Levels any final window of `half` layers containing lo..hi can use.
        wlo, whi = hi - half + 1, lo + half - 1
        window = ((1 << (whi + 1)) - 1) & ~((1 << wlo) - 1)
        empty = [~occ[0] & window, ~occ[1] & window]
        if not (empty[0] & ((ground_bit << 1) | (ground_bit >> 1)) or empty[1] & ground_bit):
            return False
        need = (1 << (hi + 1)) - (1 << lo)
        # Hamiltonian-path degree rule: a slot to fill needs two ways in and out
        # (empty neighbours, the head, or the ground for the final cell).
        head = [bit if stack == 0 else 0, bit if stack == 1 else 0]
        loose = 0
        for with_ground in (True, False):
            ext = [empty[0] | head[0] | (ground_bit if with_ground else 0), empty[1] | head[1]]
            for s_ in (0, 1):
                a, b, c = ext[s_] << 1, ext[s_] >> 1, ext[1 - s_]
                short = empty[s_] & need & ~((a & b) | (a & c) | (b & c))
                if with_ground:
                    if short:
                        return False
                else:
                    loose += bin(short).count("1")
        if loose > 1:
            return False
        reach = head
        while True:
            a = (reach[0] | (reach[0] << 1) | (reach[0] >> 1) | reach[1]) & (empty[0] | head[0])
            b = (reach[1] | (reach[1] << 1) | (reach[1] >> 1) | reach[0]) & (empty[1] | head[1])
            if a == reach[0] and b == reach[1]:
                break
            reach = [a, b]
        return not (empty[0] & need & ~reach[0] or empty[1] & need & ~reach[1])

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
            stack = 0 if (x, y) == (root[0], root[1]) else 1
            bit = 1 << (zc // 2 + half)
            if occ[stack] & bit:
                stats["slot"] += 1
                continue
            if seg is not None and seg in segments:
                stats["hinge"] += 1
                continue
            occ[stack] |= bit
            if k < n - 1 and not reachable(stack, bit, zmin // 2 + half, zmax // 2 + half):
                stats["reach"] += 1
                occ[stack] &= ~bit
                continue
            saved = (state["other"], state["zmin"], state["zmax"])
            if stack == 1 and other is None:
                state["other"] = (x, y)
            state["zmin"], state["zmax"] = zmin, zmax
            if seg is not None:
                segments.add(seg)
            motions[k] = h
            choices[k] = (kind, z)
            yield from extend(k + 1)
            if seg is not None:
                segments.discard(seg)
            occ[stack] &= ~bit
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
    geo = _Geometry(rows, cols)
    walk = _walk(circuit, ground)
    stats = Counter()
    # Unrestricted first: it decides the verdict, and if its first package has
    # the ground on top it is also the first of the restricted order.
    try:
        first = next(_search(geo, walk, False, max_nodes, stats), None)
        if first is not None and max(_apply(m, geo.centre(c))[2] for m, c in zip(first[0], walk)) > 0:
            first = next(_search(geo, walk, True, max_nodes, Counter()), first)
    except _BudgetExceeded:
        return None, f"undecided: the packing search exceeded {max_nodes} nodes (raise max_nodes)"
    if first is not None:
        return _build_state(geo, walk, *first), ""
    if not stats:
        return None, "no two-stack package: no branch of the search survives"
    ranked = ", ".join(f"{_REASONS[k]} ({v}x)" for k, v in stats.most_common())
    main = stats.most_common(1)[0][0]
    return None, f"no two-stack package: {_REASONS[main]}; every branch cut by: {ranked}"
