"""The panel-deploy command line: every main job end to end, and its error contract."""

import json
import math
import os
import re
import zipfile
from pathlib import Path

import numpy as np
import pytest

from hostile import alias_bomb, alias_flow, file_size_limit, npy_declaring, npz_with

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
    assert (data["mobility_cells"], data["mobility_bodies"]) == (10, 6)
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
    result, scene, _, k = load_trajectory(out_file)[:4]
    assert result.theta.shape == (401, 11) and scene.name == "paper_4x4"
    assert np.allclose(k, 0.1) and result.t[-1] == pytest.approx(0.01)
    # the run's own record comes back with it: scheme, counters, cut-hinge angles
    assert (result.method, result.scheme) == ("compiled", "ros34pw2")
    assert (result.nsteps, result.nfev, result.nswitches) == (s["nsteps"], s["nfev"], s["switches"])
    assert result.cut_theta.shape == (401, 1) and result.gap_limit == pytest.approx(0.01)
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
    assert np.allclose(load_trajectory(out_file).stiffness, [k[n] for n in names])
    # A result optimised under other dampers: simulated with the scene's, and said so.
    # 0.04302: the scene's 0.043 to the four figures the note prints, so no note
    for beta, noted in ((0.043, False), (0.04302, False), (0.19, True)):
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
    # cwd: not the checkout, which ``-m`` would import instead of the package under
    # test (its kernels then compile first, and the first line is the notice)
    proc = subprocess.Popen([sys.executable, "-m", "panel_deploy.cli", "optimise", PAPER,
                             "--workers", "1", "--out", str(out)], cwd=tmp_path,
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


def test_sigterm_as_timeout_sends_it_keeps_the_feasible_k_found(tmp_path):
    # Issue 33: timeout(1) signals the command and then its whole process group, so
    # the workers and, a moment later, the main process again. Once a feasible K
    # has come back, the file must hold it, whichever moment the signals hit: the
    # workers ignore them (the pool stays whole) and a repeated signal does not
    # cut the saving short. Four moments after the first feasible evaluation.
    import signal
    import subprocess
    import sys
    import time

    import yaml

    for i, delay in enumerate((0.0, 0.05, 0.2, 0.5)):
        out = tmp_path / f"best{i}.yaml"
        proc = subprocess.Popen(
            [sys.executable, "-m", "panel_deploy.cli", "optimise", PAPER, "--workers", "2",
             "--set", "optimisation.damping_ratio_bounds=[0.043,0.3]", "--out", str(out)],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
            cwd=tmp_path)  # the package under test, not the checkout (above)
        try:
            line = ""
            while "flat yes" not in line or "collision no" not in line:
                line = proc.stderr.readline()
                assert line, "the optimiser ended before a feasible K"
            os.kill(proc.pid, signal.SIGTERM)
            time.sleep(delay)
            os.killpg(proc.pid, signal.SIGTERM)
            _, err = proc.communicate(timeout=60)
        finally:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGKILL)
        assert proc.returncode == 130, (delay, err)
        data = yaml.safe_load(out.read_text())
        assert data["status"] == 3 and data["success"] is True, (delay, data["message"])
        assert data["collision"] is None and data["reached_flat"] is True


def _frames(*modules):
    """A fake stack: the first module's frame on top, called by the next, and so on
    (``name:<string>``: code ``exec`` runs from a string in module ``name``)."""
    from types import SimpleNamespace
    frame = None
    for name in reversed(modules):
        name, _, filename = name.partition(":")
        code = SimpleNamespace(co_filename=filename or "x.py",
                               co_name="<module>" if filename else "f")
        frame = SimpleNamespace(f_globals={"__name__": name}, f_code=code, f_back=frame)
    return frame


@pytest.mark.parametrize("stack, deferred", [
    (("panel_deploy.x", "__main__"), False),
    (("numpy.core", "panel_deploy.x"), False),
    (("numba.core.serialize", "panel_deploy.x"), True),
    # a ctypes callback of llvmlite's called from numba's cache loading
    (("llvmlite.binding.executionengine", "numba.core.codegen", "panel_deploy.x"), True),
    # ours, run by an import in progress: a C extension's initialisation may be under it
    (("panel_deploy.dynamics", "importlib._bootstrap", "panel_deploy.cli"), True),
    # rosbags' serialiser code, exec'd from a string while the recording starts
    (("tmpmod:<string>", "rosbags.serde.utils", "panel_deploy.record"), True),
    (("__main__:<string>",), False),  # python -c: the whole program is such a string
    # a pytest-xdist worker: python -c execs execnet's bootstrap in __main__
    (("test_x", "xdist.remote", "__main__:<string>", "__main__:<string>"), False),
])
def test_interrupts_are_deferred_under_numba_llvmlite_an_import_or_exec(stack, deferred):
    from panel_deploy.cli import deferring
    assert deferring(_frames(*stack)) is deferred


