"""The collision monitor's compiled fast paths against the plain rules they replace.

The sample distances come from one FCL batch chosen by a compiled plan, the
between-sample search is one compiled call that screens each interval's pairs
by an O(1) speed cap, box_distance prunes edge pairs and the hinge-line radii
are computed where they are read. Each must give what the plain form gives:
the sample distances and the search's events and counters to the bit
(against the per-pair loop and the Python recursion the monitor ran before,
and the check with the screen against the check without it), the pruned
enumeration a lower bound it relies on, the cap at least the bound.
"""

import math
from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from panel_deploy import fold
from panel_deploy.build import build_model
from panel_deploy.collision import CollisionMonitor, CollisionSettings, check_trajectory
from panel_deploy.boxes import corners
from panel_deploy.collision.geometry import (CERTIFY_TOL, BoxSet, _clamp_to_box, _edge_gaps, _EDGES,
                                             box_distance, box_signed_distance, corner_bound, least_overlap,
                                             pair_bounds)
from panel_deploy.collision.monitor import _segment
from panel_deploy.collision.motion import HermiteSegment, _speed_bound, hinge_radii_of, needed_radii, speed_caps
from panel_deploy.dynamics import simulate
from panel_deploy.scene import load_scene, resolve_scene

from test_collision_geometry import separated_pairs


@pytest.fixture(scope="module")
def paper_run():
    """The paper design up to just past its first collision (0.42 s), every 5 ms."""
    scene = load_scene(resolve_scene("paper_4x4"))
    model = build_model(scene)
    return model, simulate(model, replace(scene.simulation, t_end=0.45, samples=91))


def random_poses(model, n, seed):
    from panel_deploy.kinematics import forward_kinematics
    rng = np.random.default_rng(seed)
    return [forward_kinematics(model, rng.uniform(0.0, math.pi, model.n_coords)) for _ in range(n)]


def test_edge_gaps_bound_every_point_of_the_edge_from_the_other_box():
    # box_distance skips an edge pair when an edge's gap exceeds the best
    # candidate: the gap must not exceed any point's distance from the box.
    for ha, Ra, ca, hb, Rb, cb in separated_pairs(np.random.default_rng(7))[::3]:
        va = corners(Ra, ca, ha)
        q = np.empty(3)
        gaps = _edge_gaps(np.array([_clamp_to_box(v, Rb, cb, hb, q) for v in va]), hb)
        for e, (i, j) in enumerate(_EDGES):
            for s in np.linspace(0.0, 1.0, 21):
                x = va[i] + s * (va[j] - va[i])
                _clamp_to_box(x, Rb, cb, hb, q)
                assert gaps[e] <= np.linalg.norm(x - q) + 1e-15


def test_box_signed_distance_is_the_depth_or_the_distance():
    for ha, Ra, ca, hb, Rb, cb in separated_pairs(np.random.default_rng(8)):
        d = box_signed_distance(Ra, ca, ha, Rb, cb, hb)
        assert abs(d - box_distance(Ra, ca, ha, Rb, cb, hb)[0]) <= 1e-12
    rng = np.random.default_rng(9)
    interfering = 0
    for _ in range(300):
        Ra, Rb = Rotation.random(2, random_state=rng).as_matrix()
        ha, hb = rng.uniform(0.002, 0.06, 3), rng.uniform(0.002, 0.06, 3)
        ca, cb = np.zeros(3), rng.normal(size=3) * 0.05
        overlap = least_overlap(Ra, ca, ha, Rb, cb, hb)[0]
        if overlap > 0.0:
            interfering += 1
            assert box_signed_distance(Ra, ca, ha, Rb, cb, hb) == -overlap
    assert interfering > 50


def test_box_signed_distance_agrees_with_the_certified_fcl_path(paper_run):
    model, _ = paper_run
    boxes = BoxSet(model)
    h = boxes.half
    for R, p in random_poses(model, 20, 1):
        boxes.set_poses(R, p)
        for a, b in model.collision_pairs:
            fast = box_signed_distance(R[a], p[a], h[a], R[b], p[b], h[b])
            assert abs(fast - boxes.signed_distance(a, b)) <= CERTIFY_TOL


