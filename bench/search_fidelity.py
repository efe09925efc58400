"""Benchmark: how cheap can the optimiser's evaluations be before they mislead it?

Scores one Latin hypercube of stiffness sets K (over the scene's bounds) at
the scene's own simulation settings (the reference) and at cheaper search
settings, side by side in one run, and prints per setting: the median wall
time of one evaluation and its ratio to the reference, and how often the
cheap evaluation agrees with the reference on what the search acts on
(collision yes/no, reached flat yes/no, feasible), the median difference
in first-collision time (s) and approach speed v (m/s) where both collide,
and in clearance d (m) and closest approach to flat r (rad) where neither
does.

    python bench/search_fidelity.py [SCENE] [--n 40] [--seed 0] [--workers N]
                                    [--rtol 1e-3 --rtol 1e-2 ...] [--min HINGE=K ...]
                                    [--max HINGE=K ...] [--around RESULT.yaml [--spread 0.1]]
                                    [--set KEY=VALUE ...]

``--around`` samples near a result file's K (where a search polishing its
optimum evaluates) instead of over the whole box.

Every candidate checks collisions at the samples only (``refine: false``);
the reference keeps the scene's ``collision.refine``.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace

import numpy as np
import scan_args

from panel_deploy.errors import PanelDeployError
from panel_deploy.optimise.parallel import Evaluator, Job, make_backend


def with_rtol(scene, rtol, refine):
    """``scene`` integrated at ``rtol`` (atol keeping its ratio) and checked with ``refine``."""
    sim = scene.simulation
    return scene.replace(simulation=replace(sim, rtol=rtol, atol=sim.atol * rtol / sim.rtol),
                         collision=replace(scene.collision, refine=refine))


def run(model, scene, ks, workers):
    backend = make_backend(Job(model, scene), workers)
    try:
        return [e.outcome for e in Evaluator(backend, len(ks)).map(ks)]
    finally:
        backend.close()


def compare(ref, out):
    """Agreement of ``out`` with ``ref`` (lists of Outcome, same K)."""
    def agree(attr):
        return np.mean([getattr(a, attr) == getattr(b, attr) for a, b in zip(ref, out)])

    both = [(a, b) for a, b in zip(ref, out) if a.collided and b.collided]
    dt = [abs(a.first_collision["t"] - b.first_collision["t"]) for a, b in both]
    dv = [abs(a.v - b.v) for a, b in both]
    free = [(a, b) for a, b in zip(ref, out) if not (a.collided or b.collided)]
    dd = [abs(a.d - b.d) for a, b in free]
    dr = [abs(a.flat_residual - b.flat_residual) for a, b in free]
    med = lambda x: f"{np.median(x):.2g}" if x else "-"  # noqa: E731
    return (f"collided {agree('collided'):5.0%}  flat {agree('reached_flat'):5.0%}  "
            f"feasible {agree('feasible'):5.0%}  |dt| {med(dt)} s  |dv| {med(dv)} m/s "
            f"(n {len(both)})  |dd| {med(dd)} m  |dr| {med(dr)} rad (n {len(free)})")


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    scan_args.add_arguments(p, n=40, spread=0.1)
    p.add_argument("--rtol", type=float, action="append", metavar="RTOL",
                   help="candidate search rtol (repeatable; default 1e-3, 3e-3, 1e-2)")
    args = p.parse_args(argv)
    try:
        scene, model, _, ks, _, what = scan_args.sample(args)
    except PanelDeployError as e:
        sys.exit(f"search_fidelity: {e}")

    print(f"scene {scene.name}{' with ' + ', '.join(args.set) if args.set else ''}: "
          f"{what}; samples {scene.simulation.samples}")
    start = time.perf_counter()
    ref = run(model, scene, ks, args.workers)
    ref_time = np.median([o.wall_time for o in ref])
    print(f"reference rtol {scene.simulation.rtol:g}, refine {scene.collision.refine}: "
          f"median {ref_time:.3f} s per evaluation; {sum(o.collided for o in ref)} collide, "
          f"{sum(o.reached_flat for o in ref)} reach flat, {sum(o.feasible for o in ref)} feasible")
    for rtol in args.rtol or [1e-3, 3e-3, 1e-2]:
        out = run(model, with_rtol(scene, rtol, False), ks, args.workers)
        t = np.median([o.wall_time for o in out])
        print(f"rtol {rtol:<6g} refine False: median {t:.3f} s ({ref_time / t:4.1f}x faster)  "
              + compare(ref, out))
    print(f"total {time.perf_counter() - start:.0f} s")


if __name__ == "__main__":
    main()
