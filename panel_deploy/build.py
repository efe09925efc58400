"""Scene -> fold design -> frozen :class:`~panel_deploy.model.Model`.

The one place where array geometry (cell centroids, hinge edge lines, facets)
becomes bodies and hinges. Names: a body is named after its cells
(``r1c2+r1c3``), a hinge after its first cell segment (``r1c1-r2c1``).
"""

from __future__ import annotations

import numpy as np

from . import fold
from .contacts import with_panel_contacts
from .errors import DesignError, SceneError, shown
from .model import AirParameters, Body, ClosureParameters, Hinge, Model, box_inertia
from .scene import Scene


def cell_name(cell) -> str:
    return f"r{cell[0]}c{cell[1]}"


def hinge_name(segment) -> str:
    return "-".join(cell_name(c) for c in sorted(segment))


def cell_centre(cell, rows, cols, a, b) -> np.ndarray:
    """Centroid (m) of cell (row, col) in the flat array frame."""
    r, c = cell
    return np.array([(c - (cols + 1) / 2) * a, ((rows + 1) / 2 - r) * b, 0.0])


def scene_design(scene: Scene):
    """The fold design of a scene's array, circuit, ground and merges, as
    :func:`panel_deploy.fold.design` makes it (it may not pack, and merges may
    be refused: the design says why).

    A scene with ``fold.circuit: auto`` is refused: its circuit is chosen by
    screening simulations of the candidates
    (:func:`panel_deploy.ranking.resolve_circuit`), which build models
    themselves, so it is resolved before a model is built (the command line
    and the array_model node do), not inside building one.

    Raises
    ------
    SceneError
        If the circuit, ground or merge list is invalid for the array, or the
        circuit is ``auto``.
    """
    arr, f = scene.array, scene.fold
    if f.circuit == "auto":
        raise SceneError("fold.circuit", "auto: resolve the scene first "
                                         "(panel_deploy.ranking.resolve_circuit screens the "
                                         "candidate circuits)")
    try:
        return fold.design(arr.rows, arr.cols, circuit=f.circuit, ground=f.ground, merge=f.merge)
    except DesignError as e:
        raise SceneError("fold", str(e)) from None


def design_of(scene: Scene):
    """The fold design a scene asks for, ready to build a model from.

    Raises
    ------
    SceneError
        As :func:`scene_design`, and if the design does not pack into two
        stacks or a merge the scene lists is refused (the reason is in the
        message; ``merge: auto`` keeps the merges that can be made).
    """
    d = scene_design(scene)
    if d.stowed is None:
        raise SceneError("fold.circuit", f"the design does not pack into two stacks: {d.reason}")
    if d.refused and scene.fold.merge not in ("auto", "none"):
        raise SceneError("fold.merge", "; ".join(m.reason for m in d.refused))
    return d


def _segment_line(pair, facet, rows, cols, a, b, t):
    """End points (2, 3) of the shared edge of two adjacent cells, on ``facet``."""
    (r1, c1), (r2, c2) = sorted(pair)
    p = cell_centre((r1, c1), rows, cols, a, b)
    z = t / 2 if facet == "top" else -t / 2
    if r1 == r2:  # cells side by side: vertical edge at the right of the first
        x = p[0] + a / 2
        return np.array([[x, p[1] - b / 2, z], [x, p[1] + b / 2, z]])
    y = p[1] - b / 2  # first cell above the second: horizontal edge below it
    return np.array([[p[0] - a / 2, y, z], [p[0] + a / 2, y, z]])


