"""Forward kinematics of the hinge tree (plain numpy; the reference the compiled
dynamics kernels are tested against).

All quantities are in the ground frame (the flat array frame), SI units.
"""

from __future__ import annotations

import numpy as np

from .model import Model


def axis_rotation(axis, angle):
    """Rotation matrix (3, 3) by ``angle`` (rad) about the unit vector ``axis``."""
    x, y, z = axis
    c, s = np.cos(angle), np.sin(angle)
    C = 1.0 - c
    return np.array([[c + x * x * C, x * y * C - z * s, x * z * C + y * s],
                     [y * x * C + z * s, c + y * y * C, y * z * C - x * s],
                     [z * x * C - y * s, z * y * C + x * s, c + z * z * C]])


def forward_kinematics(model: Model, theta, omega=None):
    """Poses (and velocities) of every body for hinge angles ``theta``.

    Parameters
    ----------
    model : Model
    theta : (n_coords,) array_like
        Hinge angles, rad.
    omega : (n_coords,) array_like, optional
        Hinge rates, rad/s.

    Returns
    -------
    rotation : (nb, 3, 3) ndarray
    position : (nb, 3) ndarray
        Centroids, m.
    linear_velocity, angular_velocity : (nb, 3) ndarray
        Only when ``omega`` is given: centroid velocity (m/s) and angular
        velocity (rad/s).
    """
    nb = model.n_bodies
    R = np.empty((nb, 3, 3))
    p = np.empty((nb, 3))
    w = np.zeros((nb, 3))
    v = np.zeros((nb, 3))
    g = model.ground
    R[g] = np.eye(3)
    p[g] = model.bodies[g].flat_position
    for b in model.order[1:]:
        i = model.body_joint[b]
        h = model.hinges[model.joints[i]]
        a = model.parent[b]
        Rp = R[a]
        R[b] = Rp @ axis_rotation(h.axis, theta[i])
        hinge_world = p[a] + Rp @ (h.point - model.bodies[a].flat_position)
        p[b] = hinge_world + R[b] @ (model.bodies[b].flat_position - h.point)
        if omega is not None:
            u = Rp @ h.axis * omega[i]
            w[b] = w[a] + u
            v[b] = v[a] + np.cross(w[a], hinge_world - p[a]) + np.cross(w[b], p[b] - hinge_world)
    if omega is None:
        return R, p
    return R, p, v, w


def hinge_points(model: Model, rotation, position, hinge: int):
    """World positions of the ends M, N of ``hinge`` as carried by each of its bodies.

    Returns ``(M_a, N_a, M_b, N_b)``, each (3,), m. For a closed loop
    ``M_a == M_b`` and ``N_a == N_b``; at a cut hinge their difference is the gap.
    """
    h = model.hinges[hinge]
    out = []
    for body in (h.body_a, h.body_b):
        r0 = model.bodies[body].flat_position
        for end in (h.point, h.end_n):
            out.append(position[body] + rotation[body] @ (end - r0))
    M_a, N_a, M_b, N_b = out
    return M_a, N_a, M_b, N_b
