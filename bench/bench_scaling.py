"""How the simulation and the collision check grow with the array (issue 33).

    python bench/bench_scaling.py [--repeats N] [--closure exact] [--stop-ramp RAD]
                                  [--out bench/results/scaling.txt]

Scenes: the paper's 4 x 4 scene as it is, and the first circuit that packs of
5 x 6, 6 x 6, 8 x 8 and 10 x 10, as issue 33 measured them
(``--set array.rows=R --set array.cols=C --set fold.circuit=N
--set fold.ground=null`` on the paper scene), each over a short window
(``CASES``: 0.5 s for the paper scene, 0.2 s for the others), sampled every
5 ms as the scene. The larger arrays run with panel-to-panel contact
(``contact.panels=true``, every unhinged pair), without which their panels
pass through each other in the stowed stacks within 0.02-0.06 s
(docs/findings.md 3.2), and with ramped joint stops (``contact.stop_ramp``,
``--stop-ramp``, default ``STOP_RAMP``: the stowed stack's hinges chatter on
their stops, and the paper's stop, whose damper comes in at once, made most of
the rejected steps there); the paper scene without either, as it is.
The circuits close one loop each (one cut hinge; the paper scene's penalty
closure, or with ``--closure exact`` the exact one), so from 5 x 6 on the
dynamics take the O(n) articulated path (``dynamics.articulated``); the paper
scene (11 coordinates, always as it is) the dense one.

Per scene (medians of ``--repeats`` runs, wall clock, 2 shared cores):
- simulation: wall time per simulated second and per accepted step, and
  the process's CPU time per step (the machine is shared: under a load
  above its 2 cores the wall time of one run varies by 2x, its CPU time by
  a few percent);
- collision check, as production runs it (refinement on, up to and with the
  sample of the first collision): set-up of the check (once per run), and
  the median time per sample of :meth:`TrajectoryCheck.update` over all
  repeats (at least ``--repeats``, and enough for ``MIN_SAMPLES`` samples),
  with the between-sample screen off ("before", ``prune=False``: every
  pair's speed bound on every interval) and on ("after"), and with the
  speed bound alone ("1st ord", ``second_order=False``: no second-order
  bound before a pair is bisected), the checks fed the same samples in
  turn, the median of their per-sample ratios to "after", and the bisection
  steps with and without the second-order bound; their results are
  compared (first collision, t, v, d, D_j);
- the paper's D_j alone (refinement off) per sample, over the whole window;
- P, the body pairs checked, and how many got an exact distance per sample.

Error against run time: each scene once more at each (rtol, atol) of
``TOLERANCES`` (rtol 1e-8 with atol 1e-10, tighter than the scene's, then
the scene's rtol with atol 1e-6, then rtol 1e-4 and 1e-3 with atol rtol /
100), its wall time per simulated second (every loop it may take loaded
first) and how far its first collision moves from the one at the scene's
tolerances. Then the larger arrays
once with the paper's stops (ramp 0): wall time per simulated second, steps,
the ratio to the ramped run and how far the first collision moves; and once
over ``LONG_WINDOW`` (1 s): wall time per simulated second, steps, and the
steps per simulated second after the short window against those within it.
And the larger arrays that ``compiled`` runs on Tsitouras' pair (not where it
takes ROS34PW2, the stiff penalty closure) once on Dormand and Prince's pair
(``method: dopri5``): the same figures as for the paper's stops.

Then the shipped 10 x 10 design (``DESIGN``, heavily damped: c/k 3 s) over its
whole deployment at the scene's tolerances, once on the explicit pair alone
(``tsit5``) and once as ``compiled``, which hands over to ROS34PW2 where the
pair is held at its stability limit: wall time, steps, when it handed over, the first flat
sample of each and the largest angle between the two runs.

Then the exponent of each figure against n, the number of bodies, by least
squares on log-log over the five scenes, and whether issue 33's goals are met
(``GOAL_EXPONENT``, ``GOAL_LARGEST``). Everything printed is also written to
``--out``.
"""

from __future__ import annotations

import argparse
import math
import statistics
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from panel_deploy import fold
from panel_deploy.build import build_model
from panel_deploy.collision import CollisionSettings, TrajectoryCheck, check_trajectory
from panel_deploy.dynamics import simulate
from panel_deploy.dynamics.compiled import EXPLICIT_PAIR
from panel_deploy.dynamics.report import dynamics_summary
from panel_deploy.scene import load_scene

