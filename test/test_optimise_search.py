"""Stiffness optimisation machinery on closed-form stand-in evaluations.

The stand-ins replace simulate + collision check by formulas in log10 k with
a known optimum, so the search, restarts, groups, budget, parallel backends
and error handling are checked exactly and fast. The real pipeline is
exercised in test_optimise_pipeline.py.
"""

import math
import re
from dataclasses import replace

import numpy as np
import pytest

from panel_deploy.errors import OptimisationError
from panel_deploy.model import Body, Hinge, Model, box_inertia
from panel_deploy.optimise import (FLAT_TOLERANCE, Outcome, StiffnessProblem, evaluate,
                                   objective, optimise)
from panel_deploy.scene import scene_from_dict

A, T, MASS = 0.1, 0.005, 0.02


def chain_model(n_bodies=4, k=0.1, beta=0.043, gravity=(0.0, 0.0, 0.0)):
    """A row of unit panels hinged along their shared edges, zig-zag facets (a stowed stack)."""
    size = np.array([A, A, T])
    bodies = [Body(f"P{i}", ((1, i + 1),), size, MASS, box_inertia(MASS, size),
                   np.array([i * A, 0.0, 0.0])) for i in range(n_bodies)]
    hinges = []
    for i in range(n_bodies - 1):
        facet = "top" if i % 2 == 0 else "bottom"
        z = T / 2 if facet == "top" else -T / 2
        axis = np.array([0.0, -1.0, 0.0]) if facet == "top" else np.array([0.0, 1.0, 0.0])
        y0 = A / 2 if facet == "top" else -A / 2
        hinges.append(Hinge(f"h{i}", i, i + 1, np.array([(i + 0.5) * A, y0, z]), axis, A,
                            facet, k, beta * k, math.pi, (((1, i + 1), (1, i + 2)),)))
    return Model.build(bodies, hinges, 0, gravity=gravity)


def scene(**optimisation):
    data = {"array": {"rows": 1, "cols": 4, "length": A, "width": A, "thickness": T, "mass": MASS},
            "optimisation": {"bounds": [0.001, 0.2], "k0": 0.1, "workers": 1, **optimisation}}
    return scene_from_dict(data)


# Stand-in: clearance d peaks where log10 k = TARGET (per hinge), collision when
# it would go negative, and a locked deployment when any k is below LOCK.
TARGET = np.array([-1.5, -2.0, -1.2])
LOCK = 0.002


def bowl_outcome(model, settings):
    u = np.log10(model.stiffness)
    d = 0.05 - 0.02 * float(np.sum((u - TARGET) ** 2))
    locked = bool(np.any(model.stiffness < LOCK))
    if d <= 0:
        return Outcome(collided=True, v=-d * 10, d=0.0, flat_residual=0.0,
                       first_collision={"t": 0.3, "pair": ["P0", "P2"]})
    return Outcome(collided=False, v=0.0, d=d, flat_residual=math.pi if locked else 0.0)


def plateau_outcome(model, settings):
    """Collides at one constant speed unless hinge 0 is soft: a flat plateau around K_0."""
    k = model.stiffness
    if k[0] > 0.01:
        return Outcome(collided=True, v=0.5, d=0.0, flat_residual=0.0)
    return Outcome(collided=False, v=0.0, d=0.03 - 0.01 * (np.log10(k[0]) + 2.5) ** 2,
                   flat_residual=0.0)


# Stand-in for a design that needs damping: collision-free only for c/k within
# DAMPED_BAND (s), where the bowl's clearance applies; elsewhere it collides, the
# faster the further c/k lies from the band (in log c/k).
DAMPED_BAND = (0.15, 0.25)


def damped_outcome(model, settings):
    h = model.hinges[0]
    beta = h.c / h.k
    miss = max(0.0, np.log10(DAMPED_BAND[0] / beta), np.log10(beta / DAMPED_BAND[1]))
    if miss > 0:
        return Outcome(collided=True, v=miss, d=0.0, flat_residual=0.0,
                       first_collision={"t": 0.3, "pair": ["P0", "P2"]})
    return bowl_outcome(model, settings)


