"""Timings of the dynamics on the paper scene (not a test: prints medians and ratios).

    python bench/bench_dynamics.py [--window S] [--repeats R] [method ...]

Methods: any simulation.method name ("dopri5", "tsit5", "ros34pw2", "compiled"
(tsit5 or ros34pw2), and the scipy names); default: the compiled schemes over a tolerance sweep, the
scipy methods at rtol 1e-6. For each closure model (penalty, exact) it prints
the RHS and stiff-Jacobian cost (median of 5 runs of 2000 calls inside numba),
then per method and rtol (atol = 1e-2 rtol): the median over R runs of the
wall time per simulated second over the valid window (default 0.44 s, up to
the paper scene's first collision), the max hinge-angle error against a
compiled DOPRI5 reference at rtol 1e-11 (or the first of 1e-10, 1e-9 that
succeeds; sampled every 5 ms), nfev, steps,
and the time relative to compiled DOPRI5 at rtol 1e-6.
"""

from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path

import numpy as np
from numba import njit

from panel_deploy.build import build_model
from panel_deploy.dynamics import kernels, stiff
from panel_deploy.dynamics.pack import pack
from panel_deploy.dynamics.simulate import simulate
from panel_deploy.scene import load_scene

SCIPY = ("RK23", "RK45", "DOP853", "Radau", "BDF", "LSODA")
COMPILED = ("dopri5", "tsit5", "ros34pw2", "compiled")
SWEEP = (1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7)
#: Tried in turn: the exact closure's DOPRI5 step collapses at rtol 1e-11 (t ~ 0.1 s).
REFERENCE_RTOL = (1e-11, 1e-10, 1e-9)


@njit(cache=True)
def _loop(P, y, calls, jacobian):
    s = 0.0
    scratch = kernels.scratch(P)
    for _ in range(calls):
        s += stiff.stiff_jacobian(P, y, scratch[0])[0][0, 0] if jacobian else kernels.rhs(P, y, scratch)[0]
    return s


def kernel_cost(P, y, calls=2000, repeats=5):
    """Median seconds per RHS call and per stiff-Jacobian call, inside numba."""
    out = []
    for jacobian in (False, True):
        _loop(P, y, 1, jacobian)
        times = []
        for _ in range(repeats):
            t = time.perf_counter()
            _loop(P, y, calls, jacobian)
            times.append((time.perf_counter() - t) / calls)
        out.append(float(np.median(times)))
    return out


def _run(model, settings, method, repeats):
    s = dataclasses.replace(settings, method=method)
    simulate(model, dataclasses.replace(s, t_end=1e-3, samples=2))  # compile / warm up
    runs = [simulate(model, s) for _ in range(repeats)]
    return float(np.median([r.wall_time for r in runs])), runs[0]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--window", type=float, default=0.44)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("methods", nargs="*")
    args = ap.parse_args(argv)
    methods = args.methods or (COMPILED[:2] + SCIPY)
    scene = load_scene(Path(__file__).resolve().parent.parent / "config" / "scenes" / "paper_4x4.yaml")
    base = build_model(scene)
    samples = int(round(args.window / 0.005)) + 1
    settings = dataclasses.replace(scene.simulation, t_end=args.window, samples=samples)
    for closure in ("penalty", "exact"):
        model = dataclasses.replace(base, closure=dataclasses.replace(base.closure, method=closure))
        for ref_rtol in REFERENCE_RTOL:
            ref = simulate(model, dataclasses.replace(settings, method="dopri5", rtol=ref_rtol,
                                                      atol=1e-2 * ref_rtol))
            if ref.success:
                break
        mid = len(ref.t) // 2
        y = kernels.state_vector(ref.theta[mid], ref.omega[mid])
        rhs_s, jac_s = kernel_cost(pack(model), y)
        print(f"{closure}: reference (DOPRI5 rtol {ref_rtol:.0e}) {ref.message}, {ref.nsteps} steps; "
              f"RHS {rhs_s * 1e6:.1f} us, "
              f"stiff Jacobian {jac_s * 1e6:.1f} us (inside numba)", flush=True)
        baseline = None
        for method in methods:
            tols = SWEEP if method in COMPILED else (1e-6,)
            for rtol in tols:
                s = dataclasses.replace(settings, rtol=rtol, atol=1e-2 * rtol)
                wall, r = _run(model, s, method, args.repeats)
                per_s = wall / r.t[-1]
                if method == "dopri5" and rtol == 1e-6:
                    baseline = per_s
                m = min(len(r.t), len(ref.t))
                err = float(np.abs(r.theta[:m] - ref.theta[:m]).max())
                ratio = f"{per_s / baseline:6.3f}" if baseline else "   n/a"
                print(f"  {method:18s} rtol={rtol:.0e} ok={r.success!s:5s} "
                      f"wall/sim-s={per_s:8.3f} err={err:.1e} rad  nfev={r.nfev:8d} "
                      f"steps={r.nsteps:7d} vs dopri5@1e-6={ratio} "
                      f"gap={r.constraint_gap.max():.1e} m {'' if r.success else r.message}",
                      flush=True)


if __name__ == "__main__":
    main()
