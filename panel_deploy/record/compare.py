"""A scene's simulated deployment beside a recorded one: what ``replay --compare``
shows with the measured motion (a calibrated scene, say, against the deployment it
was fitted to).

The scene's model must be the recording's array (same bodies and hinges). It is
deployed from the stowed state, released ``release`` s after the recording's first
joint state (by default the release offset a ``calibrate`` fit of this recording
found and wrote under ``calibration.deployment``, else 0), and sampled at the
recording's joint-state times (:mod:`panel_deploy.dynamics.hinge_trajectory`);
:func:`collision_report` checks it there as ``collide`` checks the recording.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..build import build_model
from ..dynamics.hinge_trajectory import SAMPLE_INTERVAL, simulate_hinges
from ..errors import SceneError
from ..model import Model, hinge_order
from .analysis import RecordedDeployment


@dataclass(frozen=True)
class Compared:
    """A scene's deployment at a recording's times.

    Attributes
    ----------
    source : str
        The scene's file (or name).
    model : Model
    release : float
        s after the recording's first joint state at which the model is released.
    names : list of str
        The tree hinges, the columns of ``theta``.
    theta : (s, n_coords) ndarray
        Their angles at the recording's joint-state times, rad.
    success, message
        The simulation's.
    """

    source: str
    model: Model
    release: float
    names: list
    theta: np.ndarray
    success: bool
    message: str


def release_of(scene, recording) -> float:
    """The release offset (s after the first joint state) that a ``calibrate``
    fit wrote into ``scene`` for ``recording`` (matched by file name), else 0."""
    runs = (((scene.data.get("calibration") or {}).get("deployment") or {}).get("recordings")
            or ())
    for run in runs:
        if isinstance(run, dict) and Path(str(run.get("file", ""))).name == Path(recording).name:
            offset = run.get("release_offset")
            if isinstance(offset, (int, float)) and np.isfinite(offset):
                return float(offset)
    return 0.0


def compared(d: RecordedDeployment, scene, source: str, release: float | None = None) -> Compared:
    """Deploy ``scene``'s model beside the recorded deployment ``d``.

    Raises
    ------
    SceneError
        The scene is another array than the recording's (naming ``--compare``).
    """
    model = build_model(scene)
    if ([b.name for b in model.bodies] != [b.name for b in d.model.bodies]
            or [h.name for h in model.hinges] != [h.name for h in d.model.hinges]):
        raise SceneError("--compare", f"{source} is another array than the recording's "
                                      f"({len(model.bodies)} bodies, {len(model.hinges)} hinges "
                                      f"against {len(d.model.bodies)} and {len(d.model.hinges)}; "
                                      f"{_first_difference(model, d.model)})")
    if release is None:
        release = release_of(scene, d.recording.path)
    names = [model.hinges[h].name for h in hinge_order(model)[:model.n_coords]]
    span = max(float(d.track.t[-1]) - release, 2 * SAMPLE_INTERVAL)
    trajectory = simulate_hinges(model, scene.simulation, span, names)
    return Compared(source, model, release, names, trajectory.angles(d.track.t - release),
                    trajectory.success, trajectory.message)


def _first_difference(model, recorded) -> str:
    """What tells ``model`` from the recording's model ``recorded`` first: a body
    or hinge of the recording that ``model`` lacks (the same counts on another
    circuit differ only so), else the order of their names."""
    for kind, mine, theirs in (("body", model.bodies, recorded.bodies),
                               ("hinge", model.hinges, recorded.hinges)):
        names = {x.name for x in mine}
        missing = [x.name for x in theirs if x.name not in names]
        if missing:
            return f"the recording's {kind} {missing[0]} is not in it"
    return "the same bodies and hinges in another order"


def collision_report(beside: Compared, d: RecordedDeployment, settings):
    """The collision check of ``beside``'s deployment on the recording's own
    times, as :func:`~panel_deploy.record.analysis.check_recording` checks the
    recording (positions only: Eq. 7 from the samples): its
    :class:`~panel_deploy.collision.check.CollisionReport`."""
    from ..collision import StreamCheck

    stream = StreamCheck(beside.model, settings)
    for t, theta in zip(d.track.t, beside.theta):
        stream.update(float(t), theta)
    return stream.check.report()
