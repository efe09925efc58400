"""Error against run time for every integrator and MuJoCo on the exported model.

    python bench/work_precision.py [SCENE] [--quick] [--repeats N]

Writes bench/results/work_precision{,_quick}.csv and .png and prints the table
and the time ratios to MuJoCo at 1e-3 and 1e-6 rad (see
panel_deploy.bench.work_precision for what is measured).
"""

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from panel_deploy.bench.work_precision import work_precision_command  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"

if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scene", nargs="?", default=str(RESULTS.parent.parent / "config/scenes/paper_4x4.yaml"))
    p.add_argument("--quick", action="store_true", help="fewer tolerances and steps (< 2 min)")
    p.add_argument("--repeats", type=int, default=3)
    args = p.parse_args()
    RESULTS.mkdir(exist_ok=True)
    stem = "work_precision_quick" if args.quick else "work_precision"
    args.out = str(RESULTS / f"{stem}.csv")
    args.plot = str(RESULTS / f"{stem}.png")
    raise SystemExit(work_precision_command(args))
