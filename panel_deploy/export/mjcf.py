"""Export a :class:`~panel_deploy.model.Model` as MuJoCo MJCF, the peer simulator.

The MJCF model is the same multibody system, written so that MuJoCo's
``qpos`` of every hinge joint *is* the paper's theta:

* The body tree is the model's spanning tree, written in the FLAT
  configuration (theta = 0), so MuJoCo's joint angle 0 is the flat pose and
  a positive joint rotation about ``Hinge.axis`` folds the hinge, exactly as
  theta does. The keyframe ``stowed`` holds the stowed angles, the model's
  initial state (``mujoco.mj_resetDataKeyframe(m, d, 0)``).
* Every panel is a box geom (size = half extents) with its mass and inertia
  given explicitly by ``<inertial fullinertia=...>`` (``Body.inertia`` about
  the centroid, body axes); geoms carry no mass and have
  ``contype = conaffinity = 0``: panel collisions are detected separately,
  as in the paper, and only the panel contacts below act.
* Tree hinges carry the paper's Eq. (2) spring and damper through MuJoCo's
  joint ``stiffness = k`` with ``springref = 0`` and ``damping = c``
  (``armature = frictionloss = 0``).
* Joint limits 0..pi stand for the contact torques of Eq. (3)-(4). MuJoCo
  has no piecewise spring, so they are soft limit constraints with direct
  stiffness and damping (negative ``solref``) and impedance near 1. MuJoCo
  drives a constraint row's acceleration to ``-B v - K r``; a torsional
  penalty ``-k_s r - c_s v`` on a joint whose inverse effective inertia is
  ``A = (M^-1)_ii`` produces ``-A k_s r - A c_s v``. So ``K = A k_s`` and
  ``B = A c_s`` with A evaluated at the stowed state: the same stiffness and
  damping as the paper's for the isolated row at the start, approximate once
  the inertia changes. MuJoCo limits only push, while the paper's damper
  also pulls while a hinge leaves the limit.
* Panel contacts (``Model.contact_pairs``, the unhinged panels touching in
  the stowed stacks) are contact pairs of the two box geoms, frictionless
  (``condim="1"``) or with sliding friction mu_p (``condim="3"``; MuJoCo's
  friction sticks, ours creeps below ``friction_speed``), with (k_p, c_p) mapped to direct stiffness and damping by
  the same rule, the inverse effective mass of the relative motion along
  the contact normal at the middle of the touching region, stowed state.
  MuJoCo's box-box collider makes up to 8 contact points of a pair, each
  with that solref, where ours pushes at one point (:mod:`panel_deploy.boxes`):
  the two agree on where a contact acts and when it starts, less on how
  deep a press goes. Pairs not listed there (and every other geom pair)
  do not collide in MuJoCo, as in our model.
* A cut hinge closes its loop with two ``<connect>`` equalities, at M and at
  N, between sites on the two bodies. They make six rows for the paper's five
  penalty springs (Eq. 5): the sixth, along the hinge axis, repeats the one
  at M; MuJoCo's soft constraints tolerate that redundancy. Their ``solref``
  maps (k_M, c_M) and (k_N, c_N) to direct stiffness/damping with the mean
  diagonal of the constraint's inverse effective mass ``J M^-1 J^T`` at the
  stowed state, the same rule as the limits.
* A cut hinge's own torsional spring and damper (the paper keeps them) act
  through a ``<general>`` actuator with a site transmission: site at M on
  ``body_b`` measured against a reference site on ``body_a`` turned by pi/2
  about the hinge axis, so MuJoCo's rotation length ``theta - pi/2`` stays
  inside (-pi, pi] over the whole 0..pi range; the affine bias is
  ``-k (length + pi/2) - c velocity``. The cut hinge's contact limit is not
  modelled (the other hinges of its loop carry theirs).
* Air drag (``Model.air``) maps to MuJoCo's default fluid model, the
  inertia-box model: ``<option density="rho C_d" viscosity="0">`` and no
  geom fluid settings. Its box is the body's equivalent inertia box, here
  the panel itself (the explicit box inertia). MuJoCo's quadratic drag has
  C_d fixed at 1 (force ``-1/2 rho A |v_n| v_n`` on a face moving along its
  normal), so ``density`` carries rho C_d. The two models agree for a panel
  translating along its normal and (but for the edges) one spinning about a
  centroidal in-plane axis. They differ otherwise: MuJoCo adds a drag of the
  centroid's velocity and one of the spin, each on its own, where ours
  integrates the pressure of each face point's own normal velocity; for a
  panel swinging about a hinge on its edge that gives 5/64 rho C_d w L^4
  omega |omega| (centroid drag times its lever, plus the spin term) against
  our 1/8, 37.5 % less. MuJoCo also drags the edge faces (t/a of the face
  area: 5 % for the paper's panels) and resists a spin about the face
  normal, both of which we leave out.

Units are SI throughout, angles in radians.
"""

