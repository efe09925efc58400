"""Run the MJCF export of a model in MuJoCo at a fixed step: the benchmark peer.

MuJoCo integrates with a fixed time step (no error control), so its accuracy
is set by the step; :func:`run_mujoco` samples theta at the same evenly spaced
instants as :func:`panel_deploy.dynamics.simulate` so the two compare sample
by sample.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from ..export.mjcf import export_mjcf, qpos_index
from ..model import Model


@dataclass
class MujocoRun:
    """Sampled MuJoCo trajectory.

    Attributes
    ----------
    t : (s,) ndarray
        Sample instants, s (shorter than asked if the run diverged).
    theta, omega : (s, n) ndarray
        Hinge angles (rad) and rates (rad/s) in the model's coordinate order.
    success : bool
        False if MuJoCo reported a bad acceleration or the state left
        [-10 pi, 10 pi] or went non-finite (MuJoCo resets itself on
        divergence, so this is checked after every sample interval).
    message : str
    wall_time : float
        s, stepping only (model compilation excluded).
    nsteps : int
    timestep : float
    integrator : str
    """

    t: np.ndarray
    theta: np.ndarray
    omega: np.ndarray
    success: bool
    message: str
    wall_time: float
    nsteps: int
    timestep: float
    integrator: str


def compile_mujoco(model: Model, timestep: float, integrator: str):
    """(mjModel, mjData) of the exported model, reset to the stowed keyframe."""
    import mujoco

    m = mujoco.MjModel.from_xml_string(export_mjcf(model, timestep=timestep, integrator=integrator))
    d = mujoco.MjData(m)
    mujoco.mj_resetDataKeyframe(m, d, 0)
    return m, d


def run_mujoco(model: Model, t_end: float, samples: int, timestep: float,
               integrator: str = "RK4", theta0=None) -> MujocoRun:
    """Integrate the exported model from the stowed state (or ``theta0``) at rest.

    ``t_end / (samples - 1)`` must be a whole number of ``timestep`` (to 1e-9
    relative), so samples fall on steps.

    Raises
    ------
    ValueError
        If the sample interval is not a whole number of steps.
    """
    import mujoco

    interval = t_end / (samples - 1)
    per_sample = round(interval / timestep)
    if per_sample < 1 or abs(per_sample * timestep - interval) > 1e-9 * interval:
        raise ValueError(f"sample interval {interval:g} s is not a whole number of "
                         f"{timestep:g} s steps")
    m, d = compile_mujoco(model, timestep, integrator)
    idx = qpos_index(model)
    if theta0 is not None:
        d.qpos[idx] = theta0
    theta = np.empty((samples, model.n_coords))
    omega = np.empty((samples, model.n_coords))
    theta[0], omega[0] = d.qpos[idx], d.qvel[idx]
    bad = mujoco.mjtWarning.mjWARN_BADQACC
    message, done = "reached t_end", samples
    start = time.perf_counter()
    for j in range(1, samples):
        mujoco.mj_step(m, d, nstep=per_sample)
        theta[j], omega[j] = d.qpos[idx], d.qvel[idx]
        if (d.warning[bad].number > 0 or not np.all(np.isfinite(theta[j]))
                or np.max(np.abs(theta[j])) > 10 * math.pi):
            message, done = f"diverged before t = {j * interval:.6g} s", j
            break
    wall = time.perf_counter() - start
    return MujocoRun(np.linspace(0.0, t_end, samples)[:done], theta[:done], omega[:done],
                     done == samples, message, wall, (done - 1) * per_sample, timestep,
                     integrator)
