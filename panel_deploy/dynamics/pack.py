"""A :class:`~panel_deploy.model.Model` flattened into numpy arrays for the kernels.

Built once per model (like MuJoCo's compiled ``mjModel``). Indexing: body ``i``
(``0 <= i < n``) is the body carried by tree coordinate ``i`` (``theta[i]``);
index ``n`` is the ground. Coordinates come parents first, so ``parent[i] < i``
or ``parent[i] == n``. All vectors are in the flat array frame, SI units.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..model import Model

#: ``Packed.method`` values.
TREE, PENALTY, EXACT = 0, 1, 2


class Packed(NamedTuple):
    """Flat arrays of one model; see the module docstring for the indexing.

    Attributes
    ----------
    n : int
        Tree coordinates (non-ground bodies).
    body : (n + 1,) int64
        Model body index of each kernel body (ground last).
    parent : (n,) int64
        Parent body of each body (``n`` for the ground).
    axis, point : (n, 3) float
        Unit axis and end M of each tree hinge.
    r0 : (n + 1, 3) float
        Centroid of every body in the flat state, ground last, m.
    mass : (n,) float
        kg.
    inertia : (n, 3, 3) float
        About the centroid, body axes (= flat-frame axes), kg m^2.
    k, c : (n,) float
        Tree hinge spring (N m/rad) and damper (N m s/rad).
    cut_a, cut_b : (m,) int64
        Bodies of each cut hinge (``n`` for the ground); theta rotates b about a.
    cut_point, cut_axis : (m, 3) float
        End M and unit axis of each cut hinge, flat frame.
    cut_e1, cut_e2 : (m, 3) float
        Unit vectors normal to the cut axis (x_N, z_N of Eq. 5), flat frame,
        with ``e2 = axis x e1``.
    cut_length, cut_k, cut_c : (m,) float
    k_s, c_s : float
        Contact stiffness and damping, Eq. (4).
    stop_ramp : float
        rad past a limit over which k_s and c_s come in (0: at once, Eq. 4).
    method : int
        TREE (no cut hinge), PENALTY or EXACT.
    k_M, c_M, k_N, c_N : float
        Penalty springs and dampers, Eq. (5).
    baumgarte, regularisation : float
        Exact closure: stabilisation time constant (s), relative Tikhonov term.
    gravity : (3,) float
        m/s^2.
    has_gravity : bool
        False when gravity is zero, so the kernels skip all gravity work.
    air : (n, 3) float, or (0, 3) without air
        Per body: half length and half width of its large faces (m), and
        1/2 rho C_d (kg/m^3), the face pressure per (m/s)^2 of normal
        velocity.
    half : (n + 1, 3) float
        Half sizes of each body's box along its own axes, m (ground last).
    contact : (q, 13) float, q = 0 without panel contacts
        One row per pair of :attr:`Model.contact_pairs`: its bodies (kernel
        indices, as floats), their half edges (m, 3 + 3), k_p (N/m) and c_p
        (N s/m), of which each contact point takes its weight's share
        (:func:`panel_deploy.boxes.contact`), its friction coefficient mu_p
        and friction speed (m/s), and 1 where its faces push by a pressure
        over their overlap (``Model.contact_pressure``), else 0.

    ``air`` and ``contact`` have no rows, not None, when the model has none:
    numba types a None field and an array apart, and compiled every kernel
    that takes a Packed once for each kind of model (262 of the install's
    462 s of compiling went to the air and contact kinds).
    """

    n: int
    body: np.ndarray
    parent: np.ndarray
    axis: np.ndarray
    point: np.ndarray
    r0: np.ndarray
    mass: np.ndarray
    inertia: np.ndarray
    k: np.ndarray
    c: np.ndarray
    cut_a: np.ndarray
    cut_b: np.ndarray
    cut_point: np.ndarray
    cut_axis: np.ndarray
    cut_e1: np.ndarray
    cut_e2: np.ndarray
    cut_length: np.ndarray
    cut_k: np.ndarray
    cut_c: np.ndarray
    k_s: float
    c_s: float
    stop_ramp: float
    method: int
    k_M: float
    c_M: float
    k_N: float
    c_N: float
    baumgarte: float
    regularisation: float
    gravity: np.ndarray
    has_gravity: bool
    air: np.ndarray
    half: np.ndarray
    contact: np.ndarray


def _normal(axis):
    """A unit vector normal to ``axis``, as close to the panel plane as possible."""
    trial = np.array([0.0, 0.0, 1.0]) if abs(axis[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    e = trial - axis * (axis @ trial)
    return e / np.linalg.norm(e)


def _contact_rows(model: Model, index: dict) -> np.ndarray:
    """Packed.contact of ``model``."""
    if not model.contact_pairs:
        return np.zeros((0, 13))
    # whole columns, not a list per pair: a 10 x 10 array has 3569 pairs,
    # which pair by pair took 30 ms of every run's set-up
    a, b = np.array(model.contact_pairs).T
    half = 0.5 * np.array([body.size for body in model.bodies])
    kernel = np.array([index[i] for i in range(len(model.bodies))])
    k = np.full((len(a), 5), [model.k_p, model.c_p, model.mu_p, model.friction_speed,
                              float(model.contact_pressure)])
    return np.column_stack([kernel[a], kernel[b], half[a], half[b], k]).astype(float)


def pack(model: Model) -> Packed:
    """Flatten ``model`` into a :class:`Packed` for the compiled kernels."""
    n = model.n_coords
    body_of = [0] * n
    for b, i in enumerate(model.body_joint):
        if i >= 0:
            body_of[i] = b
    index = {b: i for i, b in enumerate(body_of)}
    index[model.ground] = n
    tree = [model.hinges[h] for h in model.joints]
    cuts = [model.hinges[h] for h in model.cut_hinges]
    f3 = lambda rows: np.array(rows, dtype=float).reshape(-1, 3)  # noqa: E731
    cut_axis = f3([h.axis for h in cuts])
    cut_e1 = f3([_normal(a) for a in cut_axis])
    cut_e2 = f3([np.cross(a, e) for a, e in zip(cut_axis, cut_e1)])
    cl = model.closure
    method = TREE if not cuts else (PENALTY if cl.method == "penalty" else EXACT)
    gravity = np.array(model.gravity, dtype=float)  # a writable copy: numba types read-only arrays apart
    drag = float(model.air.pressure_coefficient)
    return Packed(
        n=n,
        body=np.array(body_of + [model.ground], dtype=np.int64),
        parent=np.array([index[model.parent[b]] for b in body_of], dtype=np.int64),
        axis=f3([h.axis for h in tree]),
        point=f3([h.point for h in tree]),
        r0=f3([model.bodies[b].flat_position for b in body_of]
              + [model.bodies[model.ground].flat_position]),
        mass=np.array([model.bodies[b].mass for b in body_of], dtype=float),
        inertia=np.array([model.bodies[b].inertia for b in body_of], dtype=float).reshape(n, 3, 3),
        k=np.array([h.k_hinge for h in tree], dtype=float),
        c=np.array([h.c_hinge for h in tree], dtype=float),
        cut_a=np.array([index[h.body_a] for h in cuts], dtype=np.int64),
        cut_b=np.array([index[h.body_b] for h in cuts], dtype=np.int64),
        cut_point=f3([h.point for h in cuts]),
        cut_axis=cut_axis,
        cut_e1=cut_e1,
        cut_e2=cut_e2,
        cut_length=np.array([h.length for h in cuts], dtype=float),
        cut_k=np.array([h.k_hinge for h in cuts], dtype=float),
        cut_c=np.array([h.c_hinge for h in cuts], dtype=float),
        k_s=float(model.k_s),
        c_s=float(model.c_s),
        stop_ramp=float(model.stop_ramp),
        method=method,
        k_M=float(cl.k_M), c_M=float(cl.c_M), k_N=float(cl.k_N), c_N=float(cl.c_N),
        baumgarte=float(cl.baumgarte),
        regularisation=float(cl.regularisation),
        gravity=gravity,
        has_gravity=bool(np.any(gravity != 0.0)),
        air=np.array([[*(0.5 * model.bodies[b].size[:2]), drag] for b in body_of],
                     dtype=float).reshape(n, 3) if drag > 0.0 else np.zeros((0, 3)),
        half=f3([0.5 * model.bodies[b].size for b in body_of + [model.ground]]),
        contact=_contact_rows(model, index),
    )