def test_batched_fcl_distances_are_the_per_pair_ones_to_the_bit(paper_run):
    model, run = paper_run
    pairs = np.array(model.collision_pairs)
    batch, single = BoxSet(model), BoxSet(model)
    poses = random_poses(model, 10, 2) + [(run.rotation[j], run.position[j]) for j in range(0, 91, 9)]
    for R, p in poses:
        batch.set_poses(R, p)
        single.set_poses(R, p)
        before = single.exact_fallbacks
        sd, wrong = batch.signed_distances(pairs[:, 0], pairs[:, 1])
        ref = np.array([single.signed_distance(a, b) for a, b in pairs])
        np.testing.assert_array_equal(sd, ref)
        assert wrong.sum() == single.exact_fallbacks - before
    assert batch.exact_fallbacks == 0   # the batch leaves the counting to its caller


def test_radii_where_needed_are_the_full_table_to_the_bit(paper_run):
    model, _ = paper_run
    mon = CollisionMonitor(model)
    sp, rng = mon._speed, np.random.default_rng(3)
    for R, p in random_poses(model, 10, 4):
        full = sp.radii(R, p)
        rows = np.sort(rng.choice(len(mon.pairs), 5, replace=False)).astype(np.int64)
        need = needed_radii(rows, sp.coords, sp.length, mon._a, mon._b, len(R), model.n_coords)
        some = hinge_radii_of(R, p, sp.half, sp.parents, sp.points, sp.axes, need)
        np.testing.assert_array_equal(some[need], full[need])
        assert np.all(some[~need] == 0.0)


def sequential_sample_distances(mon, boxes):
    """A sample's (D, exact, fallbacks) by the rule's plain loop, one pair at a
    time on ``boxes`` (placed like the monitor's): the monitor before the batch."""
    b = boxes
    lb = b.lower_bounds(mon.pairs)
    D, exact, settled = lb.copy(), np.zeros(len(lb), bool), np.zeros(len(lb), bool)
    tol = mon.collision.tolerance
    if mon.resting is not None:
        rows = np.flatnonzero(mon.resting)
        overlap, upper = pair_bounds(b.rotation, b.position, b.half, mon.pairs[rows, 0], mon.pairs[rows, 1])
        deep = overlap > tol
        lower = np.where(overlap > 0.0, -overlap, np.maximum(lb[rows], -overlap))
        held = ~deep & ((lower > tol) | (upper <= tol)) & (upper <= mon._release[rows])
        D[rows[deep]], exact[rows[deep]] = -overlap[deep], True
        D[rows[held]] = lower[held]
        settled[rows[deep | held]] = True
    counts = ~mon.flat_contact & (~mon.resting if mon.resting is not None else True)
    best, before = math.inf, b.exact_fallbacks
    for k in np.argsort(lb, kind="stable"):
        if lb[k] > mon.collision.margin and lb[k] >= best:
            break
        if settled[k]:
            continue
        D[k], exact[k] = b.signed_distance(*mon.pairs[k]), True
        if counts[k]:
            best = min(best, D[k])
    return D, exact, b.exact_fallbacks - before


@pytest.mark.parametrize("margin", [0.02, 0.005])
def test_sample_distances_are_the_per_pair_rule_to_the_bit(paper_run, margin):
    model, run = paper_run
    mon = CollisionMonitor(model, CollisionSettings(margin=margin))
    boxes = BoxSet(model)
    computed = 0
    for j in range(len(run.t)):
        R, p = mon._kinematics(run.theta[j])
        boxes.set_poses(R, p)
        D_ref, exact_ref, fallbacks = sequential_sample_distances(mon, boxes)
        before = mon.exact_fallbacks
        mon.update(run.t[j], run.theta[j], run.omega[j], poses=(R, p))
        np.testing.assert_array_equal(mon.distances, D_ref)
        np.testing.assert_array_equal(mon.exact, exact_ref)
        if not mon.events or mon.events[-1].sample != j:   # events add their own exact queries
            assert mon.exact_fallbacks - before == fallbacks
        computed += int(exact_ref.sum())
    assert computed > 5 * len(run.t)


