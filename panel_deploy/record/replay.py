"""A recorded deployment logged to rerun (what ``panel-deploy replay`` shows).

What is logged (timeline ``sim_time``: the joint states' stamps, s; one
frame per joint state):

- ``world/panels/<body>``: every panel a box of its true size (thickness
  included, static ``half_sizes``), posed each frame by a ``Transform3D``
  (centroid and rotation from the model's forward kinematics of the
  recorded angles); the panels of the first collision turn red at the
  sample that reveals it (the motion after it is not physical).
- ``world/collisions``: the contact point of each first-collision event.
- ``hinges/<name>``: every joint of ``/joint_states`` (rad).
- ``energy/<kind>``: kinetic, spring (hinge springs, joint-limit contact
  and closure penalty springs) and gravity energy and their sum (J), from the
  model at the recorded angles and rates (kinetic and the sum need rates).
- ``distance/d``: the smallest distance between panels that share no hinge
  (m), up to the first collision.
- ``events``: one text line per first-collision event, at its sample.
- ``world/model/<body>``, ``hinges/<name>/model``: with ``compared`` (``replay
  --compare SCENE``, :mod:`.compare`), that scene's simulated deployment at the
  same times, grey boxes beside the measured ones.
- ``monitor``: what the recording's own collision monitor said, as recorded
  (``CollisionEvent`` and ``MonitorVerdict`` messages: each event, and each
  verdict that changes level or text), at its stamp on the same timeline; a
  live run's monitor saw the stream as it came, which the check above repeats.

The blueprint opens on the 3D view beside the plots and the two logs.
"""

from __future__ import annotations

import numpy as np

from .analysis import RecordedDeployment

TIMELINE = "sim_time"
PANEL_RGBA = (64, 115, 217, 255)
GROUND_RGBA = (217, 140, 51, 255)
HIT_RGBA = (242, 38, 26, 255)
MODEL_RGBA = (160, 160, 160, 110)


def body_poses(d: RecordedDeployment):
    """``(R, p)``: every body's rotation (s, nb, 3, 3) and centroid (s, nb, 3, m) at every sample."""
    return poses(d.model, d.track.theta)


def poses(model, thetas):
    """``(R, p)`` of ``model``'s bodies at each row of tree angles ``thetas`` (rad)."""
    from ..kinematics import forward_kinematics

    out = [forward_kinematics(model, theta) for theta in thetas]
    return np.array([R for R, _ in out]), np.array([p for _, p in out])


def energies(d: RecordedDeployment) -> dict:
    """Kinetic, spring and gravity energy and their sum (J) at every sample;
    only spring and gravity when the recording has no rates."""
    from ..dynamics.kernels import ACCUMULATORS, observe_samples, state_vector
    from ..dynamics.pack import pack

    P, n = pack(d.model), d.model.n_coords
    has_rates = not isinstance(d.track.omega, list)
    Y = np.empty((len(d.track.theta), 2 * n + ACCUMULATORS))
    for j, theta in enumerate(d.track.theta):
        Y[j] = state_vector(theta, d.track.omega[j] if has_rates else np.zeros(n))
    # one compiled pass over the samples: observe from Python types the
    # scratch it takes anew at each call (~0.2 ms a sample)
    energy = observe_samples(P, Y)[4]
    kinetic, spring, _, gravity = energy.T.copy()
    out = {"spring": spring, "gravity": gravity}
    return out | ({"kinetic": kinetic, "total": kinetic + spring + gravity} if has_rates else {})


def collision_events(d: RecordedDeployment):
    """``(distance, events)``: the smallest distance (m) at every sample up to
    the first collision (nan after it: the motion is no longer physical), and
    that collision's events (every pair colliding at the sample that reveals
    it), as ``collide`` finds them, contact onsets included."""
    from ..collision import CollisionSettings, StreamCheck

    stream = StreamCheck(d.model, CollisionSettings.from_scene(d.scene))
    distance = np.full(len(d.track.t), np.nan)
    for j, t in enumerate(d.states.t):  # the stamps' clock, which the onsets' times are in
        if stream.update(float(t), d.track.theta[j], d.track.omega[j], d.onsets[j]):
            break
        distance[j] = stream.check.monitor.min_distance
    return distance, stream.check.first_events


def recorded_monitor(d: RecordedDeployment) -> list:
    """``[(t, level, text)]``: every collision event and every change of the
    verdict that the recording's collision monitor published (t in s on the
    joint states' timeline, level 0 OK, 1 WARN, 2 ERROR); empty for a
    recording without them (a real array's, or one of an older format)."""
    from .. import contract
    from .messages import seconds

    rec, out = d.recording, []
    topic = rec.topic(contract.COLLISION_EVENTS)
    if rec.topics.get(topic) == contract.COLLISION_EVENT:
        for _, e in rec.messages(topic):
            out.append((seconds(e.header.stamp) - d.track.t0, contract.ERROR,
                        f"{contract.event_text(e.body_a, e.body_b, e.t)}, approach speed "
                        f"{e.approach_speed:.4f} m/s"))
    topic, said = rec.topic(contract.VERDICT), None
    if rec.topics.get(topic) == contract.MONITOR_VERDICT:
        for _, v in rec.messages(topic):
            if (v.level, v.message) != said:
                said = (v.level, v.message)
                out.append((seconds(v.header.stamp) - d.track.t0, int(v.level),
                            f"verdict: {v.message} ({v.samples} samples checked)"))
    return sorted(out, key=lambda x: x[0])


