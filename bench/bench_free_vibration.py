"""Benchmark: a known hinge damping c recovered from free-vibration tests (issue 31 part 3).

Three cases, encoder noise 1e-3 rad, 200 Hz, 1.96-sigma intervals (95 %):

- closed form: the 2 x 2 rig (two 2 x 1 PLA plates, 0.04 kg each, one hinge line of
  two springs) without weight or air, c = 0.0005 N m s/rad and k = 0.1 N m/rad per
  spring (zeta 0.097), 3 s per test released 0.30, 0.35 and 0.40 rad from an
  equilibrium of 0.6 rad; every seed is three tests, pooled.
- simulated rig: the shipped ``free_vibration_rig`` (a 0.785 kg steel test plate on
  the paper's spring, c/k = 0.043 s; its weight preloads the spring; sea-level air),
  swung by the package's own simulator from 1.5, 1.6 and 1.7 rad, 6 s per test.
- light plate: the same rig with a 0.04 kg plate and k = 0.02, c/k = 0.0058 s, where
  the drag is a few % of the damping: C_d = 1.17 is fitted too.

Per case: the relative error of c per test (log decrement and fit: median and
largest), how often the 95 % intervals cover the truth (per test and pooled), and
the pooled tests' agreement. ``--bags`` also writes the simulated rig's three tests
(seed 1) as ``bags/free_vibration_rig_{1,2,3}.mcap``.

    python bench/bench_free_vibration.py [--seeds 20] [--bags]
                                         [--out bench/results/free_vibration.txt]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from panel_deploy import free_vibration as fv
from panel_deploy.build import build_model
from panel_deploy.dynamics.simulate import simulate
from panel_deploy.model import State
from panel_deploy.scene import load_scene, resolve_scene, scene_from_dict

ROOT = Path(__file__).resolve().parent.parent
NOISE = 1e-3
RATE = 200.0
CLOSED_FORM = {"name": "rig", "array": {"rows": 2, "cols": 2, "length": 0.1, "width": 0.1,
                                        "thickness": 0.005, "mass": 0.02},
               "gravity": [0.0, 0.0, 0.0]}
LIGHT = ["array.density=400", "hinges.stiffness=0.02", "hinges.damping_ratio=0.0058"]


def closed_form_tests(seed):
    scene = scene_from_dict(CLOSED_FORM)
    rig = fv.rig_of(build_model(scene), "closed form")
    t = np.arange(0.0, 3.0, 1.0 / RATE)
    rng = np.random.default_rng(seed)
    return [(fv.Swing(f"seed {seed} test {i}", t,
                      fv.released(rig, t, 0.0005, 0.1, 0.6, amplitude)
                      + rng.normal(0.0, NOISE, t.size)), rig)
            for i, amplitude in enumerate((0.30, 0.35, 0.40))]


def simulated_runs(overrides, releases):
    """The noiseless swings of the shipped rig, simulated once per release angle (rad)."""
    scene = load_scene(resolve_scene("free_vibration_rig"), overrides)
    model = build_model(scene)
    rig = fv.rig_of(model, "free_vibration_rig")
    runs = [simulate(model, scene.simulation, State(0.0, np.array([a]), np.zeros(1)))
            for a in releases]
    return scene, rig, runs


def noisy(runs, rig, seed):
    rng = np.random.default_rng(seed)
    return [(fv.Swing(f"seed {seed} test {i}", run.t,
                      run.theta[:, 0] + rng.normal(0.0, NOISE, len(run.t))), rig)
            for i, run in enumerate(runs)]


def study(name, truth, k_true, make, seeds, lines):
    """Calibrate ``make(seed)``'s tests for every seed; the figures of c (and k) as lines."""
    errors = {"log decrement": [], "fit": []}
    k_errors = {"log decrement": [], "fit": []}
    covered = {"log decrement": 0, "fit": 0}
    pooled_covered, disagree, tests, drags, notes = 0, 0, 0, [], set()
    start = time.perf_counter()
    for seed in seeds:
        readings = [(swing, rig, fv.check_swing(swing, rig)) for swing, rig in make(seed)]
        cal = fv.calibrate(readings)
        for decrement, fit in cal.tests:
            tests += 1
            for a in (decrement, fit):
                errors[a.method].append(a.c.value / truth - 1.0)
                k_errors[a.method].append(a.k.value / k_true - 1.0)
                covered[a.method] += a.c.low <= truth <= a.c.high
            if fit.drag is not None:
                drags.append((fit.drag.value, fit.drag.low, fit.drag.high))
            notes.update(note.split(" (")[0] for note in fit.notes)
        pooled = cal.fit["c"]
        pooled_covered += pooled.estimate.low <= truth <= pooled.estimate.high
        disagree += not pooled.agree
        if seed == seeds[0]:
            first = (pooled.estimate, cal.log_decrement["c"].estimate)
    wall = time.perf_counter() - start
    lines.append(f"{name}: true c = {truth:.6g} N m s/rad, {len(seeds)} seeds x "
                 f"{tests // len(seeds)} tests ({wall / tests:.2f} s per test, both ways)")
    for method, e in errors.items():
        e = np.abs(e)
        k = np.abs(k_errors[method])
        lines.append(f"  {method:<13} c |error| median {np.median(e):.2%}, largest {e.max():.2%}; "
                     f"95 % interval covers c in {covered[method]}/{tests}; k |error| median "
                     f"{np.median(k):.2%}, largest {k.max():.2%}")
    fit_pool, decrement_pool = first
    lines.append(f"  pooled fit covers c in {pooled_covered}/{len(seeds)} seeds; tests disagree "
                 f"(chi2 p < 0.05) in {disagree}; seed {seeds[0]}: fit {fit_pool.value:.6g} "
                 f"[{fit_pool.low:.6g}, {fit_pool.high:.6g}], log decrement "
                 f"{decrement_pool.value:.6g} "
                 f"[{decrement_pool.low:.6g}, {decrement_pool.high:.6g}]")
    if drags:
        d = np.array(drags)
        inside = int(np.sum((d[:, 1] <= 1.17) & (1.17 <= d[:, 2])))
        lines.append(f"  C_d (true 1.17) identified in {len(d)}/{tests} tests: median "
                     f"{np.median(d[:, 0]):.3g}, 95 % interval covers it in {inside}/{len(d)}")
    lines += [f"  note: {note}" for note in sorted(notes)]


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--bags", action="store_true",
                        help="write bags/free_vibration_rig_*.mcap")
    parser.add_argument("--out", default=str(ROOT / "bench" / "results" / "free_vibration.txt"))
    args = parser.parse_args(argv)
    seeds = list(range(1, args.seeds + 1))
    lines = [f"# python bench/bench_free_vibration.py --seeds {args.seeds}",
             f"# noise {NOISE:g} rad, {RATE:g} Hz; c of one spring"]
    study("closed form (no weight, no air)", 0.0005, 0.1, closed_form_tests, seeds, lines)
    scene, rig, runs = simulated_runs((), (1.5, 1.6, 1.7))
    study("simulated rig free_vibration_rig (weight, air)", 0.1 * 0.043, 0.1,
          lambda seed: noisy(runs, rig, seed), seeds, lines)
    _, light_rig, light_runs = simulated_runs(LIGHT, (0.6, 0.7, 0.75))
    study("light plate (weight, air; drag a few % of the damping)", 0.02 * 0.0058, 0.02,
          lambda seed: noisy(light_runs, light_rig, seed), seeds, lines)
    text = "\n".join(lines) + "\n"
    print(text, end="")
    Path(args.out).write_text(text)
    if args.bags:
        for i, (swing, _) in enumerate(noisy(runs, rig, seed=1), start=1):
            path = ROOT / "bags" / f"free_vibration_rig_{i}.mcap"
            fv.record_swing(path, scene, swing.t, swing.theta, t0=1.7e9 + 60.0 * i)
            print(f"{path.relative_to(ROOT)}: {path.stat().st_size} bytes")


if __name__ == "__main__":
    main()