def test_a_deferred_interrupt_is_raised_once_back_in_our_code():
    # Raised inside numba's unpickling callback, the KeyboardInterrupt would
    # become a SystemError; the handler must defer it, not drop it.
    import signal
    import time

    from panel_deploy.cli import Interrupts

    interrupts = Interrupts()
    interrupts.install()
    try:
        assert interrupts(signal.SIGTERM, _frames("numba.core.serialize", "x")) is None
        assert interrupts.received == signal.SIGTERM and not interrupts.raised
        with pytest.raises(KeyboardInterrupt):
            time.sleep(2.0)  # the SIGALRM retry finds this test's frame
        assert interrupts.raised
        # a repeat (timeout(1) signals the command, then its process group)
        # must not cut short what the first one's handling does
        assert interrupts(signal.SIGTERM, _frames("x")) is None
        interrupts.over = True  # the command has ended: nothing left to stop
        assert interrupts(signal.SIGINT, _frames("x")) is None
    finally:
        interrupts.restore()
    assert signal.getsignal(signal.SIGTERM) is not interrupts
    assert signal.getitimer(signal.ITIMER_REAL) == (0.0, 0.0)


def test_an_interrupt_deferred_to_the_end_still_ends_the_command(capsys, monkeypatch):
    # The signal came while the last kernel loaded and the command then
    # finished: it is not dropped (the run counts as interrupted).
    import signal

    import panel_deploy.cli as cli

    def loads_until_the_end(args):
        signal.getsignal(signal.SIGTERM)(signal.SIGTERM, _frames("numba.core.caching"))
        signal.setitimer(signal.ITIMER_REAL, 0)  # the command ends before the retry
        return 0
    monkeypatch.setattr(cli, "_schema", loads_until_the_end)
    code, _, err = run(capsys, "schema")
    assert code == 130 and err == "panel-deploy: interrupted\n"


# --- issue 19: every bad input is one line naming the field, exit 2, before any work ---

def one_line_error(capsys, argv, monkeypatch=None):
    """Run ``argv``; assert exit 2 and exactly one stderr line; return it."""
    try:
        code = main(list(argv))
    except SystemExit as e:  # argparse
        code = e.code
    err = capsys.readouterr().err
    assert code == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    return lines[0]


@pytest.fixture
def no_work(monkeypatch):
    """Any simulation, search, export or plot started fails the test."""
    def started(*a, **k):
        raise AssertionError("work started before the arguments were checked")
    from panel_deploy import dynamics
    from panel_deploy.cli import export, optimise
    from panel_deploy.fold import plot
    monkeypatch.setattr(dynamics, "simulate", started)
    monkeypatch.setattr(optimise, "optimise", started)
    monkeypatch.setattr(export, "export_mjcf", started)
    monkeypatch.setattr(plot, "plot_design", started)