def _hinge(name, ia, ib, cells_a, segments, stowed, geom, k, c):
    """A body-level hinge from its collinear cell segments (see :class:`Hinge`)."""
    rows, cols, a, b, t = geom
    states = [stowed.hinges[s] for s in segments]
    facets = {s.facet for s in states}
    angles = {s.angle for s in states}
    if len(facets) != 1 or len(angles) != 1:
        raise DesignError(f"hinge {name}: segments disagree on facet or stowed angle")
    facet = facets.pop()
    pts = np.vstack([_segment_line(s, facet, rows, cols, a, b, t) for s in segments])
    s0 = segments[0]
    ca, cb = (s0[0], s0[1]) if s0[0] in cells_a else (s0[1], s0[0])
    n = cell_centre(cb, rows, cols, a, b) - cell_centre(ca, rows, cols, a, b)
    n /= np.linalg.norm(n)
    z = np.array([0.0, 0.0, 1.0])
    # A positive rotation must swing body b through the side of its hinge facet,
    # so that the facets meet (valley fold); small rotations move b along u x n.
    axis = np.cross(n, z) if facet == "top" else np.cross(z, n)
    proj = pts @ axis
    M, N = pts[np.argmin(proj)], pts[np.argmax(proj)]
    if np.linalg.norm(np.cross(pts - M, axis), axis=1).max() > 1e-12 * max(a, b):
        raise DesignError(f"hinge {name}: segments are not collinear")
    return Hinge(name, ia, ib, M, axis, float(np.dot(N - M, axis)), facet, k, c,
                 float(angles.pop()), tuple(segments), len(segments))


def build_model(scene: Scene, design=None) -> Model:
    """The model a scene describes: merged bodies, hinges, tree, parameters.

    Parameters
    ----------
    scene : Scene
    design : FoldDesign, optional
        Reuse a design already computed for this scene.

    Raises
    ------
    SceneError
        For a design that does not pack, unknown hinge names in
        ``hinges.overrides``, a ``closure.cut_hinge`` that is not a hinge, or
        ``fold.circuit: auto`` (:func:`scene_design`).
    """
    d = design if design is not None else design_of(scene)
    arr = scene.array
    a, b, t = arr.length, arr.width, arr.thickness
    geom = (arr.rows, arr.cols, a, b, t)
    body_of = {}
    bodies = []
    for i, cells in enumerate(d.bodies):
        rs = sorted({r for r, _ in cells})
        cs = sorted({c for _, c in cells})
        if len(rs) * len(cs) != len(cells):
            raise DesignError(f"body {cells}: merged cells do not form a rectangle")
        size = np.array([len(cs) * a, len(rs) * b, t])
        mass = arr.unit_mass * len(cells)
        centre = np.mean([cell_centre(c, arr.rows, arr.cols, a, b) for c in cells], axis=0)
        bodies.append(Body("+".join(cell_name(c) for c in sorted(cells)), tuple(sorted(cells)),
                           size, mass, box_inertia(mass, size), centre))
        for c in cells:
            body_of[c] = i

    by_pair = {}
    for seg in d.hinges:
        seg = tuple(sorted(seg))
        ia, ib = body_of[seg[0]], body_of[seg[1]]
        if ia != ib:
            by_pair.setdefault((min(ia, ib), max(ia, ib)), []).append(seg)
    names = {hinge_name(sorted(segs)[0]) for segs in by_pair.values()}
    overrides = scene.hinges.overrides or {}
    damping = scene.hinges.damping_overrides or {}
    for section, keys in (("overrides", overrides), ("damping_overrides", damping)):
        for key in keys:
            if key not in names:
                raise SceneError(f"hinges.{section}.{key}",
                                 f"no such hinge (hinges are: {', '.join(sorted(names))})")
    hinges = []
    for (ia, ib), segs in sorted(by_pair.items()):
        segs = sorted(segs)
        name = hinge_name(segs[0])
        k = overrides.get(name, scene.hinges.stiffness)
        hinges.append(_hinge(name, ia, ib, bodies[ia].cells, segs, d.stowed,
                             geom, k, damping.get(name, scene.hinges.damping_ratio * k)))

    cuts = None
    if scene.closure.cut_hinge is not None:
        cuts = []
        for i, seg in enumerate(scene.closure.cut_hinge):
            found = [j for j, h in enumerate(hinges) if seg in h.segments]
            if not found:
                raise SceneError(f"closure.cut_hinge[{i}]", f"{list(map(list, seg))} is not a hinge")
            cuts.append(found[0])
    c = scene.closure
    closure = ClosureParameters(c.method, c.k_M, c.c_M, c.k_N, c.c_N, c.baumgarte, c.regularisation)
    ground_cell = d.circuit[0] if scene.fold.ground is None else scene.fold.ground
    if ground_cell not in body_of:
        raise SceneError("fold.ground", f"{list(ground_cell)} is not a cell of the array")
    ground = body_of[ground_cell]
    groups = _hinge_groups(scene, d, hinges, bodies[ground].cells)
    try:
        model = Model.build(bodies, hinges, ground, cut_hinges=cuts, k_s=scene.contact.k_s,
                            c_s=scene.contact.c_s, closure=closure, gravity=scene.gravity,
                            name=scene.name or "", hinge_groups=groups,
                            air=AirParameters(scene.air.density, scene.air.drag_coefficient),
                            stop_ramp=scene.contact.stop_ramp)
    except Exception as e:  # ModelError from a bad cut list
        if cuts is not None:
            raise SceneError("closure.cut_hinge", str(e)) from None
        raise
    if scene.contact.panels:
        model = with_panel_contacts(model, scene.contact.k_p, scene.contact.c_p,
                                    reach=scene.contact.reach, mu_p=scene.contact.friction,
                                    friction_speed=scene.contact.friction_speed,
                                    pressure=scene.contact.pressure)
    return model


