"""Collision monitor and trajectory check on hand-built models with closed forms.

Fold model: ground panel G (0.1 x 0.1 x 0.005 m) with P1 hinged on its right
edge and P2 on its left edge, both on the top facet, folding up over G. Only
P1-P2 is checked. With theta_1 = theta_2 = omega t the two inner tip edges
are mirror images, so sd = 2 (a/2 + a cos theta) for pi/2 <= theta <= 2 pi/3
(0.1 m below pi/2), and they first touch at theta = 2 pi / 3.
"""

import math
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.interpolate import CubicHermiteSpline

from panel_deploy.collision import CollisionMonitor, CollisionSettings, TrajectoryCheck, check_trajectory
from panel_deploy.errors import TrajectoryError
from panel_deploy.model import Body, Hinge, Model, box_inertia

from test_collision_geometry import reference_signed_distance

A, T = 0.1, 0.005


def body(name, x, length=A):
    size = np.array([length, A, T])
    return Body(name, (), size, 0.02, box_inertia(0.02, size), np.array([x, 0.0, 0.0]))


def fold_model(p1_length=A):
    bodies = [body("G", 0.0), body("P1", A / 2 + p1_length / 2, p1_length), body("P2", -A)]
    hinges = [Hinge("G-P1", 0, 1, np.array([A / 2, A / 2, T / 2]), np.array([0.0, -1.0, 0.0]),
                    A, "top", 0.1, 0.0043, math.pi, ()),
              Hinge("G-P2", 0, 2, np.array([-A / 2, -A / 2, T / 2]), np.array([0.0, 1.0, 0.0]),
                    A, "top", 0.1, 0.0043, math.pi, ())]
    return Model.build(bodies, hinges, ground=0)


def trajectory(t, theta, omega):
    return SimpleNamespace(t=np.asarray(t), theta=np.asarray(theta), omega=np.asarray(omega))


def linear_fold(omega=2.0, t_end=1.5, samples=301):
    t = np.linspace(0.0, t_end, samples)
    theta = np.column_stack([omega * t, omega * t])
    return trajectory(t, theta, np.full_like(theta, omega))


def sd_closed_form(theta):
    return np.where(theta <= math.pi / 2, A, 2 * (A / 2 + A * np.cos(theta)))


def test_model_geometry_folds_over_ground():
    from panel_deploy.kinematics import forward_kinematics
    m = fold_model()
    assert m.collision_pairs == ((1, 2),)
    R, p = forward_kinematics(m, [math.pi / 2, math.pi / 2])
    assert p[1][2] > 0.04 and p[2][2] > 0.04


def test_distances_match_closed_form_and_collision_time():
    omega = 2.0
    traj = linear_fold(omega)
    rep = check_trajectory(fold_model(), traj, CollisionSettings())
    t_touch = 2 * math.pi / 3 / omega
    theta = traj.theta[: rep.n_valid, 0]
    np.testing.assert_allclose(rep.distances[: rep.n_valid, 0], sd_closed_form(theta), atol=1e-9)
    e = rep.first_collision
    assert rep.collided and e.names == ("P1", "P2")
    assert e.contact_time == pytest.approx(t_touch, abs=2e-6)
    j = e.sample
    assert traj.t[j - 1] < e.t <= traj.t[j]
    assert t_touch <= e.t <= t_touch + (traj.t[1] - traj.t[0])
    assert e.distance < -rep.collision.tolerance
    # Eq. (7) from the closed-form distances of the two samples before t_j
    D = sd_closed_form(traj.theta[[j - 2, j - 1], 0])
    assert rep.v == pytest.approx((D[0] - D[1]) / (traj.t[j - 1] - traj.t[j - 2]), abs=1e-6)
    assert rep.V[e.pair] == rep.v
    assert rep.n_valid == j and rep.valid_until == traj.t[j - 1]
    # d over the valid trajectory: the closest approach before the collision
    assert rep.d == pytest.approx(sd_closed_form(theta).min(), abs=1e-9)
    # normal speed = -d sd/dt at e.t, by central differences of the reference distance
    from panel_deploy.kinematics import forward_kinematics
    m = fold_model()
    half = [b.size / 2 for b in m.bodies]

    def sd(tt):
        R, p = forward_kinematics(m, [omega * tt, omega * tt])
        return reference_signed_distance(half[1], R[1], p[1], half[2], R[2], p[2])

    h = 1e-6
    assert e.normal_speed == pytest.approx(-(sd(e.t + h) - sd(e.t - h)) / (2 * h), rel=1e-3)


def test_without_refinement_the_collision_is_found_at_the_next_sample():
    traj = linear_fold()
    rep = check_trajectory(fold_model(), traj, CollisionSettings(refine=False))
    e = rep.first_collision
    assert e.t == traj.t[e.sample] and not e.refined
    assert e.t >= 2 * math.pi / 3 / 2.0