@pytest.mark.parametrize("argv, expected", [
    (["simulate", PAPER, "--out", "{missing}/t.npz"], "--out: cannot write {missing}/t.npz: folder"),
    (["simulate", PAPER, "--out", "{tmp}"], "--out: {tmp} is a folder"),
    (["optimise", PAPER, "--out", "{missing}/k.yaml"], "--out: cannot write {missing}/k.yaml: folder"),
    (["optimise", PAPER, "--out", "{tmp}"], "is a folder"),
    (["export", PAPER, "--mjcf", "{missing}/m.xml"], "--mjcf: cannot write {missing}/m.xml: folder"),
    (["export", PAPER, "--mjcf", "{tmp}"], "--mjcf: {tmp} is a folder"),
    (["fold", "--scene", PAPER, "--plot", "{missing}/p.png"], "--plot: cannot write {missing}/p.png: folder"),
    (["fold", "--rows", "4", "--cols", "4", "--plot", "{tmp}"], "--plot: {tmp} is a folder"),
    (["bench", "work-precision", PAPER, "--out", "{missing}/w.csv"], "--out: cannot write {missing}/w.csv: folder"),
    (["bench", "work-precision", PAPER, "--repeats", "0"], "--repeats: expected an integer >= 1"),
    (["optimise", PAPER, "--perturb", "-2"], "--perturb: expected an integer >= 0"),
    (["optimise", PAPER, "--perturb", "3", "--perturb-tol", "1.5"], "--perturb-tol: expected a fraction"),
    (["optimise", PAPER, "--perturb", "3", "--perturb-tol", "nan"], "--perturb-tol: expected a finite"),
    (["optimise", PAPER, "--perturb-tol", "0.1"], "--perturb-tol: only with --perturb"),
    (["optimise", PAPER, "--springs", "0.1,inf"], "argument --springs: expected finite"),
    (["optimise", PAPER, "--max-evaluations", "0"], "--max-evaluations: expected an integer >= 1"),
    (["optimise", PAPER, "--method", ""], "--method: expected a value for optimisation.method"),
    (["optimise", PAPER, "--method", "newton"], "--method: expected one of local, global"),
    (["optimise", PAPER, "--workers", "-1"], "--workers: expected an integer >= 0"),
    (["simulate", PAPER, "--method", ""], "--method: expected a value for simulation.method"),
    (["simulate", PAPER, "--method", "euler"], "--method: expected one of"),
    (["simulate", PAPER, "--closure", "tight"], "--closure: expected one of penalty, exact"),
    (["simulate", PAPER, "--t-end", "inf"], "--t-end: expected a number, got str 'inf'"),
    (["simulate", PAPER, "--t-end", ".inf"], "--t-end: expected a finite number"),
    (["simulate", PAPER, "--t-end", "1e6"], "--t-end: expected a number <= 600"),
    (["simulate", PAPER, "--t-end", "abc"], "--t-end: expected a number, got str 'abc'"),
    (["fold", "--scene", PAPER, "--rows", "3"], "--rows: not with --scene"),
    (["fold", "--scene", PAPER, "--circuit", "1"], "--circuit: not with --scene"),
    (["fold", "--rows", "4", "--cols", "4", "--set", "array.rows=x"], "--set: only with --scene"),
    (["fold", "--rows", "40", "--cols", "40"], "--rows/--cols: 40 x 40 is above the enumeration limit"),
    (["fold", "--rows", "4", "--cols", "0"], "--cols: expected an integer >= 1"),
    (["optimise", PAPER, "--perturb", "1" + "0" * 400],
     "--perturb: expected a finite number, got <an integer of about 401 digits>"),
    # issue 26: names the system refuses, folders that take no files, formats, ports
    (["simulate", PAPER, "--out", "{tmp}/" + "a" * 300 + ".npz"], "--out: cannot write {tmp}/aaa"),
    (["simulate", PAPER, "--record", "{tmp}/" + "a" * 300], "a: File name too long"),
    (["replay", "r.mcap", "--save", "/proc/x.rrd"], "--save: cannot write /proc/x.rrd: folder "
                                                    "/proc does not take new files"),
    (["replay", "r.mcap", "--png", "{tmp}/strip.xyz"], "--png: cannot write a picture as .xyz "
                                                       "(the suffix gives the format: "),
    (["fold", "--rows", "4", "--cols", "4", "--plot", "{tmp}/d.xyz"], "--plot: cannot write a "
                                                                      "picture as .xyz"),
    (["replay", "r.mcap", "--serve", "--port", "70000"], "--port: expected an integer <= 65535"),
    (["replay", "r.mcap", "--port", "0"], "--port: expected an integer >= 1"),
    (["replay", "r.mcap", "--save", "{tmp}/scene.yaml"], "--save: expected a rerun file name "
                                                        "ending in .rrd, got "),
])
def test_bad_flags_and_output_paths_fail_before_any_work(capsys, tmp_path, no_work, argv, expected):
    fill = {"missing": str(tmp_path / "missing"), "tmp": str(tmp_path)}
    line = one_line_error(capsys, [a.format(**fill) for a in argv])
    assert expected.format(**fill) in line, line
    assert not list(tmp_path.iterdir())  # nothing written, no stray .part


