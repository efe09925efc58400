"""The panel-deploy command line: every main job end to end, and its error contract."""

import json
from pathlib import Path

import numpy as np
import pytest

from panel_deploy.cli import main
from panel_deploy.trajectory_io import load_trajectory

PAPER = str(Path(__file__).resolve().parent.parent / "config" / "scenes" / "paper_4x4.yaml")


def run(capsys, *argv):
    code = main(list(argv))
    out = capsys.readouterr()
    return code, out.out, out.err


def test_fold_lists_circuits_as_json(capsys):
    code, out, _ = run(capsys, "fold", "--rows", "4", "--cols", "4", "--json")
    data = json.loads(out)
    assert code == 0 and data["circuits"] == 6 and data["orbits"] == 2 and data["packable"] == 6


def test_fold_scene_reports_the_paper_design(capsys, tmp_path):
    code, out, _ = run(capsys, "fold", "--scene", PAPER, "--json", "--plot", str(tmp_path / "d.png"))
    data = json.loads(out)
    assert code == 0 and data["dof_cells"] == 10 and data["dof_bodies"] == 6
    assert (tmp_path / "d.png").stat().st_size > 10_000


def test_fold_needs_a_size_or_a_scene(capsys):
    code, _, err = run(capsys, "fold")
    assert code == 2 and err.startswith("panel-deploy: error: --rows/--cols")


def test_simulate_saves_and_collide_reads_back(capsys, tmp_path):
    out_file = tmp_path / "traj.npz"
    code, out, _ = run(capsys, "simulate", "paper_4x4", "--t-end", "0.01", "--method", "compiled",
                       "--json", "--out", str(out_file))
    s = json.loads(out)
    assert code == 0 and s["success"] and s["closure"] == "penalty"
    assert s["energy_balance_error"] < 1e-6 and s["collision"]["collided"] is False
    result, scene, k = load_trajectory(out_file)
    assert result.theta.shape == (401, 11) and scene.name == "paper_4x4"
    assert np.allclose(k, 0.1) and result.t[-1] == pytest.approx(0.01)
    code, out, _ = run(capsys, "collide", str(out_file), "--json")
    assert code == 0 and json.loads(out)["collided"] is False


def test_simulate_reports_flat_by_the_scenes_flat_tolerance(capsys):
    # Stowed hinges sit at pi: flat from the first sample once the tolerance
    # exceeds pi, never within 5 ms by the paper scene's 0.05 rad.
    for tol, first_flat in (("3.2", 0.0), ("0.05", None)):
        code, out, _ = run(capsys, "simulate", "paper_4x4", "--t-end", "0.005", "--method",
                           "compiled", "--json", "--set", f"simulation.flat_tolerance={tol}")
        s = json.loads(out)
        assert code == 0 and s["flat_tolerance"] == float(tol) and s["time_to_flat"] == first_flat


def test_simulate_text_summary_and_exact_closure(capsys):
    code, out, _ = run(capsys, "simulate", PAPER, "--t-end", "0.005", "--closure", "exact",
                       "--method", "compiled")
    assert code == 0 and "closure exact" in out and "never left the stowed angle" in out


@pytest.mark.parametrize("argv, message", [
    (["simulate", PAPER, "--t-end", "-1"], "--t-end: expected a number > 0"),
    (["simulate", PAPER, "--method", "Euler"], "--method: expected one of"),
    (["collide", "missing.npz"], "missing.npz: trajectory file not found"),
    (["export", "no_such_scene", "--mjcf", "x.xml"], "no_such_scene: scene file not found"),
])
def test_bad_arguments_are_one_line_errors(capsys, argv, message):
    code, _, err = run(capsys, *argv)
    assert code == 2 and message in err and len(err.strip().splitlines()) == 1


def test_corrupt_trajectory_is_a_clear_error(capsys, tmp_path):
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a zip")
    code, _, err = run(capsys, "collide", str(bad))
    assert code == 2 and "not a trajectory file" in err


