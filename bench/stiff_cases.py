"""Stiff-case suite: every integrator on every extreme case, ok or loud failure.

    python bench/stiff_cases.py [SCENE] [--quick] [--t-end 0.3] [--sizes 6x6 8x8]

Writes bench/results/stiff_cases{,_quick}.{csv,md} and prints the outcome table.
"""

import argparse
import sys
from pathlib import Path

from panel_deploy.bench.stiff import write_suite
from panel_deploy.errors import PanelDeployError
from panel_deploy.scene import load_scene, resolve_scene

HERE = Path(__file__).resolve().parent


def size(text):
    try:
        rows, cols = text.lower().split("x")
        return int(rows), int(cols)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected ROWSxCOLS, got {text!r}") from None


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scene", nargs="?", default="paper_4x4", help="scene file or shipped name")
    p.add_argument("--quick", action="store_true", help="extreme values only")
    p.add_argument("--t-end", type=float, default=0.3, help="s")
    p.add_argument("--sizes", type=size, nargs="*", default=[(6, 6), (8, 8)],
                   help="bigger arrays to run as they are, e.g. 6x6 8x8")
    p.add_argument("--max-steps", type=int, default=100_000, help="step budget of every run")
    args = p.parse_args()
    try:
        print(write_suite(load_scene(resolve_scene(args.scene)), HERE / "results", quick=args.quick,
                          t_end=args.t_end, sizes=args.sizes, max_steps=args.max_steps))
    except PanelDeployError as e:
        sys.exit(f"stiff_cases: {e}")