@pytest.mark.parametrize("argv, flag, other", [
    (["simulate", "{scene}", "--out", "{scene}"], "--out", "scene"),
    (["simulate", "{scene}", "--out", "{link}"], "--out", "scene"),  # a symbolic link to it
    (["simulate", "{scene}", "--out", "{hard}"], "--out", "scene"),  # a hard link: same inode
    (["simulate", "{scene}", "--out", "{tmp}/sub/../s.yaml"], "--out", "scene"),
    (["simulate", PAPER, "--stiffness", "{result}", "--record", "{result}"], "--record", "--stiffness"),
    (["optimise", "{scene}", "--start", "{result}", "--out", "{result}"], "--out", "--start"),
    (["export", "{scene}", "--mjcf", "{link}"], "--mjcf", "scene"),
    (["fold", "--scene", "{scene}", "--plot", "{scene}"], "--plot", "--scene"),
    (["replay", "{mcap}", "--save", "{mcap}"], "--save", "recording"),
    (["replay", "{mcap}", "--png", "{mcap}"], "--png", "recording"),
])
def test_an_output_that_is_an_input_is_refused(capsys, tmp_path, no_work, argv, flag, other):
    scene, result, mcap = tmp_path / "s.yaml", tmp_path / "k.yaml", tmp_path / "x.mcap"
    scene.write_text(Path(PAPER).read_text())
    result.write_text("hinges: {}\n")
    mcap.write_bytes(b"\x89MCAP0\r\n")
    (tmp_path / "sub").mkdir()
    os.symlink(scene, tmp_path / "link.yaml")
    os.link(scene, tmp_path / "hard.yaml")
    before = {p: p.read_bytes() for p in (scene, result, mcap)}
    fill = {"scene": scene, "result": result, "mcap": mcap, "tmp": tmp_path,
            "link": tmp_path / "link.yaml", "hard": tmp_path / "hard.yaml"}
    line = one_line_error(capsys, [a.format(**fill) for a in argv])
    assert line.startswith(f"panel-deploy: error: {flag}: ") and f"is also the input {other} (" in line
    assert "writing it would destroy the input" in line, line
    assert all(p.read_bytes() == data for p, data in before.items())
    assert sorted(os.listdir(tmp_path)) == ["hard.yaml", "k.yaml", "link.yaml", "s.yaml", "sub",
                                            "x.mcap"]


@pytest.mark.parametrize("item, expected", [
    ("simulation.samples=10000000", "--set simulation.samples: expected an integer <= 50000"),
    ("simulation.max_step=1e-9", "--set simulation.max_step: t_end / max_step"),
    ("hinges.stiffness=1e300", "--set hinges.stiffness: expected a number <= 10000"),
    ("gravity=[0, 1e300, 0]", "--set gravity[1]: expected |g| <= 9810"),
    ("array.length=1e-300", "--set array.length: expected a number >= 1e-06"),
    ("array.rows=40", "--set array.rows: expected an integer <= 12"),
    ("simulation.t_end=" + "[" * 100 + "]" * 100, "--set simulation.t_end: value"),
    ("array.length=1" + "0" * 400, "--set array.length: expected a finite number, got <an integer"),
    ("array.rows=" + alias_flow(6, 7),  # 117649 values once written out, shown in 80 characters
     "--set array.rows: expected an integer, got list ['lol', ['lol', 'lol', 'lol', 'lol', 'lol', "
     "'lol', ...], [['lol', 'lol', 'lol..."),
    ("array.rows=" + alias_flow(), "--set array.rows: value '[&a0 \"lol\", &a1 [*a0, *a0"),
    # issue 26: refused after the whole run before, naming collision.margin (not a scene key)
    ("collision.tolerance=0.05", "--set collision.tolerance: expected a number <= 0.02, got 0.05 "
                                 "(limit: the collision check's broad phase"),
    # issue 33: tolerance 0 took the stowed package, whose panels touch, for a collision
    ("collision.tolerance=0", "--set collision.tolerance: expected a number >= 1e-09, got 0 "
                              "(limit: panels touching in the stowed stacks are 0 apart"),
])
def test_absurd_values_fail_at_once_naming_the_set_item(capsys, no_work, item, expected):
    line = one_line_error(capsys, ["simulate", PAPER, "--set", item])
    assert expected in line, line
    assert "paper_4x4.yaml" not in line  # a command-line mistake is not blamed on the file


