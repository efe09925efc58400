"""A recording's ``/joint_states`` on a scene's model: what ``collide`` and ``replay`` take.

The scene is ``--scene`` when given (a real array's recording carries none),
else the recording's ``/panel_deploy/model``.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass

from ..errors import TrajectoryError
from .reader import (HingeTrack, JointStates, Recording, hinge_track, joint_states,
                     open_recording)


@dataclass
class RecordedDeployment:
    """A recording read back with the scene and model its joint states belong to."""

    recording: Recording
    scene: object
    model: object
    track: HingeTrack
    states: JointStates  #: every joint of ``/joint_states``, as recorded


def read_deployment(path, scene: str | None = None) -> RecordedDeployment:
    """Open ``path`` and map its ``/joint_states`` onto the scene's hinges.

    A truncated file is read up to where it ends, with a note on stderr.

    Raises
    ------
    TrajectoryError
        An unreadable or foreign file, no scene (neither ``scene`` nor
        ``/panel_deploy/model``), or joint states that are not the scene's hinges.
    SceneError
        ``scene`` is not a valid scene.
    """
    from ..build import build_model
    from ..scene import load_scene, resolve_scene

    recording = open_recording(path)
    if scene:
        parsed = load_scene(resolve_scene(scene))
    else:
        parsed = recording.scene()
        if parsed is None:
            raise TrajectoryError(f"{path}: no /panel_deploy/model in this recording; "
                                  f"name its scene with --scene SCENE")
    model = build_model(parsed)
    states = joint_states(recording)
    track = hinge_track(states, model, path, parsed.name or str(parsed.source or ""))
    if recording.truncated:
        print(f"panel-deploy: note: {path} is truncated ({recording.truncated}); read up to "
              f"t = {track.t[-1] + track.t0:.4f} s ({len(track.t)} joint states)", file=sys.stderr)
    if track.t0:
        print(f"panel-deploy: note: times are counted from the first /joint_states stamp, "
              f"{track.t0:.9f} s", file=sys.stderr)
    return RecordedDeployment(recording, parsed, model, track, states)


def recording_trajectory(path, scene: str | None = None):
    """``(track, scene)`` for the collision check of ``panel-deploy collide FILE.mcap``;
    ``track`` has the ``t``, ``theta`` and ``omega`` that
    :func:`~panel_deploy.collision.check.check_trajectory` reads."""
    d = read_deployment(path, scene)
    return d.track, d.scene
