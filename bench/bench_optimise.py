"""Benchmark: full stiffness optimisation of a scene (default: the paper's 4 x 4).

Prints K_0's outcome, the optimum (per hinge group), whether it is
collision-free and flat, its d, the independent re-check at tighter
tolerances, the evaluations spent (and those up to the first feasible K),
the wall time and the time per evaluation (median of the single-run wall times, and wall time / nfev,
which includes parallel speed-up and solver overhead).

    python bench/bench_optimise.py [SCENE] [--workers N] [--method local|global]
                                   [--max-evaluations N] [--seed N] [--out RESULT.yaml]
                                   [--set KEY=VALUE ...]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from panel_deploy.build import build_model  # noqa: E402
from panel_deploy.optimise import optimise, print_progress, save_result, verify  # noqa: E402
from panel_deploy.scene import load_scene, resolve_scene  # noqa: E402


def describe(label, ev):
    o = ev.outcome
    hit = (f"collision at {o.first_collision.get('t', float('nan')):.3f} s "
           f"{o.first_collision.get('pair')} v = {o.v:.3f} m/s") if o.collided else "no collision"
    print(f"{label}: f = {ev.f:+.5f}, {hit}, d = {o.d * 1e3:.2f} mm, "
          f"closest approach to flat {o.flat_residual:.3f} rad "
          f"({'flat' if o.reached_flat else 'NOT flat'}){'' if o.simulated else ', simulation failed: ' + o.message}")


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scene", nargs="?", default=str(ROOT / "config" / "scenes" / "paper_4x4.yaml"))
    p.add_argument("--workers", type=int, default=0)
    p.add_argument("--method", choices=("local", "global"))
    p.add_argument("--max-evaluations", type=int)
    p.add_argument("--seed", type=int)
    p.add_argument("--out", help="write the result YAML here")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="scene override, as panel-deploy --set")
    args = p.parse_args(argv)

    scene = load_scene(resolve_scene(args.scene), args.set)
    model = build_model(scene)
    start = time.perf_counter()
    res = optimise(model, scene, workers=args.workers, method=args.method,
                   max_evaluations=args.max_evaluations, seed=args.seed, progress=print_progress)
    wall = time.perf_counter() - start
    print()
    print(f"scene {scene.name}{' with ' + ', '.join(args.set) if args.set else ''}: {len(model.hinges)} hinges in {res.problem.n} groups, "
          f"bounds {res.problem.bounds} N m/rad, method {res.method}")
    describe("K_0    ", res.initial)
    describe("optimum", res.best)
    print(f"status {res.status}: {res.message}")
    for names, idx in zip(res.problem.group_names(), res.problem.groups):
        print(f"  k = {res.k[idx[0]]:.4f} N m/rad  {', '.join(names)}")
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
    tighten, refine = 10.0, 2
    check = verify(model, res.k, scene, tighten=tighten, refine=refine)
    describe(f"re-check (rtol {scene.simulation.rtol / tighten:g}, samples x {refine}, "
             f"collision.refine {scene.collision.refine})", check)
    if args.out:
        save_result(res, args.out, scene.name)
        print(f"result -> {args.out}")


if __name__ == "__main__":
    main()