@pytest.mark.parametrize("argv, expected", [
    (["simulate", PAPER, "--set", "simulation.t_\nend=1"], "--set simulation.t_\\nend: unknown key"),
    (["simulate", "pa\nper"], "pa\\nper: scene file not found"),
    (["simulate", PAPER, "--out", "a\n/t.npz"], "--out: cannot write a\\n/t.npz: folder a\\n"),
    (["simulate", "x\x1b[2J"], "x\\x1b[2J: scene file not found"),  # shown, not obeyed
    (["simulate", PAPER, "--stiffness", "k\n.yaml"], "stiffness file 'k\\n.yaml': cannot"),
])
def test_control_characters_in_names_stay_on_the_one_line(capsys, no_work, argv, expected):
    line = one_line_error(capsys, argv)
    assert line.startswith("panel-deploy: error: " + expected), line


def test_a_scene_name_too_long_for_the_system_is_one_line(capsys, no_work):
    line = one_line_error(capsys, ["simulate", "s" * 300])
    assert line == f"panel-deploy: error: {'s' * 300}: cannot read scene file (File name too long)"


def test_serve_on_a_busy_port_says_so_before_reading(capsys, no_work):
    import socket
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        line = one_line_error(capsys, ["replay", "missing.mcap", "--serve", "--port", str(port)])
    assert line.startswith(f"panel-deploy: error: --port: cannot serve on 127.0.0.1:{port} "
                           "(Address already in use"), line


def test_duplicate_scene_sections_are_refused(capsys, tmp_path, no_work):
    scene = tmp_path / "dup.yaml"
    text = Path(PAPER).read_text()
    scene.write_text(text + "\nsimulation: {method: RK45}\n")
    line = one_line_error(capsys, ["simulate", str(scene)])
    # the appended section's line: after the scene's lines and the blank one
    assert f"dup.yaml: malformed YAML at line {text.count(chr(10)) + 2}" in line
    assert "duplicate key 'simulation'" in line


@pytest.fixture(scope="module")
def trajectory(tmp_path_factory):
    path = tmp_path_factory.mktemp("traj") / "t.npz"
    assert main(["simulate", PAPER, "--t-end", "0.01", "--method", "compiled", "--closure", "exact",
                 "--out", str(path)]) == 0
    return path


def rewrite(src, dst, **changes):
    with np.load(src) as z:
        data = {k: z[k] for k in z.files}
    data.update(changes)
    np.savez_compressed(dst, **data)
    return dst


def test_trajectory_records_the_flags_the_run_used(trajectory):
    scene = load_trajectory(trajectory).scene
    assert scene.closure.method == "exact" and scene.data["closure"]["method"] == "exact"
    assert scene.simulation.t_end == 0.01 and scene.data["simulation"]["method"] == "compiled"


def test_collide_refuses_non_finite_angles_naming_the_first(capsys, tmp_path, trajectory):
    with np.load(trajectory) as z:
        theta, omega = z["theta"].copy(), z["omega"].copy()
    theta[7, 3] = np.nan
    omega[2, 0] = np.inf
    for name, value, where in (("theta", theta, "theta[7, 3] is nan"),
                               ("omega", omega, "omega[2, 0] is inf")):
        bad = rewrite(trajectory, tmp_path / f"{name}.npz", **{name: value})
        line = one_line_error(capsys, ["collide", str(bad)])
        assert where in line and str(bad) in line, line


def test_collide_checks_the_stored_poses_and_scene(capsys, tmp_path, trajectory):
    with np.load(trajectory) as z:
        position = z["position"].copy()
        scene_yaml = str(z["scene_yaml"])
    position[-1, 4, 0] += 1e-3
    line = one_line_error(capsys, ["collide", str(rewrite(trajectory, tmp_path / "p.npz",
                                                          position=position))])
    assert "position[" in line and "differs from the pose" in line, line
    # Another scene with the same hinge count: the poses do not belong to it.
    import yaml
    data = yaml.safe_load(scene_yaml)
    data["array"]["length"] = 0.12  # another array, same hinge count: other poses
    other = yaml.safe_dump(data)
    line = one_line_error(capsys, ["collide", str(rewrite(trajectory, tmp_path / "s.npz",
                                                          scene_yaml=np.array(other)))])
    assert "differs from the pose" in line, line


