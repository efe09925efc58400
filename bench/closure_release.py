"""Closure study: when the loop's last hinges release and the array first lies flat,
with the exact closure and with penalty springs of several stiffnesses k_M = k_N.

    python bench/closure_release.py [SCENE] [--stiffness RESULT.yaml] [--t-end 4]
                                    [--k-M 1e5 3e5 1e6 2e6 4e6] [--set KEY=VALUE ...]
                                    [--angles HINGE ... --window T0 T1]

The paper design passes a singular configuration of its closed loop on the way to
flat (NOTES.md section 6); this shows how much its deployment owes to the
compliance of the closure there. Sample spacing and every other setting are the
scene's (the spacing is kept when --t-end lengthens the run). ``--angles`` prints
those hinges' angles (rad) at every sample in ``--window`` for each closure: at
the singular configuration the loop can leave it only when every hinge of a side
column is flat at once.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace

from panel_deploy.build import build_model
from panel_deploy.dynamics import simulate
from panel_deploy.dynamics.report import hinge_angles, hinge_release_report
from panel_deploy.errors import PanelDeployError
from panel_deploy.scene import load_scene, resolve_scene


def closures(scene, k_m_values):
    """(label, scene) for the exact closure and for each penalty stiffness (N/m)."""
    yield "exact", scene.replace(closure=replace(scene.closure, method="exact"))
    for k in k_m_values:
        yield f"penalty k_M={k:.0e}", scene.replace(
            closure=replace(scene.closure, method="penalty", k_M=k, k_N=k))


def last_release(report):
    """(name, time) of the hinge that leaves its stowed angle last; time None if one never does."""
    hinges = report["hinges"]
    if report["locked"]:
        return report["locked"][0], None
    name = max(hinges, key=lambda n: hinges[n]["released_at"])
    return name, hinges[name]["released_at"]


def when(t):
    """A sample time (s) or "never"."""
    return "never" if t is None else f"{t:.3f}"


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scene", nargs="?", default="paper_4x4")
    p.add_argument("--stiffness", metavar="RESULT.yaml", help="K from an optimisation result (default: the scene's)")
    p.add_argument("--t-end", type=float, default=4.0, help="s")
    p.add_argument("--k-M", type=float, nargs="+", default=[1e5, 3e5, 1e6, 2e6, 4e6], help="N/m")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    p.add_argument("--angles", nargs="+", default=[], metavar="HINGE", help="hinge names to print")
    p.add_argument("--window", type=float, nargs=2, default=(0.6, 0.7), metavar=("T0", "T1"),
                   help="s, where --angles prints")
    args = p.parse_args(argv)
    try:
        scene = load_scene(resolve_scene(args.scene), args.set)
        sim = scene.simulation
        dt = sim.t_end / (sim.samples - 1)
        scene = scene.replace(simulation=replace(sim, t_end=args.t_end, samples=round(args.t_end / dt) + 1))
        k = None
        if args.stiffness:
            from panel_deploy.optimise import load_stiffness
            k = load_stiffness(args.stiffness, build_model(scene))
    except PanelDeployError as e:
        sys.exit(f"closure_release: {e}")
    print(f"scene {scene.name}{' with ' + ', '.join(args.set) if args.set else ''}, "
          f"K {'from ' + args.stiffness if k is not None else 'of the scene'}, t_end {args.t_end} s")
    print(f"{'closure':20s} {'last hinge to release':>24s} {'at (s)':>7s} {'flat at (s)':>11s} "
          f"{'max gap (m)':>11s} {'wall (s)':>8s}")
    for label, variant in closures(scene, args.k_M):
        model = build_model(variant)
        if k is not None:
            model = model.with_stiffness(k)
        start = time.perf_counter()
        result = simulate(model, variant.simulation)
        wall = time.perf_counter() - start
        report = hinge_release_report(model, result, flat_tolerance=variant.simulation.flat_tolerance)
        name, at = last_release(report)
        gap = result.constraint_gap.max()
        print(f"{label:20s} {name:>24s} {when(at):>7s} {when(report['flat_at']):>11s} "
              f"{gap:11.2e} {wall:8.1f}" + ("" if result.success else f"  ({result.message})"))
        if args.angles:
            print_angles(model, result, args.angles, args.window)


def print_angles(model, result, wanted, window):
    """The angles (rad) of the hinges ``wanted`` at every sample in ``window`` (s)."""
    names, _, theta = hinge_angles(model, result)
    unknown = sorted(set(wanted) - set(names))
    if unknown:
        sys.exit(f"closure_release: --angles: no hinge named {', '.join(unknown)}")
    cols = [names.index(n) for n in wanted]
    print("    t (s) " + " ".join(f"{n:>11s}" for n in wanted))
    for j in ((result.t >= window[0]) & (result.t <= window[1])).nonzero()[0]:
        print(f"    {result.t[j]:.3f} " + " ".join(f"{theta[j, c]:+11.5f}" for c in cols))


if __name__ == "__main__":
    main()
