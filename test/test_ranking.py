"""Ranking packing circuits by a screening run, and fold.circuit: auto."""

import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import yaml

from panel_deploy.build import build_model, scene_design
from panel_deploy.cli import main
from panel_deploy.collision import CollisionSettings, check_trajectory
from panel_deploy.configure import load_array
from panel_deploy.dynamics import simulate
from panel_deploy.dynamics.report import hinge_angles
from panel_deploy.errors import SceneError
from panel_deploy import ranking
from panel_deploy.fold import circuit_by_index
from panel_deploy.ranking import (COLLISION, FLAT, NO_COLLISION, NOT_SCREENED,
                                       ScreeningSettings, rank_circuits, resolve_circuit)
from panel_deploy.optimise.parallel import task_map
from panel_deploy.scene import load_scene
from panel_deploy.trajectory_io import load_trajectory

PAPER = Path(__file__).resolve().parent.parent / "config" / "scenes" / "paper_4x4.yaml"
#: The paper's panels on any 4 x 4 circuit grounded at its first cell, with soft
#: springs: at the default screening (1 s) circuits 0 and 1 deploy without
#: collision and 2 .. 5 collide (0.25-0.75 s), so the order has something to show.
SOFT = ["fold.circuit=auto", "fold.ground=null", "hinges.stiffness=0.02"]


@pytest.fixture(scope="module")
def soft():
    return load_scene(PAPER, SOFT)


@pytest.fixture(scope="module")
def ranked(soft):
    return rank_circuits(soft)


def independent_outcome(scene, index, settings):
    """The screening of one circuit, from a whole simulation and a whole
    collision check (not the early-stopping run the ranking uses): its class,
    the key within it (the margin, or minus the collision time), the time to
    flat and the collision time. The margin by the formula of
    Screening.margin, without the optimiser's code: p v_press - q d if flat
    (d over the run up to flat), else p v_press + flat_weight (r - tol)."""
    s = settings.scene(scene.replace(fold=replace(scene.fold, circuit=index)))
    model = build_model(s)
    result = simulate(model, s.simulation)
    report = check_trajectory(model, result, CollisionSettings.from_scene(s))
    spread = np.max(np.abs(hinge_angles(model, result)[2]), axis=1)
    flat = np.flatnonzero(spread <= s.simulation.flat_tolerance)
    flat = int(flat[0]) if len(flat) else None
    if report.collided and (flat is None or report.first_collision.sample <= flat):
        return COLLISION, -report.first_collision.t, math.nan, report.first_collision.t
    assert result.success, result.message  # no failure expected on this scene
    opt = s.optimisation
    press = float(np.nanmax(result.contact_onsets[:, 1]))  # 0: the paper scene has no panel contact
    if flat is not None:
        valid = check_trajectory(model, result.head(flat + 1), CollisionSettings.from_scene(s))
        d = valid.d if math.isfinite(valid.d) else 0.0
        return FLAT, opt.p * press - opt.q * d, float(result.t[flat]), math.nan
    margin = opt.p * press + opt.flat_weight * (float(spread.min()) - s.simulation.flat_tolerance)
    return NO_COLLISION, margin, math.nan, math.nan


def test_the_ranking_puts_deploying_circuits_first_as_their_runs_say(soft, ranked):
    assert ranked.examined == 6 and ranked.screened == (0, 1, 2, 3, 4, 5)  # 4 x 4: all pack
    expected = {i: independent_outcome(soft, i, ranked.settings) for i in ranked.screened}
    outcomes = {v[0] for v in expected.values()}
    # the premise: both kinds are there, so the order below can fail
    assert COLLISION in outcomes and outcomes & {FLAT, NO_COLLISION}
    order = sorted(expected, key=lambda i: (*expected[i][:3], i))
    assert [s.index for s in ranked.table] == order
    first_collision = [s.outcome == COLLISION for s in ranked.table].index(True)
    assert all(s.outcome in (FLAT, NO_COLLISION) for s in ranked.table[:first_collision])
    for s in ranked.table:
        assert s.outcome == expected[s.index][0] and s.packs
        if s.outcome == COLLISION:
            assert s.collision_time == pytest.approx(expected[s.index][3], abs=1e-12)
            assert len(s.collision_pair) == 2 and s.clearance == 0.0 and math.isnan(s.margin)
        else:
            assert math.isnan(s.collision_time) and s.collision_pair is None
            # the ranking's run restarts its integrator every few samples: not to the bit
            assert s.margin == pytest.approx(expected[s.index][1], rel=1e-3, abs=1e-6)
    times = [s.collision_time for s in ranked.table if s.outcome == COLLISION]
    assert times == sorted(times, reverse=True)  # latest first collision first


