"""Regenerate the sample recordings in bags/ (run from the repository root).

    python bench/make_bags.py

Two deployments of the paper scene, each recorded by ``panel-deploy simulate
--record`` (see bags/README.md): uniform stiffness, which collides, and an
optimised design that deploys flat without collision. Run it again whenever
the dynamics or collision code changes what these deployments do
(test/test_record_bags.py says so when it does).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from panel_deploy.cli import main

ROOT = Path(__file__).resolve().parent.parent

#: bag file -> panel-deploy arguments (paths relative to the repository root).
BAGS = {
    "bags/paper_4x4_uniform.mcap": ["simulate", "paper_4x4"],
    "bags/paper_4x4_feasible.mcap": ["simulate", "paper_4x4", "--set", "hinges.damping_ratio=0.19",
                                     "--stiffness", "bench/results/paper_4x4_damping019.yaml"],
}


def make_bags() -> int:
    for bag, args in BAGS.items():
        argv = [*args, "--record", bag]
        print("panel-deploy " + " ".join(argv), flush=True)
        sys.argv = ["panel-deploy", *argv]  # what the recording's "run" record names
        main(argv)
        size = (ROOT / bag).stat().st_size
        print(f"-> {bag}: {size / 1e6:.2f} MB\n", flush=True)
    return 0


if __name__ == "__main__":
    import os
    argparse.ArgumentParser(description=__doc__.splitlines()[0]).parse_args()
    os.chdir(ROOT)
    sys.exit(make_bags())
