"""``panel-deploy calibrate RECORDING.mcap ...``: wiring of reading the
recordings, the fit, the calibrated scene and its plot."""

from __future__ import annotations

import sys

import yaml

from ..build import build_model
from ..calibrate import calibrate, parameters, read_measured
from ..calibrate.collisions import first_collisions
from ..calibrate.fit import Iteration
from ..calibrate.scene_out import calibrated_data
from ..record.analysis import recorded_scene
from ..scene import scene_from_dict
from ..validate import write_atomic


def calibrate_command(args) -> int:
    """``--free-vibration``: :func:`~.free_vibration.free_vibration_command`.
    Otherwise fit ``--fit`` (damping, stiffness, drag; ``--per`` scale or group) to
    the recordings' joint states and write the calibrated scene to ``--out``
    (and ``--plot``). The scene is ``--scene`` or the one the first recording
    ran, ``--set`` applied. Exit 0 when the fit converged, 1 when it did not,
    130 when interrupted (the best fit so far is still written); 2 for a
    recording that cannot be fitted, before any simulation."""
    if args.free_vibration:
        from .free_vibration import free_vibration_command
        return free_vibration_command(args)
    _, scene = recorded_scene(args.recordings[0], args.scene, args.namespace, args.set or ())
    model = build_model(scene)
    fitted = parameters(model, tuple(args.fit.split(",")), args.per)
    runs = [read_measured(path, scene, model, args.namespace, args.until)
            for path in args.recordings]
    # A recording that cannot be fitted is refused before the first simulation.
    result = calibrate(fitted, runs, scene.simulation, noise=scene.collision.noise,
                       max_evaluations=args.max_evaluations,
                       progress=None if args.quiet else _progress_line)
    collisions = first_collisions(result, scene)
    data = calibrated_data(scene, result, collisions)
    scene_from_dict(data, source=args.out)  # what is written must load as a scene
    text = (f"# Calibrated by panel-deploy calibrate from {', '.join(map(str, args.recordings))}\n"
            + yaml.safe_dump(data, sort_keys=False))
    write_atomic(args.out, lambda f: f.write(text), "--out")
    if args.plot:
        from ..calibrate.plot import plot_calibration
        plot_calibration(result, args.plot, collisions=collisions)
    for run in runs:
        for note in run.notes:
            print(f"panel-deploy: note: {note}", file=sys.stderr)
    print("\n".join(summary_lines(result, args.out, collisions)))
    for warning in result.warnings:
        print(f"panel-deploy: warning: {warning}", file=sys.stderr)
    if result.status == 3:
        return 130
    return 0 if result.success else 1


def _collision(event) -> str:
    if event is None:
        return "none"
    return f"{event['pair'][0]} - {event['pair'][1]} at {event['t']:.4f} s after release"


def _progress_line(it: Iteration) -> None:
    values = "  ".join(f"{name} {value:.5g}" for name, value in it.values.items())
    offsets = ", ".join(f"{off:.5f}" for off in it.offsets)
    print(f"calibrate  it {it.iteration:3d}  cost {it.cost:.6g}  {values}  release {offsets} s  "
          f"simulations {it.simulations}  {it.elapsed:6.1f} s", file=sys.stderr, flush=True)


def summary_lines(result, out, collisions) -> list:
    """What the fit found, one line per parameter and recording, and the first
    collisions, for stdout."""
    u = result.uncertainty
    lines = [f"{result.message} ({result.iterations} iterations, {result.simulations} "
             f"simulations, {result.wall_time:.1f} s)"]
    for i, name in enumerate(result.parameters.names):
        line = f"  {name}: {result.values[i]:.6g} (nominal {result.parameters.nominal[i]:.6g})"
        if name in result.problems:
            line += ", not identifiable" + (" (held)" if name in result.held else "")
        elif u is not None:
            _, lower, upper = u.of(name)
            line += f", 95 % interval {lower:.6g} .. {upper:.6g}"
        lines.append(line)
    for run, off, event in zip(result.residuals.runs, result.offsets, collisions["measured"]):
        lines.append(f"  {run.path}: released {off:.5f} s after its first stamp, "
                     f"{len(run.t)} joint states of {len(run.hinges)} hinges, "
                     f"first collision {_collision(event)}")
    lines.append(f"  fitted model: first collision {_collision(collisions['fitted'])}")
    lines.append(f"residual RMS {result.residual_rms * 1e3:.3g} mrad -> {out}")
    return lines