ROOT = Path(__file__).resolve().parent.parent
SCENE = ROOT / "config" / "scenes" / "paper_4x4.yaml"
DESIGN = ROOT / "config" / "scenes" / "array_10x10.yaml"
#: (rows, cols, simulated window in s); None: the paper scene as it is.
CASES = ((None, None, 0.5), (5, 6, 0.2), (6, 6, 0.2), (8, 8, 0.2), (10, 10, 0.2))
SAMPLE_INTERVAL = 0.005
#: Timed samples per check setting at least (a 10 x 10 check stops after 6 samples).
MIN_SAMPLES = 200
#: The other (rtol, atol) of the error-against-run-time line: a tighter pair,
#: whose first collision says how far the scene's own is from converged; rtol
#: with atol rtol / 100, as the scene's; and the scene's rtol with a looser atol, which on
#: the larger arrays sets the step count (the hinges ringing on their stops).
TOLERANCES = ((1e-8, 1e-10), (1e-6, 1e-6), (1e-4, 1e-6), (1e-3, 1e-5))
#: Issue 33's goals: the exponent of the wall time per simulated second against
#: the bodies, and the largest array's wall s per simulated s on this machine.
GOAL_EXPONENT = 1.5
GOAL_LARGEST = 2.0
#: The larger arrays' longer window, s: one run each over it, for the part of
#: a deployment after the short window (hinges reaching flat ring on their stops).
LONG_WINDOW = 1.0
#: contact.stop_ramp of the larger arrays, rad: a sixth of the smallest stop
#: overshoot measured on the paper scene at its k_s (0.6 mrad at 1000 N m/rad;
#: 0.2 at 5000), and 10 um at a 0.1 m panel's edge, the depth of the panel contacts' ramp.
STOP_RAMP = 1e-4
#: Simulated time (s) of the run that loads ROS34PW2's loop before the tolerance sweep.
WARM_UP = 1e-4


def design_runs():
    """The heavily damped 10 x 10 design over its deployment, on the explicit
    pair alone and as ``compiled`` (the hand-over): lines of text."""
    scene = load_scene(DESIGN)
    model = build_model(scene)
    runs = {m: simulate(model, replace(scene.simulation, method=m)) for m in (EXPLICIT_PAIR, "compiled")}
    flat = {m: dynamics_summary(model, r, flat_tolerance=scene.simulation.flat_tolerance)["time_to_flat"]
            for m, r in runs.items()}
    a, b = runs[EXPLICIT_PAIR], runs["compiled"]
    lines = [f"  {m:8s} {r.wall_time:6.1f} s wall, {r.nsteps:7d} steps, {r.scheme}, "
             f"flat at {flat[m]} s, {r.message}" for m, r in runs.items()]
    return lines + [f"  compiled / {EXPLICIT_PAIR}: {b.wall_time / a.wall_time:.2f}x the wall time, "
                    f"{b.nsteps / a.nsteps:.2f}x the steps; largest angle between the two runs "
                    f"{np.abs(a.theta - b.theta).max():.2g} rad"]


def first_packing(rows: int, cols: int) -> int:
    """Index of the first circuit of an R x C array that packs into two stacks."""
    return next(i for i, d in fold.designs(rows, cols) if d.stowed is not None)


def scene_of(rows, cols, t_end, closure, stop_ramp):
    """The scene of one case (a larger array's loop closed by ``closure``, its
    joint stops ramped over ``stop_ramp`` rad) and its label."""
    samples = [f"simulation.t_end={t_end}", f"simulation.samples={round(t_end / SAMPLE_INTERVAL) + 1}"]
    if rows is None:
        return load_scene(SCENE, samples), "4 x 4 paper"
    n = first_packing(rows, cols)
    sets = [f"array.rows={rows}", f"array.cols={cols}", f"fold.circuit={n}", "fold.ground=null",
            "contact.panels=true", f"closure.method={closure}", f"contact.stop_ramp={stop_ramp}"]
    return load_scene(SCENE, sets + samples), f"{rows} x {cols} circuit {n}"