from __future__ import annotations

import math
import re
from xml.sax.saxutils import quoteattr

import numpy as np

from ..errors import ModelError
from ..contacts import TOUCHING, aligned_overlap, touching_region
from ..kinematics import forward_kinematics
from ..model import Model

_NON_FINITE = re.compile(r"(?<![\w.])-?(nan|inf)(?![\w.])")

#: MuJoCo's largest constraint impedance (mjMAXIMP): the constraint is then
#: as hard as its solref says, with 1e-4 of the unconstrained acceleration leaking.
IMPEDANCE = 0.9999


def _f(x) -> str:
    return repr(float(x))


def _vec(v) -> str:
    return " ".join(_f(x) for x in v)


def _name(text: str) -> str:
    return quoteattr(str(text))


def _children(model: Model):
    children = [[] for _ in model.bodies]
    for b in model.order[1:]:
        children[model.parent[b]].append(b)
    return children


def qpos_index(model: Model) -> np.ndarray:
    """Where each coordinate sits in MuJoCo's ``qpos`` of :func:`export_mjcf`'s model.

    MuJoCo numbers joints depth first in the order the XML writes them, the
    model breadth first; ``qpos[qpos_index(model)]`` is theta, shape (n_coords,).
    """
    children = _children(model)
    index = np.empty(model.n_coords, dtype=int)
    stack = list(reversed(children[model.ground]))
    k = 0
    while stack:
        b = stack.pop()
        index[model.body_joint[b]] = k
        k += 1
        stack.extend(reversed(children[b]))
    return index


def mass_matrix(model: Model, theta) -> tuple[np.ndarray, list, list]:
    """Joint-space mass matrix of the open tree and the body Jacobians.

    Returns ``(M, Jv, Jw)``: M (n, n) in kg m^2, and per body the centroid
    linear Jacobian (3, n) and angular Jacobian (3, n) in the ground frame.
    Used here to map penalty stiffnesses onto MuJoCo's acceleration-level
    constraint parameters.
    """
    n = model.n_coords
    R, p = forward_kinematics(model, theta)
    axis_w = np.zeros((n, 3))
    anchor_w = np.zeros((n, 3))
    for i, h_index in enumerate(model.joints):
        h = model.hinges[h_index]
        a = h.body_a
        axis_w[i] = R[a] @ h.axis
        anchor_w[i] = p[a] + R[a] @ (h.point - model.bodies[a].flat_position)
    M = np.zeros((n, n))
    Jv, Jw = [], []
    for b, body in enumerate(model.bodies):
        jv = np.zeros((3, n))
        jw = np.zeros((3, n))
        node = b
        while model.parent[node] >= 0:
            i = model.body_joint[node]
            jw[:, i] = axis_w[i]
            jv[:, i] = np.cross(axis_w[i], p[b] - anchor_w[i])
            node = model.parent[node]
        inertia_w = R[b] @ body.inertia @ R[b].T
        M += body.mass * jv.T @ jv + jw.T @ inertia_w @ jw
        Jv.append(jv)
        Jw.append(jw)
    return M, Jv, Jw


def _point_jacobian(model, theta, Jv, Jw, body, point_flat):
    """Jacobian (3, n) of a point fixed in ``body`` (given in the flat frame)."""
    R, p = forward_kinematics(model, theta)
    r = R[body] @ (point_flat - model.bodies[body].flat_position)
    skew = np.array([[0, -r[2], r[1]], [r[2], 0, -r[0]], [-r[1], r[0], 0]])
    return Jv[body] - skew @ Jw[body]