def test_simulate_takes_stiffness_from_a_result_file(capsys, tmp_path):
    from panel_deploy.build import build_model
    from panel_deploy.scene import load_scene
    names = [h.name for h in build_model(load_scene(PAPER)).hinges]
    k = {n: 0.05 + 0.01 * i for i, n in enumerate(names)}
    stiff = tmp_path / "k.yaml"
    stiff.write_text("hinges:\n" + "".join(f"  {n}: {{k: {v}}}\n" for n, v in k.items()))
    out_file = tmp_path / "t.npz"
    code, _, _ = run(capsys, "simulate", PAPER, "--t-end", "0.004", "--method", "compiled",
                     "--stiffness", str(stiff), "--out", str(out_file))
    assert code == 0
    assert np.allclose(load_trajectory(out_file)[2], [k[n] for n in names])
    # A result optimised under other dampers: simulated with the scene's, and said so.
    for beta, noted in ((0.043, False), (0.19, True)):
        stiff.write_text("hinges:\n" + "".join(f"  {n}: {{k: {v}, c: {beta * v}}}\n"
                                               for n, v in k.items()))
        code, _, err = run(capsys, "simulate", PAPER, "--t-end", "0.004", "--method", "compiled",
                           "--stiffness", str(stiff))
        assert code == 0 and ("c/k = 0.19 s, the scene 0.043 s" in err) == noted, err
    stiff.write_text("hinges: {r1c1-r1c2: -1}\n")
    code, _, err = run(capsys, "simulate", PAPER, "--t-end", "0.004", "--stiffness", str(stiff))
    assert code == 2 and "stiffness file" in err and len(err.strip().splitlines()) == 1


def test_optimise_starts_from_a_result_file(capsys, tmp_path):
    from panel_deploy.build import build_model
    from panel_deploy.scene import load_scene
    model = build_model(load_scene(PAPER))
    k = {h.name: 0.05 for h in model.hinges}
    k["r2c2-r3c2"] = 0.02
    start = tmp_path / "start.yaml"
    start.write_text("hinges:\n" + "".join(f"  {n}: {{k: {v}}}\n" for n, v in k.items()))
    code, out, _ = run(capsys, "optimise", PAPER, "--start", str(start), "--max-evaluations", "1",
                       "--workers", "1", "--quiet", "--json")
    data = json.loads(out)
    assert code == 1 and data["nfev"] == 1  # K_0 of this start collides
    assert {n: h["k"] for n, h in data["hinges"].items()} == pytest.approx(k)
    k["r1c3-r1c4"] = 0.06  # its mirror twin r1c1-r1c2 stays at 0.05
    start.write_text("hinges:\n" + "".join(f"  {n}: {{k: {v}}}\n" for n, v in k.items()))
    code, _, err = run(capsys, "optimise", PAPER, "--start", str(start), "--quiet")
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert "k0: hinges r1c1-r1c2 and r1c3-r1c4 share groups[0]" in err


def test_sigterm_during_optimise_saves_the_best_so_far(tmp_path):
    # The optimiser is stopped once its first batch has been reported; the result
    # file must hold that batch's best K, readable back as stiffness.
    import signal
    import subprocess
    import sys

    import yaml

    from panel_deploy.build import build_model
    from panel_deploy.optimise import load_stiffness
    from panel_deploy.scene import load_scene

    out = tmp_path / "best.yaml"
    proc = subprocess.Popen([sys.executable, "-m", "panel_deploy.cli", "optimise", PAPER,
                             "--workers", "1", "--out", str(out)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        first = proc.stderr.readline()
        assert "nfev" in first, first
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=120)
    finally:
        proc.kill()
    assert proc.returncode == 130, err
    data = yaml.safe_load(out.read_text())
    assert data["status"] == 3 and data["message"].startswith("interrupted after")
    k = load_stiffness(out, build_model(load_scene(PAPER)))
    assert k.shape == (12,) and np.all(k > 0)


def test_sigterm_inside_numbas_callback_is_delivered_again_later():
    # Raised inside numba's unpickling callback, the KeyboardInterrupt would
    # become a SystemError; the handler must defer it, not drop it.
    import signal
    import time
    from types import SimpleNamespace

    from panel_deploy.cli import _interrupt

    previous = signal.signal(signal.SIGTERM, _interrupt)
    try:
        with pytest.raises(KeyboardInterrupt):
            _interrupt(signal.SIGTERM, SimpleNamespace(f_globals={"__name__": "panel_deploy.x"}))
        inside_numba = SimpleNamespace(f_globals={"__name__": "numba.core.serialize"})
        assert _interrupt(signal.SIGTERM, inside_numba) is None
        with pytest.raises(KeyboardInterrupt):
            time.sleep(2.0)
    finally:
        signal.signal(signal.SIGTERM, previous)
