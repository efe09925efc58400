"""panel-deploy calibrate: a fit that recovers known damping and stiffness
factors and the release time from synthetic recordings (noisy encoders, a
hinge and the cut hinge unmeasured, epoch stamps, a gap), the calibrated
scene re-loaded by simulate, Ctrl-C, and every refusal."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from panel_deploy.build import build_model
from panel_deploy.calibrate import calibrate, parameters, read_measured
from panel_deploy.calibrate.residuals import Residuals
from panel_deploy.dynamics.hinge_trajectory import simulate_hinges
from panel_deploy.cli import main
from panel_deploy.model import hinge_order
from panel_deploy.record import messages as m
from panel_deploy.record.writer import Recorder
from panel_deploy.scene import load_scene, resolve_scene

#: Short runs: the first 0.12 s of the paper scene's deployment, in which every
#: moving hinge swings from pi towards its stop.
T_END = 0.12
SETS = [f"simulation.t_end={T_END}", "simulation.samples=25"]
#: The hidden truth.
TRUE = {"damping": 1.3, "stiffness": 1.15}
RELEASE = 0.0437  # s after the first stamp
EPOCH = 1_763_900_000.0  # s: stamps from a driver's clock
NOISE = 1e-3  # rad
UNMEASURED = ("r4c3-r4c4", "r1c1-r1c2")  # the cut hinge and one of the loop


def paper_scene(*overrides):
    return load_scene(resolve_scene("paper_4x4"), [*SETS, *overrides])


def write_encoders(path, truth, *, rate=200.0, gap=(0.09, 0.11), seed=1, stowed_for=RELEASE,
                   t_end=T_END, epoch=EPOCH):
    """An encoder recording of the paper scene deployed with ``truth``'s model:
    the measured hinges only, stowed until the release, noisy, with a gap."""
    names = [truth.hinges[h].name for h in hinge_order(truth)]
    carried = [n for n in names if n not in UNMEASURED]
    trajectory = simulate_hinges(truth, paper_scene().simulation, t_end, carried)
    t = np.arange(0.0, stowed_for + t_end, 1.0 / rate)
    t = t[(t < gap[0]) | (t > gap[1])]
    theta = trajectory.angles(t - stowed_for)
    theta += np.random.default_rng(seed).normal(0.0, NOISE, theta.shape)
    with Recorder(path) as rec:
        for j, (tj, row) in enumerate(zip(t, theta)):
            rec.write("/joint_states", m.JOINT_STATE,
                      m.joint_state(carried, epoch + tj, row, [], []), round((epoch + tj) * 1e9))
    return path


@pytest.fixture(scope="module")
def nominal():
    return build_model(paper_scene())


@pytest.fixture(scope="module")
def truth(nominal):
    return parameters(nominal, ("damping", "stiffness")).model_at([TRUE["damping"],
                                                                   TRUE["stiffness"]])


#: A second test of the same array: another clock, 1 kHz, released later, no gap.
SECOND = {"rate": 1000.0, "gap": (1.0, 1.0), "seed": 2, "stowed_for": 0.0712, "epoch": 52.5}


@pytest.fixture(scope="module")
def encoders(tmp_path_factory, truth):
    folder = tmp_path_factory.mktemp("cal")
    return (write_encoders(folder / "encoders.mcap", truth),
            write_encoders(folder / "second.mcap", truth, **SECOND))


def test_fit_recovers_the_factors_and_the_releases_from_two_noisy_partial_recordings(
        encoders, nominal):
    scene = paper_scene("collision.noise=0.001")
    runs = [read_measured(path, scene, nominal) for path in encoders]
    assert set(runs[0].hinges).isdisjoint(UNMEASURED)
    assert [run.stamp0 for run in runs] == pytest.approx([EPOCH, SECOND["epoch"]])
    lines = []
    result = calibrate(parameters(nominal, ("damping", "stiffness")), runs, scene.simulation,
                       noise=scene.collision.noise, progress=lines.append)
    assert result.success and result.status == 0
    fitted = dict(zip(result.parameters.names, result.values))
    for name, value in TRUE.items():
        assert fitted[name] == pytest.approx(value, rel=0.03)
    assert result.offsets == pytest.approx([RELEASE, SECOND["stowed_for"]], abs=1e-3)
    u = result.uncertainty
    assert not u.problems and u.correlation.shape == (4, 4)
    assert np.all(u.lower < u.value) and np.all(u.value < u.upper)
    assert result.residual_rms == pytest.approx(NOISE, rel=0.3)
    assert set(result.rms[1]) == set(runs[1].hinges)
    assert [it.iteration for it in lines] == list(range(1, len(lines) + 1)) and lines


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """``simulate --record`` of the paper scene with the hidden k and c."""
    folder = tmp_path_factory.mktemp("record")
    path = folder / "deployed.mcap"
    ratio = 0.043 * TRUE["damping"] / TRUE["stiffness"]
    assert main(["simulate", "paper_4x4", *(f"--set={s}" for s in SETS),
                 f"--set=hinges.stiffness={0.1 * TRUE['stiffness']}",
                 f"--set=hinges.damping_ratio={ratio}", "--record", str(path)]) == 0
    return path


@pytest.fixture(scope="module")
def calibrated(recorded, tmp_path_factory):
    folder = tmp_path_factory.mktemp("calibrated")
    out, png = folder / "calibrated.yaml", folder / "fit.png"
    code = main(["calibrate", str(recorded), "--scene", "paper_4x4", "--out", str(out),
                 "--plot", str(png), "--quiet", *(f"--set={s}" for s in SETS)])
    return code, out, png


def test_calibrate_writes_the_scene_keys_and_a_calibration_section(calibrated):
    code, out, png = calibrated
    assert code == 0 and png.read_bytes()[:4] == b"\x89PNG"
    data = yaml.safe_load(out.read_text())
    assert data["hinges"]["stiffness"] == pytest.approx(0.1 * TRUE["stiffness"], rel=1e-3)
    assert data["hinges"]["damping_ratio"] == pytest.approx(
        0.043 * TRUE["damping"] / TRUE["stiffness"], rel=1e-3)
    section = data["calibration"]["deployment"]
    assert section["parameters"]["damping"]["value"] == pytest.approx(TRUE["damping"], rel=1e-3)
    lo, hi = section["parameters"]["stiffness"]["interval_95"]
    assert lo <= section["parameters"]["stiffness"]["value"] <= hi
    [run] = section["recordings"]
    assert run["samples"] == 25 and len(run["hinges"]) == 12
    assert run["release_offset"] == pytest.approx(0.0, abs=1e-4)
    assert set(run["residual_rms"]) == set(run["hinges"])
    assert section["correlation"]["names"] == ["damping", "stiffness", "release[0]"]
    assert section["first_collision"] == {"fitted": None, "measured": [None]}


def test_the_calibrated_scene_rebuilds_the_fitted_model_and_simulate_runs_it(calibrated, capsys):
    _, out, _ = calibrated
    scene = load_scene(out)
    assert scene.data["calibration"]["deployment"]["success"] is True
    model = build_model(scene)
    assert [h.k for h in model.hinges] == pytest.approx([0.1 * TRUE["stiffness"]] * 12, rel=1e-3)
    assert [h.c for h in model.hinges] == pytest.approx([0.0043 * TRUE["damping"]] * 12, rel=1e-3)
    capsys.readouterr()
    assert main(["simulate", str(out), "--t-end", "0.02", "--set", "simulation.samples=5"]) == 0


def test_interrupted_fit_keeps_the_best_point_and_writes_the_outputs(recorded, tmp_path,
                                                                     monkeypatch, capsys):
    calls = []
    jacobian = Residuals.jacobian

    def interrupted(self, x):
        calls.append(x)
        if len(calls) == 3:  # x0's, the first iteration's, then Ctrl-C
            raise KeyboardInterrupt
        return jacobian(self, x)

    monkeypatch.setattr(Residuals, "jacobian", interrupted)
    out = tmp_path / "best.yaml"
    code = main(["calibrate", str(recorded), "--scene", "paper_4x4", "--out", str(out),
                 *(f"--set={s}" for s in SETS)])
    assert code == 130
    section = yaml.safe_load(out.read_text())["calibration"]["deployment"]
    assert section["status"] == 3 and "interrupted" in section["message"]
    assert "interval_95" not in section["parameters"]["damping"]
    err = capsys.readouterr().err
    assert err.count("calibrate  it") == 1  # one progress line per finished iteration


def test_the_fitted_first_collision_is_set_beside_the_recorded_one(tmp_path, capsys):
    """The sample bag collides at 0.416 s (L2 into L1); two evaluations from the
    recording's own scene are enough to see both, whether or not the fit converged."""
    bag = Path(__file__).resolve().parent.parent / "bags" / "paper_4x4_uniform.mcap"
    out = tmp_path / "calibrated.yaml"
    code = main(["calibrate", str(bag), "--until", "0.45", "--max-evaluations", "2", "--quiet",
                 "--out", str(out)])
    assert code in (0, 1)
    collisions = yaml.safe_load(out.read_text())["calibration"]["deployment"]["first_collision"]
    [measured] = collisions["measured"]
    for event in (collisions["fitted"], measured):
        assert event["pair"] == ["r1c2+r1c3", "r2c2+r2c3"]
        assert event["t"] == pytest.approx(0.416, abs=2e-3)
    assert "first collision r1c2+r1c3 - r2c2+r2c3 at 0.41" in capsys.readouterr().out


