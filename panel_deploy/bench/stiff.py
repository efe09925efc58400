"""Stiff and ill-conditioned cases: does every integrator succeed, or fail loudly?

Each case is the base model with one thing pushed to an extreme (contact
stiffness k_s, penalty stiffness k_M = k_N (also overdamped), no damping, a 200:1 spread of hinge
stiffness, no or 10 g gravity, a 1000:1 mass ratio, bigger arrays). Every
integrator runs every case from the exactly folded stowed state (a singular
configuration of the closed loop, docs/findings.md); the outcome is
success, or ``success=False`` with a message. A run that "succeeds" with a
non-finite state is reported as silent failure, the one outcome that must
never happen.

Errors are the largest |theta - theta_ref| (rad) over the samples against a
tight reference of the same case (:func:`reference`).
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from ..model import Model
from ..scene import INTEGRATORS, SimulationSection


@dataclass(frozen=True)
class StiffCase:
    """A named variant of a base model. ``make`` maps the base model to it."""

    name: str
    description: str
    make: Callable[[Model], Model]


@dataclass
class Outcome:
    """One integrator on one case.

    ``status``: "ok", "FAIL" (success False with a message) or "SILENT"
    (reported success with a non-finite or truncated trajectory).
    """

    case: str
    method: str
    status: str
    error: float
    wall_time: float
    nfev: int
    nsteps: int
    message: str


def _with(model: Model, **changes) -> Model:
    return dataclasses.replace(model, **changes)


def _closure(model: Model, **changes) -> Model:
    return _with(model, closure=dataclasses.replace(model.closure, **changes))


def _heavy(model: Model, factor: float) -> Model:
    """The body farthest down the tree ``factor`` times heavier (mass and inertia)."""
    b = model.order[-1]
    body = model.bodies[b]
    heavy = dataclasses.replace(body, mass=body.mass * factor, inertia=body.inertia * factor)
    return _with(model, bodies=model.bodies[:b] + (heavy,) + model.bodies[b + 1:])


def _split_stiffness(model: Model, soft: float, stiff: float) -> Model:
    """Hinges on the ground body at ``soft``, every other at ``stiff`` (c follows k)."""
    k = np.array([soft if model.ground in (h.body_a, h.body_b) else stiff for h in model.hinges])
    c_over_k = np.array([h.c / h.k if h.k > 0 else 0.0 for h in model.hinges])
    return model.with_stiffness(k, c_over_k * k)


def _undamped(model: Model) -> Model:
    m = model.with_stiffness(model.stiffness, np.zeros(len(model.hinges)))
    return _closure(_with(m, c_s=0.0), c_M=0.0, c_N=0.0)


def stiff_cases(full: bool = True) -> list[StiffCase]:
    """The suite; ``full=False`` keeps one case per kind at the extremes."""
    k_s = (1e2, 1e3, 1e4, 1e5, 1e6) if full else (1e2, 1e6)
    k_M = (1e3, 1e4, 1e5, 1e6, 1e7, 1e8) if full else (1e3, 1e8)
    g = lambda m, f: _with(m, gravity=m.gravity * f)  # noqa: E731
    cases = [StiffCase("folded start", "base model from the exactly folded (singular) state",
                       lambda m: m)]
    cases += [StiffCase(f"k_s={v:.0e}", f"contact stiffness k_s = {v:g} N m/rad",
                        lambda m, v=v: _with(m, k_s=v)) for v in k_s]
    cases += [StiffCase(f"k_M={v:.0e}", f"penalty stiffness k_M = k_N = {v:g} N/m",
                        lambda m, v=v: _closure(m, k_M=v, k_N=v)) for v in k_M]
    cases += [
        StiffCase("k_M=1e8 c_M=2e4", "penalty k_M = k_N = 1e8 N/m, overdamped c_M = c_N = 2e4 N s/m: "
                  "a fast decaying mode (about -c_M / m ~ -1e6 1/s), the classic stiff case",
                  lambda m: _closure(m, k_M=1e8, k_N=1e8, c_M=2e4, c_N=2e4)),
        StiffCase("undamped", "c = c_s = c_M = c_N = 0", _undamped),
        StiffCase("k 0.001/0.2", "hinges on the ground 0.001, others 0.2 N m/rad (c follows k)",
                  lambda m: _split_stiffness(m, 0.001, 0.2)),
        StiffCase("g=0", "no gravity", lambda m: g(m, 0.0)),
        StiffCase("g=10g", "ten times gravity", lambda m: g(m, 10.0)),
        StiffCase("mass x1000", "last body in the tree 1000 times heavier",
                  lambda m: _heavy(m, 1000.0)),
    ]
    return cases if full else [c for c in cases if c.name not in ("g=0", "k 0.001/0.2")]


def _classify(result) -> str:
    finite = np.all(np.isfinite(result.theta)) and np.all(np.isfinite(result.omega))
    if result.success:
        return "ok" if finite else "SILENT"
    return "FAIL" if result.message else "SILENT"


def reference(model: Model, base: SimulationSection, rtol: float = 1e-10,
              max_steps: int = 200_000):
    """A tight reference of ``model``: DOP853 at ``rtol``, else Radau at rtol 1e-8.

    Radau is the fallback, not the first choice, and at no tighter than 1e-8:
    below that its Newton iteration stalled (step budget spent within the
    first 10 us) on the paper scene's folded start and on k_M = 1e8. Returns
    the result (check ``success``).
    """
    from ..dynamics.simulate import simulate

    for method, tol in (("DOP853", rtol), ("Radau", max(rtol, 1e-8))):
        ref = simulate(model, dataclasses.replace(base, method=method, rtol=tol, atol=tol * 1e-2),
                       max_steps=max_steps)
        if ref.success:
            break
    return ref


def run_case(model: Model, base: SimulationSection, case: StiffCase, methods=INTEGRATORS,
             max_steps: int = 100_000, verbose: bool = False,
             reference_rtol: float = 1e-10) -> list[Outcome]:
    """Every method on one case, with its error against :func:`reference`.

    ``max_steps`` is every run's step budget: a method that needs more fails
    (loudly, "step budget exhausted"), which is how an explicit method meets
    a stiffness it cannot step over at an affordable cost.
    """
    from ..dynamics.simulate import simulate

    m = case.make(model)
    ref = reference(m, base, reference_rtol, max_steps=2 * max_steps)
    out = []
    for method in methods:
        start = time.perf_counter()
        r = simulate(m, dataclasses.replace(base, method=method), max_steps=max_steps)
        wall = time.perf_counter() - start
        status = _classify(r)
        if status == "ok" and r.theta.shape[0] != base.samples:
            status = "SILENT"
        error = math.nan
        if status == "ok" and ref.success:
            error = float(np.abs(r.theta - ref.theta).max())
        out.append(Outcome(case.name, method, status, error, wall, r.nfev, r.nsteps,
                           r.message or ""))
        if verbose:
            print(f"  {case.name:14} {method:9} {status:6} err {error:9.2e} "
                  f"{wall:8.3f} s {r.nfev:8d} fev  {r.message}", flush=True)
    if not ref.success:
        out.append(Outcome(case.name, "reference", _classify(ref), math.nan, ref.wall_time,
                           ref.nfev, ref.nsteps, ref.message))
    return out


def run_suite(models: dict, base: SimulationSection, cases, methods=INTEGRATORS,
              max_steps: int = 100_000, verbose: bool = False,
              reference_rtol: float = 1e-10) -> list[Outcome]:
    """``models``: label -> Model. Every case runs on the first model; the
    other models (bigger arrays) run as they are."""
    (label, first), *others = models.items()
    out = []
    for case in cases:
        out += run_case(first, base, case, methods, max_steps, verbose, reference_rtol)
    for label, model in others:
        out += run_case(model, base, StiffCase(label, f"{label} array", lambda m: m), methods,
                        max_steps, verbose, reference_rtol)
    return out


def table(outcomes, fmt: str = "markdown") -> str:
    """Case x method outcome table: status, error, wall time, nfev."""
    methods = list(dict.fromkeys(o.method for o in outcomes))
    cases = list(dict.fromkeys(o.case for o in outcomes))
    cell = {(o.case, o.method): o for o in outcomes}

    def text(o):
        if o is None:
            return "-"
        if o.status != "ok":
            return f"{o.status} ({o.wall_time:.2f} s, {o.nfev} fev)"
        return f"ok {o.error:.1e} rad, {o.wall_time:.2f} s, {o.nfev} fev"

    if fmt == "markdown":
        lines = ["| case | " + " | ".join(methods) + " |",
                 "|---" * (len(methods) + 1) + "|"]
        lines += ["| " + c + " | " + " | ".join(text(cell.get((c, m))) for m in methods) + " |"
                  for c in cases]
        failures = [o for o in outcomes if o.status != "ok"]
        if failures:
            lines.append("")
            lines += [f"- {o.case} / {o.method}: {o.status}: {o.message}" for o in failures]
        return "\n".join(lines)
    raise ValueError(f"table: unknown format {fmt!r}")


def write_csv(outcomes, path, flag: str = "--out-dir") -> None:
    import csv

    from ..validate import write_atomic
    names = [f.name for f in dataclasses.fields(Outcome)]

    def write(f):
        w = csv.writer(f)
        w.writerow(names)
        for o in outcomes:
            w.writerow([getattr(o, n) for n in names])
    write_atomic(path, write, flag)


def array_models(scene, sizes) -> tuple[dict, list]:
    """Models of ``scene``'s array resized to each (rows, cols) of ``sizes``.

    The fold is the first circuit (in :func:`panel_deploy.fold.circuits` order)
    that packs into two stacks, with its first cell as ground and automatic
    merging. Returns ``({label: Model}, [notes, one per size])``.
    """
    from ..build import build_model
    from ..errors import PanelDeployError
    from ..fold import designs

    models, notes = {}, []
    for rows, cols in sizes:
        label = f"{rows}x{cols}"
        resized = scene.replace(array=dataclasses.replace(scene.array, rows=rows, cols=cols),
                                fold=dataclasses.replace(scene.fold, circuit=0, ground=None))
        start = time.perf_counter()
        try:
            index = next((i for i, d in designs(rows, cols) if d.stowed is not None), None)
            if index is None:
                notes.append(f"{label}: no circuit packs into two stacks")
                continue
            resized = resized.replace(fold=dataclasses.replace(resized.fold, circuit=index))
            models[label] = build_model(resized)
        except PanelDeployError as e:
            notes.append(f"{label}: not built ({e})")
            continue
        notes.append(f"{label}: circuit {index}, built in {time.perf_counter() - start:.1f} s, "
                     f"{models[label].n_bodies} bodies, {models[label].n_coords} joints, "
                     f"{len(models[label].cut_hinges)} cut hinge(s)")
    return models, notes


def write_suite(scene, out_dir, *, quick: bool = False, t_end: float = 0.3,
                sizes=((6, 6), (8, 8)), max_steps: int = 100_000) -> str:
    """Run the suite on ``scene`` (and its array resized to ``sizes``) and write
    ``out_dir``/stiff_cases{,_quick}.{csv,md}; returns the table with its header.

    ``quick`` runs the extreme values only; ``t_end`` (s) is every run's end,
    sampled every ms; ``max_steps`` the step budget of every run.
    """
    from ..build import build_model
    from ..validate import write_atomic

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)  # before the work, not after it
    base = dataclasses.replace(scene.simulation, t_end=t_end, samples=int(round(t_end / 1e-3)) + 1)
    models = {scene.name or "base": build_model(scene)}
    bigger, notes = array_models(scene, sizes)
    models.update(bigger)
    cases = stiff_cases(full=not quick)
    outcomes = run_suite(models, base, cases, max_steps=max_steps, verbose=True)
    header = [f"# Stiff-case suite: {scene.name}, t_end = {t_end:g} s, "
              f"rtol {base.rtol:g}, atol {base.atol:g}, step budget {max_steps}, "
              "error against a DOP853 (else Radau) reference at rtol 1e-10", ""]
    header += [f"- {c.name}: {c.description}" for c in cases]
    header += [f"- {n}" for n in notes] + [""]
    text = "\n".join(header) + "\n" + table(outcomes)
    stem = "stiff_cases_quick" if quick else "stiff_cases"
    write_atomic(out / f"{stem}.md", lambda f: f.write(text + "\n"), "--out-dir")
    write_csv(outcomes, out / f"{stem}.csv")
    return text
