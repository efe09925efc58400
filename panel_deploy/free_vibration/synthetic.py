"""Swings made by the model rather than measured: the rig's free response
(:func:`released`) and a recording of one (:func:`record_swing`), for the tests,
the bench and the sample bags.
"""

from __future__ import annotations


import numpy as np

from .rig import Rig, rig_of


def released(rig: Rig, t, c: float, k: float, equilibrium: float, amplitude: float):
    """theta(t), rad, of a rig without weight or air released at rest from
    ``equilibrium + amplitude`` at t = 0: the closed form of the underdamped
    oscillator, the reference the tests and the benchmark measure against.

    Raises
    ------
    ModelError
        The rig has weight or air (no closed form), or c and k (one spring,
        N m s/rad and N m/rad) do not make it underdamped.
    """
    from ..errors import ModelError

    if rig.drag > 0 or np.any(np.abs(rig.gravity) > 0):
        raise ModelError("released: the closed form is for a rig without weight and air")
    n = rig.springs
    wn = np.sqrt(n * k / rig.inertia)
    zeta = n * c / (2.0 * np.sqrt(n * k * rig.inertia))
    if not 0 <= zeta < 1:
        raise ModelError(f"released: zeta = {zeta:.3g}, not an underdamped oscillator")
    wd = wn * np.sqrt(1.0 - zeta ** 2)
    t = np.asarray(t, dtype=float)
    return equilibrium + amplitude * np.exp(-zeta * wn * t) * (
        np.cos(wd * t) + zeta * wn / wd * np.sin(wd * t))


def record_swing(path, scene, t, theta, t0: float = 0.0, carry_scene: bool = True) -> None:
    """Write a swing of ``scene``'s one hinge as a recording: ``theta`` (rad)
    at ``t`` (s, stamped from ``t0``) on ``/joint_states``, and the scene on
    ``panel_deploy/model`` unless ``carry_scene`` is False (a real rig's
    ``ros2 bag record /joint_states``, read with ``--rig``)."""
    from .. import contract
    from ..build import build_model
    from ..record import messages
    from ..record.writer import DeploymentWriter
    from ..scene_text import scene_yaml

    name = rig_of(build_model(scene), str(path)).hinge
    empty = np.zeros(0)
    with DeploymentWriter(path) as rec:
        if carry_scene:
            rec.write(contract.MODEL, messages.string(scene_yaml(scene)))
        for time, value in zip(t, theta):
            rec.write(contract.JOINT_STATES,
                      messages.joint_state([name], t0 + time, [value], empty, empty))
