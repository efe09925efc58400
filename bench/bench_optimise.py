"""Benchmark: full stiffness optimisation of a scene (default: the paper's 4 x 4).

Prints K_0's outcome, the optimum (per hinge group), whether it is
collision-free and flat, its d, the independent re-check at tighter
tolerances, the evaluations spent (and those up to the first feasible K),
the wall time and the time per evaluation (median of the single-run wall times, and wall time / nfev,
which includes parallel speed-up and solver overhead).

With ``--seeds`` it runs one search per seed instead and prints one line each
and then how many found a feasible K that the re-check confirms, and the
median time to the first feasible K of those that did: how fast a search is
can only be told over seeds when, as on the paper scene, the feasible set is
thin enough that one seed finds it and the next does not.

    python bench/bench_optimise.py [SCENE] [--seed N | --seeds 0-7]
                                   [--out RESULT.yaml] [--set KEY=VALUE ...]

(method, budget and workers are scene keys: --set optimisation.method=global,
optimisation.max_evaluations=N, optimisation.workers=N.)
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path

import numpy as np

from panel_deploy.build import build_model
from panel_deploy.optimise import optimise, print_progress, save_result, verify
from panel_deploy.scene import load_scene, resolve_scene

ROOT = Path(__file__).resolve().parent.parent

#: The re-check of :func:`panel_deploy.optimise.verify`, as ``panel-deploy optimise`` runs it.
TIGHTEN, REFINE = 10.0, 2


def describe(label, ev):
    o = ev.outcome
    hit = (f"collision at {o.first_collision.get('t', float('nan')):.3f} s "
           f"{o.first_collision.get('pair')} v = {o.v:.3f} m/s") if o.collided else "no collision"
    print(f"{label}: f = {ev.f:+.5f}, {hit}, d = {o.d * 1e3:.2f} mm, "
          f"closest approach to flat {o.flat_residual:.3f} rad "
          f"({'flat' if o.reached_flat else 'NOT flat'}){'' if o.simulated else ', simulation failed: ' + o.message}")


def seed_list(text):
    """Seeds from "0-7", "1,4,9" or a mix such as "0-3,8"."""
    seeds = []
    for part in text.split(","):
        lo, _, hi = part.partition("-")
        seeds += range(int(lo), int(hi or lo) + 1)
    return seeds


def report(model, scene, res, wall, check, sets):
    """Everything about one search (the single-seed output)."""
    print()
    print(f"scene {scene.name}{' with ' + ', '.join(sets) if sets else ''}: {len(model.hinges)} hinges in "
          f"{len(res.problem.groups)} groups, bounds {res.problem.bounds} N m/rad, method {res.method}")
    describe("K_0    ", res.initial)
    describe("optimum", res.best)
    print(f"status {res.status}: {res.message}")
    for names, idx in zip(res.problem.group_names(), res.problem.groups):
        print(f"  k = {res.k[idx[0]]:.4f} N m/rad  {', '.join(names)}")
    if res.problem.damping_variable:
        window = ("" if res.damping_window is None else
                  ", feasible for %.4f-%.4f s" % res.damping_window)
        print(f"  c/k = {res.c[0] / res.k[0]:.4f} s (searched within {res.problem.damping_bounds} s"
              f"{window})")
    ratio = res.k / res.k.max()
    print("  k / max k per hinge: " + ", ".join(f"{h.name} {r:.3f}"
                                                for h, r in zip(model.hinges, ratio)))
    times = [e.outcome.wall_time for e in res.history]
    print(f"evaluations {res.nfev}, iterations {res.nit}, starts {res.nstarts}")
    if res.first_feasible is not None:
        print(f"first feasible K after {res.first_feasible[0]} evaluations, "
              f"{res.first_feasible[1]:.1f} s")
    print(f"wall time {wall:.1f} s; per evaluation: median single run {np.median(times):.2f} s, "
          f"wall / nfev {wall / max(res.nfev, 1):.2f} s")
    describe(f"re-check (rtol {scene.simulation.rtol / TIGHTEN:g}, samples x {REFINE}, "
             f"collision.refine {scene.collision.refine})", check)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scene", nargs="?", default=str(ROOT / "config" / "scenes" / "paper_4x4.yaml"))
    p.add_argument("--seed", type=int, help="optimisation.seed")
    p.add_argument("--seeds", type=seed_list, metavar="0-7",
                   help="one search per seed; prints how many found a confirmed feasible K")
    p.add_argument("--out", help="write the result YAML here")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="scene override, as panel-deploy --set (optimisation.method=global, "
                        "optimisation.max_evaluations=400, optimisation.workers=2, ...)")
    args = p.parse_args(argv)
    if args.seeds and (args.out or args.seed is not None):
        p.error("--seeds runs several searches: give it without --seed and --out")

    scene = load_scene(resolve_scene(args.scene), args.set)
    model = build_model(scene)
    seeds = args.seeds or [args.seed]
    found, walls = [], []
    for seed in seeds:
        start = time.perf_counter()
        run = scene if seed is None else scene.replace(
            optimisation=dataclasses.replace(scene.optimisation, seed=seed))
        res = optimise(model, run, progress=None if args.seeds else print_progress)
        wall = time.perf_counter() - start
        walls.append(wall)
        check = verify(model, res.k, scene, tighten=TIGHTEN, refine=REFINE, c=res.c)
        confirmed = res.success and check.outcome.feasible
        if not args.seeds:
            report(model, scene, res, wall, check, args.set)
        else:
            first = (f"first feasible after {res.first_feasible[0]} evaluations, "
                     f"{res.first_feasible[1]:.1f} s" if res.first_feasible else "no feasible K")
            damping = ""
            if res.problem.damping_variable:
                damping = f", c/k {res.c[0] / res.k[0]:.3f} s"
                if res.damping_window is not None:
                    damping += " (%.3f-%.3f)" % res.damping_window
            print(f"seed {seed:3d}: f = {res.f:+.4f}{damping}, {first}; {res.nfev} evaluations, "
                  f"{wall:.1f} s; re-check {'confirms' if confirmed else 'does not confirm' if res.success else '-'}",
                  flush=True)
            if confirmed:
                found.append(res.first_feasible[1])
    if args.seeds:
        median = f", median time to it {np.median(found):.1f} s" if found else ""
        budget = args.max_evaluations or scene.optimisation.max_evaluations
        print(f"{len(found)} of {len(seeds)} seeds found a feasible K that the re-check "
              f"confirms{median}; budget {budget} evaluations, median search {np.median(walls):.1f} s")
    if args.out:
        save_result(res, args.out, scene.name)
        print(f"result -> {args.out}")


if __name__ == "__main__":
    main()