def test_objective_is_eq8_plus_flat_term():
    o = Outcome(collided=True, v=0.2, d=0.0, flat_residual=0.0)
    assert objective(o, 2.0, 10.0, 1.0) == pytest.approx(0.4)
    o = Outcome(collided=False, v=0.0, d=0.01, flat_residual=0.01)
    assert objective(o, 2.0, 10.0, 1.0) == pytest.approx(-0.1)        # flat: the paper's f
    o = Outcome(collided=False, v=0.0, d=0.01, flat_residual=1.05)
    assert objective(o, 2.0, 10.0, 3.0) == pytest.approx(3.0)  # 1 rad past tolerance, no d
    # never flat is a failure: no clearance earns it a better score than a feasible run
    near = Outcome(collided=False, v=0.0, d=0.05, flat_residual=FLAT_TOLERANCE + 0.1)
    tight = Outcome(collided=False, v=0.0, d=0.001, flat_residual=0.0)
    assert objective(near, 1.0, 10.0, 1.0) == pytest.approx(0.1)
    assert objective(tight, 1.0, 10.0, 1.0) < 0 < objective(near, 1.0, 10.0, 1.0)
    failed = Outcome(collided=False, v=0.0, d=0.05, flat_residual=0.0, simulated=False)
    assert objective(failed, 1.0, 10.0, 1.0) > objective(
        Outcome(collided=True, v=3.0, d=0.0, flat_residual=math.pi), 1.0, 10.0, 1.0)


def test_evaluate_makes_damping_follow_stiffness():
    model = chain_model(k=0.1, beta=0.043)
    k = np.array([0.01, 0.05, 0.2])
    ev = evaluate(model, k, scene(), evaluation=bowl_outcome)
    np.testing.assert_allclose(ev.c, 0.043 * k)
    assert ev.f == pytest.approx(objective(bowl_outcome(model.with_stiffness(k), None), 1, 10, 1))
    assert np.all(model.stiffness == 0.1)  # the base model is untouched


def test_local_search_finds_the_known_optimum():
    res = optimise(chain_model(), scene(), workers=1, evaluation=bowl_outcome)
    assert res.success and res.status == 0, res.message
    assert not res.outcome.collided and res.outcome.reached_flat
    # The forward-difference step (0.05 decades) limits accuracy to about half a step.
    np.testing.assert_allclose(np.log10(res.k), TARGET, atol=0.05)
    assert res.f < res.initial.f
    assert res.nfev == len(res.history) <= scene().optimisation.max_evaluations
    np.testing.assert_allclose(res.c, 0.043 * res.k)


@pytest.mark.parametrize("beta, bounds", [(3.0, (0.043, 3.0)), (0.3, (0.3, 1.0))])
def test_a_damping_ratio_on_a_bound_is_inside_it(beta, bounds):
    """c = (c/k) k rounds: 0.1 * 3.0 / 0.1 is 3.0000000000000004, which once made
    the search refuse the array_10x10 scene's own c/k as outside [0.043, 3]."""
    model = chain_model(beta=beta)
    problem = StiffnessProblem.from_model(model, (0.001, 0.2), 0.1, damping_bounds=bounds)
    lo, hi = problem.x_bounds[-1]
    assert lo <= problem.x0[-1] <= hi and problem.x0[-1] == pytest.approx(np.log10(beta), abs=1e-12)
    with pytest.raises(OptimisationError, match="^damping_ratio_bounds: the search starts from"):
        StiffnessProblem.from_model(model, (0.001, 0.2), 0.1,
                                    damping_bounds=(bounds[0] / 2, beta * (1 - 1e-9)))


def test_groups_share_one_stiffness():
    res = optimise(chain_model(), scene(), workers=1, evaluation=bowl_outcome,
                   groups=[["h0", "h2"]])
    assert res.k[0] == res.k[2]
    assert res.problem.groups == ((0, 2), (1,))
    # Best shared value is the mean of the two targets in log k.
    assert np.log10(res.k[0]) == pytest.approx((TARGET[0] + TARGET[2]) / 2, abs=0.05)