def _one_line_error(capsys, *parts):
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("panel-deploy: error: "), err
    for part in parts:
        assert part in err[0], err[0]


def _stowed(path, t_end, names=("r1c1-r2c1",), moving=False):
    with Recorder(path) as rec:
        for j, t in enumerate(np.arange(0.0, t_end, 0.005)):
            theta = [np.pi - (0.5 * t if moving and t > 0.02 else 0.0)] * len(names)
            rec.write("/joint_states", m.JOINT_STATE, m.joint_state(names, t, theta, [], []),
                      round(t * 1e9))
    return path


def _text(path):
    path.write_text("hinge angles, by hand\n")
    return path


#: Every hinge of the paper scene: angles that need no loop closure.
NAMES = ("r1c1-r1c2", "r1c1-r2c1", "r1c3-r1c4", "r1c4-r2c4", "r2c1-r3c1", "r2c2-r3c2",
         "r2c4-r3c4", "r3c1-r4c1", "r3c2-r4c2", "r3c4-r4c4", "r4c1-r4c2", "r4c3-r4c4")


@pytest.mark.parametrize("case", ["motionless", "too short", "fit", "per", "drag without air",
                                  "foreign joints", "out is the recording", "twice",
                                  "evaluations", "until", "not a recording", "no scene"])
