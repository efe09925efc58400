"""The frozen multibody model of a panel array, and the mutable state made from it.

Like MuJoCo's ``mjModel``/``mjData`` and Pinocchio's ``Model``/``Data``: a
:class:`Model` never changes once built (its dataclasses are frozen and their
arrays read-only; a changed model is a new one, :meth:`Model.with_stiffness`);
a :class:`State` is created from it for each run; dynamics, collision and
energy are functions of the two.

Frames and units (SI throughout): every body frame has its origin at the body's
centroid and, in the flat (deployed) configuration, axes parallel to the flat
array frame of :mod:`panel_deploy.fold.design` (x along the columns, y towards
row 1, z out of the top facet). Hinge points and axes are given in that flat
frame; since body frames are only translated from it when flat, a hinge's
point in body ``i``'s frame is ``point - bodies[i].flat_position``.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, replace
from typing import Literal

import numpy as np

from .errors import ModelError
from .scene import SimulationSection

#: The array is flat once every hinge (cut hinges included) has |theta| at most
#: this, rad: the default of the scene's ``simulation.flat_tolerance``.
FLAT_TOLERANCE = SimulationSection.flat_tolerance

ClosureMethod = Literal["penalty", "exact"]


def _frozen(value, shape) -> np.ndarray:
    """A read-only float copy of ``value`` with ``shape``."""
    a = np.array(value, dtype=float).reshape(shape)
    a.flags.writeable = False
    return a


def _freeze(obj, **shapes) -> None:
    """Make the named array fields of the frozen dataclass ``obj`` read-only copies."""
    for name, shape in shapes.items():
        object.__setattr__(obj, name, _frozen(getattr(obj, name), shape))


def box_inertia(mass: float, size) -> np.ndarray:
    """Inertia tensor (kg m^2, 3x3) of a uniform box about its centroid.

    ``size`` is (lx, ly, lz) in m along the body axes.
    """
    lx, ly, lz = size
    return (mass / 12.0) * np.diag([ly**2 + lz**2, lx**2 + lz**2, lx**2 + ly**2])


@dataclass(frozen=True)
class Body:
    """One rigid panel (a merged panel is one body).

    Attributes
    ----------
    name : str
    cells : tuple of (row, col)
        Array cells this body is made of.
    size : (3,) ndarray
        Box edge lengths (lx, ly, lz), m, along the body axes.
    mass : float
        kg.
    inertia : (3, 3) ndarray
        kg m^2, about the centroid, body axes.
    flat_position : (3,) ndarray
        Centroid in the flat array frame when deployed, m.
    """

    name: str
    cells: tuple
    size: np.ndarray
    mass: float
    inertia: np.ndarray
    flat_position: np.ndarray

    def __post_init__(self):
        _freeze(self, size=(3,), inertia=(3, 3), flat_position=(3,))


@dataclass(frozen=True)
class Hinge:
    """A revolute hinge with a torsional spring and damper, Eq. (2)-(4).

    Attributes
    ----------
    name : str
    body_a, body_b : int
        Body indices. For a tree joint ``body_a`` is the parent (nearer the
        ground); theta is the rotation of ``body_b`` relative to ``body_a``.
    point : (3,) ndarray
        End M of the hinge line in the flat frame, m.
    axis : (3,) ndarray
        Unit vector from M to N; a positive rotation of ``body_b`` about it
        (right-hand rule) folds the hinge (theta 0 -> pi).
    length : float
        |MN|, m.
    facet : "top" or "bottom"
    k : float
        Stiffness of one spring, N m/rad (free at theta = 0).
    c : float
        Damping coefficient of one spring, N m s/rad.
    theta_stowed : float
        Angle in the stowed state, rad (pi folded, 0 for a hinge that stays flat).
    segments : tuple of ((row, col), (row, col))
        The cell-level hinges (collinear segments) that make up this hinge.
    springs : int
        Spring-loaded hinges acting in parallel on this line: one per cell
        segment, since merging panels joins them into one body but leaves
        each of its edge hinges (and their springs) in place. The hinge's
        torque law uses :attr:`k_hinge` and :attr:`c_hinge`.
    """

    name: str
    body_a: int
    body_b: int
    point: np.ndarray
    axis: np.ndarray
    length: float
    facet: str
    k: float
    c: float
    theta_stowed: float
    segments: tuple
    springs: int = 1

    def __post_init__(self):
        _freeze(self, point=(3,), axis=(3,))

    @property
    def end_n(self) -> np.ndarray:
        """End N of the hinge line in the flat frame, m."""
        return self.point + self.length * self.axis

    @property
    def k_hinge(self) -> float:
        """Torsional stiffness of the whole hinge, ``springs * k``, N m/rad."""
        return self.springs * self.k

    @property
    def c_hinge(self) -> float:
        """Damping of the whole hinge, ``springs * c``, N m s/rad."""
        return self.springs * self.c

    def reversed(self) -> Hinge:
        """The same hinge with the roles of the two bodies swapped."""
        return replace(self, body_a=self.body_b, body_b=self.body_a, point=self.end_n,
                       axis=-self.axis)


@dataclass(frozen=True)
class ClosureParameters:
    """How a cut hinge closes its loop.

    ``method`` "penalty" is the paper's Eq. (5): five zero-length springs and
    dampers (k_M, c_M at M along x, y, z; k_N, c_N at N along the two directions
    normal to the hinge axis), N/m and N s/m. "exact" keeps the five
    constraints exactly with Lagrange multipliers; the stiffnesses are unused.
    ``baumgarte`` is the constraint stabilisation time constant, s, and
    ``regularisation`` the relative Tikhonov term of the multiplier solve
    (used by "exact" only).
    """

    method: ClosureMethod = "penalty"
    k_M: float = 0.0
    c_M: float = 0.0
    k_N: float = 0.0
    c_N: float = 0.0
    baumgarte: float = 1e-3
    regularisation: float = 1e-10


@dataclass(frozen=True)
class AirParameters:
    """Still air around the array: quadratic pressure drag on the panel faces.

    ``density`` rho (kg/m^3; 0: no air, the paper's model) and
    ``drag_coefficient`` C_d (dimensionless) of the pressure ``p = -1/2 rho
    C_d |v_n| v_n`` on every point of a panel's large face, v_n the point's
    velocity along the face normal (m/s); see
    :func:`panel_deploy.dynamics.air.face_drag`.
    """

    density: float = 0.0
    drag_coefficient: float = 0.0

    def __post_init__(self):
        for name in ("density", "drag_coefficient"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0.0):  # negative drag would feed energy in
                raise ModelError(f"air.{name}: expected a finite number >= 0, got {value!r}")

    @property
    def pressure_coefficient(self) -> float:
        """1/2 rho C_d, kg/m^3: the pressure (Pa) per (m/s)^2 of normal velocity."""
        return 0.5 * self.density * self.drag_coefficient


@dataclass(frozen=True)
class Model:
    """Immutable multibody model: bodies, hinges, spanning tree, parameters.

    Build with :func:`Model.build`; its arrays are read-only.

    Attributes
    ----------
    bodies : tuple of Body
    hinges : tuple of Hinge
        Tree joints have ``body_a`` = parent.
    ground : int
        Index of the body fixed to the spacecraft/frame.
    joints : tuple of int
        Hinge index of each generalised coordinate, parents before children:
        ``theta[i]`` is the angle of ``hinges[joints[i]]``.
    parent : tuple of int
        Parent body of every body (-1 for the ground).
    body_joint : tuple of int
        Coordinate index of the joint that carries each body (-1 for the ground).
    order : tuple of int
        Bodies in tree order (ground first, every parent before its children).
    cut_hinges : tuple of int
        Hinges not in the spanning tree; each closes one loop.
    k_s, c_s : float
        Joint-limit contact stiffness (N m/rad) and damping (N m s/rad), Eq. (4).
    closure : ClosureParameters
    gravity : (3,) ndarray
        m/s^2 in the flat array frame (the ground panel's frame).
    collision_pairs : tuple of (int, int)
        Body pairs that share no hinge, i < j.
    name : str
        The scene's name ("" for a model built in code).
    hinge_groups : tuple of tuple of int
        Hinge indices that share one stiffness (the scene's ``hinges.groups``
        and mirror symmetry); empty: every hinge on its own.
    air : AirParameters
        Air drag on the panel faces (default: none).
    contact_pairs : tuple of (int, int)
        Unhinged body pairs near each other in the stowed stacks, i < j: the
        panel contacts of :mod:`panel_deploy.contacts` (default: none).
    k_p, c_p : float
        Normal stiffness (N/m) and damping (N s/m) of a panel contact: of
        a face pressed evenly on another.
    contact_pressure : bool
        How a panel contact's faces push: False (default), springs of k_p /
        4 and c_p / 4 at the corners of their overlap; True, a pressure in
        proportion to the depth over the overlap (k_p and c_p over the
        smaller face's area), continuous in the pose
        (:func:`panel_deploy.boxes.contact`).
    mu_p, friction_speed : float
        Coulomb friction coefficient of a panel contact (0, default: none)
        and the slip speed (m/s) below which its friction is viscous
        (:func:`~panel_deploy.dynamics.panel_contact.panel_contacts`).
    stop_ramp : float
        Depth past a joint limit (rad) over which k_s and c_s come in
        smoothly (:func:`~panel_deploy.dynamics.hinges.stop_engagement`);
        0 (default): at once, the paper's Eq. (4).
    """

    bodies: tuple
    hinges: tuple
    ground: int
    joints: tuple
    parent: tuple
    body_joint: tuple
    order: tuple
    cut_hinges: tuple
    k_s: float
    c_s: float
    closure: ClosureParameters
    gravity: np.ndarray
    collision_pairs: tuple
    name: str = ""
    hinge_groups: tuple = ()
    air: AirParameters = AirParameters()
    contact_pairs: tuple = ()
    k_p: float = 0.0
    c_p: float = 0.0
    contact_pressure: bool = False
    mu_p: float = 0.0
    friction_speed: float = 1.0e-3
    stop_ramp: float = 0.0

    def __post_init__(self):
        _freeze(self, gravity=(3,))

    @property
    def n_bodies(self) -> int:
        return len(self.bodies)

    @property
    def n_coords(self) -> int:
        """Number of generalised coordinates (tree joints)."""
        return len(self.joints)

    @property
    def theta_stowed(self) -> np.ndarray:
        """Stowed angle of every coordinate, rad, shape (n_coords,)."""
        return np.array([self.hinges[h].theta_stowed for h in self.joints])

    @property
    def stiffness(self) -> np.ndarray:
        """k of every hinge (one spring), N m/rad, shape (n_hinges,)."""
        return np.array([h.k for h in self.hinges])

    def with_stiffness(self, k, c=None) -> Model:
        """A copy with new hinge stiffnesses (and damping), shape (n_hinges,).

        Values are per spring, as :attr:`Hinge.k` and :attr:`Hinge.c`.

        Without ``c``, damping keeps each hinge's c/k ratio (Rayleigh damping,
        paper section 3.3); a hinge whose old k is 0 keeps its c.
        """
        k = np.asarray(k, dtype=float)
        if k.shape != (len(self.hinges),):
            raise ModelError(f"stiffness: expected shape ({len(self.hinges)},), got {k.shape}")
        if c is None:
            c = [h.c * (kk / h.k) if h.k > 0 else h.c for h, kk in zip(self.hinges, k)]
        c = np.asarray(c, dtype=float)
        hinges = tuple(replace(h, k=float(kk), c=float(cc)) for h, kk, cc in zip(self.hinges, k, c))
        return replace(self, hinges=hinges)

    @classmethod
    def build(cls, bodies, hinges, ground=0, *, cut_hinges=None, k_s=0.0, c_s=0.0,
              closure=ClosureParameters(), gravity=(0.0, 0.0, 0.0), name="", hinge_groups=(),
              air=AirParameters(), stop_ramp=0.0):
        """Build a model: spanning tree from the ground, cut hinges, collision pairs.

        Parameters
        ----------
        bodies : sequence of Body
        hinges : sequence of Hinge
            In any orientation; tree joints are re-oriented parent -> child.
        ground : int
        cut_hinges : sequence of int, optional
            Hinges to cut, one per independent loop. By default, for each loop
            the hinge farthest from the ground (breadth-first) is cut.
        k_s, c_s, closure, gravity, name, hinge_groups, air, stop_ramp
            See the class attributes.

        Raises
        ------
        ModelError
            If the hinge graph is disconnected, a cut hinge is not on a loop,
            the number of cuts does not match the number of loops, or
            ``stop_ramp`` is negative or not finite.
        """
        nb = len(bodies)
        if not (math.isfinite(stop_ramp) and stop_ramp >= 0.0):
            raise ModelError(f"stop_ramp: expected a finite depth >= 0 rad, got {stop_ramp!r}")
        if not 0 <= ground < nb:
            raise ModelError(f"ground: body index {ground} out of range 0..{nb - 1}")
        hinges = list(hinges)
        for i, h in enumerate(hinges):
            if not (0 <= h.body_a < nb and 0 <= h.body_b < nb) or h.body_a == h.body_b:
                raise ModelError(f"hinges[{i}] ({h.name}): bad bodies {h.body_a}, {h.body_b}")
        n_loops = len(hinges) - nb + 1
        tree = _bfs_tree(nb, hinges, ground, exclude=())
        if len(tree) != nb - 1:
            raise ModelError("hinges: the bodies are not all connected to the ground")
        if cut_hinges is None:
            # Breadth-first search reaches each loop from both sides at once, so the
            # hinge it leaves out is the one farthest from the ground, where the
            # paper places its cut hinge (Fig. 3b).
            in_tree = {i for i, _, _ in tree}
            cut_hinges = [i for i in range(len(hinges)) if i not in in_tree]
        cut_hinges = tuple(sorted(int(i) for i in cut_hinges))
        if len(cut_hinges) != n_loops:
            raise ModelError(f"closure.cut_hinges: {n_loops} loop(s) need {n_loops} cut(s), "
                             f"got {len(cut_hinges)}")
        tree = _bfs_tree(nb, hinges, ground, exclude=cut_hinges)
        if len(tree) != nb - 1:
            raise ModelError("closure.cut_hinges: cutting these hinges disconnects the array")

        parent = [-1] * nb
        body_joint = [-1] * nb
        order = [ground]
        joints = []
        for i, b, other in tree:
            if hinges[i].body_a != b:
                hinges[i] = hinges[i].reversed()
            parent[other] = b
            body_joint[other] = len(joints)
            joints.append(i)
            order.append(other)
        linked = {frozenset((h.body_a, h.body_b)) for h in hinges}
        pairs = tuple((i, j) for i in range(nb) for j in range(i + 1, nb)
                      if frozenset((i, j)) not in linked)
        return cls(tuple(bodies), tuple(hinges), ground, tuple(joints), tuple(parent),
                   tuple(body_joint), tuple(order), cut_hinges, float(k_s), float(c_s),
                   closure, gravity, pairs, str(name),
                   tuple(tuple(int(i) for i in g) for g in hinge_groups), air,
                   stop_ramp=float(stop_ramp))


def hinge_order(model: Model) -> list:
    """Hinge indices in report order: tree coordinates, then cut hinges (the
    order of ``/joint_states`` and of every per-hinge report)."""
    return list(model.joints) + list(model.cut_hinges)


def _bfs_tree(nb, hinges, ground, exclude):
    """Breadth-first spanning tree from the ground, skipping hinges in ``exclude``.

    Returns ``[(hinge, parent body, child body), ...]`` in visiting order; it
    has ``nb - 1`` entries exactly when every body is reached.
    """
    seen = {ground}
    tree = []
    queue = deque([ground])
    while queue:
        b = queue.popleft()
        for i, h in enumerate(hinges):
            if i in exclude or b not in (h.body_a, h.body_b):
                continue
            other = h.body_b if h.body_a == b else h.body_a
            if other not in seen:
                seen.add(other)
                tree.append((i, b, other))
                queue.append(other)
    return tree


@dataclass
class State:
    """Mutable state of one run: time, hinge angles and rates.

    Attributes
    ----------
    t : float
        s.
    theta : (n_coords,) ndarray
        rad, 0 flat, pi folded.
    omega : (n_coords,) ndarray
        rad/s.
    """

    t: float
    theta: np.ndarray
    omega: np.ndarray

    @classmethod
    def stowed(cls, model: Model) -> State:
        """The stowed state at rest, t = 0: the simulator's initial state."""
        return cls(0.0, model.theta_stowed.copy(), np.zeros(model.n_coords))

    @classmethod
    def flat(cls, model: Model) -> State:
        """The deployed (all angles 0) state at rest."""
        return cls(0.0, np.zeros(model.n_coords), np.zeros(model.n_coords))
