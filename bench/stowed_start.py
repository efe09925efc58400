"""What the stowed start costs of a larger array's deployment (issue 33).

    python bench/stowed_start.py [--sizes 6 8 10] [--repeats 3] [--start 0.002]
                                 [--out bench/results/stowed_start.txt]

The first packing circuit of each R x R array, as ``bench_scaling.py`` runs it
(exact closure, ramped stops, panel contact, the scene's tolerances), with
springs at the overlap's corners and with a pressure over it
(``contact.pressure``), over its
first ``--start`` seconds and over the whole window (0.2 s): wall time (median
of ``--repeats``), accepted steps, right-hand-side evaluations and, for the
explicit pairs' loop, the attempts its error test rejected ((evaluations - 1) / 6 less
the steps; a step cut short onto a contact switch counts as rejected here).
The share of the window's wall time that its start takes says how much the
stowed stacks cost: there the pressed pairs make each evaluation dear, and
the jumps of their force (docs/findings.md 5, "The stowed start of 10 x 10")
reject nearly half of the attempts.
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

from bench_contact_pressure import LAWS, with_law
from bench_fold import timed
from bench_scaling import ROOT, STOP_RAMP, scene_of
from panel_deploy.build import build_model
from panel_deploy.dynamics import simulate
from panel_deploy.dynamics.erk import PAIRS

WINDOW = 0.2  # s, bench_scaling's window for the larger arrays
STAGES = 6  # evaluations of one attempt of the explicit pairs' compiled loop (FSAL)


def rejected(result) -> str:
    """The rejected attempts of a run on an explicit pair, else "-" (other schemes count otherwise)."""
    if result.scheme not in PAIRS:
        return "-"
    return str((result.nfev - 1) // STAGES - result.nsteps)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[6, 8, 10], metavar="R")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--start", type=float, default=0.002, metavar="S")
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "results" / "stowed_start.txt")
    args = ap.parse_args(argv)
    lines = [f"stowed_start: first packing circuits, exact closure, stops ramped over {STOP_RAMP} rad, "
             f"the scene's tolerances, the panel contacts' two laws (contact.pressure false and true); "
             f"medians of {args.repeats} runs, 2 shared cores",
             "",
             f"{'scene':<20} {'law':<9} {'window':>7} {'wall s':>7} {'steps':>6} {'evals':>6} {'rejected':>8} "
             f"{'us/eval':>7} {'share':>6}"]
    print("\n".join(lines), flush=True)
    for size, law in ((size, law) for size in args.sizes for law in LAWS):
        scene, label = scene_of(size, size, WINDOW, "exact", STOP_RAMP)
        scene = with_law(scene, law)
        model = build_model(scene)
        simulate(model, replace(scene.simulation, t_end=1e-5, samples=2))  # loads the kernels
        start_settings = replace(scene.simulation, t_end=args.start, samples=2)
        whole = timed(lambda: simulate(model, scene.simulation), args.repeats)
        start = timed(lambda: simulate(model, start_settings), args.repeats)
        for window, (wall, result) in ((args.start, start), (WINDOW, whole)):
            line = (f"{label:<20} {law:<9} {window:>7g} {wall:>7.3f} {result.nsteps:>6} {result.nfev:>6} "
                    f"{rejected(result):>8} {1e6 * wall / result.nfev:>7.0f} {wall / whole[0]:>6.0%}")
            lines.append(line)
            print(line, flush=True)
    args.out.write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
