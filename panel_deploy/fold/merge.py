"""Merging cells that never move relative to each other into one rigid body.

Two cells can merge when they share an edge of the flat array (across a hinge
that stays flat, or a slit) and have the same stowed rigid motion, so they lie
side by side on one layer of the package. A merge is made only if the hinges
stay consistent: after it, all hinge segments between the same two bodies must
lie on one line, on one facet and with one stowed angle, so they act as one
revolute joint. Otherwise the merge is refused and the reason kept.

Merges are tried pair by pair in sorted order of the cell pairs, each accepted
one uniting the two cells' current bodies (so merging is transitive).
"""

from __future__ import annotations

from collections.abc import Sequence

from ..errors import DesignError, shown
from .design import Cell, Merge, StowedState
from .grid import are_adjacent, check_cell, edge, shared_edges
from .kutzbach import body_joints


def _line(u: Cell, v: Cell):
    """The flat-array line through the shared edge of u and v."""
    if u[0] == v[0]:
        return ("between columns", min(u[1], v[1]))
    return ("between rows", min(u[0], v[0]))


def _fmt(c: Cell) -> str:
    return f"({c[0]},{c[1]})"


def _pair_ok(u, v, stowed, hinge_set):
    """Reason text if u and v may merge as far as the pair goes, else (None, why)."""
    pu, pv = stowed.placements[u], stowed.placements[v]
    if (pu.rotation, pu.offset) != (pv.rotation, pv.offset):
        where = (
            f"layers {pu.layer} and {pv.layer}"
            if pu.layer != pv.layer
            else f"layer {pu.layer} but with different stowed motions"
        )
        return None, f"{_fmt(u)}-{_fmt(v)} refused: they lie on {where}"
    kind = "flat hinge" if edge(u, v) in hinge_set else "slit"
    return f"{_fmt(u)}-{_fmt(v)}: {kind}, side by side on layer {pu.layer} with the same stowed motion", None


def _inconsistent(bodies, hinges, stowed, body):
    """Why the hinges of `body` to another body are not one joint, or None."""
    joints = body_joints(bodies, hinges)
    for (i, j), segs in joints.items():
        if body not in (i, j) or len(segs) < 2:
            continue
        kinds = {
            (_line(u, v), stowed.hinges[edge(u, v)].facet, stowed.hinges[edge(u, v)].angle)
            for u, v in segs
        }
        if len(kinds) > 1:
            names = ", ".join(f"{_fmt(u)}-{_fmt(v)}" for u, v in segs)
            return (
                f"the hinges {names} would join the same two bodies but are not one "
                "line with one facet and one stowed angle"
            )
    return None


def merge_cells(
    rows: int,
    cols: int,
    hinges: Sequence[tuple[Cell, Cell]],
    stowed: StowedState | None,
    merge="auto",
) -> tuple[tuple, tuple, tuple]:
    """Merge cells of a packed design into rigid bodies.

    Parameters
    ----------
    rows, cols : int
    hinges : sequence of (Cell, Cell)
        The circuit's hinges as sorted cell pairs.
    stowed : StowedState or None
        The package; without one nothing can merge.
    merge : "auto", "none" or sequence of cell pairs
        "auto" tries every pair of adjacent cells, "none" none, a sequence
        exactly the pairs given (each must be two adjacent cells of the array).

    Returns
    -------
    bodies : tuple of tuple of Cell
        Cells of each body, sorted, bodies ordered by their first cell.
    merges : tuple of Merge
        One per body of two or more cells, the reason listing each join.
    refused : tuple of Merge
        Pairs not merged and why (only requested pairs, and in "auto" mode
        pairs that passed the same-motion test but broke hinge consistency).

    Raises
    ------
    DesignError
        If `merge` is not "auto", "none" or a sequence of adjacent cell pairs.
    """
    all_cells = [(r, c) for r in range(1, rows + 1) for c in range(1, cols + 1)]
    if isinstance(merge, str):
        if merge not in ("auto", "none"):
            raise DesignError(f"merge: expected 'auto', 'none' or a list of cell pairs, got {shown(merge)}")
        explicit = False
        pairs = shared_edges(rows, cols) if merge == "auto" else []
    else:
        explicit = True
        pairs = []
        try:
            items = list(merge)
        except TypeError:
            raise DesignError(f"merge: expected 'auto', 'none' or a list of cell pairs, got {shown(merge)}") from None
        for item in items:
            try:
                u, v = item
            except (TypeError, ValueError):
                raise DesignError(f"merge: expected a pair of cells, got {shown(item)}") from None
            u, v = check_cell(u, rows, cols), check_cell(v, rows, cols)
            if not are_adjacent(u, v):
                raise DesignError(f"merge: cells {u} and {v} do not share an edge")
            pairs.append(edge(u, v))
        pairs = sorted(set(pairs))

    parent = {c: c for c in all_cells}

    def find(c):
        while parent[c] != c:
            parent[c] = parent[parent[c]]
            c = parent[c]
        return c

    def partition():
        groups: dict[Cell, list] = {}
        for c in all_cells:
            groups.setdefault(find(c), []).append(c)
        return sorted(tuple(sorted(g)) for g in groups.values())

    hinge_set = set(hinges)
    reasons: dict[Cell, list[str]] = {}
    refused = []
    for u, v in pairs:
        if stowed is None:
            refused.append(Merge((u, v), f"{_fmt(u)}-{_fmt(v)} refused: the design has no two-stack package"))
            continue
        if find(u) == find(v):
            continue
        ok, why = _pair_ok(u, v, stowed, hinge_set)
        if ok is None:
            # In auto mode most adjacent pairs differ in motion; that is not news.
            if explicit:
                refused.append(Merge((u, v), why))
            continue
        ru, rv = find(u), find(v)
        saved = dict(parent)
        parent[rv] = ru
        bodies = partition()
        body = next(i for i, b in enumerate(bodies) if u in b)
        why = _inconsistent(bodies, hinges, stowed, body)
        if why is not None:
            parent.clear()
            parent.update(saved)
            refused.append(Merge((u, v), f"{_fmt(u)}-{_fmt(v)} refused: {why}"))
            continue
        reasons[find(u)] = reasons.pop(ru, []) + reasons.pop(rv, []) + [ok]

    bodies = partition()
    merges = tuple(
        Merge(b, "; ".join(reasons[find(b[0])])) for b in bodies if len(b) > 1
    )
    return tuple(bodies), merges, tuple(refused)
