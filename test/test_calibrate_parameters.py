"""Calibration of stiffness per group and of the air drag, fitted directly on
simulated angles; what the calibrated scene writes for them; and the
warning when the data cannot determine a parameter."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from panel_deploy.build import build_model
from panel_deploy.calibrate import Measured, calibrate, parameters
from panel_deploy.calibrate.residuals import Residuals
from panel_deploy.calibrate.scene_out import calibrated_data
from panel_deploy.dynamics.hinge_trajectory import simulate_hinges
from panel_deploy.calibrate.uncertainty import uncertainty
from panel_deploy.model import hinge_order
from panel_deploy.scene import load_scene, resolve_scene, scene_from_dict

T_END = 0.12
#: Two stiffness groups of the paper scene, both with hinges that move in the first 0.12 s.
OUTER = ["r1c1-r1c2", "r1c3-r1c4", "r1c1-r2c1", "r1c4-r2c4", "r2c1-r3c1", "r2c4-r3c4",
         "r3c1-r4c1", "r3c4-r4c4"]
INNER = ["r2c2-r3c2", "r3c2-r4c2", "r4c1-r4c2", "r4c3-r4c4"]
RELEASE = 0.02


def scene(*overrides):
    return load_scene(resolve_scene("paper_4x4"), [f"simulation.t_end={T_END}", *overrides])


def measured(truth, simulation, seed=None) -> Measured:
    """Every hinge of ``truth`` at 500 Hz, released RELEASE s after the first
    sample; with 1e-3 rad noise if ``seed`` is given."""
    names = tuple(truth.hinges[h].name for h in hinge_order(truth))
    t = np.arange(0.0, RELEASE + T_END, 0.002)
    theta = simulate_hinges(truth, simulation, T_END, names).angles(t - RELEASE)
    if seed is not None:
        theta += np.random.default_rng(seed).normal(0.0, 1e-3, theta.shape)
    return Measured("synthetic", names, t, theta, 0.0)


def test_stiffness_per_group_is_recovered_and_written_as_overrides_that_rebuild_it():
    groups = f"hinges.groups=[{OUTER}, {INNER}]".replace("'", "")
    nominal_scene = scene(groups)
    truth = build_model(scene(groups, f"hinges.overrides={{{', '.join(f'{h}: 0.12' for h in INNER)}}}"))
    model = build_model(nominal_scene)
    fitted = parameters(model, ("stiffness",), "group")
    assert fitted.names == ("stiffness[r1c1-r1c2]", "stiffness[r2c2-r3c2]")
    result = calibrate(fitted, [measured(truth, nominal_scene.simulation)],
                       nominal_scene.simulation)
    assert result.success
    assert result.values == pytest.approx([1.0, 1.2], rel=1e-3)
    data = calibrated_data(nominal_scene, result)
    rebuilt = build_model(scene_from_dict(data))
    assert [h.k for h in rebuilt.hinges] == pytest.approx([h.k for h in result.model.hinges],
                                                           rel=1e-12)
    assert [h.c for h in rebuilt.hinges] == pytest.approx([h.c for h in result.model.hinges],
                                                           rel=1e-12)
    section = data["calibration"]["deployment"]["parameters"]["stiffness[r2c2-r3c2]"]
    assert sorted(section["hinges"]) == sorted(INNER) and section["identifiable"]


def test_drag_and_damping_are_recovered_from_a_deployment_in_air():
    air = scene("air.density=1.2")
    truth = parameters(build_model(air), ("damping", "drag")).model_at([1.3, 1.6])
    fitted = parameters(build_model(air), ("damping", "drag"))
    result = calibrate(fitted, [measured(truth, air.simulation, seed=3)], air.simulation,
                       noise=1e-3)
    assert result.success and not result.uncertainty.problems
    assert result.values == pytest.approx([1.3, 1.6], rel=0.05)
    data = calibrated_data(air, result)
    assert data["air"]["drag_coefficient"] == pytest.approx(result.values[1])
    assert data["hinges"]["damping_ratio"] == pytest.approx(0.043 * result.values[0])


def test_the_intervals_come_from_central_differences_and_the_time_is_accounted_for():
    """The standard errors agree with those of a Jacobian of central
    differences ten times finer at a thousandth of the fit's tolerance, and
    the fit's wall time splits into its parts."""
    air = scene("air.density=1.2")
    fitted = parameters(build_model(air), ("damping", "drag"))
    data = measured(fitted.model_at([1.3, 1.6]), air.simulation, seed=3)
    result = calibrate(fitted, [data], air.simulation, noise=1e-3)
    tight = Residuals(fitted, [data], replace(air.simulation, rtol=1e-9, atol=1e-11), 1e-3)
    J = np.array(result.residuals.jacobian(result.x))
    for i in range(2):
        step = np.eye(len(result.x))[i] * 1e-3
        J[:, i] = (tight(result.x + step) - tight(result.x - step)) / 2e-3
    reference = uncertainty(J, tight(result.x), result.x, result.uncertainty.names,
                            [True, True, False])
    assert result.uncertainty.se == pytest.approx(reference.se, rel=0.01)
    assert set(result.seconds) == {"residuals", "jacobian", "other"}
    assert min(result.seconds.values()) >= 0.0
    assert sum(result.seconds.values()) == pytest.approx(result.wall_time, rel=1e-9)
    assert not any("does not follow the data" in w for w in result.warnings)


