"""What a calibration of the paper scene recovers from synthetic recordings
with hidden true parameters (issue 31's benchmark, in part).

    python bench/bench_calibration.py [--seeds N] [--fit damping,stiffness[,drag]]
                                      [--t-end S] [--rate HZ]

Per seed: damping 0.5-2x nominal, stiffness +-20 %, with ``drag`` C_d 0.2-2
at 1.2 kg/m^3 (drawn uniformly); a release 20-80 ms after the first stamp;
encoder noise 1e-3 rad; the cut hinge and r1c1-r1c2 unmeasured; a 50 ms
gap. One fit per seed (``--per scale``) from the scene's values. Prints
every seed (truth, fit, whether each 95 % interval holds the truth, the
warnings, and the first collision the fitted model predicts against the
true model's, over ``--predict`` s: past the recorded window, where a fit
is used), then the median relative error of each parameter, the coverage
of the intervals, the first-collision error and the median wall time of a
fit (2 shared cores).
"""

from __future__ import annotations

import argparse

import numpy as np

from panel_deploy.build import build_model
from panel_deploy.calibrate import Measured, calibrate, parameters
from panel_deploy.calibrate.trajectory import fit_settings, simulate_hinges
from panel_deploy.collision import CollisionSettings, check_trajectory
from panel_deploy.dynamics import simulate
from panel_deploy.model import hinge_order
from panel_deploy.scene import load_scene, resolve_scene

UNMEASURED = ("r4c3-r4c4", "r1c1-r1c2")
RANGES = {"damping": (0.5, 2.0), "stiffness": (0.8, 1.2), "drag": (0.2, 2.0)}
NOISE = 1e-3  # rad
GAP = (0.12, 0.17)  # s after the first stamp


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, default=20)
    p.add_argument("--fit", default="damping,stiffness")
    p.add_argument("--t-end", type=float, default=0.3, help="s recorded after the release")
    p.add_argument("--rate", type=float, default=200.0, help="joint states per second")
    p.add_argument("--predict", type=float, default=0.6,
                   help="s after the release over which first collisions are compared")
    args = p.parse_args()
    collision = CollisionSettings.from_scene(load_scene(resolve_scene("paper_4x4")))
    scene = load_scene(resolve_scene("paper_4x4"), ["air.density=1.2"])
    model = build_model(scene)
    fitted = parameters(model, tuple(args.fit.split(",")))
    names = [model.hinges[h].name for h in hinge_order(model)]
    measured = [n for n in names if n not in UNMEASURED]
    errors, inside, times, shifts = [], [], [], []
    for seed in range(args.seeds):
        rng = np.random.default_rng(seed)
        truth = np.array([rng.uniform(*RANGES[kind]) for kind in fitted.kinds])
        release = rng.uniform(0.02, 0.08)
        deployed = simulate_hinges(fitted.model_at(truth), scene.simulation, args.t_end, measured)
        t = np.arange(0.0, release + args.t_end, 1.0 / args.rate)
        t = t[(t < GAP[0]) | (t > GAP[1])]
        theta = deployed.angles(t - release) + rng.normal(0.0, NOISE, (len(t), len(measured)))
        result = calibrate(fitted, [Measured(f"seed {seed}", tuple(measured), t, theta, 0.0)],
                           scene.simulation, noise=NOISE)
        u = result.uncertainty
        true_x = np.append(truth, release)
        holds = (u.lower <= true_x) & (true_x <= u.upper)
        errors.append(np.abs(u.value / true_x - 1.0))
        inside.append(holds)
        times.append(result.wall_time)
        true_first, fit_first = (first_collision(m, scene.simulation, collision, args.predict)
                                 for m in (fitted.model_at(truth), result.model))
        if true_first and fit_first and true_first[1] == fit_first[1]:
            shifts.append(abs(fit_first[0] - true_first[0]))
        print(f"seed {seed:2d}: status {result.status}, truth {np.round(true_x, 4)}, "
              f"fit {np.round(u.value, 4)}, in 95 % interval {holds.astype(int)}, "
              f"first collision true {_shown(true_first)}, fitted {_shown(fit_first)}, "
              f"{result.wall_time:.1f} s, {result.simulations} simulations"
              + (f"; {'; '.join(u.warnings)}" if u.warnings else ""), flush=True)
    labels = (*fitted.names, "release")
    median = np.median(errors, axis=0)
    print("median relative error: " + ", ".join(f"{n} {e * 100:.3f} %" for n, e in zip(labels, median)))
    print(f"95 % intervals holding the truth: {np.mean(inside) * 100:.0f} % "
          f"({int(np.sum(inside))} of {np.size(inside)})")
    print(f"first collision, fitted vs true model, same pair in {len(shifts)} of {args.seeds}: "
          + (f"|dt| median {np.median(shifts) * 1e3:.3f} ms, largest {max(shifts) * 1e3:.3f} ms"
             if shifts else "none to compare"))
    print(f"wall time of a fit: median {np.median(times):.1f} s, max {np.max(times):.1f} s")


def first_collision(model, simulation, collision, t_end):
    """``(t, pair)`` of ``model``'s first collision within ``t_end`` s of the release, or None."""
    report = check_trajectory(model, simulate(model, fit_settings(simulation, t_end)), collision)
    first = report.first_collision
    return None if first is None else (first.t, tuple(first.names))


def _shown(first) -> str:
    return "none" if first is None else f"{first[0]:.4f} s {'/'.join(first[1])}"


if __name__ == "__main__":
    main()
