"""A recording's joint states on a scene's model: what ``collide``, ``replay`` and
``simulate RECORDING.mcap`` take.

The scene is ``--scene`` when given (a real array's recording carries none),
else the one the recording ran (its ``dynamics/scene``, else its
``panel_deploy/model``), with ``--set`` items applied either way.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass, field

from .. import contract
from ..errors import PanelDeployError, SceneError, TrajectoryError
from .reader import (HingeTrack, JointStates, Recording, contact_onsets, hinge_track,
                     joint_states, open_recording)


@dataclass
class RecordedDeployment:
    """A recording read back with the scene and model its joint states belong to."""

    recording: Recording
    scene: object
    model: object
    track: HingeTrack
    states: JointStates  #: every joint of the joint states, as recorded
    #: Each joint state's contact onset (:func:`~.reader.contact_onsets`), or None.
    onsets: list
    #: What the reader noticed (a truncated file, times counted from a first
    #: stamp): for stderr once the command has done its work, so that a
    #: command that fails prints one line only.
    notes: list = field(default_factory=list)

    def print_notes(self) -> None:
        for note in self.notes:
            print(f"panel-deploy: note: {note}", file=sys.stderr)


def recorded_scene(path, scene: str | None = None, namespace: str | None = None,
                   overrides=(), scene_flag: str = "--scene") -> tuple:
    """``(recording, scene)``: the recording at ``path`` and the scene its
    deployment ran (``scene``, a file or shipped name, when given), with
    ``overrides`` (``--set`` items) applied and ``fold.circuit: auto``
    resolved (:func:`~panel_deploy.ranking.resolve_circuit`). ``scene_flag``
    is the flag that names a scene, for the message when the recording has none.

    Raises
    ------
    TrajectoryError
        An unreadable or foreign file, or no scene in it and none given.
    SceneError
        ``scene`` or an override is not valid.
    """
    from ..ranking import resolve_circuit
    from ..scene import apply_overrides, load_scene, resolve_scene, scene_from_dict

    recording = open_recording(path, namespace)
    if scene:
        return recording, resolve_circuit(load_scene(resolve_scene(scene), overrides))
    parsed = recording.scene()
    if parsed is None:
        cut = f" (the file was cut short: {recording.truncated})" if recording.truncated else ""
        raise TrajectoryError(f"{path}: no {recording.topic(contract.MODEL)} in this "
                              f"recording{cut}; name its scene with {scene_flag} SCENE")
    if not overrides:
        return recording, parsed
    data = apply_overrides(parsed.data, overrides)
    try:
        overridden = scene_from_dict(data, source=parsed.source)
    except SceneError as e:
        raise SceneError(f"--set {e.path}", e.reason) from None
    return recording, resolve_circuit(overridden)


def read_deployment(path, scene: str | None = None, namespace: str | None = None,
                    overrides=(), scene_flag: str = "--scene") -> RecordedDeployment:
    """Open ``path`` and map its joint states onto the scene's hinges
    (:func:`recorded_scene` says which scene).

    A truncated file is read up to where it ends, with a note (:attr:`RecordedDeployment.notes`).

    Raises
    ------
    TrajectoryError
        An unreadable or foreign file, no scene, or joint states that are
        not the scene's hinges.
    SceneError
        ``scene`` or an override is not valid.
    """
    from ..build import build_model

    recording, parsed = recorded_scene(path, scene, namespace, overrides, scene_flag)
    model = build_model(parsed)
    states = joint_states(recording, parsed.collision.stamps)
    track = hinge_track(states, model, path, parsed.name or str(parsed.source or ""))
    notes = []
    if recording.truncated:
        notes.append(f"{path} is truncated ({recording.truncated}); read up to "
                     f"t = {track.t[-1] + track.t0:.4f} s ({len(track.t)} joint states)")
    if track.t0:
        notes.append(f"times are counted from the first {recording.topic(contract.JOINT_STATES)} "
                     f"stamp, {track.t0:.9f} s")
    onsets = contact_onsets(recording, states, parsed.collision.stamps)
    return RecordedDeployment(recording, parsed, model, track, states, onsets, notes)


def check_recording(d: RecordedDeployment):
    """The collision check of a recording's joint states, done as the
    ``collision_monitor`` node does it on the same stream: message by
    message through :class:`~panel_deploy.collision.StreamCheck` with the
    scene's ``collision`` settings (noise, stamps, speed interval), hinges
    the stream lacks solved from the loop closure, gaps counted, and each
    joint state's contact onset beside it.

    Returns ``(stream, report)``: the StreamCheck (its :meth:`verdict`) and
    the first deployment's :class:`~panel_deploy.collision.check.CollisionReport`.
    """
    from ..collision import CollisionSettings, StreamCheck

    settings = CollisionSettings.from_scene(d.scene)
    stream = StreamCheck(d.model, settings)
    states = d.states
    for j, t in enumerate(states.t):
        if stream.check is not None and t <= stream.origin and stream.check.checked > 1:
            break  # the stream starts again (a replay, the next run): one deployment is checked
        velocity = None if states.velocity is None else states.velocity[j]
        try:
            stream.update_joints(float(t), states.names, states.position[j], velocity,
                                 d.onsets[j])
        except PanelDeployError as e:  # refused as the node refuses it: counted, skipped
            stream.refuse(str(e).split(":", 1)[0][:40])
    if stream.check is None:
        raise TrajectoryError(f"{d.recording.path}: no joint state could be checked "
                              f"({', '.join(f'{k}: {v}' for k, v in stream.refused.items())})")
    return stream, stream.check.report()