def _duration(t):
    """Seconds as exact nanosecond durations (a float second count would be truncated)."""
    return np.round(np.asarray(t) * 1e9).astype(np.int64).astype("timedelta64[ns]")


def _path(*parts) -> str:
    import rerun as rr
    return "/".join(rr.escape_entity_path_part(p) for p in parts)


def log_deployment(stream, d: RecordedDeployment, compared=None) -> int:
    """Log ``d`` (and a :class:`~.compare.Compared` deployment beside it) to the
    rerun ``stream``; returns the frames logged (one per joint state)."""
    import rerun as rr

    t = d.track.t
    time = [rr.TimeColumn(TIMELINE, duration=_duration(t))]
    model = d.model
    R, p = body_poses(d)
    distance, events = collision_events(d)
    hit = {b: int(e.sample) for e in events for b in e.bodies}
    stream.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    for b, body in enumerate(model.bodies):
        path = _path("world", "panels", body.name)
        stream.log(path, rr.Boxes3D(half_sizes=[np.asarray(body.size) / 2], labels=[body.name]),
                   static=True)
        stream.send_columns(path, time, rr.Transform3D.columns(translation=p[:, b],
                                                               mat3x3=R[:, b]))
        colour = GROUND_RGBA if b == model.ground else PANEL_RGBA
        stream.set_time(TIMELINE, duration=_duration(t[0]))
        stream.log(path, rr.Boxes3D.from_fields(colors=[colour]))
        if b in hit:
            stream.set_time(TIMELINE, duration=_duration(t[hit[b]]))
            stream.log(path, rr.Boxes3D.from_fields(colors=[HIT_RGBA]))
    positions = d.states.position
    for k, name in enumerate(d.states.names):
        stream.log(_path("hinges", name), rr.SeriesLines(names=[name]), static=True)
        stream.send_columns(_path("hinges", name), time, rr.Scalars.columns(scalars=positions[:, k]))
    for kind, values in energies(d).items():
        stream.send_columns(_path("energy", kind), time, rr.Scalars.columns(scalars=values))
    finite = np.isfinite(distance)
    stream.send_columns(_path("distance", "d"), [rr.TimeColumn(TIMELINE, duration=_duration(t[finite]))],
                        rr.Scalars.columns(scalars=distance[finite]))
    for e in events:
        stream.set_time(TIMELINE, duration=_duration(t[e.sample]))
        speed = e.approach_speed if np.isfinite(e.approach_speed) else e.normal_speed
        stream.log("events", rr.TextLog(f"collision between {e.names[0]} and {e.names[1]} at "
                                        f"t = {e.t:.4f} s, approach speed {speed:.4f} m/s",
                                        level=rr.TextLogLevel.ERROR))
        stream.log(_path("world", "collisions"), rr.Points3D([e.point], colors=[HIT_RGBA],
                                                             radii=[0.004]))
    if compared is not None:
        Rm, pm = poses(compared.model, compared.theta)
        for b, body in enumerate(compared.model.bodies):
            path = _path("world", "model", body.name)
            stream.log(path, rr.Boxes3D(half_sizes=[np.asarray(body.size) / 2],
                                        colors=[MODEL_RGBA]), static=True)
            stream.send_columns(path, time, rr.Transform3D.columns(translation=pm[:, b],
                                                                   mat3x3=Rm[:, b]))
        for k, name in enumerate(compared.names):
            stream.send_columns(_path("hinges", name, "model"), time,
                                rr.Scalars.columns(scalars=compared.theta[:, k]))
    levels = (rr.TextLogLevel.INFO, rr.TextLogLevel.WARN, rr.TextLogLevel.ERROR)
    for when, level, text in recorded_monitor(d):
        stream.set_time(TIMELINE, duration=_duration(max(when, 0.0)))
        stream.log("monitor", rr.TextLog(text, level=levels[min(level, 2)]))
    return len(t)


def blueprint():
    """The 3D view of the array beside hinge angles, energies, distance and events."""
    import rerun.blueprint as rrb

    return rrb.Blueprint(rrb.Horizontal(
        rrb.Spatial3DView(origin="world", name="panels"),
        rrb.Vertical(rrb.TimeSeriesView(origin="hinges", name="hinge angles (rad)"),
                     rrb.TimeSeriesView(origin="energy", name="energy (J)"),
                     rrb.TimeSeriesView(origin="distance", name="smallest distance d (m)"),
                     rrb.TextLogView(origin="events", name="collision events"),
                     rrb.TextLogView(origin="monitor", name="recorded monitor")),
        column_shares=[3, 2]), collapse_panels=True)