def test_damping_ratio_bounds_add_one_shared_variable():
    model = chain_model(beta=0.043)
    problem = StiffnessProblem.from_model(model, (0.001, 0.2), 0.1, damping_bounds=(0.01, 0.5))
    assert problem.n == 4 and problem.damping_variable
    np.testing.assert_allclose(problem.x0, np.log10([0.1, 0.1, 0.1, 0.043]))
    np.testing.assert_allclose(problem.x_bounds[-1], np.log10([0.01, 0.5]))
    x = np.log10([0.01, 0.05, 0.2, 0.2])
    np.testing.assert_allclose(problem.k_of(x), [0.01, 0.05, 0.2])
    np.testing.assert_allclose(problem.c_of(x), 0.2 * np.array([0.01, 0.05, 0.2]))
    np.testing.assert_allclose(problem.x_of(problem.k_of(x), problem.c_of(x)), x)
    with pytest.raises(OptimisationError, match="^c: "):
        problem.x_of(problem.k_of(x))
    fixed = StiffnessProblem.from_model(model, (0.001, 0.2), 0.1)
    assert fixed.n == 3 and not fixed.damping_variable
    np.testing.assert_allclose(fixed.c_of(x[:3]), 0.043 * fixed.k_of(x[:3]))


@pytest.mark.parametrize("method", ["local", "global"])
def test_search_chooses_the_damping_ratio_when_it_is_a_variable(method):
    s = scene(method=method, max_evaluations=200, seed=2, damping_ratio_bounds=[0.01, 0.5])
    res = optimise(chain_model(beta=0.043), s, workers=1, evaluation=damped_outcome)
    assert res.initial.outcome.collided  # the model's 0.043 s lies outside the band
    assert res.success and res.problem.damping_variable
    beta = res.c / res.k
    np.testing.assert_allclose(beta, beta[0])  # one lubricant for every hinge
    assert DAMPED_BAND[0] <= beta[0] <= DAMPED_BAND[1]
    # The line search in c/k along K_0 (the bounds' ends, then at most 20 evaluations) reaches the band.
    n, _ = res.first_feasible
    assert n <= 23 and np.allclose(res.history[n - 1].k, 0.1)
    # With c/k fixed at the model's, no K is collision-free.
    fixed = optimise(chain_model(beta=0.043), scene(method=method, max_evaluations=60, seed=2),
                     workers=1, evaluation=damped_outcome)
    assert not fixed.success and fixed.outcome.collided


def top_outcome(model, settings):
    """Collides alike (no slope to follow) unless c/k is within 1 % of 0.5 s,
    the top of the bounds (the 8 x 8 array of docs/findings.md 4.8)."""
    h = model.hinges[0]
    if h.c / h.k < 0.495:
        return Outcome(collided=True, v=0.1, d=0.0, flat_residual=0.0)
    return bowl_outcome(model, settings)


def test_the_damping_line_search_tries_the_ends_of_its_bounds():
    s = scene(method="local", max_evaluations=40, damping_ratio_bounds=[0.01, 0.5])
    res = optimise(chain_model(beta=0.043), s, workers=1, evaluation=top_outcome)
    assert res.success
    n, _ = res.first_feasible
    first = res.history[n - 1]
    assert n == 3 and first.c[0] / first.k[0] == pytest.approx(0.5)  # K_0, then the two ends
    assert np.allclose(first.k, 0.1) and res.history[1].c[0] / res.history[1].k[0] == pytest.approx(0.01)


def edge_outcome(model, settings):
    """Feasible for c/k in 0.18-0.22 s, with d largest at the low edge (as on the paper scene)."""
    h = model.hinges[0]
    beta = h.c / h.k
    if not 0.18 <= beta <= 0.22:
        return Outcome(collided=True, v=abs(np.log10(beta / 0.2)), d=0.0, flat_residual=0.0)
    return Outcome(collided=False, v=0.0, d=0.02 + 0.1 * np.log10(0.22 / beta), flat_residual=0.0)