def solref_parameters(model: Model) -> dict:
    """Direct MuJoCo solref (K, B) of every limit and closure, see the module doc.

    Returns a dict: ``"limit"`` -> (n_coords, 2) array of (K, B) per coordinate
    in 1/s^2 and 1/s; ``("connect", h, "M")`` / ``("connect", h, "N")`` ->
    (K, B) for cut hinge ``h``; ``("contact", a, b)`` -> (K, B) of the panel
    contact of bodies a and b. All evaluated at the stowed state.
    """
    theta = model.theta_stowed
    M, Jv, Jw = mass_matrix(model, theta)
    Minv = np.linalg.inv(M)
    out = {"limit": np.column_stack([np.diag(Minv) * model.k_s, np.diag(Minv) * model.c_s])}
    cl = model.closure
    for h_index in model.cut_hinges:
        h = model.hinges[h_index]
        for end, point, k, c in (("M", h.point, cl.k_M, cl.c_M), ("N", h.end_n, cl.k_N, cl.c_N)):
            J = (_point_jacobian(model, theta, Jv, Jw, h.body_b, point)
                 - _point_jacobian(model, theta, Jv, Jw, h.body_a, point))
            a = float(np.trace(J @ Minv @ J.T)) / 3.0
            out[("connect", h_index, end)] = (a * k, a * c)
    R, p = forward_kinematics(model, theta)
    for a, b in model.contact_pairs:
        region = touching_region(model, R, p, a, b, math.inf)  # a contact pair: it is near
        if region is None:  # pressed into each other when stowed: normal along the least overlap
            lo, hi = aligned_overlap(model, R, p, a, b)
            normals = np.eye(3)[[np.argmin(hi - lo)]]
        else:
            lo, hi = region
            normals = np.eye(3)[hi - lo <= TOUCHING]
        point = 0.5 * (lo + hi)
        J = (_point_jacobian(model, theta, Jv, Jw, b, _flat(model, R, p, b, point))
             - _point_jacobian(model, theta, Jv, Jw, a, _flat(model, R, p, a, point)))
        inverse_mass = float(np.mean([n @ J @ Minv @ J.T @ n for n in normals]))
        out[("contact", a, b)] = (inverse_mass * model.k_p, inverse_mass * model.c_p)
    return out


def _flat(model: Model, R, p, body: int, x):
    """Where body's material point at x (poses R, p) sits in the flat state, m."""
    return model.bodies[body].flat_position + R[body].T @ (x - p[body])


def _axis_quat(axis, angle):
    half = 0.5 * angle
    return np.concatenate([[math.cos(half)], math.sin(half) * np.asarray(axis, dtype=float)])


def export_mjcf(model: Model, *, timestep: float = 1e-5, integrator: str = "RK4") -> str:
    """The model as an MJCF document (a string), see the module doc.

    Raises :class:`~panel_deploy.errors.ModelError` if the model's numbers
    cannot make a valid document (a singular mass matrix, a NaN or inf from
    degenerate panels): an MJCF with ``nan`` in it is never returned.

    Parameters
    ----------
    model : Model
    timestep : float
        ``<option timestep>``, s. Only used when MuJoCo integrates.
    integrator : str
        ``<option integrator>``: Euler, RK4, implicit or implicitfast.

    Returns
    -------
    str
        MJCF XML. Joint names are the hinge names, body names the body names;
        :func:`qpos_index` maps coordinates to ``qpos``.
    """
    try:
        with np.errstate(all="ignore"):
            text = _document(model, timestep, integrator)
    except (np.linalg.LinAlgError, ZeroDivisionError, FloatingPointError) as e:
        raise ModelError(f"export: the model's mass matrix cannot be used ({e}): check the "
                         "array sizes and masses") from None
    bad = _NON_FINITE.search(text)
    if bad:
        line = text.count("\n", 0, bad.start()) + 1
        raise ModelError(f"export: the model has a non-finite value ({bad.group(0)} on line {line} "
                         "of the MJCF): check the array sizes and masses (degenerate panels?)")
    return text


def _fluid(model: Model) -> str:
    """The ``<option>`` attributes of the air (see the module doc), or "" without air."""
    q = 2.0 * model.air.pressure_coefficient  # rho C_d
    return f' density="{_f(q)}" viscosity="0"' if q > 0 else ""


