"""Free-vibration tests (``panel-deploy calibrate --free-vibration``): c and k of a
hinge spring from recordings of one panel swinging on one hinge."""

import json
from pathlib import Path

import numpy as np
import pytest
import yaml

from panel_deploy import free_vibration as fv
from panel_deploy.build import build_model
from panel_deploy.cli import main
from panel_deploy.errors import ModelError, SceneError
from panel_deploy.scene import load_scene, scene_from_dict

#: The rig: a 2 x 2 array merges into two 2 x 1 bodies on one hinge line (two
#: springs); no gravity and no air, so its free vibration is the closed form.
RIG = {"name": "rig", "array": {"rows": 2, "cols": 2, "length": 0.1, "width": 0.1,
                                "thickness": 0.005, "mass": 0.02},
       "gravity": [0.0, 0.0, 0.0]}
K, C = 0.1, 0.0005          # N m/rad, N m s/rad of one spring: zeta about 0.1
NOISE = 1e-3                # rad
RATE, DURATION = 200.0, 3.0  # Hz, s
BAGS = Path(__file__).resolve().parent.parent / "bags"


@pytest.fixture(scope="module")
def rig():
    return fv.rig_of(build_model(scene_from_dict(RIG)), "rig")


def closed_form(rig, t, c=C, k=K, equilibrium=0.6, amplitude=0.4):
    return fv.released(rig, t, c, k, equilibrium, amplitude)


def noisy_swing(rig, seed, **kwargs):
    t = np.arange(0.0, DURATION, 1.0 / RATE)
    theta = closed_form(rig, t, **kwargs) + np.random.default_rng(seed).normal(0.0, NOISE, t.size)
    return fv.Swing(f"seed{seed}", t, theta)


def write_recording(path, theta, carry_scene=True):
    """A recording of the rig's joint states at RATE (with the rig scene unless not to)."""
    fv.record_swing(path, scene_from_dict(RIG), np.arange(len(theta)) / RATE, theta, t0=1000.0,
                    carry_scene=carry_scene)
    return str(path)


def test_rig_is_the_panel_about_its_hinge(rig):
    # a 0.04 kg, 0.2 x 0.1 x 0.005 m plate about its long edge on the top facet:
    # m (b^2 + t^2) / 12 + m ((b/2)^2 + (t/2)^2)
    m, b, t = 0.04, 0.1, 0.005
    assert rig.inertia == pytest.approx(m * (b ** 2 + t ** 2) / 3.0, rel=1e-9)
    assert rig.springs == 2 and rig.drag == 0.0
    assert np.allclose(rig.gravity, 0.0)


def test_closed_form_recovers_c_within_2_percent_both_ways(rig):
    swing = noisy_swing(rig, seed=0)
    peaks = fv.check_swing(swing, rig)
    assert peaks.noise == pytest.approx(NOISE, rel=0.2)
    decrement = fv.log_decrement(swing, rig, peaks)
    fit = fv.fit_swing(swing, rig, peaks, decrement)
    assert decrement.success and fit.success
    for a in (decrement, fit):
        assert a.c.value == pytest.approx(C, rel=0.02)
        assert a.k.value == pytest.approx(K, rel=0.02)
        assert a.ratio.value == pytest.approx(C / K, rel=0.02)
        assert a.c.low < a.c.value < a.c.high
    assert fit.c.low <= C <= fit.c.high
    assert fit.rms == pytest.approx(NOISE, rel=0.1)  # the model explains all but the noise
    assert fit.equilibrium == pytest.approx(0.6, abs=1e-3)


