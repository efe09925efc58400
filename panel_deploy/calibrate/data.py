"""Recorded joint states as a fit takes them: the measured hinges of one
recording, on its own time axis, checked to be worth fitting.

A recording comes from a real array as readily as from ``simulate --record``:
any hinge subset the loop closure completes, stamps from any base (an
epoch, a driver's clock), gaps, and a release somewhere after the first
sample. Angles in rad, times in s.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .. import contract
from ..errors import TrajectoryError
from ..record.reader import hinge_track, joint_states, open_recording

#: Smallest change of a measured angle that counts as motion, rad; with
#: noisy encoders :data:`MOTION_NOISE` standard deviations, if more.
MIN_MOTION = 0.01
MOTION_NOISE = 5.0
#: Joint states after the motion starts that a fit needs at least: fewer
#: cannot tell a stiffness from a damping from a release time.
MIN_MOVING_SAMPLES = 10
#: The per-message arrays of :class:`~panel_deploy.record.reader.JointStates`.
PER_SAMPLE = ("t", "position", "velocity", "effort", "log_time")


@dataclass(frozen=True)
class Measured:
    """One recording's measured hinge angles.

    Attributes
    ----------
    path : str
    hinges : tuple of str
        The hinges the recording carries (the residuals' columns).
    t : (s,) ndarray
        Stamps, s, counted from the first one (``stamp0``).
    theta : (s, m) ndarray
        Measured angles, rad.
    stamp0 : float
        The first stamp, s, in the recording's own base.
    topic : str
        The joint states' topic (namespaced as recorded).
    notes : tuple of str
        What the reader noticed (a truncated file).
    """

    path: str
    hinges: tuple
    t: np.ndarray
    theta: np.ndarray
    stamp0: float
    topic: str = contract.JOINT_STATES.name
    notes: tuple = ()

    @property
    def duration(self) -> float:
        return float(self.t[-1])


def read_measured(path, scene, model, namespace: str | None = None,
                  until: float | None = None) -> Measured:
    """The joint states of the recording at ``path`` on ``model``'s hinges,
    stamped as ``scene.collision.stamps`` says; with ``until``, only those
    up to ``until`` s after the first stamp (a window: the part of a
    deployment before its first collision, which the model cannot follow).

    Raises
    ------
    TrajectoryError
        An unreadable recording, joints that are not the model's hinges, a
        hinge set the loop closure does not complete, or angles that cannot
        close the loop (every sample is put through the closure, as the
        collision monitor does).
    """
    recording = open_recording(path, namespace)
    states = joint_states(recording, scene.collision.stamps)
    hinge_track(states, model, path, scene.name or str(scene.source or ""))
    if until is not None:
        keep = states.t - states.t[0] <= until + 1e-9  # stamps count whole nanoseconds
        states = replace(states, **{key: getattr(states, key)[keep] for key in PER_SAMPLE
                                    if getattr(states, key) is not None})
    notes = ()
    if recording.truncated:
        notes = (f"{path} is truncated ({recording.truncated}); read its "
                 f"{len(states.t)} joint states",)
    return Measured(str(path), tuple(states.names), states.t - states.t[0], states.position,
                    float(states.t[0]), recording.topic(contract.JOINT_STATES), notes)


def motion_threshold(noise: float) -> float:
    """Change of a measured angle (rad) that counts as motion at encoder ``noise`` (rad)."""
    return max(MIN_MOTION, MOTION_NOISE * noise)


def first_motion(t, theta, threshold: float) -> float | None:
    """The first time (s) at which some angle of ``theta`` (s, m) is more
    than ``threshold`` (rad) from its first value; None if none is."""
    moved = np.flatnonzero(np.abs(theta - theta[0]).max(axis=1) > threshold)
    return float(t[moved[0]]) if len(moved) else None


def still_hinges(runs, threshold: float) -> set:
    """Names of the measured hinges that stay within ``threshold`` (rad) of
    their first angle in every recording of ``runs`` that carries them."""
    moved = {h for run in runs for h, change in zip(run.hinges, np.ptp(run.theta, axis=0))
             if change > threshold}
    return {h for run in runs for h in run.hinges} - moved


def check_measured(run: Measured, noise: float) -> float:
    """The time (s) at which ``run`` starts to move, after checking that it
    moves and moves long enough to be fitted.

    Raises
    ------
    TrajectoryError
        Naming the file and its ``/joint_states``: motionless (no angle
        changes by more than :func:`motion_threshold`), or fewer than
        :data:`MIN_MOVING_SAMPLES` joint states from the first motion on.
    """
    topic = run.topic
    threshold = motion_threshold(noise)
    start = first_motion(run.t, run.theta, threshold)
    if start is None:
        change = float(np.abs(run.theta - run.theta[0]).max())
        raise TrajectoryError(f"{run.path}: {topic} is motionless: no hinge moves more than "
                              f"{change:.3g} rad (motion: > {threshold:g} rad); nothing to fit")
    moving = int(np.count_nonzero(run.t >= start))
    if moving < MIN_MOVING_SAMPLES:
        raise TrajectoryError(f"{run.path}: {topic} is too short: {moving} joint states after "
                              f"the motion starts at {start:.4f} s, a fit needs at least "
                              f"{MIN_MOVING_SAMPLES}")
    return start
