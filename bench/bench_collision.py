"""Collision check cost: per sample, per pair, growth with panel count, and
against the simulation it checks. Prints medians (wall clock, 2 shared cores).

    python bench/bench_collision.py [--no-sim] [--stream] [--repeats N]

Models: the paper's 4x4 scene (12 bodies, 54 pairs) and synthetic R x C
arrays of unit panels hinged along a snake path (a tree), at random angles
(panels pass through each other; only the cost is of interest) and flat.
Variants per sample: "all pairs" (one python-fcl distance call per pair),
"broad phase" (numpy AABB/sphere bounds, exact only within the margin or
where the sample minimum could be; the production path), and "FCL manager"
(DynamicAABBTreeCollisionManager.update + one distance() call: it returns
only the global minimum, not the vector D_j).

Streaming (``--stream`` runs only this): the paper deployment fed one joint
state at a time to StreamCheck, as the live node does, at 1 kHz (an encoder
rate, 2 s) and 200 Hz (0.6 s): per-update median, mean, p99 and max, and
the worst delay of a sample arriving at its stamp behind the updates before
it (below the period when the check keeps up).
"""

from __future__ import annotations

import argparse
import math
import statistics
import time
from pathlib import Path

import fcl
import numpy as np

from panel_deploy.build import build_model
from panel_deploy.collision import CollisionMonitor, CollisionSettings, check_trajectory
from panel_deploy.kinematics import forward_kinematics
from panel_deploy.model import Body, Hinge, Model, State, box_inertia
from panel_deploy.scene import load_scene

SCENE = Path(__file__).resolve().parent.parent / "config" / "scenes" / "paper_4x4.yaml"


def snake_model(rows, cols, a=0.1, t=0.005):
    """R x C unit panels, hinged along a boustrophedon path (a tree, no loop)."""
    cells = [(r, c if r % 2 == 0 else cols - 1 - c) for r in range(rows) for c in range(cols)]
    size = np.array([a, a, t])
    bodies = [Body(f"r{r}c{c}", ((r, c),), size, 0.02, box_inertia(0.02, size),
                   np.array([c * a, -r * a, 0.0])) for r, c in cells]
    hinges = []
    for i in range(len(cells) - 1):
        (r0, c0), (r1, c1) = cells[i], cells[i + 1]
        if r0 == r1:
            x = (max(c0, c1)) * a - a / 2
            point, axis = np.array([x, -r0 * a - a / 2, t / 2]), np.array([0.0, 1.0, 0.0])
        else:
            y = -r0 * a - a / 2
            point, axis = np.array([c0 * a - a / 2, y, t / 2]), np.array([1.0, 0.0, 0.0])
        hinges.append(Hinge(f"h{i}", i, i + 1, point, axis, a, "top", 0.1, 0.0043, math.pi, ()))
    return Model.build(bodies, hinges, ground=0)


def median_time(fn, repeats):
    out = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t0)
    return statistics.median(out)


def per_sample(model, theta_list, repeats):
    """Median seconds per sample of the three variants over the given configurations."""
    mon = CollisionMonitor(model, CollisionSettings())
    boxes = mon._boxes
    pairs = mon.pairs
    poses = [forward_kinematics(model, th) for th in theta_list]
    mon.resting = np.zeros(len(pairs), dtype=bool)

    def all_pairs():
        for R, p in poses:
            boxes.set_poses(R, p)
            for a, b in pairs:
                boxes.signed_distance(a, b)

    def broad():
        for R, p in poses:
            boxes.set_poses(R, p)
            mon._sample_distances()

    objs = [fcl.CollisionObject(fcl.Box(*b.size), fcl.Transform()) for b in model.bodies]
    manager = fcl.DynamicAABBTreeCollisionManager()
    manager.registerObjects(objs)
    manager.setup()

    def managed():
        for R, p in poses:
            for o, Ri, pi in zip(objs, R, p):
                o.setRotation(Ri)
                o.setTranslation(pi)
            manager.update()
            data = fcl.DistanceData()
            manager.distance(data, fcl.defaultDistanceCallback)

    n = len(poses)
    return (median_time(all_pairs, repeats) / n, median_time(broad, repeats) / n,
            median_time(managed, repeats) / n, len(pairs))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--no-sim", action="store_true", help="skip the paper-scene simulation")
    ap.add_argument("--stream", action="store_true", help="only the streaming case")
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    rng = np.random.default_rng(0)

    scene = load_scene(SCENE)
    if args.stream:
        stream_costs(scene, args.repeats)
        return
    paper = build_model(scene)
    print("per-sample cost of D_j (median of", args.repeats, "runs), microseconds")
    print(f"{'model':24s} {'bodies':>6s} {'pairs':>6s} {'all pairs':>10s} {'per pair':>9s} "
          f"{'broad ph.':>10s} {'FCL mgr':>9s}")
    cases = [("paper 4x4 stowed", paper, [State.stowed(paper).theta] * 20),
             ("paper 4x4 random", paper, [rng.uniform(0, math.pi, paper.n_coords) for _ in range(20)]),
             ("paper 4x4 flat", paper, [np.zeros(paper.n_coords)] * 20)]
    for r, c in ((4, 4), (6, 6), (8, 8)):
        m = snake_model(r, c)
        cases.append((f"snake {r}x{c} random", m,
                       [rng.uniform(-0.3, 0.3, m.n_coords) for _ in range(20)]))
        cases.append((f"snake {r}x{c} flat", m, [np.zeros(m.n_coords)] * 20))
    for name, m, thetas in cases:
        full, broad, mgr, P = per_sample(m, thetas, args.repeats)
        print(f"{name:24s} {m.n_bodies:6d} {P:6d} {full * 1e6:10.0f} {full / P * 1e6:9.2f} "
              f"{broad * 1e6:10.0f} {mgr * 1e6:9.0f}")

    if args.no_sim:
        return
    # The scene as it is collides at 0.42 s; with c/k = 0.19 s (README) K_0
    # deploys to flat, so the refinement runs over the whole deployment.
    k = paper.stiffness
    for label, model in (("paper scene", paper),
                         ("paper scene, c/k 0.19 s", paper.with_stiffness(k, 0.19 * k))):
        check_costs(label, model, scene, args.repeats)
    stream_costs(scene, args.repeats)


