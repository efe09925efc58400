"""Result files, spring snapping, re-verification and the tolerance check."""

import itertools

import numpy as np
import pytest
import yaml

from panel_deploy.errors import OptimisationError
from panel_deploy.optimise import (Outcome, load_damping, load_stiffness, optimise, save_result, snap_to_springs,
                                   soft_hinges, tolerance_check, verify)
from test_optimise_search import bowl_outcome, chain_model, scene


def settings_echo(model, settings):
    """Stand-in that reports the simulation settings it was given."""
    sim = settings.simulation
    return Outcome(collided=False, v=0.0, d=0.01, flat_residual=0.0,
                   message=f"{sim.rtol!r} {sim.atol!r} {sim.samples}")


def band_outcome(model, settings):
    """Collision-free while every k is within 3 % of 0.05 and every c within 3 % of 0.043 k."""
    k = model.stiffness
    c = np.array([h.c for h in model.hinges])
    ok = np.all(np.abs(k / 0.05 - 1) <= 0.03) and np.all(np.abs(c / (0.043 * 0.05) - 1) <= 0.03)
    return Outcome(collided=not ok, v=0.0 if ok else 0.1, d=0.01 if ok else 0.0, flat_residual=0.0)


def test_result_file_round_trip(tmp_path):
    model = chain_model()
    res = optimise(model, scene(max_evaluations=30), workers=1, evaluation=bowl_outcome)
    path = save_result(res, tmp_path / "r.yaml", "chain", extra={"note": {"x": 1}})
    data = yaml.safe_load(path.read_text())
    assert data["format"] == "panel_deploy.stiffness/1" and data["scene"] == "chain"
    assert data["f"] == pytest.approx(res.f) and data["d"] == pytest.approx(res.outcome.d)
    assert data["nfev"] == res.nfev and data["collision"] is None and data["note"] == {"x": 1}
    assert data["initial"]["f"] == pytest.approx(res.initial.f)
    np.testing.assert_array_equal(load_stiffness(path, model), res.k)
    assert [data["hinges"][h.name]["c"] for h in model.hinges] == pytest.approx(list(res.c))
    np.testing.assert_array_equal(load_damping(path, model), res.c)


@pytest.mark.parametrize("content, expected", [
    ("hinges: {h0: 0.1, h1: 0.1}", "hinges: missing h2"),
    ("hinges: {h0: 0.1, h1: 0.1, h2: 0.1, h9: 0.1}", "hinges.h9: no such hinge"),
    ("hinges: {h0: 0.1, h1: {k: -1}, h2: 0.1}", "hinges.h1.k: expected a finite number >= 0"),
    ("hinges: {h0: 0.1, h1: {c: 1}, h2: 0.1}", "hinges.h1.k: expected"),
    ("hinges: {h0: .nan, h1: 0.1, h2: 0.1}", "hinges.h0.k: expected"),
    ("[1, 2]", "expected a mapping with a 'hinges' mapping"),
    ("hinges: [", "not valid YAML"),
])
def test_bad_stiffness_files_name_the_entry(tmp_path, content, expected):
    path = tmp_path / "k.yaml"
    path.write_text(content)
    with pytest.raises(OptimisationError, match="stiffness file") as e:
        load_stiffness(path, chain_model())
    assert expected in str(e.value)
    with pytest.raises(OptimisationError, match="cannot read"):
        load_stiffness(tmp_path / "missing.yaml", chain_model())


def test_plain_mapping_file_loads(tmp_path):
    path = tmp_path / "k.yaml"
    path.write_text("hinges: {h0: 0.02, h1: 0, h2: {k: 0.2}}")
    np.testing.assert_array_equal(load_stiffness(path, chain_model()), [0.02, 0.0, 0.2])
    assert load_damping(path, chain_model()) is None   # no c given: damping follows k


def test_damping_given_for_some_hinges_only_names_the_first_without(tmp_path):
    path = tmp_path / "k.yaml"
    path.write_text("hinges: {h0: {k: 0.1, c: 0.004}, h1: 0.1, h2: {k: 0.1, c: 0.004}}")
    with pytest.raises(OptimisationError, match=r"hinges\.h1\.c: expected a finite number >= 0 "
                                                r"N m s/rad, got None"):
        load_damping(path, chain_model())


def test_soft_hinges_are_ten_times_softer_than_all_the_rest():
    k = np.array([0.1, 0.004, 0.05, 0.003, 0.2])
    np.testing.assert_array_equal(soft_hinges(k, 10), [False, True, False, True, False])
    assert not soft_hinges(np.array([0.1, 0.02, 0.05]), 10).any()   # 0.02 * 10 > 0.05
    assert not soft_hinges(np.array([0.1, 0.1]), 10).any()


