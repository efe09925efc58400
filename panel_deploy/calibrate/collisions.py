"""The first collision the fitted model predicts against the one each
recording shows: what a calibration is for (a design is trusted when its
model collides where the array did), checked as ``simulate`` and the
collision monitor check (the scene's ``collision`` settings)."""

from __future__ import annotations

from ..collision import CollisionSettings, StreamCheck, check_trajectory
from ..dynamics.simulate import simulate
from .fit import CalibrationResult
from ..dynamics.hinge_trajectory import fit_settings


def _event(event, shift: float) -> dict:
    """A collision event as the calibration section writes it: t in s since release."""
    return {"t": float(event.t + shift), "pair": list(event.names)}


def first_collisions(result: CalibrationResult, scene) -> dict:
    """``{"fitted": event or None, "measured": [event or None per recording]}``,
    each event ``{"t": s since release, "pair": [body, body]}``, over the
    span of the recordings."""
    settings = CollisionSettings.from_scene(scene)
    res = result.residuals
    span = max(run.t[-1] - off for run, off in zip(res.runs, result.offsets))
    fitted = None
    if span > 0:
        report = check_trajectory(result.model, simulate(result.model,
                                                         fit_settings(scene.simulation, span)),
                                  settings)
        fitted = None if report.first_collision is None else _event(report.first_collision, 0.0)
    measured = []
    for run, off in zip(res.runs, result.offsets):
        stream = StreamCheck(result.model, settings)
        found = None
        for t, theta in zip(run.t, run.theta):
            events = stream.update_joints(float(t), run.hinges, theta)
            if events:
                found = _event(events[0], stream.origin - off)
                break
        measured.append(found)
    return {"fitted": fitted, "measured": measured}
