"""The calibration itself: weighted least squares of the recorded angles over
the chosen parameters and every recording's release offset
(:func:`scipy.optimize.least_squares`, trust region reflective, with
bounds), then the uncertainty at the optimum.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np
from scipy.optimize import least_squares

from ..model import Model
from .data import check_measured, motion_threshold, still_hinges
from .parameters import Parameters, parameters as make_parameters
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
#: Gain of the cost (half the sum of squared weighted residuals) in one step
#: at which the fit has converged, relative to that cost's value for
#: residuals that are noise alone (half the number of residuals): a step
#: of one standard error moves the cost by 0.5, so the fit stops within a
#: small fraction of one. Relative to the cost, as scipy's ``ftol``, with
#: residuals above the noise the tolerance grows with the standard errors,
#: which grow with the residuals (a fixed ``ftol`` of 1e-4 allowed gains of
#: 0.18 at 1 kHz, 3600 residuals).
COST_GAIN = 0.05
#: Gauss-Newton steps with the central-difference Jacobian after the search, at most.
POLISH_STEPS = 5
#: Residual RMS above this many times the noise: the fitted model does not
#: follow the data (a local minimum, or what the model leaves out).
MISFIT = 3.0


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
        """One sentence per parameter the data do not determine, and one
        when the residuals are far above the noise (:data:`MISFIT`)."""
        out = [warning(name, why) for name, why in self.problems.items()]
        rms = self.residual_rms
        if rms > MISFIT * self.noise:
            out.append(f"the fitted model leaves {rms * 1e3:.3g} mrad RMS where the noise is "
                       f"{self.noise * 1e3:.3g} mrad: it does not follow the data (a local "
                       "minimum of the fit, or something the model leaves out); the intervals "
                       "widen with the residuals but assume the model is right")
        return out

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
        Residual evaluations of the search at most, per stage (about one per
        iteration, each with one Jacobian: parameters + 1 simulations).
    progress : callable, optional
        Called with an :class:`Iteration` after every iteration.

    With ``parameters.per`` "group" the fit starts from a fit of one factor
    each (a stage of a few parameters, its evaluations counted in the
    result's): from the scene's values, a fit of 11 group factors and C_d
    ended 1 of 40 times in a local minimum with 1000x the cost of the
    truth (bench_calibration, seed 9 at 200 Hz); started from the scale fit
    it found the truth, in less time. Interrupted in that stage, the result
    is the stage's (one factor each).

    Raises
    ------
    TrajectoryError
        A recording that is motionless or too short (:func:`~.data.check_measured`).
    """
    clock = time.perf_counter()
    noise = noise if noise > 0 else DEFAULT_NOISE
    starts = [check_measured(run, noise) for run in runs]
    if parameters.per != "group" or len(parameters.names) == len(parameters.fit):
        return _fit(parameters, runs, simulation, noise, max_evaluations, progress, clock, starts)
    first = _fit(make_parameters(parameters.model, parameters.fit, "scale"), runs, simulation,
                 noise, max_evaluations, progress, clock, starts)
    if first.status == 3:
        return first
    by_kind = dict(zip(first.parameters.kinds, first.values))
    return _fit(replace(parameters, start=np.array([by_kind[k] for k in parameters.kinds])),
                runs, simulation, noise, max_evaluations, progress, clock, first.offsets, first)


def _fit(parameters: Parameters, runs, simulation, noise, max_evaluations, progress, start_clock,
         starts, before: CalibrationResult | None = None) -> CalibrationResult:
    """:func:`calibrate` from ``parameters.start``: ``starts`` are the
    recordings' release offsets to start from (s), or their first motions
    when there is no ``before`` (a stage whose iterations, simulations and
    times count in the result)."""
    done = (0, 0, {}) if before is None else (before.iterations, before.simulations,
                                              before.seconds)
    held = _unmoved(parameters, runs, motion_threshold(noise))
    free = parameters.without(held)
    residuals = Residuals(free, runs, simulation, noise)
    if before is None:
        nominal = residuals.trajectory(free.nominal, [0.0] * len(runs))
        offsets = start_offsets(starts, nominal, motion_threshold(noise))
    else:
        offsets = np.asarray(starts, dtype=float)
    x0 = np.concatenate([np.log(free.start), offsets])
    lower = np.concatenate([np.log(free.lower), offsets - OFFSET_REACH])
    upper = np.concatenate([np.log(free.upper), offsets + OFFSET_REACH])
    iterations = [0]
    names = free.names

    def report(intermediate_result):  # the name asks scipy for cost and x
        iterations[0] += 1
        if progress is not None:
            values, offs = residuals.split(intermediate_result.x)
            progress(Iteration(done[0] + iterations[0], float(intermediate_result.cost),
                               dict(zip(names, map(float, values))), tuple(map(float, offs)),
                               done[1] + residuals.simulations, time.perf_counter() - start_clock))

    unc = None
    try:
        fit = least_squares(residuals, x0, jac=residuals.jacobian, bounds=(lower, upper),
                            method="trf", x_scale="jac",
                            ftol=COST_GAIN / (0.5 * sum(run.theta.size for run in runs)),
                            xtol=TOLERANCE,
                            gtol=TOLERANCE, max_nfev=max_evaluations, callback=report)
        x, r = fit.x, fit.fun
        status = 0 if fit.status > 0 else 1
        message = (fit.message if fit.status > 0
                   else f"the budget of {max_evaluations} evaluations ran out before convergence")
        x, r, J = _polish(residuals, x, r, fit.jac, lower, upper)
        unc = uncertainty(J, r, x,
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
    values = np.array([fitted[names.index(n)] if n in names else nominal
                       for n, nominal in zip(parameters.names, parameters.nominal)])
    seconds = {key: done[2].get(key, 0.0) + spent for key, spent in residuals.seconds.items()}
    return CalibrationResult(
        success=status == 0, status=status, message=message, parameters=parameters,
        values=values, held=held, offsets=offs, x=np.asarray(x), cost=0.5 * float(r @ r),
        noise=noise, uncertainty=unc, rms=residuals.per_hinge_rms(x), model=free.model_at(fitted),
        residuals=residuals, iterations=done[0] + iterations[0],
        simulations=done[1] + residuals.simulations, wall_time=wall_time,
        seconds={**seconds, "other": wall_time - sum(seconds.values())})


def _polish(residuals: Residuals, x, r, forward, lower, upper) -> tuple:
    """``(x, r, J)`` after Gauss-Newton steps from where least_squares stopped
    (``x``, residuals ``r``, its forward-difference Jacobian ``forward``)
    with the central-difference Jacobian (:meth:`~.residuals.Residuals.central`),
    while a step gains at least :data:`COST_GAIN`; ``J`` central at ``x``.

    Forward differences of 1 % err by 5-10 % of a column on the paper scene
    (the curvature over the step): the trust region then stalls where its
    model stops predicting the gains, at 1 kHz up to 4 standard errors from
    the optimum, with a cost above the truth's. A converged fit costs one
    simulation more."""
    J = residuals.central(x, forward)
    for _ in range(POLISH_STEPS):
        step = np.linalg.lstsq(J, -r, rcond=None)[0]
        trial = np.clip(x + step, lower, upper)
        r_trial = residuals(trial)
        if 0.5 * (r @ r - r_trial @ r_trial) < COST_GAIN:
            break
        x, r = trial, r_trial
        J = residuals.central(x, residuals.jacobian(x))
    return x, r, J


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
