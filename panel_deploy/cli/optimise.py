"""``panel-deploy optimise SCENE``: wiring of optimise, verify, snap, tolerance check, record."""

from __future__ import annotations

import json
import sys
from dataclasses import replace
from functools import partial

from ..build import build_model
from ..errors import SceneError
from ..optimise.io import dump_result, load_stiffness, result_to_dict, save_result
from ..optimise.manufacture import snap_to_springs, tolerance_check, verify
from ..optimise.search import optimise, print_progress
from ..progress import Progress
from .args import scene_of


def optimise_command(args) -> int:
    """Run the optimisation the scene describes (``--set`` and its aliases
    ``--method``, ``--max-evaluations``, ``--workers`` applied); exit code 0 if
    it found a feasible K (collision-free, reaching flat) and the independent
    re-check of that K agrees, else 1; 130 when interrupted (the best K so far
    is still written). With ``fold.circuit: auto``, a circuit that gives no
    design is followed by the next-ranked ones (:func:`optimise_ranked`).

    - ``out`` [--out RESULT.yaml]: result file; without it the YAML goes to stdout.
    - ``record`` [--record FILE.mcap]: then record the deployment of the result.
    - ``dask`` [--dask ADDRESS]: Dask scheduler to run the evaluations on.
    - ``start`` [--start RESULT.yaml]: start from this result's K instead of
      the scene's ``optimisation.k0`` (to go on from an earlier search).
    - ``springs`` [--springs 0.07,0.1]: available spring stiffnesses (N m/rad);
      snap the optimum to them (up to two in parallel, hinges ten times softer
      than the rest unsprung) and re-verify.
    - ``perturb`` [--perturb N]: re-simulate N copies with k and c off by up to
      ``perturb_tol`` [--perturb-tol 0.05] and count the collision-free ones.
    - ``quiet`` [--quiet]: no progress lines and no re-check line on stderr.
    - ``json`` [--json]: print a one-object JSON summary instead of the YAML.
    """
    if args.record and not args.out:
        raise SceneError("--record", "needs --out RESULT.yaml: the recording deploys the K written there")
    scene = scene_of(args, parallel=True)
    if args.record:
        from ..record.deployment import check_recordable, record_optimum
        check_recordable(scene)
    code, scene = optimise_ranked(args, scene)
    if args.record and code != 130:
        record_optimum(args.record, scene, args.out)
        print(f"recorded the deployment of {args.out} -> {args.record}", file=sys.stderr)
    return code


def _option(args, name, default=None):
    """``args.name``, or ``default`` for a namespace without it (the tests pass partial ones)."""
    return getattr(args, name, default)


def optimise_ranked(args, scene) -> tuple:
    """:func:`optimise_scene` on ``scene``; when ``fold.circuit: auto`` chose
    its circuit, then on the next-ranked circuits in turn while no design
    passes (exit code 1), up to ``optimisation.circuits`` circuits in all.
    Returns ``(exit code, the scene of the last circuit optimised)``."""
    from ..ranking import next_ranked

    for _ in range(scene.optimisation.circuits - 1):
        code, why = optimise_scene(args, scene)
        following = next_ranked(scene, why) if code == 1 else None
        if following is None:
            return code, scene
        print(f"panel-deploy: note: circuit {scene.fold.circuit} gave no design ({why}); "
              f"optimising circuit {following.fold.circuit}, ranked "
              f"{following.fold.circuit_choice['rank']} ({following.fold.circuit_choice['outcome']})",
              file=sys.stderr)
        scene = following
    return optimise_scene(args, scene)[0], scene


def optimise_scene(args, scene) -> tuple:
    """:func:`optimise_command` on a loaded ``scene``, without the recording and
    the next-ranked circuits: ``(exit code, why no design)``, the reason empty
    unless the exit code is 1."""
    arg = partial(_option, args)

    model = build_model(scene)
    quiet = arg("quiet", False)
    budget = scene.optimisation.max_evaluations
    with Progress(budget, "optimise", "evaluations", enabled=not quiet) as bar:
        def report(p):
            if bar.live:
                bar.update(p.nfev - bar.done, phase=p.phase, best_f=f"{p.best_f:+.5f}",
                           feasible="yes" if not p.collision and p.reached_flat else "no")
            else:
                print_progress(p, sys.stderr, budget)
        result = optimise(model, scene, dask_address=arg("dask"),
                          progress=None if quiet else report,
                          k0=load_stiffness(arg("start"), model) if arg("start") else None)
    circuit = scene.fold.circuit
    extra = {"circuit": circuit if isinstance(circuit, int) else [list(c) for c in circuit]}
    if scene.fold.circuit_choice is not None:
        extra["circuit_choice"] = scene.fold.circuit_choice
    if result.status == 3:
        return save_interrupted(result, arg("out"), scene.name, extra), ""
    try:
        return check_and_write(args, model, scene, result, extra)
    except KeyboardInterrupt:
        # The search's K stands whatever check the signal cut short: saved
        # with the checks done so far, as an interrupted result.
        result = replace(result, status=3, message=(
            f"interrupted during the checks after the search ({result.message})"))
        return save_interrupted(result, arg("out"), scene.name, extra), ""


