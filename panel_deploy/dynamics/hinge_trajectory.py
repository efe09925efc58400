"""The simulated angles of the measured hinges at any time after the release:
one deployment from the stowed state, sampled densely and interpolated.

The recorded stamps fall anywhere (any rate, gaps, a release between two of
them), so the simulation is sampled every :data:`SAMPLE_INTERVAL` and
interpolated: cubic Hermite on the tree coordinates' own rates, a cubic
through the cut hinges' angles (computed from the body poses, without
rates). Before the release the array rests stowed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from scipy.interpolate import CubicHermiteSpline

from .simulate import simulate
from ..model import Model, hinge_order

#: Spacing of the simulation's samples, s: the interpolation between them
#: errs by about 1e-6 rad on the paper scene, far below encoder noise.
SAMPLE_INTERVAL = 1e-3
#: Relative tolerance of a fit's simulations at most: well below the
#: changes a finite-difference step of
#: :data:`panel_deploy.calibrate.residuals.FD_STEP` makes.
FIT_RTOL = 1e-6


def fit_settings(simulation, t_end: float, sample_interval: float = SAMPLE_INTERVAL):
    """The scene's ``simulation`` section for a fit's run to ``t_end`` (s):
    samples at most ``sample_interval`` (s) apart and a tolerance no looser
    than :data:`FIT_RTOL`."""
    rtol = min(simulation.rtol, FIT_RTOL)
    return replace(simulation, t_end=t_end, samples=max(3, math.ceil(t_end / sample_interval) + 1),
                   rtol=rtol, atol=min(simulation.atol, rtol * 1e-2))


@dataclass(frozen=True)
class Trajectory:
    """Angles (rad) of some hinges against the time since release (s).

    ``success``, ``status`` and ``message`` are the simulation's; after a
    failed run's last sample the angles stay where they were.
    """

    stowed: np.ndarray
    spline: object
    t_last: float
    success: bool
    status: int
    message: str

    def angles(self, tau) -> np.ndarray:
        """(s, m) angles at times ``tau`` (s) since release; stowed before it."""
        tau = np.asarray(tau, dtype=float)
        out = self.spline(np.clip(tau, 0.0, self.t_last))
        out[tau < 0] = self.stowed
        return out

    def rates(self, tau) -> np.ndarray:
        """(s, m) d theta / d tau (rad/s); 0 before the release and after a failed run's end."""
        tau = np.asarray(tau, dtype=float)
        out = self.spline(np.clip(tau, 0.0, self.t_last), 1)
        out[(tau < 0) | (tau > self.t_last)] = 0.0
        return out


def simulate_hinges(model: Model, simulation, t_end: float, hinges,
                    sample_interval: float = SAMPLE_INTERVAL) -> Trajectory:
    """Simulate ``model`` from stowed to ``t_end`` (s) with the scene's
    ``simulation`` section (:func:`fit_settings`, samples ``sample_interval``
    s apart at most) and interpolate the angles of the hinges named ``hinges``."""
    result = simulate(model, fit_settings(simulation, t_end, sample_interval))
    order = hinge_order(model)
    column = {model.hinges[h].name: i for i, h in enumerate(order)}
    cols = [column[name] for name in hinges]
    stowed = np.array([model.hinges[order[i]].theta_stowed for i in cols])
    status = (result.success, int(result.status), result.message)
    if len(result.t) < 2:  # failed at the first step: the array never left the stowed state
        still = CubicHermiteSpline([0.0, sample_interval], [stowed, stowed],
                                   np.zeros((2, len(cols))), axis=0)
        return Trajectory(stowed, still, 0.0, *status)
    theta = np.hstack([result.theta, result.cut_theta])[:, cols]
    # Cut hinges have no rates of their own (their angles come from the body
    # poses): second-order differences, exact enough at this spacing.
    rates = np.hstack([result.omega, np.gradient(result.cut_theta, result.t, axis=0)])[:, cols]
    return Trajectory(stowed, CubicHermiteSpline(result.t, theta, rates, axis=0),
                      float(result.t[-1]), *status)
