"""``panel-deploy bench work-precision SCENE``: error against run time, every integrator and MuJoCo."""

from __future__ import annotations

from ..bench.work_precision import plot, work_precision, work_precision_text, write_csv
from ..build import build_model
from .args import scene_of


def work_precision_command(args) -> int:
    """Measure, print the table and ratios, write ``args.out`` (CSV) and ``args.plot`` (PNG)."""
    scene = scene_of(args)
    report = work_precision(build_model(scene), scene.simulation, collision=scene.collision,
                            quick=args.quick, repeats=args.repeats, verbose=True)
    write_csv(report, args.out)
    plot(report, args.plot)
    print(work_precision_text(report))
    print(f"wrote {args.out} and {args.plot}")
    return 0