def lockstep(model, result, collisions):
    """Check ``result`` with every setting of ``collisions`` at once, sample by
    sample, the order turned at each sample, up to and with the sample of the
    first collision: (set-up s, per-sample update times s, check) of each."""
    out = []
    for collision in collisions:
        t0 = time.perf_counter()
        check = TrajectoryCheck(model, collision, capacity=len(result.t))
        out.append((time.perf_counter() - t0, [], check))
    for j in range(len(result.t)):
        if out[0][2].collided:
            break
        for _, times, check in out[::1 if j % 2 else -1]:
            t0 = time.perf_counter()
            check.update(result.t[j], result.theta[j], result.omega[j], (result.rotation[j], result.position[j]),
                         result.contact_onsets[j])
            times.append(time.perf_counter() - t0)
    return out


def d_j_per_sample(model, result, collision):
    """Median time (s) per sample of D_j alone (no refinement), every sample."""
    check = TrajectoryCheck(model, collision, capacity=len(result.t))
    times = []
    for j in range(len(result.t)):
        t0 = time.perf_counter()
        check.update(result.t[j], result.theta[j], result.omega[j], (result.rotation[j], result.position[j]),
                     result.contact_onsets[j])
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def same(a, b) -> bool:
    """Whether two checks found the same: first collision, t, v, d and D_j."""
    ra, rb = a.report(), b.report()
    ea, eb = ra.first_collision, rb.first_collision
    if (ea is None) != (eb is None):
        return False
    events = ea is None or (ea.pair == eb.pair and ea.t == eb.t)
    return events and ra.v == rb.v and ra.d == rb.d and np.array_equal(ra.distances, rb.distances)


def measure(rows, cols, t_end, repeats, closure, stop_ramp):
    scene, label = scene_of(rows, cols, t_end, closure, stop_ramp)
    model = build_model(scene)
    runs, cpu = [], []
    for _ in range(repeats):
        c0 = time.process_time()
        runs.append(simulate(model, scene.simulation))
        cpu.append(time.process_time() - c0)
    result = runs[0]
    wall = statistics.median(r.wall_time for r in runs)
    collisions = [CollisionSettings.from_scene(scene, prune=prune) for prune in (False, True)]
    collisions.append(replace(collisions[1], second_order=False))
    checked = len(lockstep(model, result, collisions)[0][1])  # and compile / warm up
    setup, before, after, first, ratio, first_ratio = [], [], [], [], [], []
    # A check is cheap next to the simulation: enough repeats for MIN_SAMPLES timed samples.
    for _ in range(max(repeats, math.ceil(MIN_SAMPLES / checked))):
        (_, t_off, off), (s_on, t_on, on), (_, t_first, first_order) = lockstep(model, result, collisions)
        setup.append(s_on)
        before += t_off
        after += t_on
        first += t_first
        ratio += [x / y for x, y in zip(t_off, t_on)]
        first_ratio += [x / y for x, y in zip(t_first, t_on)]
    refine_off = CollisionSettings.from_scene(scene, refine=False)
    dj = statistics.median(d_j_per_sample(model, result, refine_off) for _ in range(repeats))
    report = on.report()
    # A run of the sweep may hand over to ROS34PW2 (`compiled`), whose loop this
    # process has not loaded yet: load it first, so that its time is the run's.
    simulate(model, replace(scene.simulation, method="ros34pw2", t_end=WARM_UP, samples=2))
    sweep = [(rtol, atol, *compare_run(with_tolerances(scene, rtol, atol), model, report.first_collision))
             for rtol, atol in TOLERANCES]
    paper_stops = long = dopri5 = None
    if rows is not None:
        plain = scene_of(rows, cols, t_end, closure, 0.0)[0]
        paper_stops = compare_run(plain, build_model(plain), report.first_collision)
        if result.scheme == EXPLICIT_PAIR:  # not where the scene is stiff (ROS34PW2 ran)
            dopri5 = compare_run(replace(scene, simulation=replace(scene.simulation, method="dopri5")), model,
                                 report.first_collision)
        long = simulate(model, scene_of(rows, cols, LONG_WINDOW, closure, stop_ramp)[0].simulation)
    return dict(
        label=label, bodies=model.n_bodies, joints=model.n_coords, pairs=len(model.collision_pairs),
        t_end=t_end, steps=result.nsteps, sim_per_s=wall / result.t[-1], per_step=wall / result.nsteps,
        cpu_step=statistics.median(cpu) / result.nsteps,
        setup=statistics.median(setup), before=statistics.median(before), after=statistics.median(after),
        ratio=statistics.median(ratio), dj=dj, first=statistics.median(first),
        first_ratio=statistics.median(first_ratio), first_same=same(first_order, on),
        bisections=(first_order.report().counters["refine_evaluations"], report.counters["refine_evaluations"]),
        exact=report.counters["exact_pairs"] / report.counters["samples"], checked=report.counters["samples"],
        identical=same(off, on),
        contacts=len(model.contact_pairs), outcome=outcome(report), sweep=sweep, paper_stops=paper_stops,
        dopri5=dopri5, long=long)