def test_refusals_are_one_line_naming_the_field_and_exit_2(case, recorded, tmp_path, capsys):
    out = str(tmp_path / "out.yaml")
    rec = str(recorded)
    args, parts = {
        "motionless": ([str(_stowed(tmp_path / "still.mcap", 0.3, NAMES))],
                       ["still.mcap", "/joint_states is motionless"]),
        "too short": ([str(_stowed(tmp_path / "short.mcap", 0.06, NAMES, moving=True))],
                      ["short.mcap", "too short", "a fit needs at least 10"]),
        "fit": ([rec, "--fit", "damping,friction"], ["--fit", "'friction'"]),
        "per": ([rec, "--per", "hinge"], ["--per", "scale, group"]),
        "drag without air": ([rec, "--fit", "drag"], ["air.density", "no air"]),
        "foreign joints": ([str(_stowed(tmp_path / "arm.mcap", 0.1, ("shoulder",)))],
                           ["arm.mcap", "'shoulder'"]),
        "out is the recording": ([rec, "--out", rec], ["--out", "destroy the input"]),
        "twice": ([rec, rec], ["RECORDING", "twice"]),
        "evaluations": ([rec, "--max-evaluations", "0"], ["--max-evaluations"]),
        "until": ([rec, "--until", "0"], ["--until", "expected a number > 0"]),
        "not a recording": ([str(_text(tmp_path / "notes.mcap"))], ["notes.mcap"]),
        "no scene": ([str(_stowed(tmp_path / "bare.mcap", 0.3, NAMES))],
                     ["bare.mcap", "no /panel_deploy/model", "--scene"]),
    }[case]
    if "--out" not in args:
        args = [*args, "--out", out]
    scene = [] if case == "no scene" else ["--scene", "paper_4x4"]
    code = main(["calibrate", *args, *scene, *(f"--set={s}" for s in SETS)])
    assert code == 2
    _one_line_error(capsys, *parts)
    assert not (tmp_path / "out.yaml").exists()


@pytest.mark.parametrize("args, parts", [
    (["DEPLOYMENT", "--free-vibration", "SWING", "--out", "OUT"], ["RECORDING", "not both"]),
    (["--free-vibration", "SWING", "--fit", "drag"], ["--fit", "not with --free-vibration"]),
    (["--free-vibration", "SWING", "--max-evaluations", "5"], ["--max-evaluations"]),
    (["DEPLOYMENT", "--hinge", "r1c1-r1c2", "--out", "OUT"], ["--hinge", "only with --free"]),
    (["DEPLOYMENT"], ["--out", "required"]),
    ([], ["RECORDING", "--free-vibration"]),
])
def test_the_two_modes_take_only_their_own_flags(args, parts, recorded, tmp_path, capsys):
    """Deployments (RECORDING ...) or swing tests (--free-vibration ...): one line, exit 2."""
    swing = Path(__file__).resolve().parent.parent / "bags" / "free_vibration_rig_1.mcap"
    given = {"DEPLOYMENT": str(recorded), "SWING": str(swing), "OUT": str(tmp_path / "o.yaml")}
    assert main(["calibrate", *(given.get(a, a) for a in args)]) == 2
    _one_line_error(capsys, *parts)
    assert not (tmp_path / "o.yaml").exists()