def _symmetries(rows, cols):
    maps = [lambda r, c: (r, cols + 1 - c), lambda r, c: (rows + 1 - r, c),
            lambda r, c: (rows + 1 - r, cols + 1 - c)]
    if rows == cols:
        maps += [lambda r, c: (c, r), lambda r, c: (cols + 1 - c, rows + 1 - r),
                 lambda r, c: (c, rows + 1 - r), lambda r, c: (cols + 1 - c, r)]
    return maps


def _hinge_groups(scene, design, hinges, ground_cells):
    """Hinge index groups sharing one stiffness, as ``hinges.groups`` asks."""
    spec = scene.hinges.groups
    if spec == "auto":
        return symmetry_groups(hinges, scene.array.rows, scene.array.cols, ground_cells)
    if spec == "none":
        return tuple((i,) for i in range(len(hinges)))
    index = {h.name: i for i, h in enumerate(hinges)}
    seen = set()
    groups = []
    for gi, names in enumerate(spec):
        group = []
        for name in names:
            if name not in index:
                raise SceneError(f"hinges.groups[{gi}]", f"no such hinge {shown(name)} "
                                 f"(hinges are: {', '.join(sorted(index))})")
            if name in seen:
                raise SceneError(f"hinges.groups[{gi}]", f"hinge {shown(name)} is in two groups")
            seen.add(name)
            group.append(index[name])
        groups.append(tuple(sorted(group)))
    groups += [(i,) for i in range(len(hinges)) if hinges[i].name not in seen]
    return tuple(sorted(groups))


def symmetry_groups(hinges, rows, cols, ground_cells):
    """Hinge indices that share one stiffness under the design's symmetries.

    A symmetry of the rectangle counts if it maps the hinge set onto itself,
    keeps every hinge's facet, and keeps the ground body. Returns the orbits of
    the hinges under those symmetries, as a tuple of sorted index tuples.
    """
    facet = {tuple(sorted(s)): h.facet for h in hinges for s in h.segments}
    index = {tuple(sorted(s)): i for i, h in enumerate(hinges) for s in h.segments}
    ground_cells = set(ground_cells)
    parent = list(range(len(hinges)))

    def find(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for m in _symmetries(rows, cols):
        image = {tuple(sorted((m(*p), m(*q)))): f for (p, q), f in facet.items()}
        if image != facet or {m(*c) for c in ground_cells} != ground_cells:
            continue
        for seg, i in index.items():
            j = index[tuple(sorted((m(*seg[0]), m(*seg[1]))))]
            parent[find(i)] = find(j)
    groups = {}
    for i in range(len(hinges)):
        groups.setdefault(find(i), []).append(i)
    return tuple(sorted(tuple(g) for g in groups.values()))