def test_screening_settings_are_the_scenes_own_shortened_and_loosened(soft):
    s = ScreeningSettings.of(soft)
    sim = soft.simulation  # t_end 2 s, rtol 1e-6, atol 1e-8, 401 samples
    assert (s.t_end, s.rtol, s.refine) == (1.0, 1e-4, False)
    assert s.atol == pytest.approx(sim.atol * 100) and s.samples == 201  # the 5 ms grid kept
    # never longer nor tighter than the scene's own
    loose = replace(sim, t_end=0.5, rtol=1e-3)
    s = ScreeningSettings.of(soft.replace(simulation=loose), t_end=3.0, rtol=1e-5)
    assert (s.t_end, s.rtol, s.samples) == (0.5, 1e-3, 401)


def test_the_scenes_screening_section_sets_the_screening(soft):
    """screening.t_end, rtol and damping_ratio are the ranking's defaults; the
    damping ratio goes into every hinge of the screened scene, and the record."""
    scene = load_scene(PAPER, SOFT + ["screening.t_end=1.5", "screening.rtol=1e-5",
                                      "screening.damping_ratio=0.3", "screening.candidates=2"])
    s = ScreeningSettings.of(scene)
    assert (s.t_end, s.rtol, s.damping_ratio) == (1.5, 1e-5, 0.3)
    assert s.scene(scene).hinges.damping_ratio == 0.3
    assert ScreeningSettings.of(soft).scene(soft).hinges == soft.hinges  # default: as it is
    r = rank_circuits(scene)
    assert r.candidates == 2 and r.to_dict()["settings"]["damping_ratio"] == 0.3
    damped = {e.index: e for e in r.table}
    as_is = {e.index: e for e in rank_circuits(soft, 2, t_end=1.5, rtol=1e-5).table}
    # the damping changed the runs, so the setting reached them
    assert any(damped[i].text() != as_is[i].text() for i in damped)


def same_ranking(a, b):
    """The two rankings agree in everything but their wall times."""
    def drop_wall(r):
        d = r.to_dict()
        d.pop("wall_time")
        for e in d["ranking"]:
            e.pop("wall_time")
        return d
    assert drop_wall(a) == drop_wall(b)


def test_screenings_on_worker_processes_rank_as_here(soft, ranked):
    """task_map(2): the screenings on two local processes, each in its own
    interpreter, give the same ranking as one after the other here."""
    seen = []
    with task_map(2) as screen:
        parallel = rank_circuits(soft, progress=seen.append, task_map=screen)
    same_ranking(parallel, ranked)
    assert sorted(e.index for e in seen) == sorted(e.index for e in ranked.table)


def test_candidates_bound_the_work_and_say_which_were_screened(soft):
    r = rank_circuits(soft.replace(array=replace(soft.array, rows=5, cols=6)), 2,
                      t_end=0.01)
    assert len(r.screened) == 2 and r.candidates == 2
    # the first circuits in index order: those that do not pack are listed, unscreened
    skipped = [s for s in r.table if not s.packs]
    assert r.examined == len(r.table) == 2 + len(skipped) and r.screened[-1] == r.examined - 1
    assert all(s.outcome == NOT_SCREENED and s.message.startswith("does not pack")
               for s in skipped) and r.table[-len(skipped):] == tuple(skipped)
    assert json.loads(json.dumps(r.to_dict()))["screened"] == list(r.screened)


