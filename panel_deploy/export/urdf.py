"""Export a :class:`~panel_deploy.model.Model` as URDF, for ``/robot_description``.

The URDF is the model's spanning tree for display (robot_state_publisher,
rerun, Foxglove); the joint angle of every revolute joint *is* the paper's
theta, with the sign convention of :func:`panel_deploy.kinematics.forward_kinematics`.

Links and frames
----------------
* ``world`` is the model's ground frame, the flat array frame of
  :mod:`panel_deploy.model` (x along the columns, y towards row 1, z out of
  the top facet), in m.
* One link per body, named exactly ``Body.name`` (e.g. ``r1c2+r1c3``). Every
  link frame has the body's orientation (parallel to the flat array frame
  when theta = 0, like the model's body frames), but not every link frame
  sits at the centroid:

  - the ground body's link frame is at its centroid; a fixed joint
    ``world_to_<ground name>`` puts it at ``flat_position`` in ``world``;
  - every other body's link frame sits on the hinge line of the tree joint
    that carries it, at that hinge's end M (``Hinge.point``): a URDF
    revolute joint turns its child about the joint frame's origin, and the
    child link frame *is* the joint frame, so it has to lie on the axis.

  :func:`link_origin` gives each link frame's origin in the flat frame when
  theta = 0, and :func:`link_poses` turns the model's centroid poses into
  link-frame poses in ``world``: a /tf publisher that broadcasts those under
  the link names agrees with robot_state_publisher fed the same angles.
* Each link carries a box ``<visual>`` and ``<collision>`` of the body's
  true size (``Body.size``, thickness included) and an ``<inertial>`` with
  ``Body.mass`` and ``Body.inertia`` (about the centroid, body axes); all
  three have ``origin xyz`` = centroid minus link origin (zero for the
  ground) and ``rpy`` 0, so the box is centred on the centroid.

Joints
------
* One ``revolute`` joint per tree hinge, in coordinate order
  (``Model.joints``), named exactly ``Hinge.name``; parent = the link of
  ``Hinge.body_a``, child = that of ``Hinge.body_b``. Its ``origin xyz`` is
  the hinge point M in the parent link frame (``rpy`` 0) and its ``axis`` is
  ``Hinge.axis`` (the parent's and child's axes are parallel to the flat
  frame at theta = 0), so the child's rotation is
  ``R_parent @ axis_rotation(axis, theta)``: positive theta folds, 0 is flat.
* ``<limit lower="0" upper="pi">`` is the hinge's range (the contact stops of
  Eq. 3-4). URDF requires ``effort`` and ``velocity`` for a revolute joint;
  nothing enforces them here (the hinges are driven by springs, not motors).
  ``effort`` is the hinge's largest spring torque ``Hinge.k_hinge * pi``
  (N m; the contact stops can exceed it briefly) and ``velocity`` is
  :data:`VELOCITY_LIMIT` (rad/s), a nominal bound, not a property of the model.
* Each cut hinge (``Model.cut_hinges``) closes a kinematic loop, which a URDF
  tree cannot hold: it is not a joint, only an XML comment that names it,
  its two bodies and its line, and says that its angle is still published in
  ``/joint_states``.

Numbers are written with ``repr`` (shortest exact round trip), so a parser
recovers the model's floats exactly; the output depends only on the model.
SI units, angles in radians.
"""

from __future__ import annotations

import math

import numpy as np

from ..contract import WORLD
from ..model import Model
from .mjcf import _f, _name, _vec

#: ``velocity`` attribute of every revolute joint, rad/s. URDF requires one;
#: it is a nominal display value, far above the hinge rates of a deployment,
#: and nothing enforces it.
VELOCITY_LIMIT = 100.0


#: rgba of the ground panel and of the other panels.
GROUND_RGBA = (0.85, 0.55, 0.2, 1.0)
PANEL_RGBA = (0.25, 0.45, 0.8, 1.0)


def robot_name(model: Model) -> str:
    """The URDF robot name: the scene name, or ``panel_array`` without one."""
    return model.name or "panel_array"


def link_origin(model: Model) -> np.ndarray:
    """Origin of every body's URDF link frame in the flat frame at theta = 0, (nb, 3), m.

    The ground body's centroid (``flat_position``); for every other body the
    end M (``Hinge.point``) of the tree hinge that carries it.
    """
    origin = np.array([b.flat_position for b in model.bodies], dtype=float).reshape(-1, 3)
    for b in model.order[1:]:
        origin[b] = model.hinges[model.joints[model.body_joint[b]]].point
    return origin


