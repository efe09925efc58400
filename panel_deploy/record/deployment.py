"""Recording a deployment as it is computed: ``simulate --record`` and ``optimise --record``.

The samples of :class:`panel_deploy.live.Deployment` go to the file as
they come (in batches of :data:`BATCH`), so a recording cut short keeps what
was computed up to its last closed chunk. First the metadata records
``scene``, ``model``, ``integrator`` and ``run`` and a channel for every
topic of :data:`~.messages.TOPICS`. Each sample t_j (simulated s, also the MCAP log time) writes
``/clock``, ``/joint_states``, ``/panel_deploy/panels`` and ``/tf``; the
collision check runs on the same samples as ``panel-deploy simulate`` (the
paper's D_j, stopping at the first collision) and writes each collision event
to ``/panel_deploy/collision_events`` at the sample that revealed it. At t = 0:
``/robot_description``, ``/panel_deploy/model`` and ``/tf_static``; at the
end, the outcome on ``/diagnostics`` and as the ``outcome`` metadata record.
"""

from __future__ import annotations

from pathlib import Path


from ..collision import CollisionSettings, StreamCheck
from ..export.urdf import model_urdf
from ..live import Deployment, scene_yaml
from ..summary import deployment_summary
from . import messages as m
from .cdr import SampleEncoder
from .writer import Recorder, run_metadata

#: Samples encoded together (vectorised poses): 50 ms of simulated time at 200 Hz.
BATCH = 10


def _batches(samples, size):
    """Lists of up to ``size`` consecutive items of ``samples``."""
    batch = []
    for s in samples:
        batch.append(s)
        if len(batch) == size:
            yield batch
            batch = []
    if batch:
        yield batch


def _relative(source) -> str:
    """A scene file relative to the working directory when it lies below it."""
    if not source:
        return ""
    path = Path(source).resolve()
    return str(path.relative_to(Path.cwd())) if path.is_relative_to(Path.cwd()) else str(source)


def _model_record(model) -> dict:
    c = model.closure
    return {"hinges": [h.name for h in model.hinges],
            "stiffness": [float(h.k) for h in model.hinges],           # N m/rad, one spring
            "damping": [float(h.c) for h in model.hinges],             # N m s/rad, one spring
            "springs": [int(h.springs) for h in model.hinges],
            "k_s": float(model.k_s), "c_s": float(model.c_s),
            "closure": c.method, "k_M": c.k_M, "c_M": c.c_M, "k_N": c.k_N, "c_N": c.c_N,
            "gravity": [float(g) for g in model.gravity]}


def _integrator_record(scene) -> dict:
    s = scene.simulation
    return {"method": s.method, "rtol": s.rtol, "atol": s.atol, "t_end": s.t_end,
            "samples": s.samples, "rate_hz": (s.samples - 1) / s.t_end,
            "flat_tolerance": s.flat_tolerance, "collision_tolerance": scene.collision.tolerance}


def outcome_record(summary: dict) -> dict:
    """The ``outcome`` metadata record of a :func:`deployment_summary` with its
    collision part: success, time to flat (s), first collision (t s, pair,
    approach speed v m/s) and the smallest distance d (m)."""
    c = summary["collision"]
    first = c["first_collision"]
    return {"success": bool(summary["success"]), "message": summary["message"],
            "t_end": summary["t_end"], "time_to_flat": summary["time_to_flat"],
            "collided": c["collided"],
            "first_collision_t": None if first is None else float(first["t"]),
            "first_collision_pair": None if first is None else list(first["pair"]),
            "approach_speed": float(c["v"]) if first is not None else None,
            "d": None if c["d"] is None else float(c["d"]), "wall_time": summary["wall_time"]}


def record_deployment(path, scene, model):
    """Simulate ``model`` as ``scene.simulation`` asks, check it for collisions
    and record it all to ``path`` while it is computed.

    Returns ``(result, report)`` equal to what
    :func:`panel_deploy.pipeline.simulate_scene` gives for the same model.
    """
    settings = CollisionSettings.from_scene(scene)
    sim = scene.simulation
    scene_text = scene_yaml(scene, model)
    with Recorder(path) as rec:
        rec.metadata("scene", {"name": scene.name or "", "source": _relative(scene.source),
                               "yaml": scene_text})
        rec.metadata("model", _model_record(model))
        rec.metadata("integrator", _integrator_record(scene))
        rec.metadata("run", run_metadata())
        for topic, (typename, _) in m.TOPICS.items():  # every topic, even one left empty
            rec.channel(topic, typename)
        rec.write("/robot_description", m.STRING, m.string(model_urdf(model)), 0)
        rec.write("/panel_deploy/model", m.STRING, m.string(scene_text), 0)
        rec.write("/tf_static", m.TF_MESSAGE, m.tf_static(model), 0)
        deployment = Deployment(model, sim)
        check = StreamCheck(model, settings)
        n = model.n_coords
        encoder = SampleEncoder(model, check.names)
        for batch in _batches(deployment, BATCH):
            for s, (clock, joint_state, panels, tf) in zip(batch, encoder.encode(batch)):
                ns = m.nanoseconds(s.t)
                rec.write("/clock", m.CLOCK, clock, ns)
                rec.write("/joint_states", m.JOINT_STATE, joint_state, ns)
                rec.write("/panel_deploy/panels", m.MARKER_ARRAY, panels, ns)
                rec.write("/tf", m.TF_MESSAGE, tf, ns)
                if check.check is None or not check.check.collided:
                    events = check.update(s.t, s.theta[:n], s.omega[:n])
                    if events:
                        rec.write("/panel_deploy/collision_events", m.DIAGNOSTIC_ARRAY,
                                  m.diagnostics(s.t, *(m.event_status(e) for e in events)), ns)
        result = deployment.result
        report = check.check.report()
        summary = deployment_summary(model, result, report, flat_tolerance=sim.flat_tolerance)
        level, text, values = check.verdict()
        t_end = float(result.t[-1])
        rec.write("/diagnostics", m.DIAGNOSTIC_ARRAY, m.diagnostics(
            t_end, m.outcome_status(summary),
            m.status(m.MONITOR_STATUS, level, text, values)), m.nanoseconds(t_end))
        rec.metadata("outcome", outcome_record(summary))
    return result, report


def record_optimum(path, scene, result_file):
    """``optimise --record``: record the deployment of the K and c written to
    ``result_file`` (the result of ``optimise --out``) with the scene's simulation settings."""
    from ..build import build_model
    from ..optimise import load_hinges

    model = build_model(scene)
    k, c = load_hinges(result_file, model)
    return record_deployment(path, scene, model.with_stiffness(k, c))
