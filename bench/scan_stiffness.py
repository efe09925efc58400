"""Scan: evaluate a Latin hypercube of stiffness sets K and count the outcomes.

Evidence for what the optimiser can and cannot find: every K is scored
exactly as the search scores it (simulation at ``optimisation.rtol``,
collision check, flat residual), on all cores. Prints how many K are
collision-free, reach flat, both, and which pairs collide first.

    python bench/scan_stiffness.py [SCENE] [--n 80] [--seed 0] [--workers N]
                                   [--min GROUP=K ...] [--max GROUP=K ...]
                                   [--around RESULT.yaml [--spread 0.15]] [--set KEY=VALUE ...]

GROUP is any hinge name of the group (e.g. ``--min r3c2-r4c2=0.09`` samples
that group only from 0.09 N m/rad up); the other groups span the scene's bounds.
``--around`` samples within ``--spread`` decades of a result file's K instead.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import Counter

import numpy as np
import scan_args

from panel_deploy.errors import PanelDeployError
from panel_deploy.optimise.parallel import Evaluator, Job, make_backend
from panel_deploy.optimise.search import search_scene


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    scan_args.add_arguments(p, n=80, spread=0.15)
    args = p.parse_args(argv)
    try:
        scene, model, problem, ks, (lo, hi), what = scan_args.sample(args)
    except PanelDeployError as e:
        sys.exit(f"scan_stiffness: {e}")
    print(f"scene {scene.name}{' with ' + ', '.join(args.set) if args.set else ''}: {what}")
    backend = make_backend(Job(model, search_scene(scene)), args.workers)
    start = time.perf_counter()
    try:
        evals = Evaluator(backend, args.n).map(ks)
    finally:
        backend.close()
    wall = time.perf_counter() - start

    for names, a, b in zip(problem.group_names(), 10 ** lo, 10 ** hi):
        print(f"  {a:.4f} .. {b:.4f} N m/rad  {', '.join(names)}")
    out = [e.outcome for e in evals]
    free = [o for o in out if not o.collided and o.simulated]
    print(f"{args.n} K in {wall:.1f} s ({wall / args.n:.2f} s each on {backend.workers} workers): "
          f"{len(free)} collision-free, {sum(o.reached_flat for o in out)} reach flat, "
          f"{sum(o.feasible for o in out)} both, {sum(not o.simulated for o in out)} failed")
    hits = Counter(tuple(o.first_collision["pair"]) for o in out if o.collided)
    for pair, count in hits.most_common(5):
        print(f"  first collision {pair[0]} - {pair[1]}: {count}")
    collided = [o for o in out if o.collided]
    if collided:
        v = np.array([o.v for o in collided])
        t = np.array([o.first_collision["t"] for o in collided])
        print(f"  approach speed v median {np.median(v):.2f} m/s ({v.min():.2f} .. {v.max():.2f}), "
              f"time median {np.median(t):.3f} s ({t.min():.3f} .. {t.max():.3f})")
    if free:
        r = np.array([o.flat_residual for o in free])
        print(f"  collision-free: closest approach to flat median {np.median(r):.3f} rad "
              f"(best {r.min():.3f})")
    best = min(evals, key=lambda e: e.f)
    print(f"best f {best.f:+.4f}: " + ", ".join(
        f"{problem.hinge_names[idx[0]]} {best.k[idx[0]]:.4f}" for idx in problem.groups))


if __name__ == "__main__":
    main()