def test_auto_resolves_to_the_top_ranked_circuit_once_per_scene(soft, ranked, monkeypatch):
    chosen = resolve_circuit(soft)
    index = ranked.best.index
    assert chosen.fold.circuit == index and chosen.fold.circuit_choice["by"] == "ranking"
    assert chosen.fold.circuit_choice["screened"] == list(ranked.screened)
    # the scene it stores says so, and reads back as that circuit
    assert chosen.data["fold"]["circuit"] == index
    assert chosen.data["fold"]["circuit_choice"]["index"] == index
    assert soft.data["fold"]["circuit"] == "auto"  # the loaded scene is left as it was
    assert scene_design(chosen).circuit == circuit_by_index(4, 4, index)
    # once per scene: loading it again and resolving it ranks nothing
    monkeypatch.setattr(ranking, "rank_circuits", lambda *a, **k: pytest.fail("ranked again"))
    again = load_scene(PAPER, SOFT)
    assert resolve_circuit(again).fold.circuit == index
    assert resolve_circuit(chosen) is chosen  # a circuit index is left alone
    # building is no screening: a scene still on auto is refused, naming the key
    for build in (build_model, scene_design):
        with pytest.raises(SceneError, match="^fold.circuit: auto: resolve the scene first"):
            build(again)


def test_next_ranked_moves_down_the_ranking_saying_why(soft, ranked):
    first = resolve_circuit(soft)
    order = [s.index for s in ranked.table if s.outcome < ranking.FAILED]
    assert [e["index"] for e in first.fold.circuit_choice["ranked"]] == order
    second = ranking.next_ranked(first, "re-check: collision")
    choice = second.fold.circuit_choice
    assert second.fold.circuit == order[1] == choice["index"] == second.data["fold"]["circuit"]
    assert choice["rank"] == 2 and choice["outcome"] == ranked.table[1].text()
    assert choice["passed_over"] == [{"index": order[0], "why": "re-check: collision"}]
    assert scene_design(second).circuit == circuit_by_index(4, 4, order[1])
    text = ranking.choice_text(choice)
    assert "ranked 2" in text and f"circuit {order[0]} passed over: re-check: collision" in text
    last = second
    for _ in order[2:]:
        last = ranking.next_ranked(last, "no design")
    assert last.fold.circuit == order[-1] and len(last.fold.circuit_choice["passed_over"]) == len(order) - 1
    assert ranking.next_ranked(last, "no design") is None  # the ranking ends
    assert ranking.next_ranked(load_scene(PAPER), "no design") is None  # not chosen by one


def test_the_array_model_publishes_the_circuit_auto_chose(soft, ranked, tmp_path):
    path = tmp_path / "soft.yaml"
    path.write_text(yaml.safe_dump(soft.data))
    scene, model, text = load_array(str(path))
    published = yaml.safe_load(text)["fold"]
    assert scene.fold.circuit == published["circuit"] == ranked.best.index
    assert published["circuit_choice"]["by"] == "ranking"


def test_auto_refusals_are_one_line_naming_fold_circuit(soft):
    none = load_scene(PAPER, ["fold.circuit=auto", "fold.ground=null", "array.rows=1"])
    with pytest.raises(SceneError) as e:
        resolve_circuit(none)
    assert str(e.value) == ("fold.circuit: auto: no circuit of the 1 x 4 array packs into two "
                            "stacks (0 examined)")
    # every packing circuit refused by the scene (a hinge override naming no hinge)
    unbuildable = load_scene(PAPER, [*SOFT, "hinges.overrides={nope: 0.1}"])
    with pytest.raises(SceneError) as e:
        resolve_circuit(unbuildable)
    text = str(e.value)
    assert text.startswith("fold.circuit: auto: no packing circuit can be built from this scene "
                           "(circuit 0: not built: hinges.overrides.nope: no such hinge")
    assert "\n" not in text
    with pytest.raises(SceneError, match="^candidates: expected an integer >= 1"):
        rank_circuits(soft, 0)