def test_the_result_sits_in_the_middle_of_its_feasible_damping_range():
    s = scene(max_evaluations=200, damping_ratio_bounds=[0.01, 0.5])
    res = optimise(chain_model(beta=0.043), s, workers=1, evaluation=edge_outcome)
    assert res.success and res.nfev <= 200
    lo, hi = res.damping_window
    tol = 10 ** 0.005  # the bisection's resolution
    assert 0.18 <= lo < 0.18 * tol and 0.22 / tol < hi <= 0.22
    assert res.c[0] / res.k[0] == pytest.approx(math.sqrt(lo * hi), rel=1e-9)
    assert "centred" in res.message
    # The search's own best was at the low edge, with more clearance.
    edge = min(res.history, key=lambda e: e.f)
    assert edge.outcome.feasible and edge.f < res.f and edge.c[0] / edge.k[0] < 0.18 * 1.1
    # A budget with no room for the centring leaves c/k where the search put it.
    small = optimise(chain_model(beta=0.043), scene(max_evaluations=25, damping_ratio_bounds=[0.01, 0.5]),
                     workers=1, evaluation=edge_outcome)
    assert small.damping_window is None and small.nfev <= 25


def holed_outcome(model, settings):
    """edge_outcome with a hole at c/k 0.195-0.205 s, around the window's middle."""
    h = model.hinges[0]
    if 0.195 <= h.c / h.k <= 0.205:
        return Outcome(collided=True, v=0.01, d=0.0, flat_residual=0.0)
    return edge_outcome(model, settings)


def test_a_hole_in_the_damping_range_leaves_the_searchs_k():
    s = scene(max_evaluations=200, damping_ratio_bounds=[0.01, 0.5])
    res = optimise(chain_model(beta=0.043), s, workers=1, evaluation=holed_outcome)
    assert res.success and res.damping_window is None
    assert res.best is min(res.history, key=lambda e: e.f) and "centred" not in res.message


def two_basins(model, settings):
    """k[0] >= 0.05: d = 50 mm, feasible for c/k 0.1995-0.2005 s only; else d = 30 mm, 0.15-0.25 s."""
    h = model.hinges[0]
    band, d = ((0.1995, 0.2005), 0.05) if h.k >= 0.05 else ((0.15, 0.25), 0.03)
    ok = band[0] <= h.c / h.k <= band[1]
    return Outcome(collided=not ok, v=0.0 if ok else 0.1, d=d if ok else 0.0, flat_residual=0.0)


def test_centring_prefers_a_k_with_margin_in_damping_to_a_knife_edge():
    from panel_deploy.optimise.damping import centre_damping
    from panel_deploy.optimise.parallel import Job, SerialBackend
    from panel_deploy.optimise.search import Run

    model = chain_model(beta=0.043)
    problem = StiffnessProblem.from_model(model, (0.001, 0.2), 0.1, damping_bounds=(0.01, 0.5))
    run = Run(problem, SerialBackend(Job(model, scene(), two_basins)), 200)
    knife, wide = run.batch([np.log10([0.1, 0.1, 0.1, 0.2]), np.log10([0.01, 0.1, 0.1, 0.2])])
    assert knife.f < wide.f < 0
    centred, (lo, hi) = centre_damping(run)
    tol = 10 ** 0.005
    assert 0.15 <= lo < 0.15 * tol and 0.25 / tol < hi <= 0.25
    assert centred.k[0] == pytest.approx(0.01)
    assert centred.c[0] / centred.k[0] == pytest.approx(math.sqrt(lo * hi))


