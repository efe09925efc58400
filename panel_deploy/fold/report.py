"""Text and JSON-able reports of fold designs."""

from __future__ import annotations

import itertools

from ..errors import DesignError
from .circuits import ENUMERATION_LIMIT, count_circuits, count_circuits_up_to_symmetry
from .design import FoldDesign
from .mobility import jacobian_mobility


def _cell(c):
    return [int(c[0]), int(c[1])]


def _fmt(c) -> str:
    return f"({c[0]},{c[1]})"


def design_dict(d: FoldDesign, index: int | None = None) -> dict:
    """A JSON-able description of one design.

    Parameters
    ----------
    d : FoldDesign
    index : int, optional
        The circuit index, if known.

    Returns
    -------
    dict
        Keys ``rows, cols, index, circuit, ground, packs, reason, hinges,
        slits, footprint, stacks, placements, bodies, merges, refused_merges,
        dof_cells, dof_bodies, mobility_cells, mobility_bodies`` (Kutzbach's
        count, and the mobility from the loop-closure Jacobian's rank,
        :func:`.mobility.jacobian_mobility`: None when the design does not
        pack). Hinges carry ``stowed_angle`` (0 or pi) and
        ``facet`` when the design packs; stacks are listed top layer first.
    """
    st = d.stowed
    mobility = jacobian_mobility(d)
    hinges = []
    for u, v in d.hinges:
        h = {"cells": [_cell(u), _cell(v)]}
        if st is not None:
            hs = st.hinges[(u, v)]
            h["stowed_angle"] = hs.angle
            h["folded"] = hs.angle != 0
            h["facet"] = hs.facet
        hinges.append(h)
    out = {
        "rows": d.rows,
        "cols": d.cols,
        "index": index,
        "circuit": [_cell(c) for c in d.circuit],
        "ground": _cell(d.ground) if d.ground is not None else None,
        "packs": st is not None,
        "reason": d.reason,
        "hinges": hinges,
        "slits": [[_cell(u), _cell(v)] for u, v in d.slits],
        "footprint": [_cell(c) for c in st.footprint] if st else None,
        "stacks": [[_cell(c) for c in st.stack_order(s)] for s in (0, 1)] if st else None,
        "placements": (
            [
                {
                    "cell": _cell(p.cell),
                    "stack": p.stack,
                    "layer": p.layer,
                    "face_up": p.face_up,
                    "rotation": list(p.rotation),
                    "offset": list(p.offset),
                }
                for p in sorted(st.placements.values(), key=lambda p: p.cell)
            ]
            if st
            else None
        ),
        "bodies": [[_cell(c) for c in b] for b in d.bodies],
        "merges": [{"cells": [_cell(c) for c in m.cells], "reason": m.reason} for m in d.merges],
        "refused_merges": [
            {"cells": [_cell(c) for c in m.cells], "reason": m.reason} for m in d.refused
        ],
        "dof_cells": d.dof_cells,
        "dof_bodies": d.dof_bodies,
        "mobility_cells": mobility[0] if mobility else None,
        "mobility_bodies": mobility[1] if mobility else None,
    }
    return out


