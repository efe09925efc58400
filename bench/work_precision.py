"""Error against run time for every integrator and MuJoCo on the exported model.

    python bench/work_precision.py [SCENE] [--quick] [--repeats N]

Writes bench/results/work_precision{,_quick}.csv and .png and prints the table
and the time ratios to MuJoCo at 1e-3 and 1e-6 rad (see
panel_deploy.bench.work_precision for what is measured): ``panel-deploy bench
work-precision`` with the results folder as its output.
"""

import argparse
from pathlib import Path

from panel_deploy.cli import main

RESULTS = Path(__file__).resolve().parent / "results"

if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scene", nargs="?", default="paper_4x4", help="scene file or shipped name")
    p.add_argument("--quick", action="store_true", help="fewer tolerances and steps (< 2 min)")
    p.add_argument("--repeats", default="3")
    args = p.parse_args()
    stem = "work_precision_quick" if args.quick else "work_precision"
    raise SystemExit(main(["bench", "work-precision", args.scene, "--repeats", args.repeats,
                           "--out", str(RESULTS / f"{stem}.csv"),
                           "--plot", str(RESULTS / f"{stem}.png"), *(["--quick"] if args.quick else [])]))