def _document(model: Model, timestep: float, integrator: str) -> str:
    children = _children(model)
    solref = solref_parameters(model)
    imp = f'"{IMPEDANCE} {IMPEDANCE} 0.001 0.5 2"'
    lines = [
        f"<mujoco model={_name(model.name or 'panel_array')}>",
        '  <compiler angle="radian" autolimits="true" inertiafromgeom="false"/>',
        f'  <option gravity="{_vec(model.gravity)}" timestep="{_f(timestep)}" '
        f'integrator="{integrator}"{_fluid(model)}/>',
        '  <default><geom contype="0" conaffinity="0" mass="0"/></default>',
        "  <worldbody>",
    ]
    cut_sites = {}
    for h_index in model.cut_hinges:
        h = model.hinges[h_index]
        cut_sites.setdefault(h.body_a, []).append((h_index, "a"))
        cut_sites.setdefault(h.body_b, []).append((h_index, "b"))

    def body_xml(b, indent):
        body = model.bodies[b]
        pad = " " * indent
        parent = model.parent[b]
        offset = body.flat_position - (model.bodies[parent].flat_position if parent >= 0 else 0.0)
        lines.append(f"{pad}<body name={_name(body.name)} pos=\"{_vec(offset)}\">")
        I = body.inertia
        lines.append(f'{pad}  <inertial pos="0 0 0" mass="{_f(body.mass)}" fullinertia="'
                     f'{_vec([I[0, 0], I[1, 1], I[2, 2], I[0, 1], I[0, 2], I[1, 2]])}"/>')
        if parent >= 0:
            i = model.body_joint[b]
            h = model.hinges[model.joints[i]]
            K, B = solref["limit"][i]
            lines.append(
                f"{pad}  <joint name={_name(h.name)} type=\"hinge\" "
                f'pos="{_vec(h.point - body.flat_position)}" axis="{_vec(h.axis)}" '
                f'stiffness="{_f(h.k_hinge)}" springref="0" damping="{_f(h.c_hinge)}" armature="0" '
                f'frictionloss="0" range="0 {_f(math.pi)}" '
                f'solreflimit="{_f(-K)} {_f(-B)}" solimplimit={imp}/>')
        lines.append(f'{pad}  <geom name={_name(body.name)} type="box" size="{_vec(0.5 * body.size)}"/>')
        for h_index, side in cut_sites.get(b, ()):
            h = model.hinges[h_index]
            # the side-a site doubles as the actuator's reference, turned by pi/2
            quat = _axis_quat(h.axis, 0.5 * math.pi) if side == "a" else np.array([1.0, 0, 0, 0])
            for end, point in (("M", h.point), ("N", h.end_n)):
                lines.append(f"{pad}  <site name={_name(f'{h.name}_{end}_{side}')} "
                             f'pos="{_vec(point - body.flat_position)}" quat="{_vec(quat)}"/>')
        for child in children[b]:
            body_xml(child, indent + 2)
        lines.append(f"{pad}</body>")

    body_xml(model.ground, 4)
    lines.append("  </worldbody>")
    if model.cut_hinges:
        lines.append("  <equality>")
        for h_index in model.cut_hinges:
            h = model.hinges[h_index]
            for end in ("M", "N"):
                K, B = solref[("connect", h_index, end)]
                lines.append(f"    <connect name={_name(f'{h.name}_{end}')} "
                             f"site1={_name(f'{h.name}_{end}_a')} site2={_name(f'{h.name}_{end}_b')} "
                             f'solref="{_f(-K)} {_f(-B)}" solimp={imp}/>')
        lines.append("  </equality>")
        lines.append("  <actuator>")
        for h_index in model.cut_hinges:
            h = model.hinges[h_index]
            lines.append(f"    <general name={_name(f'{h.name}_spring')} "
                         f"site={_name(f'{h.name}_M_b')} refsite={_name(f'{h.name}_M_a')} "
                         f'gear="0 0 0 {_vec(h.axis)}" gainprm="0" biastype="affine" '
                         f'biasprm="{_f(-0.5 * math.pi * h.k_hinge)} {_f(-h.k_hinge)} {_f(-h.c_hinge)}"/>')
        lines.append("  </actuator>")
    if model.contact_pairs:
        lines.append("  <contact>")
        # MuJoCo's sliding friction (its pyramid's two directions; spin and roll at its defaults)
        friction = (f'condim="3" friction="{_f(model.mu_p)} {_f(model.mu_p)} 0.005 0.0001 0.0001" '
                    if model.mu_p > 0 else 'condim="1" ')
        for a, b in model.contact_pairs:
            K, B = solref[("contact", a, b)]
            lines.append(f"    <pair geom1={_name(model.bodies[a].name)} geom2={_name(model.bodies[b].name)} "
                         f'{friction}solref="{_f(-K)} {_f(-B)}" solimp={imp}/>')
        lines.append("  </contact>")
    qpos = np.empty(model.n_coords)
    qpos[qpos_index(model)] = model.theta_stowed
    lines.append("  <keyframe>")
    lines.append(f'    <key name="stowed" qpos="{_vec(qpos)}"/>')
    lines.append("  </keyframe>")
    lines.append("</mujoco>")
    return "\n".join(lines) + "\n"
