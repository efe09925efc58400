"""The shipped 5 x 6 design (config/scenes/array_5x6.yaml, issue 33).

Circuit 134, merged to 24 bodies, deploys collision-free to flat on uniform
springs once the hinges are damped heavily enough, and collides near flat when
they are not (docs/findings.md 4.7): what the scene's c/k bounds rely on.
"""

import numpy as np
import pytest

from panel_deploy.build import build_model
from panel_deploy.fold import design, kutzbach_dof
from panel_deploy.fold.kutzbach import body_joints
from panel_deploy.optimise import evaluate
from panel_deploy.scene import load_scene, resolve_scene


@pytest.fixture(scope="module")
def scene():
    return load_scene(resolve_scene("array_5x6"))


def test_the_scene_folds_along_circuit_134_merged_to_dof_18(scene):
    d = design(5, 6, scene.fold.circuit)
    assert d.stowed is not None
    # 30 hinge segments: 2 inside merged bodies, 4 pairs collinear between the same two.
    assert (len(d.bodies), len(d.hinges), len(body_joints(d.bodies, d.hinges))) == (24, 30, 24)
    # Kutzbach, 6 (n - 1) - 5 j, of the merged bodies against the cells' 24.
    assert kutzbach_dof(24, 24) == 18 == d.dof_bodies < d.dof_cells == 24
    model = build_model(scene)
    assert (len(model.bodies), len(model.hinges)) == (24, 24)


@pytest.mark.parametrize("ratio, feasible", [(1.0, True), (0.3, False)])
def test_uniform_springs_deploy_flat_without_collision_only_when_heavily_damped(scene, ratio, feasible):
    model = build_model(scene)
    k = np.full(len(model.hinges), 0.1)
    o = evaluate(model, k, scene, c=ratio * k).outcome
    assert o.simulated
    assert o.feasible == feasible
    if feasible:
        assert o.t_stop < scene.simulation.t_end and o.flat_residual <= scene.simulation.flat_tolerance
    else:
        # Not a stall: the light damping lets it collide on its way, within 0.5 rad of flat.
        assert o.collided and 0.05 < o.flat_residual < 0.5