def test_restart_leaves_a_colliding_plateau():
    res = optimise(chain_model(), scene(restarts=5, seed=3), workers=1, evaluation=plateau_outcome)
    assert res.initial.outcome.collided  # K_0 collides, and the gradient there is zero
    assert res.nstarts > 1
    assert res.success and res.k[0] <= 0.01
    # The first feasible K is recorded when it came back, not at the end.
    n, t = res.first_feasible
    assert res.history[n - 1].outcome.feasible
    assert not any(e.outcome.feasible for e in res.history[:n - 1])
    assert 0 < t <= res.wall_time


def test_no_feasible_point_is_reported_not_raised():
    res = optimise(chain_model(), scene(restarts=1, bounds=[0.05, 0.2], k0=0.1), workers=1,
                   evaluation=plateau_outcome)
    assert not res.success and res.status == 2 and res.nstarts == 2
    assert "collides" in res.message
    assert res.first_feasible is None


def test_global_search_finds_the_known_optimum():
    res = optimise(chain_model(), scene(method="global", max_evaluations=150, seed=1), workers=1,
                   evaluation=bowl_outcome)
    assert res.success and res.method == "global"
    np.testing.assert_allclose(np.log10(res.k), TARGET, atol=0.1)
    assert res.nfev <= 150


def test_search_goes_on_from_a_previous_results_per_hinge_k():
    first = optimise(chain_model(), scene(max_evaluations=12), workers=1, evaluation=bowl_outcome,
                     groups=[["h0", "h2"]])
    again = optimise(chain_model(), scene(max_evaluations=12), workers=1, evaluation=bowl_outcome,
                     groups=[["h0", "h2"]], k0=first.k)
    np.testing.assert_array_equal(again.initial.k, first.k)
    np.testing.assert_array_equal(again.problem.k0, first.k[[0, 1]])
    assert again.f <= first.f


def test_budget_is_respected():
    res = optimise(chain_model(), scene(max_evaluations=9), workers=1, evaluation=bowl_outcome)
    # K_0, then gradient batches of n + 1 = 4: the third batch would pass 9
    assert res.nfev == 8 and res.status == 1 and res.success
    assert res.message == ("collision-free and flat; stopped by the evaluation budget "
                           "(its next batch, 4 K, did not fit in the 1 left)")


def test_a_budget_below_one_generation_says_so():
    """Differential evolution evaluates 2 K per variable at once (6 here, K_0
    among them, so 5 new): a budget that leaves fewer buys K_0 alone, and the
    message says why."""
    res = optimise(chain_model(), scene(max_evaluations=5, method="global"), workers=1,
                   evaluation=plateau_outcome)
    assert res.nfev == 1 and not res.success
    assert res.message.endswith("the search's next batch (5 K) did not fit in the 4 left")


def test_progress_reports_every_batch():
    seen = []
    res = optimise(chain_model(), scene(max_evaluations=30), workers=1, evaluation=bowl_outcome,
                   progress=seen.append)
    assert seen and seen[-1].nfev == res.nfev
    assert [p.nfev for p in seen] == sorted(p.nfev for p in seen)
    assert all(p.elapsed >= 0 and p.phase for p in seen)
    assert seen[-1].best_f == pytest.approx(res.f)


def test_process_pool_gives_the_serial_result():
    serial = optimise(chain_model(), scene(max_evaluations=40), workers=1, evaluation=bowl_outcome)
    pooled = optimise(chain_model(), scene(max_evaluations=40), workers=2, evaluation=bowl_outcome)
    np.testing.assert_array_equal(pooled.k, serial.k)
    assert [e.f for e in pooled.history] == [e.f for e in serial.history]


