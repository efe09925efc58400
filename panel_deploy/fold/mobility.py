"""Mobility from the rank of the loop-closure Jacobian, beside Kutzbach's count.

Kutzbach's 6 (n - 1) - 5 j assumes every loop imposes six independent
constraints. Hinge lines of a folded array are parallel or collinear, so
loops are over-constrained: the 2 x 2 cells count -2 and still fold. The
mobility is the number of hinge rates that keep every loop closed: j minus
the rank of the loop-closure Jacobian, whose columns are the hinge axes'
twists, one row block of six per independent loop.

The flat and the stowed states are singular (every axis along x or y), so
the rank is taken at configurations near the flat state that close every
loop, reached by random walks from it, each step projected back onto the
closure. There the mobility is the dimension of the branch the walk is on;
the largest over a few walks is reported.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import numpy as np

from ..errors import DesignError
from .design import Cell, FoldDesign
from .kutzbach import body_joints

#: Panel thickness in cell pitches of the geometry the rank is taken on (the
#: hinge lines lie on the top or bottom facet); 0.05 is the reference
#: scene's 5 mm on 100 mm panels. The rank does not depend on it unless it is 0.
THICKNESS = 0.05
#: Random walks from the flat state; each ends on a branch of the closed
#: configurations (circuit 1 of the 4 x 4 array, merged, has branches of
#: mobility 4 and 5 there: one walk in six ended on the smaller).
WALKS = 4
#: Steps of a walk, and the standard deviation of each step's change of every
#: hinge angle, rad: small enough that each step projects back onto the closure.
WALK_STEPS = 10
STEP = 0.05
#: Levenberg-Marquardt iterations a projection may take.
PROJECTION_STEPS = 200
#: Singular values below this times the largest count as zero in the rank.
RANK_TOL = 1e-8
#: Loop-closure error (m in cell pitches, rad) at which a projection stops.
CLOSURE_TOL = 1e-12


def hinge_twist(segment: tuple[Cell, Cell], facet: str, rows: int, cols: int,
                thickness: float = THICKNESS) -> np.ndarray:
    """Unit twist (v, omega) of the hinge on the shared edge of ``segment``
    in the flat state, lengths in cell pitches; the rotation is of the
    second cell relative to the first (the sign does not change a rank)."""
    (r1, c1), (r2, c2) = sorted(segment)
    z = thickness / 2 if facet == "top" else -thickness / 2
    if r1 == r2:  # side by side: the edge runs along y at x between the columns
        point = np.array([c1 + 0.5 - (cols + 1) / 2, 0.0, z])
        omega = np.array([0.0, 1.0, 0.0])
    else:  # one above the other: the edge runs along x
        point = np.array([0.0, (rows + 1) / 2 - r1 - 0.5, z])
        omega = np.array([1.0, 0.0, 0.0])
    return np.concatenate([-np.cross(omega, point), omega])


def _exp(twist: np.ndarray, angle: float) -> np.ndarray:
    """The rigid motion (4 x 4) of a rotation by ``angle`` about a unit-axis twist."""
    v, w = twist[:3], twist[3:]
    K = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
    R = np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K
    g = np.eye(4)
    g[:3, :3] = R
    g[:3, 3] = (np.eye(3) - R) @ np.cross(w, v) + w * np.dot(w, v) * angle
    return g


def _adjoint(g: np.ndarray, twist: np.ndarray) -> np.ndarray:
    R, p = g[:3, :3], g[:3, 3]
    w = R @ twist[3:]
    return np.concatenate([R @ twist[:3] + np.cross(p, w), w])


class _Loops:
    """Bodies joined by hinges as a spanning tree from the ground plus one cut
    hinge per independent loop."""

    def __init__(self, n_bodies: int, joints: Sequence[tuple[int, int]], twists, ground: int):
        bodies = range(n_bodies)
        if ground not in bodies or any(a not in bodies or b not in bodies for a, b in joints):
            raise DesignError(f"joints: expected pairs of body indices 0..{n_bodies - 1} and a "
                              f"ground among them, got ground {ground!r} and joints {joints!r}")
        self.twists = [np.asarray(t, dtype=float) for t in twists]
        self.parent = {ground: None}  # body -> (joint, parent body)
        order, cuts = [ground], []
        adjacent = {b: [] for b in range(n_bodies)}
        for e, (a, b) in enumerate(joints):
            adjacent[a].append((e, b))
            adjacent[b].append((e, a))
        seen = set()
        for body in order:  # breadth first: order grows as bodies are reached
            for e, other in adjacent[body]:
                if e in seen:
                    continue
                seen.add(e)
                if other in self.parent:
                    cuts.append((e, body, other))
                else:
                    self.parent[other] = (e, body)
                    order.append(other)
        self.order, self.cuts = order, cuts

    def poses(self, theta):
        g = {self.order[0]: np.eye(4)}
        for body in self.order[1:]:
            e, up = self.parent[body]
            g[body] = g[up] @ _exp(self.twists[e], theta[e])
        return g

    def _path(self, body):
        joints = []
        while self.parent[body] is not None:
            e, body = self.parent[body]
            joints.append((e, body))
        return joints

    def residual_and_jacobian(self, theta):
        """Closure error of every loop (6 each: position, rotation) and its
        Jacobian over every hinge angle (the hinges' current twists)."""
        g = self.poses(theta)
        n = len(self.twists)
        res = np.zeros(6 * len(self.cuts))
        J = np.zeros((6 * len(self.cuts), n))
        for row, (e, a, b) in enumerate(self.cuts):
            rows = slice(6 * row, 6 * row + 6)
            E = g[a] @ _exp(self.twists[e], theta[e]) @ np.linalg.inv(g[b])
            R = E[:3, :3]
            # a small rotation's vector is half the skew part of its matrix
            skew = 0.5 * np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
            res[rows] = np.concatenate([E[:3, 3], skew])
            J[rows, e] += _adjoint(g[a], self.twists[e])
            for sign, body in ((1.0, a), (-1.0, b)):
                for j, up in self._path(body):
                    J[rows, j] += sign * _adjoint(g[up], self.twists[j])
        return res, J

    def project(self, theta):
        """``theta`` moved onto the closed configurations (Levenberg-Marquardt:
        near the singular flat state plain Gauss-Newton steps diverge), and the
        Jacobian there; (None, None) if it does not close."""
        damping = 1e-3
        res, J = self.residual_and_jacobian(theta)
        cost = res @ res
        eye = np.eye(len(theta))
        for _ in range(PROJECTION_STEPS):
            if np.abs(res).max() < CLOSURE_TOL:
                return theta, J
            trial = theta - np.linalg.solve(J.T @ J + damping * eye, J.T @ res)
            res_t, J_t = self.residual_and_jacobian(trial)
            if res_t @ res_t < cost:
                theta, res, J, cost = trial, res_t, J_t, res_t @ res_t
                damping = max(damping / 10, 1e-15)
            else:
                damping *= 10
        return None, None

    def walk(self, rng):
        """The Jacobian at the end of a random walk from the flat state over
        closed configurations (:data:`WALK_STEPS` steps of :data:`STEP` rad
        per hinge, each projected), or None if no step closed."""
        theta, J = np.zeros(len(self.twists)), None
        for _ in range(WALK_STEPS):
            moved, J_moved = self.project(theta + rng.normal(0.0, STEP, len(theta)))
            if moved is not None:
                theta, J = moved, J_moved
        return J


def loop_mobility(n_bodies: int, joints: Sequence[tuple[int, int]], twists: Iterable,
                  ground: int = 0, seed: int = 0) -> int | None:
    """Mobility of bodies joined by revolute hinges, from the closure Jacobian's rank.

    Parameters
    ----------
    n_bodies : int
        Bodies, ground included; every one must be reached through the joints.
    joints : sequence of (int, int)
        The two bodies each hinge joins.
    twists : iterable of (6,) array_like
        Each hinge's unit twist (v, omega) in the reference configuration,
        which must close every loop (the flat state); lengths in any one unit.
    ground : int
        The body held fixed.
    seed : int
        Of the random walks.

    Returns
    -------
    int or None
        Number of hinges minus the rank of the loop-closure Jacobian at a
        closed configuration near the reference one: the largest over
        :data:`WALKS` random walks (the dimension of the largest branch);
        None if no walk could keep the loops closed.

    Raises
    ------
    DesignError
        If a joint names no body, the twists do not match the joints, or a
        body is not joined to the ground.
    """
    loops = _Loops(n_bodies, joints, twists, ground)
    n = len(loops.twists)
    if n != len(joints) or any(np.shape(t) != (6,) for t in loops.twists):
        raise DesignError(f"twists: expected one (6,) twist per joint ({len(joints)}), got "
                          f"{n} of shapes {sorted({np.shape(t) for t in loops.twists})}")
    if len(loops.order) != n_bodies:
        raise DesignError(f"joints: {n_bodies - len(loops.order)} of the {n_bodies} bodies "
                          f"are not joined to the ground body {ground}")
    if not loops.cuts:
        return n  # a tree: nothing constrains the hinges
    rng = np.random.default_rng(seed)
    found = []
    for _ in range(WALKS):
        J = loops.walk(rng)
        if J is not None:
            s = np.linalg.svd(J, compute_uv=False)
            found.append(n - int(np.sum(s > RANK_TOL * s[0])))
    return max(found, default=None)


def jacobian_mobility(design: FoldDesign) -> tuple[int | None, int | None] | None:
    """Mobility of ``design``'s cells and of its merged bodies from the
    loop-closure Jacobian's rank (:func:`loop_mobility`), or None when the
    design does not pack (its hinges then have no facet)."""
    if design.stowed is None:
        return None
    facets = {cells: h.facet for cells, h in design.stowed.hinges.items()}
    cells = [((r, c),) for r in range(1, design.rows + 1) for c in range(1, design.cols + 1)]
    return tuple(_mobility(design, bodies, facets) for bodies in (cells, design.bodies))


def _mobility(design: FoldDesign, bodies, facets) -> int | None:
    joints = body_joints(bodies, design.hinges)
    pairs = list(joints)
    # collinear segments of one joint share its line: the first one stands for it
    twists = [hinge_twist(joints[p][0], facets[joints[p][0]], design.rows, design.cols)
              for p in pairs]
    ground = next(i for i, body in enumerate(bodies) if design.ground in body)
    return loop_mobility(len(bodies), pairs, twists, ground)