@pytest.mark.parametrize("change, expected", [
    ({"format_version": np.array("one")}, "format_version: expected an integer"),
    ({"format_version": np.array([1, 1])}, "format_version: expected an integer"),
    ({"t": np.array([[0.0, 1.0]])}, "t: expected a 1-d array"),
    ({"t": np.array(["a", "b"])}, "t: expected a 1-d array of numbers"),
    ({"scene_yaml": np.array("array: {}\narray: {}\n")}, "duplicate key 'array'"),
    ({"stiffness": np.zeros(3)}, "stiffness has shape (3,)"),
    ({"status": np.array(-7)}, "status: -7 is not a simulation status"),
    ({"status": np.array(-2)}, "success True contradicts status -2"),
    ({"scene_yaml": np.array(alias_bomb())}, "stored scene is invalid (at line 1, column 281: "
                                              "aliases expand it beyond 1000000"),
])
def test_malformed_trajectory_arrays_are_one_line(capsys, tmp_path, trajectory, change, expected):
    line = one_line_error(capsys, ["collide", str(rewrite(trajectory, tmp_path / "x.npz", **change))])
    assert expected in line, line


@pytest.mark.parametrize("member, content, expected", [
    ("theta.npy", npy_declaring((10**12,)),  # 8 TB declared in a 128-byte header
     "theta.npy: its header declares shape (1000000000000,) of float64 (8000000000000 bytes), "
     "but the member holds 0 bytes"),
    ("t.npy", npy_declaring((3, 10**6), bytes(800)), "but the member holds 800 bytes"),
    ("t.npy", npy_declaring((50_001,), bytes(8 * 50_001)),
     "t.npy: 50001 samples, above the limit of 50000"),
    ("notes.txt", b"x", "notes.txt: not an array"),
])
def test_declared_sizes_are_checked_before_reading(capsys, tmp_path, trajectory, member, content,
                                                   expected):
    bad = tmp_path / "declared.npz"
    data = trajectory.read_bytes()
    if member.endswith(".npy"):
        bad.write_bytes(npz_with(data, member, content))
    else:
        bad.write_bytes(data)
        with zipfile.ZipFile(bad, "a") as z:
            z.writestr(member, content)
    line = one_line_error(capsys, ["collide", str(bad)])
    assert line == f"panel-deploy: error: {bad}: {expected}" or expected in line, line


def test_an_archive_declaring_more_than_any_trajectory_is_refused(capsys, tmp_path, trajectory,
                                                                 monkeypatch):
    # zeros deflate a thousand fold: 2 GB held in 2 MB; here the limit is scaled down
    from panel_deploy import trajectory_io
    monkeypatch.setattr(trajectory_io, "_BYTES_PER_BODY_SAMPLE", 1)
    bad = tmp_path / "big.npz"
    bad.write_bytes(npz_with(trajectory.read_bytes(), "closure_sigma_min.npy",
                             npy_declaring((10, 10**5), bytes(8 * 10**6))))
    assert bad.stat().st_size < trajectory.stat().st_size + 20_000
    line = one_line_error(capsys, ["collide", str(bad)])
    declared = re.match(rf"panel-deploy: error: {re.escape(str(bad))}: its arrays declare (\d+) bytes", line)
    assert declared and int(declared.group(1)) > 8 * 10**6, line  # the 8 MB member counted
    assert line.endswith("above the 7200000 of the largest trajectory a scene can ask for (50000 "
                         "samples of 12 x 12 panels)"), line


def test_corrupt_compressed_data_is_one_line(capsys, tmp_path, trajectory):
    data = bytearray(trajectory.read_bytes())
    i = data.index(b"theta.npy") + 200  # inside theta's deflated data
    data[i:i + 64] = bytes(64)
    bad = tmp_path / "zlib.npz"
    bad.write_bytes(bytes(data))
    line = one_line_error(capsys, ["collide", str(bad)])
    assert "not a readable trajectory file" in line, line


def test_collide_says_when_the_stored_run_failed(capsys, tmp_path, trajectory):
    bad = rewrite(trajectory, tmp_path / "f.npz", success=np.array(False), status=np.array(-1),
                  message=np.array("step size collapsed"))
    code, out, _ = run(capsys, "collide", str(bad))
    assert code == 0 and out.startswith("the stored run FAILED at t = 0.01 s (step size collapsed)")
    code, out, _ = run(capsys, "collide", str(bad), "--json")
    assert json.loads(out)["run"] == {"success": False, "status": -1,
                                      "message": "step size collapsed", "t_end": 0.01}


def _hinges(tmp_path, text):
    path = tmp_path / "k.yaml"
    path.write_bytes(text if isinstance(text, bytes) else text.encode())
    return str(path)


