"""Stiff-case suite: every integrator on every extreme case, ok or loud failure.

    python bench/stiff_cases.py [SCENE] [--quick] [--t-end 0.3] [--sizes 6x6 8x8]

Writes bench/results/stiff_cases{,_quick}.{csv,md} and prints the outcome table.
"""

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from panel_deploy.bench.stiff import stiff_command  # noqa: E402

HERE = Path(__file__).resolve().parent


def size(text):
    rows, cols = text.lower().split("x")
    return int(rows), int(cols)


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scene", nargs="?", default=str(HERE.parent / "config/scenes/paper_4x4.yaml"))
    p.add_argument("--quick", action="store_true", help="extreme values only")
    p.add_argument("--t-end", type=float, default=0.3, help="s")
    p.add_argument("--sizes", type=size, nargs="*", default=[(6, 6), (8, 8)],
                   help="bigger arrays to run as they are, e.g. 6x6 8x8")
    p.add_argument("--max-steps", type=int, default=100_000, help="step budget of every run")
    args = p.parse_args()
    args.out_dir = str(HERE / "results")
    raise SystemExit(stiff_command(args))