def run(capsys, *argv):
    code = main([str(a) for a in argv])
    out = capsys.readouterr()
    return code, out.out, out.err


def test_cli_simulate_says_which_circuit_auto_chose(capsys, tmp_path):
    scene = tmp_path / "auto.yaml"
    data = yaml.safe_load(PAPER.read_text())
    data["fold"] = {"circuit": "auto", "ground": None}
    scene.write_text(yaml.safe_dump(data))
    code, out, err = run(capsys, "simulate", scene, "--json", "--t-end", "0.05",
                         "--out", tmp_path / "t.npz")
    summary = json.loads(out)
    choice = summary["circuit_choice"]
    assert code == 0 and choice["by"] == "ranking" and choice["screening"]["t_end"] == 0.05
    assert f"fold.circuit: auto chose circuit {choice['index']}" in err
    stored = load_trajectory(tmp_path / "t.npz").scene
    assert stored.fold.circuit == choice["index"] and stored.fold.circuit_choice == choice
    # the same file with no circuit that packs: one line, exit 2
    data["array"]["rows"] = 1
    scene.write_text(yaml.safe_dump(data))
    code, out, err = run(capsys, "simulate", scene, "--t-end", "0.05")
    assert code == 2 and out == "" and len(err.strip().splitlines()) == 1
    assert "fold.circuit: auto: no circuit of the 1 x 4 array packs" in err


def test_cli_fold_rank_prints_the_ranking(capsys):
    code, out, _ = run(capsys, "fold", "--scene", PAPER, "--rank", "--candidates", "2", "--json",
                       "--set", "simulation.t_end=0.3")
    r = json.loads(out)
    assert code == 0 and r["screened"] == [0, 1] and r["settings"]["t_end"] == 0.3
    # the paper's springs grounded at L1: circuit 0 collides at 0.15 s, circuit 1 not by 0.3 s
    assert [(e["index"], e["outcome"]) for e in r["ranking"]] == [(1, "no collision"),
                                                                 (0, "collision")]
    assert r["ranking"][1]["collision_time"] < 0.3 and r["ranking"][0]["collision_time"] is None
    code, out, _ = run(capsys, "fold", "--scene", PAPER, "--rank", "--candidates", "2",
                       "--set", "simulation.t_end=0.3")
    lines = out.splitlines()
    assert code == 0 and lines[0].startswith("4 x 4 array: 2 packing circuit(s) screened of 2")
    assert [int(line.split()[1]) for line in lines[2:]] == [e["index"] for e in r["ranking"]]


def test_cli_fold_rank_screens_to_the_end_time_asked(capsys):
    code, out, _ = run(capsys, "fold", "--scene", PAPER, "--rank", "--candidates", "2", "--json",
                       "--screen-t-end", "0.2")
    r = json.loads(out)
    assert code == 0 and r["settings"]["t_end"] == 0.2
    # as at 0.3 s: circuit 0 collides at 0.15 s, circuit 1 has not by the end
    assert [(e["index"], e["outcome"]) for e in r["ranking"]] == [(1, "no collision"),
                                                                 (0, "collision")]