def link_poses(model: Model, rotation, position) -> tuple[np.ndarray, np.ndarray]:
    """URDF link-frame poses in ``world`` from the model's body (centroid) poses.

    Parameters
    ----------
    model : Model
    rotation : (nb, 3, 3) array_like
        Body rotations in the ground frame, as returned by
        :func:`~panel_deploy.kinematics.forward_kinematics` (or
        ``SimulationResult.rotation`` at one sample).
    position : (nb, 3) array_like
        Body centroids in the ground frame, m.

    Returns
    -------
    R_links : (nb, 3, 3) ndarray
        Rotation of link ``model.bodies[i].name`` in ``world``: the body's own
        rotation (link frames and body frames are parallel).
    p_links : (nb, 3) ndarray
        Origin of that link frame in ``world``, m:
        ``position + rotation @ (link_origin - flat_position)``.
    """
    R = np.array(rotation, dtype=float)
    p = np.asarray(position, dtype=float)
    flat = np.array([b.flat_position for b in model.bodies], dtype=float).reshape(-1, 3)
    offset = link_origin(model) - flat
    return R, p + np.einsum("...bij,bj->...bi", R, offset)


def _comment(text: str) -> str:
    # "--" may not occur inside an XML comment, nor "-" right before its end.
    while "--" in text:
        text = text.replace("--", "- -")
    return f"<!-- {text} -->"


def _rgba(v) -> str:
    return " ".join(repr(float(x)) for x in v)


def model_urdf(model: Model) -> str:
    """The model as a URDF document (a string), see the module doc.

    Returns
    -------
    str
        URDF XML: link ``world``, one link per body (``Body.name``), a fixed
        joint from ``world`` to the ground body and one revolute joint per tree
        hinge (``Hinge.name``) whose angle is theta; cut hinges appear as
        comments only. :func:`link_poses` gives the link-frame poses.
    """
    origin = link_origin(model)
    ground = model.bodies[model.ground]
    lines = [
        '<?xml version="1.0"?>',
        f"<robot name={_name(robot_name(model))}>",
        _comment("Generated by panel_deploy.export.urdf from the frozen Model: SI units, "
                 "radians. world = the flat array frame; joint angle = theta "
                 "(0 flat, pi folded)."),
        f'  <material name="ground_panel"><color rgba="{_rgba(GROUND_RGBA)}"/></material>',
        f'  <material name="panel"><color rgba="{_rgba(PANEL_RGBA)}"/></material>',
        f"  <link name={_name(WORLD)}/>",
    ]
    for b, body in enumerate(model.bodies):
        centre = _vec(body.flat_position - origin[b])
        box = f'<box size="{_vec(body.size)}"/>'
        material = "ground_panel" if b == model.ground else "panel"
        I = body.inertia
        lines += [
            f"  <link name={_name(body.name)}>",
            "    <inertial>",
            f'      <origin xyz="{centre}" rpy="0 0 0"/>',
            f'      <mass value="{_f(body.mass)}"/>',
            f'      <inertia ixx="{_f(I[0, 0])}" ixy="{_f(I[0, 1])}" ixz="{_f(I[0, 2])}" '
            f'iyy="{_f(I[1, 1])}" iyz="{_f(I[1, 2])}" izz="{_f(I[2, 2])}"/>',
            "    </inertial>",
            "    <visual>",
            f'      <origin xyz="{centre}" rpy="0 0 0"/>',
            f"      <geometry>{box}</geometry>",
            f'      <material name="{material}"/>',
            "    </visual>",
            "    <collision>",
            f'      <origin xyz="{centre}" rpy="0 0 0"/>',
            f"      <geometry>{box}</geometry>",
            "    </collision>",
            "  </link>",
        ]
    lines += [
        f"  <joint name={_name(f'{WORLD}_to_{ground.name}')} type=\"fixed\">",
        f"    <parent link={_name(WORLD)}/>",
        f"    <child link={_name(ground.name)}/>",
        f'    <origin xyz="{_vec(origin[model.ground])}" rpy="0 0 0"/>',
        "  </joint>",
    ]
    for h_index in model.joints:
        h = model.hinges[h_index]
        lines += [
            f"  <joint name={_name(h.name)} type=\"revolute\">",
            f"    <parent link={_name(model.bodies[h.body_a].name)}/>",
            f"    <child link={_name(model.bodies[h.body_b].name)}/>",
            f'    <origin xyz="{_vec(h.point - origin[h.body_a])}" rpy="0 0 0"/>',
            f'    <axis xyz="{_vec(h.axis)}"/>',
            f'    <limit lower="0.0" upper="{_f(math.pi)}" effort="{_f(h.k_hinge * math.pi)}" '
            f'velocity="{_f(VELOCITY_LIMIT)}"/>',
            "  </joint>",
        ]
    for h_index in model.cut_hinges:
        h = model.hinges[h_index]
        a, b = model.bodies[h.body_a].name, model.bodies[h.body_b].name
        lines.append("  " + _comment(
            f'cut hinge "{h.name}" between links "{a}" and "{b}" (axis {_vec(h.axis)} '
            f"through {_vec(h.point)} in world when flat): it closes a kinematic loop, "
            f"which URDF cannot hold, so it is not a joint here; its angle is still "
            f"published in /joint_states."))
    lines.append("</robot>")
    return "\n".join(lines) + "\n"
