"""configure, dynamics.deployment, scene_text and timing: the ROS-free core of the nodes, checked against the batch core."""


import time

import numpy as np
import pytest
from hostile import alias_bomb

from panel_deploy.build import build_model
from panel_deploy.dynamics import simulate
from panel_deploy.dynamics.report import hinge_states
from panel_deploy.errors import SceneError
from panel_deploy.dynamics.deployment import Deployment
from panel_deploy.configure import DynamicsParameters, apply_stiffness, configure
from panel_deploy.timing import Pacer
from panel_deploy.scene_text import optimisation_scene, scene_from_yaml, scene_yaml
from panel_deploy.scene import load_scene, resolve_scene


@pytest.fixture(scope="module")
def scene():
    return load_scene(resolve_scene("paper_4x4"))


@pytest.fixture(scope="module")
def short(scene):
    return configure(scene, DynamicsParameters(t_end=0.5, rate_hz=200.0))


def test_configure_sets_samples_from_the_rate(short):
    scene, model = short
    assert scene.simulation.t_end == 0.5 and scene.simulation.samples == 101


@pytest.mark.parametrize("params, message", [
    # issue 26: 800,001 samples, +467 MB, past the scene schema's ten minutes
    ({"t_end": 4000.0}, r"^t_end: expected a number <= 600, got 4000 \(limit: "),
    ({"t_end": 300.0}, r"^rate_hz: 200 Hz over 300 s gives 60001 samples: expected an integer "
                       r"<= 50000, got 60001 \(limit: memory"),
    ({"t_end": 0.005}, r"^rate_hz: 200 Hz over 0.005 s gives 2 samples: expected an integer >= 3"),
    ({"rtol": 1e-13}, r"^rtol: expected a number >= 1e-12, got 1e-15 .*\(scene key "
                     r"simulation\.atol\)$"),
])
def test_configure_keeps_the_scene_schemas_limits(scene, params, message):
    with pytest.raises(SceneError, match=message):
        configure(scene, DynamicsParameters(**params))


def test_configure_checks_the_step_budget_with_the_scenes_max_step():
    scene = load_scene(resolve_scene("paper_4x4"), ["simulation.max_step=1e-4"])
    with pytest.raises(SceneError, match=r"^t_end: t_end / max_step = 3e\+06 steps is above the "
                                         r"step budget .*\(scene key simulation\.max_step\)$"):
        configure(scene, DynamicsParameters(t_end=300.0, rate_hz=1.0))


def test_configured_scene_carries_what_it_runs(short):
    scene, _ = short  # what /panel_deploy/model and recordings write of it
    assert scene.data["simulation"]["t_end"] == 0.5 and scene.data["simulation"]["samples"] == 101


def test_deployment_streams_the_batch_trajectory(short):
    scene, model = short
    deployment = Deployment(model, scene.simulation, block=7)
    samples = list(deployment)
    batch = simulate(model, scene.simulation)
    assert len(samples) == len(batch.t) == 101
    names, theta, omega, torque = hinge_states(model, batch)
    assert deployment.names == names
    got = np.array([s.theta for s in samples])
    assert np.abs(got - theta).max() <= 1e-9
    assert np.abs(np.array([s.omega for s in samples]) - omega).max() <= 1e-9
    assert np.allclose(deployment.result.position, batch.position, atol=1e-9)


def test_stopped_deployment_keeps_its_samples_and_says_so(short):
    scene, model = short
    deployment = Deployment(model, scene.simulation, block=5)
    seen = 0
    for _ in deployment:
        seen += 1
        if seen == 3:
            deployment.stop()
    result = deployment.result
    assert len(result.t) == seen == 6  # the first block: start sample + 5
    assert not result.success and result.status == 1 and "stopped" in result.message


