"""The shipped 10 x 10 design (config/scenes/array_10x10.yaml, issue 33).

Circuit 525, merged to 90 bodies on one loop, deploys collision-free to flat on
uniform springs K_0 damped at c/k 3 s, and collides on its way at c/k 2 s
(r8c7 - r8c8 at 5.05 s, 0.067 m/s; docs/findings.md 4.8). Simulated at the search's tolerance (optimisation.rtol),
as the search judges it; the scene's own tolerance gives the same verdicts.
"""

from dataclasses import replace

import numpy as np
import pytest

from panel_deploy.build import build_model
from panel_deploy.fold import design, kutzbach_dof
from panel_deploy.fold.kutzbach import body_joints
from panel_deploy.optimise import evaluate
from panel_deploy.scene import IMPACT_SPEED, load_scene, resolve_scene


@pytest.fixture(scope="module")
def scene():
    s = load_scene(resolve_scene("array_10x10"))
    rtol = s.optimisation.rtol
    return s.replace(simulation=replace(s.simulation, rtol=rtol,
                                        atol=s.simulation.atol * rtol / s.simulation.rtol))


@pytest.fixture(scope="module")
def model(scene):
    return build_model(scene)


def test_the_scene_folds_along_circuit_525_merged_to_dof_84(scene, model):
    assert scene.fold.circuit == 525
    d = design(10, 10, 525)
    assert d.stowed is not None
    assert (len(d.bodies), len(d.hinges), len(body_joints(d.bodies, d.hinges))) == (90, 100, 90)
    assert kutzbach_dof(90, 90) == 84 == d.dof_bodies < d.dof_cells == 94
    assert (len(model.bodies), len(model.hinges), len(model.cut_hinges)) == (90, 90, 1)


@pytest.mark.parametrize("ratio, deploys", [(3.0, True), (2.0, False)])
def test_uniform_springs_deploy_flat_without_collision_only_if_damped_heavily(
        scene, model, ratio, deploys):
    ks = np.full(len(model.hinges), scene.hinges.stiffness)
    o = evaluate(model, ks, scene, c=ratio * ks).outcome
    assert o.simulated
    assert o.feasible == deploys and o.collided != deploys
    if deploys:
        assert 15.0 < o.t_stop < scene.simulation.t_end
        assert o.flat_residual <= scene.simulation.flat_tolerance
        assert o.d > 0.05   # m, the closest two panels came that are not in contact
    else:
        assert o.t_stop < 15.0 and o.v > IMPACT_SPEED and o.flat_residual > 0.5