def test_a_held_release_and_a_record_started_mid_swing_are_read_alike(rig):
    """A hand holds the panel 0.4 s before letting go; another record starts
    0.13 s after the release: the release and the cut swing are left out."""
    t = np.arange(0.0, DURATION, 1.0 / RATE)
    noise = np.random.default_rng(9).normal(0.0, NOISE, t.size)
    held = np.where(t < 0.4, closed_form(rig, 0.0), closed_form(rig, np.maximum(t - 0.4, 0.0)))
    late = closed_form(rig, t + 0.13)
    for theta in (held + noise, late + noise):
        swing = fv.Swing("test", t, theta)
        peaks = fv.check_swing(swing, rig)
        fit = fv.fit_swing(swing, rig, peaks, fv.log_decrement(swing, rig, peaks))
        assert fit.c.value == pytest.approx(C, rel=0.02)
        assert fit.rms == pytest.approx(NOISE, rel=0.1)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_pooled_interval_covers_the_truth(rig, seed):
    readings = []
    for test in range(3):
        swing = noisy_swing(rig, 10 * seed + test, amplitude=0.3 + 0.05 * test)
        readings.append((swing, rig, fv.check_swing(swing, rig)))
    cal = fv.calibrate(readings)
    pooled = cal.fit["c"]
    assert pooled.dof == 2 and pooled.agree
    assert pooled.estimate.low <= C <= pooled.estimate.high
    # pooling narrows the interval below every single test's
    widths = [fit.c.high - fit.c.low for _, fit in cal.tests]
    assert pooled.estimate.high - pooled.estimate.low < min(widths)
    assert cal.log_decrement["c"].estimate.value == pytest.approx(C, rel=0.02)


def test_a_swing_the_model_cannot_describe_says_so(rig):
    """Dry friction: the amplitude falls linearly, not geometrically."""
    t = np.arange(0.0, DURATION, 1.0 / RATE)
    theta = 0.6 + np.maximum(0.4 - 0.1 * t, 0.0) * np.cos(38.6 * t)
    swing = fv.Swing("dry", t, theta + np.random.default_rng(2).normal(0.0, NOISE, t.size))
    peaks = fv.check_swing(swing, rig)
    fit = fv.fit_swing(swing, rig, peaks, fv.log_decrement(swing, rig, peaks))
    assert fit.rms > 3 * NOISE and "the model misses the record" in fit.notes[0]


def test_pool_flags_tests_that_disagree():
    tight = [fv.Estimate.from_log(np.log(v), 0.001, 100) for v in (1.0, 1.1, 0.9)]
    pooled = fv.pool(tight)
    assert not pooled.agree and pooled.widened and pooled.chi2 > 100
    assert pooled.estimate.low < 0.97 and pooled.estimate.high > 1.03  # Birge-widened
    agreeing = fv.pool([fv.Estimate.from_log(np.log(v), 0.1, 100) for v in (1.0, 1.1, 0.9)])
    assert agreeing.agree and not agreeing.widened
    assert agreeing.estimate.value == pytest.approx(np.exp(np.mean(np.log([1.0, 1.1, 0.9]))))