def test_residuals_far_above_the_noise_are_warned_of():
    """Encoders 10 mrad off zero: what no damping or drag can fit."""
    air = scene("air.density=1.2")
    fitted = parameters(build_model(air), ("damping", "drag"))
    data = measured(fitted.model_at([1.3, 1.6]), air.simulation, seed=3)
    biased = Measured(data.path, data.hinges, data.t, data.theta + 0.01, 0.0)
    result = calibrate(fitted, [biased], air.simulation, noise=1e-3)
    assert result.residual_rms > 5e-3
    assert any("does not follow the data" in w for w in result.warnings)


def test_drag_in_air_too_thin_to_act_is_reported_not_identifiable():
    thin = scene("air.density=1e-7")
    model = build_model(thin)
    fitted = parameters(model, ("damping", "drag"))
    result = calibrate(fitted, [measured(model, thin.simulation, seed=4)], thin.simulation,
                       noise=1e-3)
    u = result.uncertainty
    assert "drag" in u.problems and "damping" not in u.problems
    assert any(w.startswith("drag is not identifiable") for w in u.warnings)
    entry = calibrated_data(thin, result)["calibration"]["deployment"]["parameters"]["drag"]
    assert entry["identifiable"] is False and "interval_95" not in entry


def test_a_group_whose_hinges_rest_on_their_stops_is_held_at_the_scenes_values():
    """In the first 0.12 s the top horizontal hinges stay folded: their
    stiffness is not fitted but held, and said so; the other group is fitted."""
    top = ["r1c1-r1c2", "r1c3-r1c4"]
    rest = [h for h in OUTER + INNER if h not in top]
    groups = f"hinges.groups=[{top}, {rest}]".replace("'", "")
    nominal_scene = scene(groups)
    model = build_model(nominal_scene)
    truth = parameters(model, ("stiffness",), "group").model_at([1.0, 1.1])
    result = calibrate(parameters(model, ("stiffness",), "group"),
                       [measured(truth, nominal_scene.simulation)], nominal_scene.simulation)
    assert list(result.held) == ["stiffness[r1c1-r1c2]"]
    assert "held at the scene's value" in result.held["stiffness[r1c1-r1c2]"]
    assert result.values == pytest.approx([1.0, 1.1], rel=1e-3)
    assert result.uncertainty.names == ("stiffness[r1c1-r2c1]", "release[0]")
    entry = calibrated_data(nominal_scene, result)["calibration"]["deployment"]["parameters"]
    assert entry["stiffness[r1c1-r1c2]"]["held"] and not entry["stiffness[r1c1-r1c2]"]["identifiable"]
    assert entry["stiffness[r1c1-r2c1]"]["identifiable"]


def test_the_deployment_entry_keeps_what_other_calibrations_wrote():
    base = scene("air.density=1.2")
    earlier = scene_from_dict({**base.data, "calibration": {"free_vibration": {"c": 0.0043}}})
    model = build_model(earlier)
    result = calibrate(parameters(model, ("damping",)), [measured(model, earlier.simulation, 5)],
                       earlier.simulation, noise=1e-3)
    written = calibrated_data(earlier, result)["calibration"]
    assert written["free_vibration"] == {"c": 0.0043}
    assert written["deployment"]["parameters"]["damping"]["value"] == pytest.approx(1.0, rel=0.01)
