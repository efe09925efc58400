"""The frames of the ROS contract as numbers: every tree joint's child link in its
parent link (what ``/tf`` carries), ``world`` to the ground link (``/tf_static``),
and rotation matrices as quaternions. Every ``/tf`` this package sends or
records, live or in a file, is built from :func:`tree_transforms`."""

from __future__ import annotations

import numpy as np

from .export.urdf import link_poses


def quaternions(R) -> np.ndarray:
    """Unit quaternions (x, y, z, w) of rotation matrices ``R`` (k, 3, 3), w >= 0.

    Shepperd's method: each quaternion is computed from its largest
    component, so there is no division by a small number.
    """
    R = np.asarray(R, dtype=float)
    m00, m11, m22 = R[:, 0, 0], R[:, 1, 1], R[:, 2, 2]
    # 4 x^2, 4 y^2, 4 z^2, 4 w^2
    d = np.stack([1 + m00 - m11 - m22, 1 - m00 + m11 - m22, 1 - m00 - m11 + m22,
                  1 + m00 + m11 + m22], axis=1)
    big = np.argmax(d, axis=1)
    s = 2 * np.sqrt(d[np.arange(len(R)), big])  # 4 times the largest component
    yz, xz, xy = R[:, 1, 2] + R[:, 2, 1], R[:, 0, 2] + R[:, 2, 0], R[:, 0, 1] + R[:, 1, 0]
    wx, wy, wz = R[:, 2, 1] - R[:, 1, 2], R[:, 0, 2] - R[:, 2, 0], R[:, 1, 0] - R[:, 0, 1]
    quarter = s * s / 4
    # Row j: 4 * the largest component times (x, y, z, w), if component j is the largest.
    candidates = np.array([[quarter, xy, xz, wx], [xy, quarter, yz, wy],
                           [xz, yz, quarter, wz], [wx, wy, wz, quarter]])  # (4, 4, k)
    q = candidates[big, :, np.arange(len(R))] / s[:, None]
    return q * np.where(q[:, 3:] < 0, -1.0, 1.0)


def tree_transforms(model, rotation, position):
    """Every tree joint's child link in its parent link's frame, as
    robot_state_publisher would broadcast them (frames = URDF link names).

    ``rotation`` (..., nb, 3, 3) and ``position`` (..., nb, 3, m) are the body
    (centroid) poses in ``world`` (leading axes: samples). Returns ``(parent,
    child, R, p)``: body indices (k,), rotations (..., k, 3, 3) and
    translations (..., k, 3, m), in ``model.joints`` order.
    The recordings' ``/tf`` and the dynamics node's are made of these.
    """
    R, p = link_poses(model, rotation, position)
    pairs = [(model.hinges[h].body_a, model.hinges[h].body_b) for h in model.joints]
    a, b = np.array(pairs).T
    Ra = R[..., a, :, :]
    R_rel = np.einsum("...kji,...kjl->...kil", Ra, R[..., b, :, :])        # R_a^T R_b
    p_rel = np.einsum("...kji,...kj->...ki", Ra, p[..., b, :] - p[..., a, :])  # R_a^T (p_b - p_a)
    return a, b, R_rel, p_rel


def ground_transform(model):
    """``world`` -> the ground body's link (the URDF's fixed joint): ``(R, p)``."""
    g = model.ground
    R, p = link_poses(model, np.eye(3)[None].repeat(model.n_bodies, 0),
                      np.array([b.flat_position for b in model.bodies]))
    return R[g], p[g]
