"""Timings of the dynamics on the paper scene (not a test: prints medians and ratios).

    python -m panel_deploy.dynamics.benchmark [t_end] [method ...]

Prints the RHS cost (median of 5 runs of 2000 calls, from Python and from inside
numba) and, per closure model, integrator and switch location on/off, the wall
time per simulated second at rtol 1e-6, atol 1e-8, with nfev, steps and switches.
"""

from __future__ import annotations

import dataclasses
import sys
import time

import numpy as np
from numba import njit

from ..build import build_model
from ..model import State
from ..scene import load_scene
from . import kernels
from .pack import pack
from .report import energy_balance_error, hinge_release_report
from .simulate import simulate

METHODS = ("compiled", "RK23", "RK45", "DOP853", "Radau", "BDF", "LSODA")


@njit(cache=True)
def _rhs_loop(P, y, calls):
    s = 0.0
    for _ in range(calls):
        s += kernels.rhs(P, y)[0]
    return s


def rhs_cost(P, y, calls=2000, repeats=5):
    """Median seconds per RHS call from Python and from numba."""
    kernels.rhs(P, y)
    _rhs_loop(P, y, 1)
    py, nb = [], []
    for _ in range(repeats):
        t = time.perf_counter()
        for _ in range(calls):
            kernels.rhs(P, y)
        py.append((time.perf_counter() - t) / calls)
        t = time.perf_counter()
        _rhs_loop(P, y, calls)
        nb.append((time.perf_counter() - t) / calls)
    return float(np.median(py)), float(np.median(nb))


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    t_end = float(argv[0]) if argv else 0.5
    methods = argv[1:] or METHODS
    scene = load_scene("config/scenes/paper_4x4.yaml")
    base = build_model(scene)
    for closure in ("penalty", "exact"):
        model = dataclasses.replace(base, closure=dataclasses.replace(base.closure, method=closure))
        P = pack(model)
        s = State.stowed(model)
        y = np.concatenate([s.theta - 0.1, np.full(model.n_coords, 0.3), [0.0, 0.0]])
        py, nb = rhs_cost(P, y)
        print(f"{closure}: RHS {py * 1e6:.1f} us from Python, {nb * 1e6:.1f} us inside numba")
        for method in methods:
            for events in (True, False):
                settings = dataclasses.replace(scene.simulation, t_end=t_end, method=method,
                                               rtol=1e-6, atol=1e-8, events=events, samples=101)
                simulate(model, dataclasses.replace(settings, t_end=1e-4))  # compile / warm up
                r = simulate(model, settings, max_steps=400_000)
                rep = hinge_release_report(model, r)
                print(f"  {method:8s} events={events!s:5s} ok={r.success!s:5s} "
                      f"wall/sim-s={r.wall_time / r.t[-1]:8.2f} nfev={r.nfev:8d} njev={r.njev:5d} "
                      f"steps={r.nsteps:7d} switches={r.extra['switches']:4d} "
                      f"us/step={1e6 * r.wall_time / max(r.nsteps, 1):7.1f} "
                      f"balance={energy_balance_error(r).max():.1e} gap={r.constraint_gap.max():.1e} "
                      f"locked={len(rep['locked'])} {'' if r.success else r.message}", flush=True)


if __name__ == "__main__":
    main()