def test_snap_rounds_up_to_parallel_combinations():
    springs = [0.07, 0.1]
    k = np.array([0.08, 0.15, 0.005, 0.3, 0.07])
    snap = snap_to_springs(k, springs, max_parallel=2)
    buildable = sorted({sum(c) for r in (1, 2)
                        for c in itertools.combinations_with_replacement(springs, r)})
    for ki, si, zi, ci in zip(k, snap.k, snap.zeroed, snap.capped):
        if zi:
            assert si == 0
        elif ci:
            assert si == max(buildable) < ki
        else:  # the softest buildable value at least k
            assert si == min(b for b in buildable if b >= ki)
    assert snap.zeroed.tolist() == [False, False, True, False, False]
    assert snap.springs[1] == (0.07, 0.1) and sum(snap.springs[0]) == snap.k[0]
    near = snap_to_springs([0.08], springs, zero_ratio=None, mode="nearest")
    assert near.k[0] == 0.07   # |log(0.07/0.08)| < |log(0.1/0.08)|
    with pytest.raises(OptimisationError, match="^springs: "):
        snap_to_springs(k, [])
    with pytest.raises(OptimisationError, match="^mode: "):
        snap_to_springs(k, springs, mode="down")


def test_verify_tightens_tolerances_and_refines_samples():
    s = scene()
    ev = verify(chain_model(), [0.1] * 3, s, tighten=100.0, refine=4, evaluation=settings_echo)
    rtol, atol, samples = ev.outcome.message.split()
    assert float(rtol) == pytest.approx(s.simulation.rtol / 100)
    assert float(atol) == pytest.approx(s.simulation.atol / 100)
    assert int(samples) == (s.simulation.samples - 1) * 4 + 1


def test_tolerance_check_counts_the_perturbed_copies():
    model = chain_model()
    exact = tolerance_check(model, [0.05] * 3, scene(), n=4, stiffness_tol=0.0, damping_tol=0.0,
                            workers=1, evaluation=band_outcome)
    assert exact.collision_free == exact.feasible == 4
    wide = tolerance_check(model, [0.05] * 3, scene(), n=30, stiffness_tol=0.1, damping_tol=0.1,
                           workers=1, evaluation=band_outcome, seed=5)
    inside = [bool(np.all(np.abs(e.k / 0.05 - 1) <= 0.03)
                   and np.all(np.abs(e.c / (0.043 * 0.05) - 1) <= 0.03)) for e in wide.evaluations]
    assert len(wide.evaluations) == 30
    assert wide.collision_free == sum(inside) < 30
    assert all(np.all(np.abs(e.k / 0.05 - 1) <= 0.1) for e in wide.evaluations)
    # Given damping replaces the model's c/k: 0.2 k lies outside the band.
    damped = tolerance_check(model, [0.05] * 3, scene(), c=[0.2 * 0.05] * 3, n=3, stiffness_tol=0.0,
                             damping_tol=0.0, workers=1, evaluation=band_outcome)
    assert damped.collision_free == 0
    np.testing.assert_allclose(damped.evaluations[0].c, 0.2 * 0.05)
    with pytest.raises(OptimisationError, match="^stiffness_tol: "):
        tolerance_check(model, [0.05] * 3, scene(), stiffness_tol=1.5, evaluation=band_outcome)


def test_feasible_interval_is_clopper_pearson():
    # All or none feasible: the exact two-sided interval has the closed form (alpha / 2)^(1/n).
    from panel_deploy.optimise.manufacture import ToleranceReport

    def report(feasible, n=20):
        return ToleranceReport(n, 0.05, 0.05, feasible, feasible, feasible)

    assert report(20).feasible_interval() == pytest.approx((0.025 ** (1 / 20), 1.0))
    assert report(0).feasible_interval() == pytest.approx((0.0, 1 - 0.025 ** (1 / 20)))
    lo, hi = report(13).feasible_interval(0.9)
    assert lo < 13 / 20 < hi and report(13).feasible_interval(0.99)[0] < lo
    assert report(20).to_dict()["feasible_interval_95"] == pytest.approx([0.8316, 1.0], abs=1e-4)


def test_tolerance_check_reports_progress_in_batches():
    done = []
    report = tolerance_check(chain_model(), [0.05] * 3, scene(), n=5, stiffness_tol=0.1,
                             damping_tol=0.1, workers=1, evaluation=band_outcome, seed=2,
                             progress=done.append)
    assert done == [2, 4, 5] and len(report.evaluations) == 5