def test_calibrate_writes_a_scene_that_reloads(tmp_path, rig, capsys):
    paths = [write_recording(tmp_path / f"swing{i}.mcap", noisy_swing(rig, 40 + i).theta)
             for i in range(2)]
    out = tmp_path / "calibrated.yaml"
    assert main(["calibrate", "--free-vibration", *paths, "--scene", "paper_4x4",
                 "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "pooled fit (2 tests" in text and "pooled log decrement" in text
    scene = load_scene(out)
    assert scene.hinges.damping_ratio == pytest.approx(C / K, rel=0.02)
    assert scene.name == "paper_4x4" and scene.hinges.stiffness == 0.1  # the rest untouched
    record = scene.data["calibration"]["free_vibration"]
    assert [t["recording"] for t in record["tests"]] == paths
    assert record["fit"]["ratio"]["value"] == scene.hinges.damping_ratio
    assert record["fit"]["c"]["low"] <= C <= record["fit"]["c"]["high"]
    build_model(scene)  # the calibrated scene builds as any other


def test_a_recording_without_its_scene_is_read_with_rig(tmp_path, rig, capsys):
    """A real rig's ``ros2 bag record /joint_states``: the rig's scene from --rig,
    and a scene's earlier calibrations kept beside this one."""
    path = write_recording(tmp_path / "bare.mcap", noisy_swing(rig, 5).theta, carry_scene=False)
    out = tmp_path / "calibrated.yaml"
    assert main(["calibrate", "--free-vibration", path, "--out", str(out)]) == 2
    assert capsys.readouterr().err.strip().endswith("name its scene with --rig SCENE")
    (tmp_path / "rig.yaml").write_text(yaml.safe_dump(RIG))
    target = tmp_path / "target.yaml"
    target.write_text(yaml.safe_dump({**RIG, "calibration": {"deployment": {"rms": 0.01}}}))
    assert main(["calibrate", "--free-vibration", path, "--rig", str(tmp_path / "rig.yaml"),
                 "--scene", str(target), "--out", str(out)]) == 0
    scene = load_scene(out)
    assert scene.hinges.damping_ratio == pytest.approx(C / K, rel=0.02)
    assert scene.data["calibration"]["deployment"] == {"rms": 0.01}
    assert "free_vibration" in scene.data["calibration"]


def test_hinge_flag_sets_that_hinge_s_damping(tmp_path, rig, capsys):
    path = write_recording(tmp_path / "swing.mcap", noisy_swing(rig, 7).theta)
    out = tmp_path / "calibrated.yaml"
    assert main(["calibrate", "--free-vibration", path, "--scene", "paper_4x4", "--hinge",
                 "r1c1-r2c1", "--out", str(out), "--json"]) == 0
    record = json.loads(capsys.readouterr().out)  # standard output is that one object
    scene = load_scene(out)
    c = scene.hinges.damping_overrides["r1c1-r2c1"]
    assert c == pytest.approx(C, rel=0.02) and c == record["fit"]["c"]["value"]
    assert scene.hinges.damping_ratio == load_scene(out).hinges.damping_ratio == 0.043
    model = build_model(scene)
    assert {h.name: h.c for h in model.hinges}["r1c1-r2c1"] == pytest.approx(c)


def test_the_closed_form_is_refused_where_it_does_not_hold(rig):
    with pytest.raises(ModelError, match="not an underdamped"):
        fv.released(rig, [0.0], 0.01, K, 0.6, 0.4)
    heavy = fv.rig_of(build_model(scene_from_dict({**RIG, "gravity": [0, 0, -9.81]})))
    with pytest.raises(ModelError, match="without weight and air"):
        fv.released(heavy, [0.0], C, K, 0.6, 0.4)


def test_the_sample_recordings_calibrate_the_paper_scene(tmp_path, capsys):
    """bags/free_vibration_rig_*.mcap: the shipped rig (weight, air) swung by the
    simulator, c = 0.0043 N m s/rad and k = 0.1 N m/rad per spring."""
    bags = sorted(str(p) for p in BAGS.glob("free_vibration_rig_*.mcap"))
    assert len(bags) == 3
    out = tmp_path / "calibrated.yaml"
    assert main(["calibrate", "--free-vibration", *bags, "--scene", "paper_4x4", "--out",
                 str(out)]) == 0
    assert "drag not identifiable" in capsys.readouterr().out
    fit = load_scene(out).data["calibration"]["free_vibration"]["fit"]
    assert fit["c"]["low"] <= 0.0043 <= fit["c"]["high"]
    assert fit["c"]["value"] == pytest.approx(0.0043, rel=0.02)
    assert fit["ratio"]["value"] == pytest.approx(0.043, rel=0.02)


@pytest.mark.parametrize("flags, named", [
    (["--scene", "paper_4x4"], "--scene"),
    (["--hinge", "r1c1-r2c1"], "--hinge"),
    (["--set", "hinges.stiffness=0.2"], "--set"),
])
def test_flags_that_shape_the_written_scene_need_out(tmp_path, capsys, flags, named):
    assert main(["calibrate", "--free-vibration", str(tmp_path / "a.mcap"), *flags]) == 2
    assert capsys.readouterr().err.strip() == (
        f"panel-deploy: error: {named}: only with --out CALIBRATED.yaml (the scene it shapes)")


def test_an_unknown_hinge_is_refused_before_any_recording_is_read(tmp_path, capsys):
    assert main(["calibrate", "--free-vibration", str(tmp_path / "none.mcap"), "--scene",
                 "paper_4x4", "--hinge", "h9", "--out", str(tmp_path / "out.yaml")]) == 2
    assert "--hinge: 'h9' is no hinge of the scene (hinges: r1c1-r1c2," in capsys.readouterr().err


def test_calibration_section_must_be_a_mapping():
    with pytest.raises(SceneError, match="calibration: expected a mapping"):
        scene_from_dict({**RIG, "calibration": "fitted"})


@pytest.mark.parametrize("case, expected", [
    ("missing", "cannot read the recording"),
    ("array", "not one panel on one hinge: its scene has 12 bodies and 12 hinges"),
    ("motionless", "motionless"),
    ("few_peaks", "too few peaks"),
    ("stop", "reaches a joint stop"),
    ("growing", "the swing does not decay"),
])
def test_bad_recordings_are_refused_in_one_line(tmp_path, rig, capsys, case, expected):
    t = np.arange(0.0, DURATION, 1.0 / RATE)
    noise = np.random.default_rng(3).normal(0.0, NOISE, t.size)
    if case == "missing":
        path = str(tmp_path / "none.mcap")
    elif case == "array":
        path = str(BAGS / "paper_4x4_uniform.mcap")
    else:
        theta = {"motionless": 0.5 + noise,
                 "few_peaks": closed_form(rig, t, c=0.003) + noise,  # zeta 0.58: one swing
                 "stop": closed_form(rig, t, equilibrium=0.2, amplitude=0.4) + noise,
                 "growing": 0.6 + 0.05 * np.exp(0.5 * t) * np.cos(38.0 * t) + noise}[case]
        path = write_recording(tmp_path / f"{case}.mcap", theta)
    good = write_recording(tmp_path / "good.mcap", noisy_swing(rig, 0).theta)
    out = tmp_path / "out.yaml"
    assert main(["calibrate", "--free-vibration", good, path, "--out", str(out)]) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and not out.exists()  # refused before any work
    lines = captured.err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"panel-deploy: error: {path}: ")
    assert expected in lines[0]


def simulated_swing(overrides, theta0, seed):
    """The package's own simulator swinging the shipped rig from rest at theta0 (rad),
    with NOISE added: gravity, air drag and the full multibody model."""
    from panel_deploy.dynamics.simulate import simulate
    from panel_deploy.model import State
    from panel_deploy.scene import resolve_scene

    scene = load_scene(resolve_scene("free_vibration_rig"), overrides)
    model = build_model(scene)
    run = simulate(model, scene.simulation, State(0.0, np.array([theta0]), np.zeros(1)))
    assert run.success
    theta = run.theta[:, 0] + np.random.default_rng(seed).normal(0.0, NOISE, len(run.t))
    return fv.Swing(f"sim{seed}", run.t, theta), fv.rig_of(model, "rig")


def test_the_simulated_rig_with_weight_and_air_recovers_c_and_k():
    swing, rig = simulated_swing((), 1.6, seed=0)
    assert rig.gravity[2] > 0 and rig.drag > 0  # the weight folds the hinge; air on
    peaks = fv.check_swing(swing, rig)
    decrement = fv.log_decrement(swing, rig, peaks)
    fit = fv.fit_swing(swing, rig, peaks, decrement)
    c = 0.1 * 0.043
    assert fit.c.value == pytest.approx(c, rel=0.02) and fit.c.low <= c <= fit.c.high
    assert fit.k.value == pytest.approx(0.1, rel=0.005)
    assert decrement.c.value == pytest.approx(c, rel=0.02)
    # the decrement linearises the weight's torque at the equilibrium: k a few % off
    assert decrement.k.value == pytest.approx(0.1, rel=0.05)
    # on the heavy plate the drag is 0.5 % of the damping: said, not fitted
    assert fit.drag is None and "drag not identifiable" in fit.notes[0]


LIGHT = ["array.density=400", "hinges.stiffness=0.02", "hinges.damping_ratio=0.0058"]


def test_drag_is_identified_on_a_light_plate_and_not_on_a_short_record():
    swing, rig = simulated_swing(LIGHT, 0.75, seed=1)
    peaks = fv.check_swing(swing, rig)
    decrement = fv.log_decrement(swing, rig, peaks)
    fit = fv.fit_swing(swing, rig, peaks, decrement)
    c = 0.02 * 0.0058
    assert fit.drag is not None and fit.drag.low <= 1.17 <= fit.drag.high
    assert fit.c.value == pytest.approx(c, rel=0.02)
    assert "counts the air drag as damping" in decrement.notes
    short, rig = simulated_swing([*LIGHT, "simulation.t_end=1.5", "simulation.samples=301"],
                                 0.75, seed=1)
    peaks = fv.check_swing(short, rig)
    fit = fv.fit_swing(short, rig, peaks, fv.log_decrement(short, rig, peaks))
    assert fit.drag is None and "drag not identifiable" in fit.notes[0]
    assert fit.c.value == pytest.approx(c, rel=0.02)  # with the scene's (true) C_d