@pytest.mark.parametrize("flag", ["--stiffness", "--start"])
@pytest.mark.parametrize("text, expected", [
    (b"hinges: {a: \xff\xfe}\n", "is not UTF-8 text"),
    ("format: other/2\nhinges: {a: 1}\n", "format: expected panel_deploy.stiffness/1"),
    ("hinges: {a: 1}\nbogus: 3\n", "bogus: unknown key"),
    ("hinges: {a: 1}\nhinges: {b: 2}\n", "duplicate key 'hinges'"),
    (alias_bomb(key="hinges"), "aliases expand it beyond 1000000"),
])
def test_bad_result_files_are_one_line(capsys, tmp_path, no_work, flag, text, expected):
    command = "simulate" if flag == "--stiffness" else "optimise"
    line = one_line_error(capsys, [command, PAPER, flag, _hinges(tmp_path, text)])
    assert "stiffness file" in line and expected in line, line


def test_export_refuses_degenerate_models(capsys, tmp_path, monkeypatch):
    from panel_deploy.export import mjcf
    real = mjcf._document
    monkeypatch.setattr(mjcf, "_document", lambda *a: real(*a).replace('pos="0.0', 'pos="nan', 1))
    out = tmp_path / "m.xml"
    line = one_line_error(capsys, ["export", PAPER, "--mjcf", str(out)])
    assert "export: the model has a non-finite value (nan on line" in line
    assert not list(tmp_path.iterdir())


def test_optimise_result_is_rescued_when_the_folder_vanishes(capsys, tmp_path, monkeypatch):
    folder = tmp_path / "out"
    folder.mkdir()
    from panel_deploy.cli import optimise as command
    real = command.verify

    def verify_then_remove(*a, **k):  # the folder goes away while the work runs
        if folder.exists():
            folder.rmdir()
        return real(*a, **k)
    monkeypatch.setattr(command, "verify", verify_then_remove)
    monkeypatch.chdir(tmp_path)
    line = one_line_error(capsys, ["optimise", PAPER, "--max-evaluations", "1", "--workers", "1",
                                   "--quiet", "--set", "simulation.t_end=0.05",
                                   "--out", str(folder / "k.yaml")])
    assert line.startswith("panel-deploy: error: --out: cannot write") and "saved in" in line
    rescued = Path(line.rsplit("saved in ", 1)[1])
    assert rescued.parent == tmp_path and "hinges:" in rescued.read_text()


def test_collide_never_prints_a_non_finite_report(capsys, trajectory, monkeypatch):
    from panel_deploy.collision.check import CollisionReport
    real = CollisionReport.to_dict
    monkeypatch.setattr(CollisionReport, "to_dict", lambda self, **k: {**real(self, **k), "v": math.nan})
    code, out, err = run(capsys, "collide", str(trajectory), "--json")
    assert code == 1 and out == "" and err.strip() == "panel-deploy: collide: non-finite result: v = nan"


@pytest.mark.parametrize("target, limit, expected", [
    ("/dev/full", None, "--out: cannot write /dev/full (No space left on device); the result is "
                        "saved in {tmp}/panel-deploy-rescued-full-"),
    ("old.npz", 20_000, "--out: cannot write old.npz (File too large), nor a fallback file (File "
                        "too large); the result is lost"),  # ulimit -f
])
def test_an_output_that_cannot_be_written_is_one_line(tmp_path, target, limit, expected):
    import subprocess
    import sys

    (tmp_path / "old.npz").write_bytes(b"the previous trajectory")
    cli = str(Path(sys.executable).parent / "panel-deploy")
    proc = subprocess.run([cli, "simulate", PAPER, "--t-end", "0.3", "--out", target],
                          capture_output=True, text=True, timeout=300, cwd=tmp_path,
                          preexec_fn=file_size_limit(limit))
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
    assert lines[-1].startswith("panel-deploy: error: " + expected.format(tmp=tmp_path)), lines
    assert (tmp_path / "old.npz").read_bytes() == b"the previous trajectory"
    rescued = sorted(set(tmp_path.iterdir()) - {tmp_path / "old.npz"})
    if limit:  # the fallback failed too: no unreadable partial file is left
        assert rescued == []
    else:
        assert [str(p) for p in rescued] == [lines[-1].rsplit("saved in ", 1)[1]]
        result, scene = load_trajectory(rescued[0])[:2]
        assert result.t[-1] == pytest.approx(0.3) and scene.name == "paper_4x4"
