"""The weighted residuals of a calibration and their Jacobian.

The unknowns are ``x = (log of the parameter values, release offsets)``:
one release offset per recording, s from its first stamp to the release,
since a recording's stamps start wherever its recorder did. A residual is
``(theta_measured - theta_simulated(t - offset)) / noise`` for every
measured hinge at every recorded stamp; recordings of the same array share
one simulation.
"""

from __future__ import annotations

import math
import time

import numpy as np

from .data import first_motion
from .parameters import Parameters
from ..dynamics.hinge_trajectory import Trajectory, simulate_hinges

#: Forward-difference step of the Jacobian in log parameter space (1 %):
#: the simulation's error (rtol :data:`~panel_deploy.dynamics.hinge_trajectory.FIT_RTOL`) then spoils a
#: column by about 1e-4, the curvature by about 0.5 %, which only slows the
#: Gauss-Newton steps a little: the optimum is where the exact residuals put it.
#: On the paper scene 1e-3 at rtol 1e-7 gave the same fit to 5 digits in 2.5x the time.
FD_STEP = 1e-2
#: Simulations end on a multiple of this, s, past the last stamp: the sample
#: grid then stays put while the release offsets move a little.
END_GRID = 0.01


class Residuals:
    """Weighted residuals as a function of ``x`` (see the module), with the
    best point seen so far.

    Parameters
    ----------
    parameters : Parameters
    runs : sequence of :class:`~.data.Measured`
    simulation : SimulationSection
        The scene's settings (method, tolerances); t_end and the samples
        follow the recordings.
    noise : float
        Standard deviation of a measured angle, rad (the residuals' unit).

    Attributes
    ----------
    simulations : int
        Simulations run so far.
    seconds : dict
        Wall time (s) of those simulations (interpolation included):
        ``"residuals"`` those of the points the fit asked about,
        ``"jacobian"`` those of the difference steps.
    failures : list of str
        Messages of simulations that failed (their angles held after the end).
    best : tuple
        ``(cost, x)`` of the lowest cost seen (cost = half the sum of squares).
    """

    def __init__(self, parameters: Parameters, runs, simulation, noise: float):
        self.parameters = parameters
        self.runs = list(runs)
        self.simulation = simulation
        self.noise = float(noise)
        self.hinges = tuple(dict.fromkeys(h for run in self.runs for h in run.hinges))
        self._columns = [[self.hinges.index(h) for h in run.hinges] for run in self.runs]
        self.n_values = len(parameters.names)
        self.simulations = 0
        self.seconds = {"residuals": 0.0, "jacobian": 0.0}
        self.failures = []
        self.best = (math.inf, None)
        self._last = (None, None)  # (x bytes, Trajectory)

    def split(self, x) -> tuple:
        """``(values, offsets)`` of ``x``: parameter values (factors, C_d) and release offsets, s."""
        x = np.asarray(x, dtype=float)
        return np.exp(x[:self.n_values]), x[self.n_values:]

    def trajectory(self, values, offsets, purpose: str = "residuals") -> Trajectory:
        """The simulated angles of the measured hinges with parameter ``values``,
        long enough for every recording at its release ``offsets``; its wall
        time counts in ``seconds[purpose]``."""
        latest = max(run.t[-1] - off for run, off in zip(self.runs, offsets))
        t_end = (math.floor(max(latest, 0.0) / END_GRID) + 1) * END_GRID
        self.simulations += 1
        start = time.perf_counter()
        run = simulate_hinges(self.parameters.model_at(values), self.simulation, t_end,
                              self.hinges)
        self.seconds[purpose] += time.perf_counter() - start
        if not run.success:
            self.failures.append(run.message)
        return run

    def of(self, trajectory: Trajectory, offsets) -> np.ndarray:
        """The weighted residuals of every recording against ``trajectory``, one vector."""
        parts = [(run.theta - trajectory.angles(run.t - off)[:, cols]).ravel()
                 for run, off, cols in zip(self.runs, offsets, self._columns)]
        return np.concatenate(parts) / self.noise

    def _at(self, x) -> Trajectory:
        key = np.asarray(x, dtype=float).tobytes()
        if self._last[0] != key:
            self._last = (key, self.trajectory(*self.split(x)))
        return self._last[1]

    def _seen(self, x, r) -> None:
        cost = 0.5 * float(r @ r)
        if cost < self.best[0]:
            self.best = (cost, np.array(x, dtype=float))

    def __call__(self, x) -> np.ndarray:
        r = self.of(self._at(x), self.split(x)[1])
        self._seen(x, r)
        return r

    def jacobian(self, x) -> np.ndarray:
        """d residuals / d x: forward differences of :data:`FD_STEP` in the
        log values; the release offsets' columns exact, from the
        simulated rates (d r / d offset = theta_simulated'(t - offset) / noise)."""
        x = np.asarray(x, dtype=float)
        values, offsets = self.split(x)
        base = self.of(self._at(x), offsets)
        J = np.zeros((len(base), len(x)))
        for i in range(self.n_values):
            step = x.copy()
            step[i] += FD_STEP
            r = self._stepped(step, offsets)
            J[:, i] = (r - base) / FD_STEP
        row = 0
        trajectory = self._at(x)
        for j, (run, off, cols) in enumerate(zip(self.runs, offsets, self._columns)):
            size = run.theta.size
            J[row:row + size, self.n_values + j] = (
                trajectory.rates(run.t - off)[:, cols].ravel() / self.noise)
            row += size
        return J

    def _stepped(self, x, offsets) -> np.ndarray:
        """The residuals at a difference step ``x``, the recordings held at ``offsets``."""
        r = self.of(self.trajectory(self.split(x)[0], offsets, "jacobian"), offsets)
        self._seen(x, r)
        return r

    def central(self, x, forward) -> np.ndarray:
        """The Jacobian at ``x`` with central differences in the log values,
        from its ``forward`` differences (:meth:`jacobian` at ``x``) and one
        step back per value. On the paper scene (1 kHz, 4 parameters) the
        standard errors from forward differences of 1 % came out up to 8 %
        small against central differences of 0.1 % at rtol 1e-9 (the
        curvature over the step); central ones of 1 % at most 2.6 %."""
        x = np.asarray(x, dtype=float)
        offsets = self.split(x)[1]
        base = self.of(self._at(x), offsets)
        J = np.array(forward, dtype=float)
        for i in range(self.n_values):
            step = x.copy()
            step[i] -= FD_STEP
            J[:, i] = 0.5 * (J[:, i] + (base - self._stepped(step, offsets)) / FD_STEP)
        return J

    def per_hinge_rms(self, x) -> list:
        """RMS residual of every measured hinge of every recording, rad:
        one ``{hinge: rms}`` per recording."""
        trajectory = self._at(x)
        offsets = self.split(x)[1]
        out = []
        for run, off, cols in zip(self.runs, offsets, self._columns):
            error = run.theta - trajectory.angles(run.t - off)[:, cols]
            out.append({h: float(np.sqrt(np.mean(error[:, i] ** 2)))
                        for i, h in enumerate(run.hinges)})
        return out


def start_offsets(starts, trajectory: Trajectory, threshold: float) -> np.ndarray:
    """Release offsets (s) to start a fit from: each recording's first
    motion (``starts``, s) less the time the nominal ``trajectory`` takes to
    move as far (``threshold``, rad) from the stowed state."""
    tau = np.arange(0.0, trajectory.t_last, 1e-4)
    lag = first_motion(tau, trajectory.angles(tau), threshold) if len(tau) > 1 else None
    return np.asarray(starts, dtype=float) - (lag or 0.0)
