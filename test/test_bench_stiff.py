"""The stiff-case suite at small size: every run succeeds or fails loudly.

Short runs of the paper scene (a few ms of deployment), a few cases, a small
step budget. A failure must be ``success=False`` with a message, never a NaN
trajectory reported as success; on the stiff (overdamped penalty) case the
implicit solvers must succeed where an explicit one runs out of budget.
"""

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from panel_deploy.bench import stiff
from panel_deploy.build import build_model
from panel_deploy.scene import load_scene

SCENE = Path(__file__).resolve().parent.parent / "config" / "scenes" / "paper_4x4.yaml"
CASES = ("folded start", "k_M=1e+08", "k_M=1e8 c_M=2e4")
METHODS = ("RK45", "Radau", "BDF")


@pytest.fixture(scope="module")
def outcomes():
    scene = load_scene(SCENE)
    model = build_model(scene)
    base = dataclasses.replace(scene.simulation, t_end=0.004, samples=5)
    cases = [c for c in stiff.stiff_cases(full=True) if c.name in CASES]
    assert [c.name for c in cases] == list(CASES)
    # RK45 needs ~1.6e4 steps per 10 ms on the overdamped penalty, Radau ~200
    return stiff.run_suite({"paper": model}, base, cases, METHODS, max_steps=1500,
                           reference_rtol=1e-8)


def test_every_run_succeeds_except_explicit_on_the_overdamped_penalty(outcomes):
    assert len(outcomes) == len(CASES) * len(METHODS)
    assert not [o for o in outcomes if o.method == "reference"]  # every reference converged
    for o in outcomes:
        if (o.case, o.method) == ("k_M=1e8 c_M=2e4", "RK45"):
            # fails loudly: a status and a message, not a NaN trajectory
            assert o.status == "FAIL" and "step budget (1500) exhausted" in o.message, o
        else:
            assert o.status == "ok", o
            assert math.isfinite(o.error) and o.error >= 0.0, o
            assert o.nfev > 0


def test_runs_are_accurate_against_the_reference(outcomes):
    # rtol 1e-6 over 4 ms: far below a milliradian
    for o in outcomes:
        if o.status == "ok":
            assert o.error < 1e-3, o


def test_stiff_solvers_carry_the_case_an_explicit_one_cannot(outcomes):
    cell = {(o.case, o.method): o for o in outcomes}
    explicit = cell[("k_M=1e8 c_M=2e4", "RK45")]
    assert explicit.status == "FAIL" and "budget" in explicit.message
    for method in ("Radau", "BDF"):
        assert cell[("k_M=1e8 c_M=2e4", method)].status == "ok"


def test_nan_trajectory_reported_as_success_is_classified_silent():
    class Fake:
        success = True
        message = "reached t_end"
        theta = np.array([[0.0, np.nan]])
        omega = np.zeros((1, 2))

    assert stiff._classify(Fake) == "SILENT"
    Fake.success, Fake.message = False, ""
    assert stiff._classify(Fake) == "SILENT"
    Fake.message = "step size collapsed"
    assert stiff._classify(Fake) == "FAIL"


def test_case_variants_change_only_what_they_name():
    model = build_model(load_scene(SCENE))
    cases = {c.name: c for c in stiff.stiff_cases(full=True)}
    heavy = cases["mass x1000"].make(model)
    changed = [b for b, (x, y) in enumerate(zip(model.bodies, heavy.bodies)) if x.mass != y.mass]
    assert changed == [model.order[-1]]
    assert heavy.bodies[changed[0]].mass == pytest.approx(1000 * model.bodies[changed[0]].mass)
    undamped = cases["undamped"].make(model)
    assert all(h.c == 0 for h in undamped.hinges) and undamped.c_s == 0
    assert undamped.closure.c_M == undamped.closure.c_N == 0
    np.testing.assert_array_equal(undamped.stiffness, model.stiffness)
    split = cases["k 0.001/0.2"].make(model)
    ks = {h.k for h in split.hinges}
    assert ks == {0.001, 0.2}
    for h, h0 in zip(split.hinges, model.hinges):
        assert h.c / h.k == pytest.approx(h0.c / h0.k)  # Rayleigh: c follows k


def test_time_at_equal_error_interpolates_each_method_in_log_log():
    from panel_deploy.bench.work_precision import Point, time_at_error

    def point(method, wall, error, success=True):
        return Point("ours", method, 0.0, wall, 0, 0, error, error, success, "")

    points = [point("A", 1.0, 1e-2), point("A", 10.0, 1e-4), point("A", 0.5, 1e-1),
              point("B", 0.1, 1.0), point("B", 0.2, math.nan, success=False)]
    # straight line in log-log from (1 s, 1e-2) to (10 s, 1e-4): 1e-3 at sqrt(10) s
    t, method = time_at_error(points, 1e-3)
    assert method == "A" and t == pytest.approx(math.sqrt(10.0))
    assert time_at_error(points, 1e-1) == (0.5, "A")
    t, method = time_at_error(points, 1e-6)
    assert math.isnan(t) and method == ""


def test_write_suite_writes_its_table_and_csv(tmp_path, monkeypatch):
    # two cases, one method: the writing, not the suite, is under test
    cases = [c for c in stiff.stiff_cases(full=False)][:2]
    monkeypatch.setattr(stiff, "stiff_cases", lambda full: cases)
    real = stiff.run_suite
    monkeypatch.setattr(stiff, "run_suite", lambda *a, **k: real(*a, methods=("compiled",), **k))
    out = tmp_path / "new" / "folder"
    text = stiff.write_suite(load_scene(SCENE), out, quick=True, t_end=0.002, sizes=(), max_steps=500)
    assert sorted(p.name for p in out.iterdir()) == ["stiff_cases_quick.csv", "stiff_cases_quick.md"]
    assert (out / "stiff_cases_quick.md").read_text() == text + "\n"
    rows = (out / "stiff_cases_quick.csv").read_text().splitlines()
    assert rows[0].startswith("case,method,status") and len(rows) == 1 + 2
    assert all(",compiled,ok," in row for row in rows[1:])