class PythonSearch(CollisionMonitor):
    """The between-sample search as the monitor ran it in Python, one bisection
    step per call, with the compiled search's distances (box_signed_distance)."""

    def _at(self, seg, t, rows):
        R, p = self._kinematics(seg(t)[0])
        h = self._boxes.half
        sd = np.array([box_signed_distance(R[a], p[a], h[a], R[b], p[b], h[b]) for a, b in self.pairs[rows]])
        return sd, self._speed.radii(R, p)

    def _refine(self, prev, cur):
        s = self.collision
        threshold = -s.tolerance
        seg = _segment(prev, cur)
        last_touch = np.where(prev.distances >= 0.0, prev.t, np.nan)
        found = {}

        def bisect(k, lo, hi, level):
            while hi - lo > s.time_resolution:
                mid = 0.5 * (lo + hi)
                if self._at(seg, mid, [k])[0][0] >= level:
                    lo = mid
                else:
                    hi = mid
            return lo, hi

        def first_touch(k, t_hit):
            return None if math.isnan(last_touch[k]) else bisect(k, last_touch[k], t_hit, 0.0)[0]

        def visit(tm, rows, Sm):
            for k, sd in zip(rows, Sm):
                if k in found:
                    continue
                if sd < threshold:
                    found[k] = (tm, first_touch(k, tm))
                elif sd >= 0.0:
                    last_touch[k] = tm

        def speeds(t, rows):
            return self._speed.speeds(*self._kinematics(*seg(t)), rows)

        def node(a, b, Sa, Sb, Ra, Rb, rows):
            L = self._speed(seg.rate_bound(a, b), b - a, Ra, Rb, rows)
            open_ = (Sa + Sb - L * (b - a)) / 2.0 < threshold - s.resolution
            open_ &= np.array([k not in found for k in rows], dtype=bool)
            open_ &= ~((Sb < threshold) & (b - a <= s.time_resolution))
            if s.second_order and open_.any():
                acc = self._speed.acceleration(seg.rate_bound(a, b), seg.accel_bound(a, b), b - a, Ra, Rb,
                                               rows[open_])
                tau = 0.5 * (b - a)
                grow = 0.5 * acc * tau
                Va, Vb = speeds(a, rows[open_]), speeds(b, rows[open_])
                lower = np.minimum(Sa[open_] - tau * (Va + grow).min(axis=0),
                                   Sb[open_] - tau * (Vb + grow).min(axis=0))
                open_[open_] = lower < threshold - s.resolution
            if not open_.any():
                return
            rows, Sa, Sb = rows[open_], Sa[open_], Sb[open_]
            m = 0.5 * (a + b)
            Sm, Rm = self._at(seg, m, rows)
            self.counters["refine_evaluations"] += 1
            node(a, m, Sa, Sm, Ra, Rm, rows)
            visit(m, rows, Sm)
            node(m, b, Sm, Sb, Rm, Rb, rows)

        evaluations = self.counters["refine_evaluations"]
        touching = (np.abs(prev.distances) <= s.tolerance) & (np.abs(cur.distances) <= s.tolerance)
        pressed = np.flatnonzero(~self.colliding & touching)
        if pressed.size:
            m = 0.5 * (prev.t + cur.t)
            self.counters["contact_midpoints"] += 1
            for k, sd in zip(pressed, self._at(seg, m, pressed)[0]):
                if sd < threshold:
                    t_in = bisect(k, prev.t, m, threshold)[1]
                    found[k] = (t_in, first_touch(k, t_in))
        rows = np.flatnonzero(~self.colliding & ~touching)
        node(prev.t, cur.t, prev.distances[rows], cur.distances[rows], prev.radii, cur.radii, rows)
        if self.counters["refine_evaluations"] > evaluations:
            self.counters["refined_intervals"] += 1
        visit(cur.t, rows, cur.distances[rows])
        return found


@pytest.mark.parametrize("deep, second_order", [(False, True), (True, True), (False, False)])
def test_compiled_search_takes_the_python_search_steps(paper_run, deep, second_order):
    # deep: collisions located to 1e-9 m and 1e-12 s, ~30 levels down, where
    # the search's stack (16 levels at first) has to grow.
    model, run = paper_run
    settings = replace(CollisionSettings(resolution=1e-9, time_resolution=1e-12) if deep else CollisionSettings(),
                       second_order=second_order)
    fast, slow = CollisionMonitor(model, settings), PythonSearch(model, settings)
    for j in range(len(run.t)):
        a = fast.update(run.t[j], run.theta[j], run.omega[j])
        b = slow.update(run.t[j], run.theta[j], run.omega[j])
        assert [(e.pair, e.t, e.contact_time) for e in a] == [(e.pair, e.t, e.contact_time) for e in b]
    for key in ("refine_evaluations", "refined_intervals", "contact_midpoints"):
        assert fast.counters[key] == slow.counters[key]
    assert fast.counters["refine_evaluations"] > 100
    assert any(e.refined and e.contact_time is not None for e in fast.events)
    assert (len(fast._stack[3]) > 16) == deep


@pytest.fixture(scope="module")
def array_6x6_run():
    """6 x 6, first circuit that packs, as issue 33 ran it, for 0.1 s: it
    "collides" (panels pressing in the stack) at 0.042 s."""
    first = next(i for i, d in fold.designs(6, 6) if d.stowed is not None)
    scene = load_scene(resolve_scene("paper_4x4"), ["array.rows=6", "array.cols=6", f"fold.circuit={first}",
                                                    "fold.ground=null", "simulation.t_end=0.1",
                                                    "simulation.samples=21"])
    model = build_model(scene)
    return model, simulate(model, scene.simulation)