def test_hinge_states_cut_hinge_rate_is_the_angle_derivative(short):
    from panel_deploy.dynamics import closure
    from panel_deploy.dynamics.pack import pack
    from panel_deploy.kinematics import forward_kinematics
    scene, model = short
    result = simulate(model, scene.simulation)
    names, theta, omega, torque = hinge_states(model, result)
    cut = len(names) - 1
    assert names[cut] == model.hinges[model.cut_hinges[0]].name
    P = pack(model)

    def cut_angle(q):
        return closure.cut_angles(P, forward_kinematics(model, q)[0][P.body])[0]

    eps = 1e-6
    for j in range(0, len(result.t), 10):
        q, w = result.theta[j], result.omega[j]
        derivative = (cut_angle(q + eps * w) - cut_angle(q - eps * w)) / (2 * eps)
        assert omega[j, cut] == pytest.approx(derivative, rel=1e-6, abs=1e-7)
        assert theta[j, cut] == pytest.approx(cut_angle(q), abs=1e-12)
    h = model.hinges[model.joints[0]]
    expected = -h.k_hinge * theta[:, 0] - h.c_hinge * omega[:, 0]
    inside = (theta[:, 0] >= 0) & (theta[:, 0] <= np.pi)
    assert inside.sum() > 10
    assert np.allclose(torque[inside, 0], expected[inside], rtol=1e-12, atol=1e-15)


def test_apply_stiffness_per_group_and_per_hinge(scene):
    model = build_model(scene)
    groups = model.hinge_groups
    k = apply_stiffness(model, [0.01 * (g + 1) for g in range(len(groups))]).stiffness
    for g, idx in enumerate(groups):
        assert np.allclose(k[list(idx)], 0.01 * (g + 1))
    per_hinge = np.linspace(0.01, 0.12, len(model.hinges))
    m = apply_stiffness(model, per_hinge, damping_ratio=0.2)
    assert np.allclose(m.stiffness, per_hinge)
    assert np.allclose([h.c for h in m.hinges], 0.2 * per_hinge)
    with pytest.raises(SceneError, match=r"^stiffness: expected \d+ values"):
        apply_stiffness(model, [0.1, 0.1])


@pytest.mark.parametrize("field, value, match", [
    ("stiffness", (-0.1,), "stiffness"), ("stiffness", (float("nan"),), "stiffness"),
    ("rate_hz", 0.0, "rate_hz"), ("real_time_factor", -1.0, "real_time_factor"),
    ("method", "Euler", "method"), ("closure", "glue", "closure"), ("rtol", 2.0, "rtol"),
    ("t_end", float("inf"), "t_end"), ("t_end", 4000.0, "t_end"),
])
def test_dynamics_parameters_name_the_bad_field(field, value, match):
    with pytest.raises(SceneError, match=f"^{match}:"):
        DynamicsParameters(**{field: value})


def test_scene_text_round_trips_with_stiffness(scene):
    model = build_model(scene)
    k = np.linspace(0.02, 0.13, len(model.hinges))
    again = build_model(scene_from_yaml(scene_yaml(scene, model.with_stiffness(k))))
    assert np.allclose(again.stiffness, k)
    with pytest.raises(SceneError, match="not valid YAML"):
        scene_from_yaml("array: [1, 2")


def test_a_model_message_with_an_alias_bomb_is_refused_at_once():
    # one such message on /panel_deploy/model took down collision_monitor and dynamics
    start = time.perf_counter()
    with pytest.raises(SceneError, match=r"^/panel_deploy/model: not valid YAML \(at line 1, "
                                         r"column \d+: aliases expand it beyond 1000000"):
        scene_from_yaml(alias_bomb(key="array"))
    assert time.perf_counter() - start < 0.5


def test_optimisation_scene_validates_overrides(scene):
    s = optimisation_scene(scene, max_evaluations=7, method="", damping_ratio_bounds=(0.043, 0.3))
    assert s.optimisation.max_evaluations == 7 and s.optimisation.damping_ratio_bounds == (0.043, 0.3)
    assert s.optimisation.method == scene.optimisation.method
    with pytest.raises(SceneError, match=r"optimisation\.max_evaluations"):
        optimisation_scene(scene, max_evaluations=-3)


def test_pacer_keeps_real_time():
    import time
    pacer = Pacer(2.0)
    start = time.monotonic()
    for t in (0.0, 0.1, 0.2):
        pacer.wait(t)
    assert 0.09 <= time.monotonic() - start < 0.5
    fast = Pacer(0.0)
    start = time.monotonic()
    fast.wait(100.0)
    assert time.monotonic() - start < 0.05
