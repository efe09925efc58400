"""The calibration itself: weighted least squares of the recorded angles over
the chosen parameters and every recording's release offset
(:func:`scipy.optimize.least_squares`, trust region reflective, with
bounds), then the uncertainty at the optimum.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from ..model import Model
from .data import check_measured, motion_threshold, still_hinges
from .parameters import Parameters
from .residuals import Residuals, start_offsets
from .uncertainty import Uncertainty, uncertainty, warning

#: Noise assumed for the weights when the scene states none
#: (``collision.noise`` 0), rad: a good encoder's. The standard errors do not
#: depend on it (they scale with the residuals' own variance).
DEFAULT_NOISE = 1e-3
#: How far a release offset may move from where the motion starts, s.
OFFSET_REACH = 0.2
#: Relative change of x at which the fit has converged.
TOLERANCE = 1e-6
#: Relative reduction of the cost in one step at which the fit has
#: converged. Near the optimum the Gauss-Newton steps shrink fast, so a step
#: that gains less than this leaves the determined parameters where they are;
#: at 1e-6 the 15-parameter fit of the paper scene went on for another 60 s,
#: moving only parameters the data do not determine.
COST_TOLERANCE = 1e-4


@dataclass(frozen=True)
class Iteration:
    """What a progress callback gets once per iteration of the fit."""

    iteration: int
    cost: float
    values: dict  #: parameter name -> value (factor, C_d)
    offsets: tuple  #: release offset of every recording, s
    simulations: int
    elapsed: float  #: s


@dataclass(frozen=True)
class CalibrationResult:
    """A calibration's outcome, as data.

    Attributes
    ----------
    success : bool
        The least-squares fit converged (status 0).
    status : int
        0 converged, 1 the evaluation budget ran out, 3 interrupted (the
        best point so far is the result), -1 the fit could not start.
    message : str
    parameters : Parameters
        Every parameter asked for.
    values : (p,) ndarray
        Fitted factors and C_d (the held ones at the scene's values).
    held : dict
        Parameter name -> why the data cannot determine it, for factors not
        fitted but held at the scene's values: those whose measured hinges
        never leave their first angle.
    offsets : (R,) ndarray
        Release time of every recording, s after its first stamp.
    x : ndarray
        The fit's unknowns (log values, offsets).
    cost : float
        Half the sum of the squared weighted residuals.
    noise : float
        rad, the residuals' unit.
    uncertainty : Uncertainty or None
        None when no Jacobian at the result exists (interrupted before one).
    rms : list of dict
        RMS residual per hinge of every recording, rad.
    model : Model
        The fitted model (``parameters.model`` is the scene's).
    residuals : Residuals
        The evaluator, for plots of any point.
    iterations, simulations : int
    wall_time : float
        s.
    seconds : dict
        Where ``wall_time`` went, s: ``"residuals"`` and ``"jacobian"``
        the simulations of the points tried and of the difference steps
        (:attr:`.residuals.Residuals.seconds`), ``"other"`` the rest (the
        residuals from the simulations, the trust-region steps, the intervals).
    """

    success: bool
    status: int
    message: str
    parameters: Parameters
    values: np.ndarray
    held: dict
    offsets: np.ndarray
    x: np.ndarray
    cost: float
    noise: float
    uncertainty: Uncertainty | None
    rms: list
    model: Model
    residuals: Residuals
    iterations: int
    simulations: int
    wall_time: float
    seconds: dict

    @property
    def samples(self) -> int:
        """Joint states fitted, over all recordings."""
        return sum(len(run.t) for run in self.residuals.runs)

    @property
    def problems(self) -> dict:
        """Parameter name -> why the data do not determine it (held or not)."""
        return {**(self.uncertainty.problems if self.uncertainty else {}), **self.held}

    @property
    def warnings(self) -> list:
        """One sentence per parameter the data do not determine."""
        return [warning(name, why) for name, why in self.problems.items()]

    @property
    def residual_rms(self) -> float:
        """RMS of measured minus fitted angles over every recording and hinge, rad."""
        size = sum(run.theta.size for run in self.residuals.runs)
        return self.noise * float(np.sqrt(2 * self.cost / size))


def calibrate(parameters: Parameters, runs, simulation, *, noise: float = 0.0,
              max_evaluations: int = 50, progress=None) -> CalibrationResult:
    """Fit ``parameters`` to the recordings ``runs`` (:class:`~.data.Measured`
    of the same array).

    Parameters
    ----------
    parameters : Parameters
    runs : sequence of Measured
    simulation : SimulationSection
        The scene's integrator settings.
    noise : float
        Standard deviation of a measured angle, rad; 0: :data:`DEFAULT_NOISE`.
    max_evaluations : int
        Residual evaluations of the search at most (about one per iteration,
        each with one Jacobian: parameters + 1 simulations).
    progress : callable, optional
        Called with an :class:`Iteration` after every iteration.

    Raises
    ------
    TrajectoryError
        A recording that is motionless or too short (:func:`~.data.check_measured`).
    """
    start_clock = time.perf_counter()
    noise = noise if noise > 0 else DEFAULT_NOISE
    starts = [check_measured(run, noise) for run in runs]
    held = _unmoved(parameters, runs, motion_threshold(noise))
    free = parameters.without(held)
    residuals = Residuals(free, runs, simulation, noise)
    nominal = residuals.trajectory(free.nominal, [0.0] * len(runs))
    offsets = start_offsets(starts, nominal, motion_threshold(noise))
    x0 = np.concatenate([np.log(free.start), offsets])
    lower = np.concatenate([np.log(free.lower), offsets - OFFSET_REACH])
    upper = np.concatenate([np.log(free.upper), offsets + OFFSET_REACH])
    iterations = [0]
    names = free.names

    def report(intermediate_result):  # the name asks scipy for cost and x
        iterations[0] += 1
        if progress is not None:
            values, offs = residuals.split(intermediate_result.x)
            progress(Iteration(iterations[0], float(intermediate_result.cost),
                               dict(zip(names, map(float, values))), tuple(map(float, offs)),
                               residuals.simulations, time.perf_counter() - start_clock))

    unc = None
    try:
        fit = least_squares(residuals, x0, jac=residuals.jacobian, bounds=(lower, upper),
                            method="trf", x_scale="jac", ftol=COST_TOLERANCE, xtol=TOLERANCE,
                            gtol=TOLERANCE, max_nfev=max_evaluations, callback=report)
        x, r = fit.x, fit.fun
        status = 0 if fit.status > 0 else 1
        message = (fit.message if fit.status > 0
                   else f"the budget of {max_evaluations} evaluations ran out before convergence")
        # least_squares hands back the forward-difference Jacobian at its
        # result; one step back per value makes it central (see Residuals.central).
        unc = uncertainty(residuals.central(x, fit.jac), r, x,
                          (*names, *(f"release[{i}]" for i in range(len(runs)))),
                          [True] * len(names) + [False] * len(runs))
    except KeyboardInterrupt:
        x = residuals.best[1] if residuals.best[1] is not None else x0
        r = residuals(x)
        status, message = 3, (f"interrupted after {iterations[0]} iterations: the best point "
                              "so far is the result, without intervals")
    if residuals.failures:
        message += (f"; {len(residuals.failures)} of {residuals.simulations} simulations "
                    f"failed (first: {residuals.failures[0]})")
    fitted, offs = residuals.split(x)
    wall_time = time.perf_counter() - start_clock
    values = np.array([fitted[names.index(n)] if n in names else start
                       for n, start in zip(parameters.names, parameters.start)])
    return CalibrationResult(
        success=status == 0, status=status, message=message, parameters=parameters,
        values=values, held=held, offsets=offs, x=np.asarray(x), cost=0.5 * float(r @ r),
        noise=noise, uncertainty=unc, rms=residuals.per_hinge_rms(x), model=free.model_at(fitted),
        residuals=residuals, iterations=iterations[0],
        simulations=residuals.simulations, wall_time=wall_time,
        seconds={**residuals.seconds, "other": wall_time - sum(residuals.seconds.values())})


def _unmoved(parameters: Parameters, runs, threshold: float) -> dict:
    """Parameter name -> why, for each k or c factor whose measured hinges all
    stay put (within ``threshold``, rad) in every recording: hinges resting on
    a stop, whose spring and damper barely act on the data. Fitted, such a
    factor wanders far along a flat valley of the cost (the paper scene's top
    hinges: k 3.4x for a true 1.55x, c anywhere in 0.02-50x) and slows the fit."""
    still = still_hinges(runs, threshold)
    measured = {h for run in runs for h in run.hinges}
    out = {}
    for name, kind, group in zip(parameters.names, parameters.kinds, parameters.groups):
        hinges = [parameters.model.hinges[i].name for i in group]
        seen = [h for h in hinges if h in measured]
        if kind != "drag" and seen and set(seen) <= still:
            out[name] = (f"its measured hinges ({', '.join(seen)}) stay within {threshold:g} rad "
                         "of their first angle in every recording; held at the scene's value")
    return out