@pytest.mark.parametrize("kwargs, field", [
    ({"bounds": (0.2, 0.001)}, "bounds"),
    ({"bounds": (0.0, 0.2)}, "bounds"),
    ({"bounds": (0.1, 0.1)}, "bounds"),
    ({"k0": 0.5}, "k0"),
    ({"k0": [0.1, 0.1]}, "k0"),
    ({"groups": [["h0"], []]}, "groups[1]"),
    ({"groups": [["h0", "nope"]]}, "groups[0]"),
    ({"groups": [[0, 1], [1, 2]]}, "groups[1]"),
    ({"groups": [[7]]}, "groups[0]"),
    ({"k0": [0.1, 0.05, 0.2], "groups": [["h0", "h2"]]}, "k0"),
    ({"damping_bounds": (0.0, 0.3)}, "damping_ratio_bounds"),
    ({"damping_bounds": (0.3, 0.01)}, "damping_ratio_bounds"),
    ({"damping_bounds": (0.1, 0.3)}, "damping_ratio_bounds"),  # the start, 0.043 s, is outside
])
def test_bad_problem_names_the_field(kwargs, field):
    model = chain_model()
    args = {"bounds": (0.001, 0.2), "k0": 0.1, **kwargs}
    with pytest.raises(OptimisationError, match="^" + re.escape(field) + ": "):
        StiffnessProblem.from_model(model, args["bounds"], args["k0"], args.get("groups"),
                                    args.get("damping_bounds"))


def test_bad_options_raise_before_any_evaluation():
    # A scene built in code skips load_scene's validation; optimise checks again.
    s = scene()
    bad = s.replace(optimisation=type(s.optimisation)(bounds=(0.2, 0.001), k0=0.1))
    with pytest.raises(OptimisationError, match="^bounds: "):
        optimise(chain_model(), bad, workers=1, evaluation=bowl_outcome)
    with pytest.raises(OptimisationError, match="^workers: "):
        optimise(chain_model(), s, workers=-1, evaluation=bowl_outcome)
    for field, value in (("method", "newton"), ("max_evaluations", 0), ("restarts", -1)):
        bad = s.replace(optimisation=replace(s.optimisation, **{field: value}))
        with pytest.raises(OptimisationError, match=f"^{field}: "):
            optimise(chain_model(), bad, evaluation=bowl_outcome)


def test_unreachable_scheduler_is_a_clear_error():
    # Port 9 (discard) on loopback: nothing listens, the connect times out quickly.
    with pytest.raises(OptimisationError, match="^dask_address: cannot reach"):
        optimise(chain_model(), scene(), dask_address="tcp://127.0.0.1:9", evaluation=bowl_outcome)


_CALLS = []


def interrupted_outcome(model, settings):
    """bowl_outcome, until the 12th run, where the user presses Ctrl-C."""
    _CALLS.append(1)
    if len(_CALLS) == 12:
        raise KeyboardInterrupt
    return bowl_outcome(model, settings)


def test_ctrl_c_returns_the_best_so_far_as_a_result(tmp_path):
    _CALLS.clear()
    res = optimise(chain_model(), scene(), workers=1, evaluation=interrupted_outcome)
    # The batch the interrupt hit is lost; every batch before it is kept.
    assert res.status == 3 and f"interrupted after {res.nfev} evaluations" in res.message
    assert res.success == res.outcome.feasible
    assert 0 < res.nfev == len(res.history) < 12
    assert res.f == min(e.f for e in res.history)


def test_search_scene_loosen_rtol_atol_and_refinement():
    from panel_deploy.optimise.search import search_scene
    s = scene()
    assert search_scene(s) == s                      # default: the scene's own
    assert search_scene(scene(refine=False)).collision.refine is False
    loose = scene(rtol=1e-3)
    sim = search_scene(loose).simulation
    assert sim.rtol == 1e-3
    assert sim.atol / sim.rtol == pytest.approx(loose.simulation.atol / loose.simulation.rtol)
    with pytest.raises(Exception, match=r"optimisation\.rtol"):
        scene(rtol=-1.0)


def test_a_non_finite_value_in_the_result_file_makes_it_a_failure():
    from panel_deploy.optimise import result_to_dict
    res = optimise(chain_model(), scene(), workers=1, evaluation=bowl_outcome)
    assert result_to_dict(res)["success"]
    out = result_to_dict(res, extra={"verification": {"d": math.nan}})
    assert out["success"] is False
    assert out["message"].startswith("non-finite result: verification.d = nan")
