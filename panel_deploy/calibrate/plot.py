"""The picture of a calibration: per measured hinge the recorded angles, the
scene's simulation (nominal) and the fitted one against the time since
release, and the residuals of the fit."""

from __future__ import annotations

import math

import numpy as np

from ..validate import save_figure
from .fit import CalibrationResult

#: Panels per row of the figure.
COLUMNS = 4


def plot_calibration(result: CalibrationResult, path, flag: str = "--plot",
                     collisions: dict | None = None) -> None:
    """Draw ``result`` to ``path`` (PNG, or the suffix's format); two
    simulations (nominal and fitted) over the recordings' span. With
    ``collisions`` (:func:`~.collisions.first_collisions`) every panel marks
    the fitted first collision and each recording's."""
    import matplotlib
    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    res = result.residuals
    nominal = res.trajectory(res.parameters.nominal, result.offsets)
    fitted = res.trajectory(*res.split(result.x))
    hinges = res.hinges
    rows = math.ceil((len(hinges) + 1) / COLUMNS)
    fig = Figure(figsize=(3.2 * COLUMNS, 2.4 * rows), layout="constrained")
    axes = fig.subplots(rows, COLUMNS, squeeze=False).ravel()
    span = max(run.t[-1] - off for run, off in zip(res.runs, result.offsets))
    tau = np.linspace(min(-off for off in result.offsets), span, 2000)
    theta_nominal, theta_fitted = nominal.angles(tau), fitted.angles(tau)
    residual_axes = axes[len(hinges)]
    for i, hinge in enumerate(hinges):
        ax = axes[i]
        for j, (run, off) in enumerate(zip(res.runs, result.offsets)):
            if hinge not in run.hinges:
                continue
            col = run.hinges.index(hinge)
            ax.plot(run.t - off, run.theta[:, col], ".", ms=2, color=f"C{j % 10}",
                    label="measured" if j == 0 else None)
            error = run.theta[:, col] - fitted.angles(run.t - off)[:, i]
            residual_axes.plot(run.t - off, error * 1e3, ".", ms=1.5)
        ax.plot(tau, theta_nominal[:, i], "--", color="0.4", lw=1, label="nominal")
        ax.plot(tau, theta_fitted[:, i], "-", color="k", lw=1, label="fitted")
        for j, event in enumerate(_marks(collisions)):
            ax.axvline(event["t"], color="k" if j == 0 else "C3", ls=":", lw=1,
                       label=("fitted" if j == 0 else "measured") + " 1st collision")
        ax.set_title(hinge, fontsize=9)
        ax.set_ylabel("theta, rad", fontsize=8)
        ax.tick_params(labelsize=7)
    axes[0].legend(fontsize=7)
    residual_axes.set_title("residuals, measured - fitted", fontsize=9)
    residual_axes.set_ylabel("mrad", fontsize=8)
    residual_axes.tick_params(labelsize=7)
    for ax in axes[len(hinges) + 1:]:
        ax.set_visible(False)
    for ax in axes[:len(hinges) + 1]:
        ax.set_xlabel("t since release, s", fontsize=8)
    values = ", ".join(f"{n} {v:.4g}" for n, v in zip(result.parameters.names, result.values))
    fig.suptitle(f"calibration: {values}", fontsize=10)
    save_figure(fig, path, flag)


def _marks(collisions) -> list:
    """The first collisions to mark: the fitted one first, then the recordings'."""
    if collisions is None:
        return []
    return [e for e in (collisions["fitted"], *collisions["measured"]) if e is not None]