def save_interrupted(result, out, scene_name, extra) -> int:
    """Write an interrupted ``result`` (to ``out``, or stdout) without more
    checks, which a further wait would risk; exit code 130."""
    if out:
        save_result(result, out, scene_name, extra)
        print(f"{result.message} -> {out}", file=sys.stderr)
    else:
        print(dump_result(result, scene_name, extra), end="")
    return 130


def check_and_write(args, model, scene, result, extra) -> tuple:
    """The re-check, ``--springs`` and ``--perturb`` of a finished search's
    ``result``; writes the result with them (into ``extra``) and returns the
    exit code of :func:`optimise_command` and, for exit code 1, why the
    result is no design (the search's message or the re-check's verdict)."""
    arg = partial(_option, args)

    quiet = arg("quiet", False)
    check = verify(model, result.k, scene, c=result.c)
    extra["verification"] = {"tighten": 10.0, "refine": 2, **check.to_dict()}
    lines = [verdict("re-check (rtol / 10, twice the samples)", check)]
    springs = arg("springs")
    if springs:
        values = [float(s) for s in springs.split(",")] if isinstance(springs, str) else springs
        snap = snap_to_springs(result.k, values)
        # Each hinge keeps the optimum's c/k (its lubricant) on the snapped spring.
        built = verify(model, snap.k, scene, tighten=1.0, refine=1,
                       c=result.c / result.k * snap.k)
        extra["manufacture"] = {
            "springs": values,
            "hinges": {name: {"k": float(k), "springs": list(s), "zeroed": bool(z)}
                       for name, k, s, z in zip(result.problem.hinge_names, snap.k,
                                                snap.springs, snap.zeroed)},
            **built.to_dict()}
        lines.append(verdict("snapped to the springs", built))
    n = arg("perturb")
    if n:
        tol = arg("perturb_tol")
        tol = 0.05 if tol is None else tol  # 0 is a request (exact copies), not "default"
        with Progress(n, "tolerance check", "copies", enabled=not quiet) as bar:
            report = tolerance_check(model, result.k, scene, c=result.c, n=n, stiffness_tol=tol,
                                     damping_tol=tol, dask_address=arg("dask"),
                                     progress=lambda done: bar.update(done - bar.done))
        extra["tolerance"] = report.to_dict()
        lo, hi = report.feasible_interval()
        lines.append(f"{report.feasible} of {n} copies with k and c within +-{tol * 100:g} % collision-free "
                     f"and flat (95 % interval of the feasible fraction {lo * 100:.0f}-{hi * 100:.0f} %)")
    out = arg("out")
    if out:
        save_result(result, out, scene.name, extra)
    written = result_to_dict(result, scene.name, extra)
    if arg("json", False):
        print(json.dumps(written))
    elif not out:
        print(dump_result(result, scene.name, extra), end="")
    else:
        damping = (f", c/k {result.c[0] / result.k[0]:.4g} s" if result.problem.damping_variable
                   else "")
        print(f"{result.message}: f = {result.f:.5f}{damping}, nfev {result.nfev}, "
              f"{result.wall_time:.1f} s -> {out}")
    if out and not arg("json", False):
        print("\n".join(lines))
    elif not quiet:
        print("\n".join(lines), file=sys.stderr)
    if result.status == 2 and not quiet:
        print(next_steps(result, out), file=sys.stderr)
    # A K the search found feasible counts only if the independent re-check agrees.
    if not written["success"]:
        return 1, written["message"]
    return (0, "") if check.outcome.feasible else (1, lines[0])


def verdict(label, check) -> str:
    """One line on a check of a K (an :class:`Evaluation` of :func:`verify`)."""
    o = check.outcome
    head = f"{label}: "
    if not o.simulated:
        return head + f"the simulation failed ({o.message})"
    if o.collided:
        fc = o.first_collision
        return head + (f"collision at {fc['t']:.4f} s between {fc['pair'][0]} and {fc['pair'][1]}, "
                       f"approach speed {o.v:.3f} m/s")
    if not o.reached_flat:
        return head + f"collision-free but never flat (closest {o.flat_residual:.3f} rad)"
    press = f", fastest press {o.press_speed:.3g} m/s" if o.press_speed > 0 else ""
    return head + f"collision-free and flat, d = {o.d * 1e3:.3g} mm{press}"


def next_steps(result, out) -> str:
    """What a user can try when the search found no feasible K (status 2)."""
    start = f"--start {out} " if out else ""
    steps = [f"more evaluations (--max-evaluations), or a local search from the best K "
             f"({start}--method local)"]
    if not result.problem.damping_variable:
        steps.append("letting the search choose one c/k for all hinges "
                     "(--set \"optimisation.damping_ratio_bounds=[lo,hi]\", s), which widens a "
                     "thin feasible set (docs/findings.md, optimisation and damping)")
    return "no feasible K: try " + "; or ".join(steps)
