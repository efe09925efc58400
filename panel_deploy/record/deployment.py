"""Recording a deployment as it is computed: ``simulate --record`` and ``optimise --record``.

The samples of :class:`panel_deploy.dynamics.deployment.Deployment` go to a
:class:`~.writer.DeploymentWriter` (the one recording path, also the
recorder node's) as they come, in batches of :data:`BATCH`, so a recording
cut short keeps what was computed up to its last closed chunk. At t = 0:
``/robot_description``, ``/panel_deploy/model`` and what the deployment runs
(:meth:`~.writer.DeploymentWriter.deployed`). Each sample t_j (simulated s,
also the MCAP log time) writes ``/clock``, ``/joint_states``,
``/panel_deploy/panels`` and ``/tf``; the collision check runs on the same
samples as ``panel-deploy simulate`` (the paper's D_j, stopping at the first
collision) and writes each collision event to
``panel_deploy/collision_events`` and ``panel_deploy/collision_markers`` at
the sample that revealed it. At the end, the outcome and the monitor's
verdict on ``/diagnostics`` and the verdict on ``collision_monitor/verdict``
(as the nodes send them) and as the ``outcome`` metadata record.
"""

from __future__ import annotations

from .. import contract
from ..contract.cdr import SampleEncoder
from ..collision import CollisionSettings, StreamCheck
from ..collision.stream import onset_fields
from ..dynamics.deployment import Deployment
from ..errors import SceneError
from ..export.urdf import model_urdf
from ..kinematics import forward_kinematics
from ..scene_text import scene_yaml
from ..summary import deployment_summary
from . import messages as m
from .writer import DeploymentWriter

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


def check_recordable(scene, flag: str = "--record") -> None:
    """Refuse, before any work, a run whose samples a recording cannot tell
    apart: stamps count whole nanoseconds, so samples closer than 1 ns would
    share one and the recording could not be read back.

    Raises
    ------
    SceneError
        Naming ``flag`` and what to change.
    """
    sim = scene.simulation
    interval = sim.t_end / (sim.samples - 1)
    if contract.nanoseconds(interval) < 1:
        raise SceneError(flag, f"samples {interval:.3g} s apart (simulation.t_end / "
                               f"(simulation.samples - 1)) cannot be told apart in a recording, "
                               f"whose stamps count whole nanoseconds: give simulation.t_end >= "
                               f"{(sim.samples - 1) * 1e-9:.3g} s or fewer samples")


def record_deployment(path, scene, model):
    """Simulate ``model`` as ``scene.simulation`` asks, check it for collisions
    and record it all to ``path`` while it is computed.

    Returns ``(result, report)`` equal to what
    :func:`panel_deploy.pipeline.simulate_scene` gives for the same model.
    """
    settings = CollisionSettings.from_scene(scene)
    sim = scene.simulation
    monitor = contract.status_name("", "collision_monitor")
    with DeploymentWriter(path) as rec:
        rec.write(contract.ROBOT_DESCRIPTION, m.string(model_urdf(model)))
        rec.write(contract.MODEL, m.string(scene_yaml(scene)))
        rec.deployed(scene, model, scene_yaml(scene, model), scene.source)
        deployment = Deployment(model, sim)
        check = StreamCheck(model, settings)
        n = model.n_coords
        encoder = SampleEncoder(model)
        for batch in _batches(deployment, BATCH):
            for s, (clock, joint_state, panels, tf) in zip(batch, encoder.encode(batch)):
                ns = m.nanoseconds(s.t)
                rec.write(contract.CLOCK_TOPIC, clock, ns)
                rec.write(contract.JOINT_STATES, joint_state, ns)
                if model.contact_pairs:
                    rec.write(contract.CONTACT_ONSETS, encoder.onset(s.t, s.onset), ns)
                rec.write(contract.PANELS, panels, ns)
                rec.write(contract.TF, tf, ns)
                if check.check is None or not check.check.collided:
                    # as the monitor takes dynamics/contact_onsets
                    onset = onset_fields(model, s.onset) if model.contact_pairs else None
                    events = check.update(s.t, s.theta[:n], s.omega[:n], onset)
                    if events:
                        for e in events:
                            rec.write(contract.COLLISION_EVENTS, m.collision_event(e), ns)
                        R, p = forward_kinematics(model, s.theta[:n])[:2]
                        rec.write(contract.COLLISION_MARKERS,
                                  m.collision_markers(model, events[0], R, p), ns)
        result = deployment.result
        report = check.check.report()
        summary = deployment_summary(model, result, report, flat_tolerance=sim.flat_tolerance)
        level, text, values = check.verdict()
        t_end = float(result.t[-1])
        rec.write(contract.DIAGNOSTICS, m.diagnostics(
            t_end, m.outcome_status(contract.status_name("", "dynamics"), summary, len(result.t)),
            m.status(monitor, level, text, values)), m.nanoseconds(t_end))
        rec.write(contract.VERDICT, m.verdict(level, text, values, t_end), m.nanoseconds(t_end))
        rec.close(summary)
    return result, report


def record_optimum(path, scene, result_file):
    """``optimise --record``: record the deployment of the result written to
    ``result_file`` (``optimise --out``) with the scene's simulation settings.

    The result is deployed by the one rule for result files
    (:func:`~panel_deploy.configure.result_model`) on the scene with the c/k the
    search found (``hinges.damping_ratio``, when it searched one), so that the
    recording's scene says what was deployed."""
    from ..build import build_model
    from ..configure import damping_ratio_of, result_model
    from ..scene import apply_overrides, scene_from_dict
    from ..scene_text import yaml_value

    model = build_model(scene)
    deployed, c_file = result_model(scene, model, result_file)
    ratio = damping_ratio_of(deployed, c_file)
    if ratio is not None and ratio != scene.hinges.damping_ratio:
        scene = scene_from_dict(apply_overrides(
            scene.data, [f"hinges.damping_ratio={yaml_value(ratio)}"]), source=scene.source)
        deployed = result_model(scene, model, result_file)[0]
    return record_deployment(path, scene, deployed)