def test_streaming_without_rates_gives_the_same_events():
    traj = linear_fold()
    rep = check_trajectory(fold_model(), traj)
    mon = CollisionMonitor(fold_model())
    events = []
    for t, th in zip(traj.t, traj.theta):
        events += mon.update(t, th)          # encoder angles only
        if events:
            break
    assert events[0].sample == rep.first_collision.sample
    assert events[0].t == pytest.approx(rep.first_collision.t, abs=2e-6)
    np.testing.assert_allclose(mon.distances, rep.distances[-1], atol=1e-12)


def test_monitor_rejects_time_going_backwards_and_bad_shapes():
    mon = CollisionMonitor(fold_model())
    mon.update(0.1, [0.0, 0.0])
    with pytest.raises(TrajectoryError):
        mon.update(0.1, [0.0, 0.0])
    with pytest.raises(TrajectoryError):
        mon.update(0.2, [0.0])


def tunnelling_trajectory(samples=301, t_end=1.0):
    """P1 (0.3 m long) sweeps through the wall P2 (held at pi/2) within one sample interval.

    theta_1 = 2.75 + 0.9 tanh((t - t_c) / tau), t_c mid-way between two
    samples, tau = dt / 3: the samples either side sit at theta ~ 1.94 and
    3.56, both clear of the wall, while P1 passes right through it.
    """
    t = np.linspace(0.0, t_end, samples)
    dt = t[1] - t[0]
    tc, tau = t[samples // 2] + dt / 2, dt / 3
    th1 = 2.75 + 0.9 * np.tanh((t - tc) / tau)
    w1 = 0.9 / tau * (1.0 - np.tanh((t - tc) / tau) ** 2)
    theta = np.column_stack([th1, np.full_like(t, math.pi / 2)])
    omega = np.column_stack([w1, np.zeros_like(t)])
    return trajectory(t, theta, omega)


def reference_first_interference(model, traj, tol, n=20001):
    """First instant with sd < -tol on the Hermite motion, by a dense grid and the QP reference."""
    from panel_deploy.kinematics import forward_kinematics
    spline = CubicHermiteSpline(traj.t, traj.theta, traj.omega)
    half = [b.size / 2 for b in model.bodies]
    j = len(traj.t) // 2
    grid = np.linspace(traj.t[j], traj.t[j + 1], n)
    for tt in grid:
        R, p = forward_kinematics(model, spline(tt))
        if reference_signed_distance(half[1], R[1], p[1], half[2], R[2], p[2]) < -tol:
            return tt, grid[1] - grid[0]
    return None, None


def test_tunnelling_between_samples_is_caught():
    model = fold_model(p1_length=0.3)
    traj = tunnelling_trajectory()
    tol = CollisionSettings().tolerance
    sampled = check_trajectory(model, traj, CollisionSettings(refine=False))
    assert not sampled.collided                       # every sample is clear: it tunnels
    assert np.all(sampled.distances > tol)
    rep = check_trajectory(model, traj)
    e = rep.first_collision
    assert rep.collided and e.refined and e.names == ("P1", "P2")
    j = len(traj.t) // 2
    assert e.sample == j + 1
    t_ref, step = reference_first_interference(model, traj, tol)
    assert t_ref is not None
    assert abs(e.t - t_ref) <= step + 2 * rep.collision.time_resolution


def test_a_touching_pair_pressing_in_between_samples_is_caught():
    """P1 and P2 touch (theta = 2 pi / 3) at every sample, and the Hermite motion
    between the last two presses them ~1.7 mm into each other and back out. That
    is no pass-through, so only the mid-point check of touching pairs can see it."""
    th, w, dt = 2 * math.pi / 3, 4.0, 0.01
    traj = trajectory([0.0, dt, 2 * dt], np.full((3, 2), th), np.array([[-w, -w], [w, w], [-w, -w]]))
    model = fold_model()
    tol = CollisionSettings().tolerance
    sampled = check_trajectory(model, traj, CollisionSettings(refine=False))
    assert not sampled.collided and np.all(np.abs(sampled.distances) <= tol)
    rep = check_trajectory(model, traj)
    e = rep.first_collision
    assert rep.collided and e.refined and e.names == ("P1", "P2") and e.sample == 2
    assert rep.counters["contact_midpoints"] == 2
    t_ref, step = reference_first_interference(model, traj, tol)
    assert t_ref is not None
    assert abs(e.t - t_ref) <= step + 2 * rep.collision.time_resolution


def slit_model():
    """G (0, 0), P1 (a, 0) hinged to G, Q (0, a) hinged to G, P2 (a, a) hinged to Q.

    Flat, P1 and P2 share a slit and G-P2, P1-Q touch at a corner line."""
    def cell(name, x, y):
        size = np.array([A, A, T])
        return Body(name, (), size, 0.02, box_inertia(0.02, size), np.array([x, y, 0.0]))
    bodies = [cell("G", 0, 0), cell("P1", A, 0), cell("Q", 0, A), cell("P2", A, A)]
    top = T / 2
    hinges = [Hinge("G-P1", 0, 1, np.array([A / 2, A / 2, top]), np.array([0, -1.0, 0]), A, "top", 0.1, 0.0, math.pi, ()),
              Hinge("G-Q", 0, 2, np.array([-A / 2, A / 2, top]), np.array([1.0, 0, 0]), A, "top", 0.1, 0.0, math.pi, ()),
              Hinge("Q-P2", 2, 3, np.array([A / 2, 3 * A / 2, top]), np.array([0, -1.0, 0]), A, "top", 0.1, 0.0, math.pi, ())]
    return Model.build(bodies, hinges, ground=0)


def test_designed_contacts_in_the_flat_state_are_not_collisions():
    m = slit_model()
    mon = CollisionMonitor(m)
    names = {mon.pair_names(k) for k in np.flatnonzero(mon.flat_contact)}
    assert names == {("G", "P2"), ("P1", "Q"), ("P1", "P2")}
    for t in (0.0, 0.01, 0.02):
        assert mon.update(t, np.zeros(3), np.zeros(3)) == []
    assert np.all(np.abs(mon.distances) < 1e-12)      # they do touch
    assert mon.min_distance == math.inf                # and none counts towards d


def test_interference_beyond_tolerance_is_a_collision():
    """Unfolding G-Q past flat (theta < 0) swings P2's lower slit edge into P1."""
    m = slit_model()
    settings = CollisionSettings()
    mon = CollisionMonitor(m, settings)
    i = [m.hinges[h].name for h in m.joints].index("G-Q")
    theta = np.zeros(3)
    mon.update(0.0, theta, np.zeros(3))
    events, depth_seen = [], []
    for j, phi in enumerate(np.linspace(0.0, 0.2, 21)[1:], start=1):
        theta[i] = -phi
        events += mon.update(0.01 * j, theta)
        depth_seen.append(mon.distances[mon.pairs.tolist().index([1, 3])])
    assert events and events[0].names == ("P1", "P2")
    assert events[0].distance < -settings.tolerance
    # no event while the interference was within the tolerance
    first = events[0].sample
    assert all(d >= -settings.tolerance for d in depth_seen[: first - 1])


def test_stowed_paper_design_is_at_rest_without_collision():
    from pathlib import Path
    from panel_deploy.build import build_model
    from panel_deploy.model import State
    from panel_deploy.scene import load_scene

    scene = Path(__file__).resolve().parent.parent / "config" / "scenes" / "paper_4x4.yaml"
    m = build_model(load_scene(scene))
    mon = CollisionMonitor(m, CollisionSettings(margin=math.inf))
    s = State.stowed(m)
    for t in (0.0, 0.01, 0.02):
        assert mon.update(t, s.theta, s.omega) == []
    touching = np.abs(mon.distances) < 1e-9
    assert touching.any()                              # the stacks touch by design
    assert np.all(mon.distances >= -mon.collision.tolerance)
    assert np.all(mon.resting[touching])               # and are left out of d
    assert mon.min_distance >= mon.collision.tolerance
    # Nothing has cleared the 8-layer package (h = 7 t + t = 0.04 m) yet: the stack
    # spacing is not d.
    assert mon.package_height == pytest.approx(8 * 0.005)
    assert np.all(mon.resting) and mon.min_distance == math.inf


def test_d_counts_a_pair_once_it_has_cleared_the_package():
    # Two panels folded onto a ground panel (fold_model) start one package apart;
    # d must not count the start but must count the closest approach after they part.
    m = fold_model()
    mon = CollisionMonitor(m, CollisionSettings(margin=math.inf))
    mon.update(0.0, [math.pi, 0.0])
    assert mon.min_distance == math.inf
    h = mon.package_height
    for t, th in ((0.1, 2.0), (0.2, 1.0), (0.3, 0.0)):
        mon.update(t, [th, 0.0])
    assert not mon.resting.any()
    assert mon.min_distance == pytest.approx(mon.distances[0]) and mon.distances[0] > h


def test_trajectory_check_fed_in_blocks_equals_the_one_shot_check():
    traj = linear_fold(samples=151)
    whole = check_trajectory(fold_model(), traj, CollisionSettings())
    check = TrajectoryCheck(fold_model(), CollisionSettings(), capacity=10)
    for a in range(0, 151, 13):
        block = trajectory(traj.t[a:a + 13], traj.theta[a:a + 13], traj.omega[a:a + 13])
        if check.feed(block):
            break
    piece = check.report()
    assert piece.collided and whole.collided
    assert piece.first_collision.t == whole.first_collision.t
    assert (piece.n_valid, piece.v, piece.d) == (whole.n_valid, whole.v, whole.d)
    np.testing.assert_array_equal(piece.distances, whole.distances)
    np.testing.assert_array_equal(piece.t, whole.t)


def test_monitor_poses_are_the_numpy_forward_kinematics():
    # The monitor takes poses from the compiled dynamics kernel; they must be the
    # reference forward kinematics, in model body order, on a branched closed loop.
    from panel_deploy.kinematics import forward_kinematics
    from test_dynamics_helpers import random_branched
    m = random_branched(3)
    mon = CollisionMonitor(m)
    rng = np.random.default_rng(0)
    for _ in range(5):
        theta = rng.uniform(0.0, math.pi, m.n_coords)
        R, p = mon._kinematics(theta)
        R_ref, p_ref = forward_kinematics(m, theta)
        np.testing.assert_allclose(R, R_ref, atol=1e-14)
        np.testing.assert_allclose(p, p_ref, atol=1e-14)


def test_resting_pairs_settled_without_an_exact_distance_keep_every_verdict():
    # Resting pairs whose collision and release can be told from bounds keep a
    # lower bound instead of an exact distance; every verdict (collision,
    # release from the package, d) must be the one exact distances give.
    from pathlib import Path
    from dataclasses import replace
    from panel_deploy.build import build_model
    from panel_deploy.collision.geometry import BoxSet
    from panel_deploy.dynamics import simulate
    from panel_deploy.scene import load_scene

    scene = load_scene(Path(__file__).resolve().parent.parent / "config" / "scenes" / "paper_4x4.yaml")
    m = build_model(scene)
    run = simulate(m, replace(scene.simulation, t_end=0.45, samples=91))
    mon = CollisionMonitor(m, CollisionSettings(margin=math.inf))
    boxes = BoxSet(m)
    tol = mon.collision.tolerance
    settled = 0
    for j in range(len(run.t)):
        mon.update(run.t[j], run.theta[j], run.omega[j])
        boxes.set_poses(run.rotation[j], run.position[j])
        ref = np.array([boxes.signed_distance(a, b) for a, b in mon.pairs])
        if j == 0:
            release, resting = ref + mon.package_height, ref <= mon.package_height
        resting &= ~(ref > release)
        np.testing.assert_allclose(mon.distances[mon.exact], ref[mon.exact], atol=1e-12)
        assert np.all(mon.distances <= ref + 1e-12)
        np.testing.assert_array_equal(mon.colliding, ref < -tol)
        np.testing.assert_array_equal(np.abs(mon.distances) <= tol, np.abs(ref) <= tol)  # touching
        np.testing.assert_array_equal(mon.resting, resting)
        counts = ~mon.flat_contact & ~resting
        assert mon.min_distance == (ref[counts].min() if counts.any() else math.inf)
        settled += int(np.count_nonzero(~mon.exact & mon.resting))
    assert settled > 100          # the shortcut was taken
    assert mon.colliding.any()    # K_0 collides at 0.42 s: a verdict was tested


def test_a_resting_pair_whose_bounds_straddle_the_tolerance_gets_its_exact_distance():
    # Corner to corner along their diagonal, 1.1 tolerances apart, both turned
    # by Q: the bounding boxes and the separating axes (g / sqrt 3) say
    # touching, the truth does not, and the refinement must not take the pair
    # for touching.
    from scipy.spatial.transform import Rotation
    from panel_deploy.collision.geometry import BoxSet, least_overlap
    m = fold_model()
    mon = CollisionMonitor(m, CollisionSettings(margin=math.inf, refine=False))
    tol = mon.collision.tolerance
    Q = Rotation.from_euler("zx", [30, 20], degrees=True).as_matrix()
    R = np.array([np.eye(3), Q, Q])
    half = np.array([A, A, T]) / 2
    stacked = np.array([[0.0, 0.0, -1.0], [0.0, 0.0, 0.0], Q @ [0.0, 0.0, T]])
    mon.update(0.0, [math.pi, math.pi], poses=(R, stacked))
    assert mon.resting[0] and abs(mon.distances[0]) < 1e-12
    g = 1.1 * tol
    corner = stacked.copy()
    corner[2] = Q @ (2 * half + g * np.ones(3) / math.sqrt(3))
    boxes = BoxSet(m)
    boxes.set_poses(R, corner)
    assert boxes.lower_bounds(mon.pairs)[0] < tol and -least_overlap(*(
        x for i in (1, 2) for x in (R[i], corner[i], half)))[0] < tol
    mon.update(0.1, [math.pi, math.pi], poses=(R, corner))
    assert mon.resting[0] and mon.exact[0]
    assert mon.distances[0] == pytest.approx(g, rel=1e-9)