def with_tolerances(scene, rtol, atol):
    """``scene`` integrated at (rtol, atol)."""
    return replace(scene, simulation=replace(scene.simulation, rtol=rtol, atol=atol))


def compare_run(scene, model, reference):
    """One run of ``scene``: wall s per simulated s, accepted steps, and how far
    its first collision is from ``reference`` (the bench's own run): the time
    difference (s), or why it cannot be compared."""
    result = simulate(model, scene.simulation)
    event = check_trajectory(model, result, CollisionSettings.from_scene(scene)).first_collision
    if (event is None) != (reference is None):
        error = "a different verdict"
    elif event is None:
        error = "none either"
    elif event.names != reference.names:
        error = f"{event.t - reference.t:+.4f} s, another pair"
    else:
        error = f"{event.t - reference.t:+.5f} s"
    return result.wall_time / result.t[-1], result.nsteps, error


def outcome(report) -> str:
    """The first collision, its pair and normal speed, and whether it is a press."""
    e = report.first_collision
    if e is None:
        return "no collision"
    kind = "press" if report.note else "impact"
    return f"collision {e.t:.4f} s {e.names[0]}-{e.names[1]} {abs(e.normal_speed):.3f} m/s ({kind})"


def exponent(n, y) -> float:
    """Slope of log y against log n, least squares."""
    return float(np.polyfit(np.log(n), np.log(y), 1)[0])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--closure", choices=("penalty", "exact"), default="penalty",
                    help="loop closure of the larger arrays (the paper scene keeps its own)")
    ap.add_argument("--stop-ramp", type=float, default=STOP_RAMP, metavar="RAD",
                    help="contact.stop_ramp of the larger arrays (0: the paper's stops)")
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "results" / "scaling.txt")
    args = ap.parse_args(argv)
    start = time.perf_counter()
    if not 0.0 <= args.stop_ramp <= 0.01:
        ap.error(f"--stop-ramp: {args.stop_ramp:g} rad is outside [0, 0.01]")
    rows = [measure(r, c, t, args.repeats, args.closure, args.stop_ramp) for r, c, t in CASES]
    lines = [f"bench_scaling: larger arrays closed by {args.closure}, joint stops ramped over "
             f"{args.stop_ramp:g} rad; "
             f"medians of {args.repeats} runs, 2 shared cores, load average "
             f"{open('/proc/loadavg').read().split()[0]}; n = bodies (after merging); "
             f"check times per sample up to the first collision, refinement on",
             "",
             f"{'scene':22s} {'n':>3s} {'joints':>6s} {'pairs':>5s} {'cont':>5s} {'t_end':>5s} {'steps':>6s} "
             f"{'sim s/s':>8s} {'us/step':>8s} {'cpu us':>7s} {'setup ms':>8s} {'before ms':>9s} {'after ms':>8s} "
             f"{'1st ord ms':>10s} "
             f"{'D_j ms':>7s} {'exact':>6s} {'same':>5s}  outcome"]
    for x in rows:
        lines.append(f"{x['label']:22s} {x['bodies']:3d} {x['joints']:6d} {x['pairs']:5d} {x['contacts']:5d} {x['t_end']:5.2f} "
                     f"{x['steps']:6d} {x['sim_per_s']:8.2f} {x['per_step'] * 1e6:8.1f} {x['cpu_step'] * 1e6:7.1f} "
                     f"{x['setup'] * 1e3:8.1f} {x['before'] * 1e3:9.3f} {x['after'] * 1e3:8.3f} "
                     f"{x['first'] * 1e3:10.3f} "
                     f"{x['dj'] * 1e3:7.3f} {x['exact']:6.1f} {str(x['identical']):>5s}  "
                     f"{x['outcome']} ({x['checked']} samples checked)")
    n = np.array([x["bodies"] for x in rows], dtype=float)
    lines += ["", "exponent against n (bodies), least squares on log-log over the five scenes:"]
    for key, name in (("pairs", "pairs P"), ("sim_per_s", "simulation, wall s per simulated s"),
                      ("per_step", "simulation, wall per step"),
                      ("cpu_step", "simulation, CPU per step"), ("setup", "check set-up"),
                      ("before", "check per sample, before (prune off)"),
                      ("after", "check per sample, after (prune on)"),
                      ("first", "check per sample, speed bound only"), ("dj", "D_j per sample (refine off)")):
        lines.append(f"  {name:40s} {exponent(n, [x[key] for x in rows]):5.2f}")
    largest, overall = rows[-1], exponent(n, [x["sim_per_s"] for x in rows])
    lines += ["", "issue 33's goals, at the scene's tolerances:",
              f"  exponent of wall s per simulated s <= {GOAL_EXPONENT}: {overall:.2f}, "
              f"{'met' if overall <= GOAL_EXPONENT else 'not met'}",
              f"  {largest['label']} under {GOAL_LARGEST} s per simulated s: {largest['sim_per_s']:.2f} s, "
              f"{'met' if largest['sim_per_s'] < GOAL_LARGEST else 'not met'}"]
    lines += ["", "error against run time: one run at each other (rtol, atol) (the scene's "
              "are 1e-6, 1e-8), wall s per simulated s, and its first collision's time less "
              "the scene's:"]
    for x in rows:
        lines.append(f"  {x['label']:22s} " + "; ".join(
            f"{rtol:g}/{atol:g}: {per_s:6.2f} s/s, {error}"
            for rtol, atol, per_s, _, error in x["sweep"]))
    for key, what in (("paper_stops", "the paper's stops (contact.stop_ramp 0)"),
                      ("dopri5", "Dormand and Prince's pair (method dopri5)")):
        if all(x[key] is None for x in rows):
            continue
        lines += ["", f"{what} on the larger arrays, one run: wall s per simulated s, steps, both as "
                  "ratios to the bench's run, and its first collision's time less the bench's:"]
        for x in rows:
            if x[key] is not None:
                per_s, steps, error = x[key]
                lines.append(f"  {x['label']:22s} {per_s:6.2f} s/s ({per_s / x['sim_per_s']:.2f}x), "
                             f"{steps} steps ({steps / x['steps']:.2f}x), {error}")
    lines += ["", f"the larger arrays over 0-{LONG_WINDOW:g} s, one run: wall s per simulated s, steps, "
              "steps per simulated s after the short window against within it, and how the run ended:"]
    for x in rows:
        if x["long"] is not None:
            r, later = x["long"], x["long"].t[-1] - x["t_end"]
            lines.append(f"  {x['label']:22s} {r.wall_time / r.t[-1]:6.2f} s/s, {r.nsteps} steps, "
                         f"{(r.nsteps - x['steps']) / later / (x['steps'] / x['t_end']):.2f}x; "
                         f"{r.message}")
    lines += ["", f"the 10 x 10 design ({DESIGN.name}) over its deployment, "
              "at the scene's tolerances, one run each:", *design_runs()]
    lines += ["", "before / after, median of the per-sample ratios: "
              + ", ".join(f"{x['label']} {x['ratio']:.2f}" for x in rows),
              "speed bound only / after (the second-order bound), median of the per-sample ratios, "
              "bisection steps without and with it, and whether both found the same:",
              *(f"  {x['label']:22s} {x['first_ratio']:5.2f}x, {x['bisections'][0]} -> {x['bisections'][1]} "
                f"steps, same {x['first_same']}" for x in rows),
              f"total bench time {time.perf_counter() - start:.0f} s"]
    text = "\n".join(lines)
    print(text)
    args.out.write_text(text + "\n")


if __name__ == "__main__":
    main()