@pytest.mark.parametrize("argv, expected", [
    (["fold", "--rows", "4", "--cols", "4", "--rank"], "--rank: needs --scene"),
    (["fold", "--rows", "4", "--cols", "4", "--candidates", "3"], "--candidates: only with --rank"),
    (["fold", "--scene", PAPER, "--rank", "--candidates", "0"], "--candidates: expected"),
    (["fold", "--scene", PAPER, "--screen-t-end", "6"], "--screen-t-end: only with --rank"),
    (["fold", "--scene", PAPER, "--rank", "--screen-t-end", "0"], "--screen-t-end: expected a number > 0"),
    (["fold", "--scene", PAPER, "--rank", "--screen-t-end", "nan"], "--screen-t-end: expected a number"),
    (["fold", "--scene", PAPER, "--rank", "--set", "screening.damping_ratio=-1"],
     "screening.damping_ratio: expected a number >= 0"),
    (["fold", "--scene", PAPER, "--workers", "2"], "--workers: only with --rank"),
    (["fold", "--scene", PAPER, "--rank", "--workers", "-1"], "--workers: expected an integer >= 0"),
    (["fold", "--scene", PAPER, "--rank", "--dask", " "], "--dask: expected a scheduler address"),
    (["fold", "--scene", PAPER, "--rank", "--dask", "tcp://127.0.0.1:9"],
     "dask_address: cannot reach a Dask scheduler"),
])
def test_cli_fold_rank_flags_are_checked(capsys, argv, expected):
    code, out, err = run(capsys, *argv)
    assert code == 2 and out == "" and len(err.strip().splitlines()) == 1 and expected in err


def test_optimise_tries_the_next_ranked_circuits_while_no_design_passes(soft, monkeypatch, capsys):
    from types import SimpleNamespace

    from panel_deploy.cli import optimise as command

    chosen = resolve_circuit(soft)
    order = [e["index"] for e in chosen.fold.circuit_choice["ranked"]]
    tried = []

    def stand_in(args, scene):  # circuit order[1] gives the design
        tried.append(scene.fold.circuit)
        return (0, "") if scene.fold.circuit == order[1] else (1, "re-check: collision")

    monkeypatch.setattr(command, "optimise_scene", stand_in)
    code, last = command.optimise_ranked(SimpleNamespace(), chosen)
    assert code == 0 and tried == order[:2] and last.fold.circuit == order[1]
    assert last.fold.circuit_choice["passed_over"] == [{"index": order[0],
                                                        "why": "re-check: collision"}]
    assert (f"circuit {order[0]} gave no design (re-check: collision); optimising circuit "
            f"{order[1]}, ranked 2") in capsys.readouterr().err
    # optimisation.circuits bounds the tries; a circuit the scene names is the only one
    tried.clear()
    one = replace(chosen, optimisation=replace(chosen.optimisation, circuits=1))
    assert command.optimise_ranked(SimpleNamespace(), one)[0] == 1 and tried == order[:1]
    tried.clear()
    named = load_scene(PAPER, ["fold.circuit=2", "fold.ground=null"])
    assert command.optimise_ranked(SimpleNamespace(), named) == (1, named) and tried == [2]


def test_a_result_of_auto_deploys_on_its_own_circuit(soft, monkeypatch, tmp_path):
    from panel_deploy.cli.args import result_scene
    from panel_deploy.errors import OptimisationError

    on_one = load_scene(PAPER, ["fold.circuit=1", "fold.ground=null"])
    result = tmp_path / "k.yaml"
    result.write_text(yaml.safe_dump({
        "format": "panel_deploy.stiffness/1", "circuit": 1,
        "hinges": {h.name: {"k": 0.05} for h in build_model(on_one).hinges}}))
    monkeypatch.setattr(ranking, "rank_circuits", lambda *a, **k: pytest.fail("ranked"))
    scene = result_scene(soft, result)
    assert scene.fold.circuit == 1 and scene.data["fold"]["circuit"] == 1
    assert scene.fold.circuit_choice == {"index": 1, "by": "stiffness file", "file": str(result)}
    assert result_scene(on_one, result) is on_one  # a circuit the scene names stays
    # another circuit's model: the error says which circuit the file is for
    with pytest.raises(OptimisationError, match="the file is for fold.circuit 1, "
                                                "--set fold.circuit=1 builds it"):
        from panel_deploy.pipeline import scene_model
        scene_model(load_scene(PAPER, ["fold.circuit=0", "fold.ground=null"]), result)
    result.write_text(result.read_text().replace("circuit: 1", "circuit: 99"))
    with pytest.raises(OptimisationError, match=r"^stiffness file '.*k.yaml': circuit: circuit "
                                                r"index 99 out of range"):
        result_scene(soft, result)
