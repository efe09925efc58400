"""The panel contact's two laws side by side on the larger arrays (issue 33).

    python bench/bench_contact_pressure.py [--repeats N] [--closure exact] [--t-end S]
                                           [--out bench/results/contact_pressure.txt]

The first packing circuits of 6 x 6, 8 x 8 and 10 x 10, as ``bench_scaling``
builds them (contact on every unhinged pair, joint stops ramped over
``STOP_RAMP``, the loop closed by ``--closure``), each over ``--t-end`` with
faces pushing at the corners of their overlap (``contact.pressure: false``,
the default) and by a pressure over it (``true``: continuous in the pose,
:func:`panel_deploy.boxes.contact`). Runs of the two alternate; per law the
median wall time per simulated second, the accepted steps, the right-hand
side evaluations and the first collision (``check_trajectory``), and the ratio
of the medians. Everything printed is also written to ``--out``.
"""

from __future__ import annotations

import argparse
import os
import statistics
from dataclasses import replace
from pathlib import Path

from bench_scaling import STOP_RAMP, outcome, scene_of

from panel_deploy.build import build_model
from panel_deploy.collision import CollisionSettings, check_trajectory
from panel_deploy.dynamics import simulate

ROOT = Path(__file__).resolve().parent.parent
CASES = ((6, 6), (8, 8), (10, 10))
LAWS = ("corners", "pressure")


def with_law(scene, law):
    """``scene`` with the panel contacts' law ``law``, one of LAWS
    (``contact.pressure`` false or true)."""
    return replace(scene, contact=replace(scene.contact, pressure=law == "pressure"))


def measure(rows, cols, t_end, closure, repeats):
    scene, label = scene_of(rows, cols, t_end, closure, STOP_RAMP)
    scenes = {law: with_law(scene, law) for law in LAWS}
    models = {law: build_model(s) for law, s in scenes.items()}
    runs = {law: [] for law in LAWS}
    for _ in range(repeats):
        for law in LAWS:
            runs[law].append(simulate(models[law], scenes[law].simulation))
    out = {"label": label}
    for law in LAWS:
        result = runs[law][0]
        report = check_trajectory(models[law], result, CollisionSettings.from_scene(scenes[law]))
        out[law] = dict(sim_per_s=statistics.median(r.wall_time for r in runs[law]) / result.t[-1],
                        steps=result.nsteps, nfev=result.nfev, status=result.message,
                        outcome=outcome(report))
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--closure", choices=("penalty", "exact"), default="exact")
    ap.add_argument("--t-end", type=float, default=0.2)
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "results" / "contact_pressure.txt")
    args = ap.parse_args(argv)
    if args.repeats < 1:
        ap.error(f"--repeats: {args.repeats} is below 1")
    if not 0.0 < args.t_end <= 2.0:
        ap.error(f"--t-end: {args.t_end:g} s is outside (0, 2]")
    lines = [f"bench_contact_pressure: closure {args.closure}, joint stops ramped over {STOP_RAMP:g} rad, "
             f"0-{args.t_end:g} s, medians of {args.repeats} runs (the laws in turn), 2 shared cores, "
             f"load average {os.getloadavg()[0]:.2f}", ""]
    print(*lines, sep="\n", flush=True)
    for rows, cols in CASES:
        row = measure(rows, cols, args.t_end, args.closure, args.repeats)
        c, p = row["corners"], row["pressure"]
        for law in LAWS:
            r = row[law]
            line = (f"{row['label']:18s} {law:8s} {r['sim_per_s']:7.2f} s/s {r['steps']:6d} steps "
                    f"{r['nfev']:7d} evaluations  {r['outcome']}")
            if r["status"] != "reached t_end":
                line += f"  [{r['status']}]"
            lines.append(line)
            print(line, flush=True)
        ratio = (f"{'':18s} pressure / corners: {p['sim_per_s'] / c['sim_per_s']:.2f}x the time, "
                 f"{p['steps'] / c['steps']:.2f}x the steps, {p['nfev'] / c['nfev']:.2f}x the evaluations")
        lines.append(ratio)
        print(ratio, flush=True)
    args.out.write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