def stream_costs(scene, repeats):
    """Per-update cost of StreamCheck on the paper deployment at 1 kHz and 200 Hz, ms."""
    from panel_deploy.dynamics import simulate
    from panel_deploy.collision import StreamCheck
    from panel_deploy.configure import DynamicsParameters, configure

    print("\nstreaming check, refine on, per update (median of", max(1, repeats // 2), "runs), ms")
    print(f"{'stream':22s} {'samples':>7s} {'median':>7s} {'mean':>7s} {'p99':>7s} {'max':>7s} {'delay':>7s}")
    for rate, t_end in ((1000.0, 0.0), (200.0, 0.6)):
        streamed, model = configure(scene, DynamicsParameters(rate_hz=rate, t_end=t_end))
        result = simulate(model, streamed.simulation)
        collision = CollisionSettings.from_scene(streamed)
        StreamCheck(model, collision).update(result.t[0], result.theta[0], result.omega[0])  # compile
        runs = []
        for _ in range(max(1, repeats // 2)):
            check = StreamCheck(model, collision)
            d = np.empty(len(result.t))
            for j in range(len(result.t)):
                t0 = time.perf_counter()
                check.update(result.t[j], result.theta[j], result.omega[j])
                d[j] = time.perf_counter() - t0
            runs.append((np.median(d), d.mean(), np.percentile(d, 99), d.max(), worst_delay(result.t, d)))
        med = np.median(np.array(runs), axis=0) * 1e3
        label = f"{rate:g} Hz, {result.t[-1]:g} s"
        print(f"{label:22s} {len(result.t):7d} " + " ".join(f"{x:7.3f}" for x in med))


def worst_delay(t, d):
    """Largest time (s) from a sample's arrival at its stamp t to the end of its
    update, updates served in order taking d (s) each."""
    free, worst = -math.inf, 0.0
    for tj, dj in zip(t, d):
        free = max(free, tj) + dj
        worst = max(worst, free - tj)
    return worst


def check_costs(label, model, scene, repeats):
    """Simulate ``model`` and time its trajectory check with and without refinement."""
    from panel_deploy.dynamics import simulate
    t0 = time.perf_counter()
    result = simulate(model, scene.simulation)
    sim = time.perf_counter() - t0
    print(f"\n{label}, {len(result.t)} samples: simulation {sim:.2f} s ({result.method}, "
          f"{result.message})")
    rep = None
    for name, collision in (("refine on (default)", CollisionSettings.from_scene(scene)),
                           ("refine off", CollisionSettings.from_scene(scene, refine=False)),
                           ("refine on, no broad phase", CollisionSettings.from_scene(scene, margin=math.inf)),
                           ("whole trajectory, refine off", None)):
        if collision is None:
            collision = CollisionSettings.from_scene(scene, refine=False)
            fn = lambda: check_trajectory(model, result, collision, stop_at_first=False)  # noqa: E731
        else:
            fn = lambda: check_trajectory(model, result, collision)  # noqa: E731
        times = []
        for _ in range(max(1, repeats // 2)):
            t0 = time.perf_counter()
            rep = fn()
            times.append(time.perf_counter() - t0)
        med = statistics.median(times)
        print(f"  check {name:30s} {med:7.3f} s  ratio check/simulation {med / sim:.3f}  "
              f"samples {len(rep.t)}  {rep.counters}")
    print("\n" + rep.to_text())
    print("\n" + check_trajectory(model, result, CollisionSettings.from_scene(scene)).to_text())

if __name__ == "__main__":
    main()