def design_text(d: FoldDesign, index: int | None = None) -> str:
    """A human-readable report of one design (same content as :func:`design_dict`)."""
    st = d.stowed
    head = f"{d.rows} x {d.cols} array" + (f", circuit {index}" if index is not None else "")
    lines = [head, "circuit: " + "-".join(_fmt(c) for c in d.circuit) + f"-{_fmt(d.circuit[0])}"]
    lines.append(f"ground: {_fmt(d.ground)}" if d.ground is not None else "ground: -")
    lines.append("verdict: packs into two stacks" if st else f"verdict: does not pack: {d.reason}")
    lines.append(f"hinges ({len(d.hinges)}):")
    for u, v in d.hinges:
        if st is None:
            lines.append(f"  {_fmt(u)}-{_fmt(v)}")
            continue
        hs = st.hinges[(u, v)]
        state = "folded (pi)" if hs.angle else "flat (0)"
        lines.append(f"  {_fmt(u)}-{_fmt(v)}  {state:12s} {hs.facet} facet")
    lines.append(f"slits ({len(d.slits)}): " + ", ".join(f"{_fmt(u)}-{_fmt(v)}" for u, v in d.slits))
    if st is not None:
        lines.append(
            f"stacks on footprint {_fmt(st.footprint[0])} {_fmt(st.footprint[1])}, "
            f"{st.layers} layers each, top to bottom:"
        )
        for s in (0, 1):
            cells = st.stack_order(s)
            marks = [
                _fmt(c) + ("" if st.placements[c].face_up else "v") for c in cells
            ]
            lines.append(f"  stack {s}: " + " ".join(marks))
        lines.append("  (v = face down)")
    if d.merges:
        lines.append(f"merges ({len(d.merges)}):")
        for m in d.merges:
            lines.append("  " + "+".join(_fmt(c) for c in m.cells) + ": " + m.reason)
    if d.refused:
        lines.append(f"refused merges ({len(d.refused)}):")
        for m in d.refused:
            lines.append("  " + m.reason)
    lines.append(
        f"bodies: {len(d.bodies)}; Kutzbach DoF {d.dof_cells} (cells) -> {d.dof_bodies} (bodies)"
    )
    mobility = jacobian_mobility(d)
    if mobility is not None:
        # Kutzbach counts six constraints a loop; parallel hinge lines impose fewer
        cells, bodies = ("not found" if m is None else m for m in mobility)
        lines.append(f"mobility from the loop-closure Jacobian's rank: {cells} (cells) -> "
                     f"{bodies} (bodies)")
    return "\n".join(lines)


def designs_summary(rows: int, cols: int, limit: int = 50, progress=None) -> dict:
    """Count the circuits of an array and report the first `limit` designs.

    The total comes from the frontier DP; the orbit count and the number of
    packable circuits only when the array has at most 36 cells (they need
    every circuit), otherwise they are None. ``progress``, if given, is
    called with no argument after each circuit examined.

    Returns
    -------
    dict
        ``rows, cols, circuits, orbits, packable, listed`` (list of
        ``{"index", "packs", "reason", "bodies", "dof_cells", "dof_bodies"}``).
    """
    from . import designs

    if isinstance(limit, bool) or not isinstance(limit, int) or limit < 0:
        raise DesignError(f"limit: expected an integer >= 0, got {limit!r}")
    total = count_circuits(rows, cols)
    small = rows * cols <= ENUMERATION_LIMIT
    listed = []
    packable = 0 if small else None
    it = designs(rows, cols)
    for i, d in it if small else itertools.islice(it, limit):
        if progress is not None:
            progress()
        if small and d.stowed is not None:
            packable += 1
        if i < limit:
            listed.append(
                {
                    "index": i,
                    "packs": d.stowed is not None,
                    "reason": d.reason,
                    "bodies": len(d.bodies),
                    "dof_cells": d.dof_cells,
                    "dof_bodies": d.dof_bodies,
                }
            )
    return {
        "rows": rows,
        "cols": cols,
        "circuits": total,
        "orbits": count_circuits_up_to_symmetry(rows, cols) if small else None,
        "packable": packable,
        "listed": listed,
    }


def short_reason(reason: str) -> str:
    """Why a circuit does not pack, in its first clause (the full reason also
    counts every branch the search cut)."""
    return reason.split(";")[0].removeprefix("no two-stack package: ")


def designs_text(s: dict) -> str:
    """A human-readable form of :func:`designs_summary`."""
    lines = [f"{s['rows']} x {s['cols']} array: {s['circuits']} Hamiltonian circuits"]
    if s["orbits"] is not None:
        lines.append(f"  {s['orbits']} up to the symmetries of the rectangle")
    if s["packable"] is not None:
        lines.append(f"  {s['packable']} pack into two stacks, {s['circuits'] - s['packable']} do not")
    if len(s["listed"]) < s["circuits"]:
        lines.append(f"first {len(s['listed'])} circuits:")
    for e in s["listed"]:
        verdict = (
            f"packs; {e['bodies']} bodies, DoF {e['dof_cells']} -> {e['dof_bodies']}"
            if e["packs"]
            else "does not pack: " + short_reason(e["reason"])
        )
        lines.append(f"  {e['index']:5d}  {verdict}")
    return "\n".join(lines)
