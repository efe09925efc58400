"""Scan: the scene's stiffness K under a range of hinge damping ratios beta = c/k.

For every beta (s) the scene's own K (``--stiffness RESULT.yaml`` for a
result's) is scored as the search scores it, then ``--copies`` copies with
every k and c off by up to ``--tol`` are re-simulated
(:func:`~panel_deploy.optimise.manufacture.tolerance_check`). Prints K's
outcome and how many copies stay collision-free, reach flat, and both: how
robust the design is to how its springs and dampers are built, against how
strongly its hinges are damped (the paper's section 5 names hinge damping,
through lubricant viscosity, as the property to control).

    python bench/scan_damping.py [SCENE] [--ratios 0.043,0.1,0.2] [--copies 20]
                                 [--tol 0.05] [--stiffness RESULT.yaml]
                                 [--workers N] [--set KEY=VALUE ...]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from panel_deploy.build import build_model
from panel_deploy.errors import PanelDeployError
from panel_deploy.optimise import evaluate, load_stiffness, tolerance_check
from panel_deploy.optimise.search import search_scene
from panel_deploy.scene import load_scene, resolve_scene

ROOT = Path(__file__).resolve().parent.parent


def describe(ev) -> str:
    o = ev.outcome
    if o.collided:
        fc = o.first_collision
        return f"collides at {fc['t']:.3f} s ({fc['pair'][0]} - {fc['pair'][1]}, {o.v:.2f} m/s)"
    if o.reached_flat:
        return f"flat at {o.t_stop:.3f} s, d = {o.d * 1e3:.1f} mm"
    return f"collision-free, never flat ({o.flat_residual:.3f} rad short)"


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scene", nargs="?", default=str(ROOT / "config" / "scenes" / "paper_4x4.yaml"))
    p.add_argument("--ratios", default="0.043,0.1,0.15,0.2,0.3",
                   help="damping ratios beta = c/k to try, s (comma-separated)")
    p.add_argument("--copies", type=int, default=20)
    p.add_argument("--tol", type=float, default=0.05, help="relative spread of k and c of the copies")
    p.add_argument("--stiffness", help="a result file's K instead of the scene's")
    p.add_argument("--workers", type=int, default=0)
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    args = p.parse_args(argv)
    try:
        ratios = [float(r) for r in args.ratios.split(",")]
    except ValueError:
        sys.exit(f"scan_damping: --ratios: expected numbers separated by commas, got {args.ratios!r}")
    print(f"{'beta (s)':>8s}  {'K':<52s} {'copies within +-' + format(args.tol, '.0%'):>28s}")
    for beta in ratios:
        try:
            scene = load_scene(resolve_scene(args.scene), [*args.set, f"hinges.damping_ratio={beta}"])
            model = build_model(scene)
            k = load_stiffness(args.stiffness, model) if args.stiffness else model.stiffness
            start = time.perf_counter()
            ev = evaluate(model, k, search_scene(scene))
            copies = tolerance_check(model, k, scene, n=args.copies, stiffness_tol=args.tol,
                                     damping_tol=args.tol, workers=args.workers)
        except PanelDeployError as e:
            sys.exit(f"scan_damping: {e}")
        print(f"{beta:8.3f}  {describe(ev):<52s} {copies.collision_free:3d} collision-free, "
              f"{copies.reached_flat:3d} flat, {copies.feasible:3d} both of {copies.n}  "
              f"({time.perf_counter() - start:.1f} s)", flush=True)


if __name__ == "__main__":
    main()
