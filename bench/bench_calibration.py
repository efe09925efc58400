"""What a calibration of the paper scene recovers from synthetic recordings
with hidden true parameters (issue 31's benchmark).

    python bench/bench_calibration.py [--seeds N] [--fit damping,stiffness[,drag]]
                                      [--per group|scale] [--t-end S] [--rate HZ]
                                      [--truth-method M] [--truth-rtol R]

Per seed, drawn uniformly: per symmetry group (``--per group``; one value for
all hinges with ``--per scale``) damping 0.5-2x and stiffness 0.8-1.2x the
scene's, and with ``drag`` C_d 0-2 at 1.2 kg/m^3; a release 20-80 ms after
the first stamp; encoder noise 1e-3 rad; the cut hinge and r1c1-r1c2
unmeasured; a 50 ms gap. The recording is simulated with ``--truth-method``
at ``--truth-rtol`` sampled every 0.1 ms (by default scipy's DOP853 at 1e-10,
not the fit's compiled Rosenbrock-W at 1e-6 sampled every 1 ms: no inverse
crime in the integration; ``--truth-method compiled --truth-rtol 1e-6
--truth-interval 1e-3`` commits it). One fit per seed from the scene's values.

Prints every seed (how many of its identifiable parameters' 95 % intervals
hold the truth, whether the joint 95 % region does, the first collision the
fitted model predicts against the true model's over ``--predict`` s, past the
recorded window, where a fit is used; time and simulations), then per
parameter the median relative error and the coverage of the intervals over
the seeds where the data determine it, and where the wall time of a fit goes:
its simulations (of the points tried, of the Jacobian's difference steps),
the rest of the fit, the collision check of the fitted model, and the I/O of
the command (reading the sample recording bags/paper_4x4_uniform.mcap,
writing the calibrated scene). 2 shared cores: the load average is printed.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import yaml
from scipy.stats import chi2

from panel_deploy.build import build_model
from panel_deploy.calibrate import Measured, calibrate, parameters, read_measured
from panel_deploy.calibrate.scene_out import calibrated_data
from panel_deploy.dynamics.hinge_trajectory import fit_settings, simulate_hinges
from panel_deploy.collision import CollisionSettings, check_trajectory
from panel_deploy.dynamics import simulate
from panel_deploy.model import hinge_order
from panel_deploy.scene import load_scene, resolve_scene

UNMEASURED = ("r4c3-r4c4", "r1c1-r1c2")
RANGES = {"damping": (0.5, 2.0), "stiffness": (0.8, 1.2), "drag": (0.0, 2.0)}
NOISE = 1e-3  # rad
GAP = (0.12, 0.17)  # s after the first stamp
SAMPLE_BAG = Path(__file__).resolve().parent.parent / "bags" / "paper_4x4_uniform.mcap"


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, default=20)
    p.add_argument("--fit", default="damping,stiffness,drag")
    p.add_argument("--per", default="group", choices=("group", "scale"))
    p.add_argument("--t-end", type=float, default=0.3, help="s recorded after the release")
    p.add_argument("--rate", type=float, default=200.0, help="joint states per second")
    p.add_argument("--predict", type=float, default=0.6,
                   help="s after the release over which first collisions are compared")
    p.add_argument("--truth-method", default="DOP853")
    p.add_argument("--truth-rtol", type=float, default=1e-10)
    p.add_argument("--truth-interval", type=float, default=1e-4,
                   help="s between the true simulation's samples (interpolated between)")
    args = p.parse_args()
    # scipy's DOP853 tries steps on which the right-hand side overflows, and rejects them.
    warnings.filterwarnings("ignore", "invalid value encountered", RuntimeWarning)
    print(f"# load average at the start: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    collision = CollisionSettings.from_scene(load_scene(resolve_scene("paper_4x4")))
    scene = load_scene(resolve_scene("paper_4x4"), ["air.density=1.2"])
    model = build_model(scene)
    fitted = parameters(model, tuple(args.fit.split(",")), args.per)
    true_simulation = replace(scene.simulation, method=args.truth_method, rtol=args.truth_rtol,
                              atol=args.truth_rtol * 1e-2)
    names = [model.hinges[h].name for h in hinge_order(model)]
    measured = [n for n in names if n not in UNMEASURED]
    labels = (*fitted.names, "release[0]")
    errors, inside, joint, times, shifts, seconds = [], [], [], [], [], []
    for seed in range(args.seeds):
        rng = np.random.default_rng(seed)
        truth = np.array([rng.uniform(*RANGES[kind]) for kind in fitted.kinds])
        release = rng.uniform(0.02, 0.08)
        true_model = fitted.model_at(truth)
        deployed = simulate_hinges(true_model, true_simulation, args.t_end, measured,
                                   args.truth_interval)
        t = np.arange(0.0, release + args.t_end, 1.0 / args.rate)
        t = t[(t < GAP[0]) | (t > GAP[1])]
        theta = deployed.angles(t - release) + rng.normal(0.0, NOISE, (len(t), len(measured)))
        result = calibrate(fitted, [Measured(f"seed {seed}", tuple(measured), t, theta, 0.0)],
                           scene.simulation, noise=NOISE)
        u = result.uncertainty
        true_x = np.append(truth, release)
        value = np.append(result.values, result.offsets)
        known = np.array([name not in result.problems for name in labels])
        lo, hi = (np.array([u.of(n)[k] if n in u.names else np.nan for n in labels])
                  for k in (1, 2))
        holds = (lo <= true_x) & (true_x <= hi)
        errors.append(np.where(known, np.abs(value / true_x - 1.0), np.nan))
        inside.append(np.where(known, holds, np.nan))
        joint.append(_mahalanobis(u, labels, known, true_x))
        times.append(result.wall_time)
        clock = time.perf_counter()
        fit_first = first_collision(result.model, scene.simulation, collision, args.predict)
        seconds.append({**result.seconds, "collision check": time.perf_counter() - clock})
        true_first = first_collision(true_model, scene.simulation, collision, args.predict)
        if true_first and fit_first and true_first[1] == fit_first[1]:
            shifts.append(abs(fit_first[0] - true_first[0]))
        print(f"seed {seed:2d}: status {result.status}, intervals hold the truth "
              f"{int(np.sum(holds[known]))} of {int(np.sum(known))} identifiable "
              f"(missed: {', '.join(np.array(labels)[known & ~holds]) or '-'}), "
              f"joint 95 % region {'holds' if joint[-1] <= chi2.ppf(0.95, known.sum()) else 'misses'}"
              f" (chi2 {joint[-1]:.1f} on {known.sum()}), held {len(result.held)}, "
              f"first collision true {_shown(true_first)}, fitted {_shown(fit_first)}, "
              f"{result.wall_time:.1f} s, {result.simulations} simulations", flush=True)
    errors, inside = np.array(errors), np.array(inside)
    print("\nper parameter (truth range; median relative error and 95 % intervals holding "
          "the truth over the seeds where the data determine it):")
    for i, name in enumerate(labels):
        seen = ~np.isnan(errors[:, i])
        kind = fitted.kinds[i] if i < len(fitted.kinds) else "release"
        span = RANGES.get(kind, (0.02, 0.08))
        if not seen.any():
            print(f"  {name:24s} {span[0]:g}-{span[1]:g}: not identifiable in any seed")
            continue
        print(f"  {name:24s} {span[0]:g}-{span[1]:g}: median error "
              f"{np.nanmedian(errors[:, i]) * 100:7.3f} %, largest "
              f"{np.nanmax(errors[:, i]) * 100:7.3f} %, coverage {int(np.nansum(inside[:, i]))} "
              f"of {int(seen.sum())}" + (f" (not identifiable in {int((~seen).sum())})"
                                         if (~seen).any() else ""))
    total, held = int(np.nansum(inside)), int(np.sum(~np.isnan(inside)))
    dof = [int(np.sum(~np.isnan(row))) for row in inside]
    joint_in = sum(m <= chi2.ppf(0.95, k) for m, k in zip(joint, dof))
    print(f"95 % intervals holding the truth: {total / held * 100:.0f} % ({total} of {held}); "
          f"joint 95 % regions: {joint_in} of {len(joint)} (mean chi2 / dof "
          f"{np.mean(np.array(joint) / np.array(dof)):.2f}, 1 expected)")
    print(f"first collision, fitted vs true model, same pair in {len(shifts)} of {args.seeds}: "
          + (f"|dt| median {np.median(shifts) * 1e3:.3f} ms, largest {max(shifts) * 1e3:.3f} ms"
             if shifts else "none to compare"))
    print(f"wall time of a fit: median {np.median(times):.1f} s, max {np.max(times):.1f} s")
    print("where one fit's time goes (medians over the seeds): " + ", ".join(
        f"{key} {np.median([s[key] for s in seconds]):.2f} s" for key in seconds[0]))
    print("I/O of the command: " + io_seconds(scene, model, result))
    print(f"# load average at the end: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")


def _mahalanobis(u, labels, known, true_x) -> float:
    """(fit - truth)^T C^-1 (fit - truth) over the identifiable parameters, in
    the fit's own unknowns (log values, offsets): chi2 with as many degrees of
    freedom when the covariance C is right."""
    idx = [u.names.index(n) for n, k in zip(labels, known) if k]
    log = np.array([not n.startswith("release") for n in np.array(labels)[known]])
    se_x = np.where(log, u.relative_se[idx], u.se[idx])
    cov = u.correlation[np.ix_(idx, idx)] * np.outer(se_x, se_x)
    d = np.where(log, np.log(u.value[idx] / true_x[known]), u.value[idx] - true_x[known])
    return float(d @ np.linalg.solve(cov, d))


def io_seconds(scene, model, result) -> str:
    """Wall time of the command's reading of the sample recording and of
    writing ``result`` as a calibrated scene."""
    clock = time.perf_counter()
    read_measured(SAMPLE_BAG, scene, model, until=0.3)
    read = time.perf_counter() - clock
    clock = time.perf_counter()
    with tempfile.TemporaryDirectory() as folder:
        (Path(folder) / "calibrated.yaml").write_text(
            yaml.safe_dump(calibrated_data(scene, result), sort_keys=False))
    return f"reading {SAMPLE_BAG.name} (0.3 s) {read:.3f} s, writing the scene {time.perf_counter() - clock:.3f} s"


def first_collision(model, simulation, collision, t_end):
    """``(t, pair)`` of ``model``'s first collision within ``t_end`` s of the release, or None."""
    report = check_trajectory(model, simulate(model, fit_settings(simulation, t_end)), collision)
    first = report.first_collision
    return None if first is None else (first.t, tuple(first.names))


def _shown(first) -> str:
    return "none" if first is None else f"{first[0]:.4f} s {'/'.join(first[1])}"


if __name__ == "__main__":
    main()