@pytest.mark.parametrize("case", ["paper", "6x6"])
def test_speed_caps_are_at_least_the_speed_bound(paper_run, array_6x6_run, case):
    # The screen closes a pair only if the bound would: the cap must not be
    # below the bound for any pair, on random intervals between random states.
    model, _ = paper_run if case == "paper" else array_6x6_run
    mon = CollisionMonitor(model)
    sp, rng = mon._speed, np.random.default_rng(11)
    rows = np.arange(len(mon.pairs), dtype=np.int64)
    closed = 0
    for _ in range(10):
        theta = rng.uniform(0.0, math.pi, (2, model.n_coords))
        omega = rng.normal(0.0, 10.0, (2, model.n_coords))
        h = rng.uniform(1e-4, 1e-2)
        seg = HermiteSegment(0.0, theta[0], omega[0], h, theta[1], omega[1])
        radii = [sp.radii(*mon._kinematics(th)) for th in theta]
        w = seg.rate_bound(0.0, h)
        L = _speed_bound(w, h, radii[0], radii[1], rows, sp.coords, sp.length, sp.chain_a, sp.chain_b, sp.a, sp.b)
        cap = speed_caps(w, h, radii[0], radii[1], rows, sp.tree, sp.lca, sp.reach_a, sp.reach_b, mon._a, mon._b)
        assert np.all(cap >= L)
        closed += int(np.count_nonzero(cap < 3.0 * L))
    assert closed > len(rows)   # and near it for many pairs, or it would screen nothing


def test_corner_bound_is_within_the_smaller_circumradius_of_the_centres():
    # What lets a resting pair skip its corners (monitor._sample_plan).
    for ha, Ra, ca, hb, Rb, cb in separated_pairs(np.random.default_rng(12)):
        R, c, h = np.array([Ra, Rb]), np.array([ca, cb]), np.array([ha, hb])
        reach = min(np.linalg.norm(ha), np.linalg.norm(hb)) + np.linalg.norm(cb - ca)
        assert corner_bound(R, c, h, 0, 1) <= reach + 1e-12


@pytest.mark.parametrize("case", ["paper", "6x6"])
def test_screened_check_is_the_unscreened_one(paper_run, array_6x6_run, case):
    model, run = paper_run if case == "paper" else array_6x6_run
    screened, plain = (check_trajectory(model, run, CollisionSettings(prune=prune)) for prune in (True, False))
    a, b = screened.first_collision, plain.first_collision
    assert a is not None and (a.pair, a.contact_time, a.refined) == (b.pair, b.contact_time, b.refined)
    for x, y in ((a.t, b.t), (screened.v, plain.v), (screened.d, plain.d), (a.normal_speed, b.normal_speed)):
        assert abs(x - y) <= 1e-12
    assert screened.d_pair == plain.d_pair and screened.d_time == plain.d_time
    assert [e.pair for e in screened.events] == [e.pair for e in plain.events]
    np.testing.assert_allclose(screened.distances, plain.distances, rtol=0.0, atol=1e-12)
    np.testing.assert_array_equal(screened.exact, plain.exact)
    assert screened.counters == plain.counters
    assert screened.counters["refine_evaluations"] > 100


@pytest.mark.parametrize("case", ["paper", "6x6"])
def test_the_second_order_bound_finds_what_the_speed_bound_alone_finds_in_fewer_steps(
        paper_run, array_6x6_run, case):
    """Both bounds are bounds, so the search finds the same first collision,
    each at an instant within what the guarantee allows (the time resolution,
    and the time the pair takes to go the depth slack deeper), and the same
    D_j; it bisects less where the second-order bound closes intervals the
    speed bound leaves open."""
    model, run = paper_run if case == "paper" else array_6x6_run
    settings = CollisionSettings()
    second, first = (check_trajectory(model, run, replace(settings, second_order=on)) for on in (True, False))
    a, b = second.first_collision, first.first_collision
    assert a is not None and a.pair == b.pair
    assert abs(a.t - b.t) <= settings.time_resolution + settings.resolution / abs(b.normal_speed)
    assert (second.v, second.d) == (first.v, first.d)
    np.testing.assert_array_equal(second.distances, first.distances)
    steps = second.counters["refine_evaluations"], first.counters["refine_evaluations"]
    assert 0 < steps[0] < 0.6 * steps[1], steps
