"""Error against run time for every integrator, with MuJoCo as the peer (issue 3).

For each of our integrators and a sweep of tolerances, and for MuJoCo on the
exported model (:mod:`panel_deploy.export.mjcf`) at a sweep of fixed steps,
the run is timed (median of repeats) and its hinge angles are compared, sample
by sample over the valid window, with a converged reference of the same
model in the same simulator:

* ours: DOP853 at a tight tolerance; a second reference at ten times that
  tolerance measures how well the first is converged (``reference_spread``,
  the conditioning figure: no error below it means anything);
* MuJoCo: RK4 at a step below the smallest of the sweep (self-convergence),
  checked the same way with a step twice as large.

Errors are the largest |theta - theta_ref| over samples and hinges (rad,
``max_error``) and at the window's end (``final_error``). ``ours_vs_mujoco``
is the same distance between the two references: how far the two models'
trajectories are from each other (penalty closure and limits against
MuJoCo's soft constraints; see the export's docstring).
"""

from __future__ import annotations

import csv
import math
import statistics
import time
from dataclasses import dataclass, field, replace

import numpy as np

from ..model import Model
from ..scene import INTEGRATORS, SimulationSection
from .mujoco_peer import run_mujoco

#: Every integrator but "compiled", which is one of tsit5 and ros34pw2.
SWEPT_METHODS = tuple(m for m in INTEGRATORS if m != "compiled")

SAMPLE_INTERVAL = 1e-3

FULL_RTOLS = (1e-2, 1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10)
QUICK_RTOLS = (1e-2, 1e-3, 1e-6)
#: Fixed window of ``--quick``, s (no collision probe).
QUICK_WINDOW = 0.1
FULL_STEPS = {"RK4": (1e-4, 5e-5, 2e-5, 1e-5, 5e-6, 2e-6, 1e-6),
              "implicitfast": (1e-3, 5e-4, 2e-4, 1e-4, 5e-5, 2e-5, 1e-5, 5e-6, 2e-6, 1e-6)}
QUICK_STEPS = {"RK4": (1e-4, 5e-5, 2e-5, 1e-5), "implicitfast": (1e-3, 1e-4, 1e-5)}


@dataclass
class Point:
    """One timed run: a solver at one setting.

    ``setting`` is rtol for ours, the time step (s) for MuJoCo. Errors in rad,
    NaN when the run failed; ``wall_time`` in s (median of the repeats).
    """

    simulator: str
    method: str
    setting: float
    wall_time: float
    nfev: int
    nsteps: int
    max_error: float
    final_error: float
    success: bool
    message: str


@dataclass
class WorkPrecision:
    """Everything one work-precision run measured."""

    window: float
    points: list
    reference_spread: float
    mujoco_reference_spread: float
    ours_vs_mujoco: float
    reference_wall_time: float
    notes: list = field(default_factory=list)


def _settings(base: SimulationSection, window: float, **kw) -> SimulationSection:
    samples = int(round(window / SAMPLE_INTERVAL)) + 1
    return replace(base, t_end=window, samples=samples, **kw)


def valid_window(model: Model, base: SimulationSection, collision=None, max_steps=2_000_000):
    """The valid part of the deployment: 0 .. last sample before the first collision, s.

    Probed with the scene's own integrator settings over its ``t_end``,
    sampled every ``SAMPLE_INTERVAL``, and checked by
    :func:`panel_deploy.collision.check_trajectory` (``collision``: the
    scene's collision section). Returns ``(window, note)``; the window is
    ``t_end`` if nothing collides.
    """
    from ..collision import check_trajectory
    from ..dynamics.simulate import simulate

    probe = simulate(model, _settings(base, base.t_end), max_steps=max_steps)
    report = check_trajectory(model, probe, collision)
    if report.first_collision is None:
        return float(probe.t[-1]), f"no collision up to {probe.t[-1]:g} s ({base.method} probe)"
    e = report.first_collision
    window = float(probe.t[report.n_valid - 1])
    return window, (f"first collision at {e.t:.4g} s ({e.names[0]} / {e.names[1]}, "
                    f"{base.method} rtol {base.rtol:g} probe): window 0..{window:g} s")


def _errors(theta, ref):
    """(max, final) |theta - ref| in rad; NaN if the run stopped early."""
    if theta.shape != ref.shape or not np.all(np.isfinite(theta)):
        return math.nan, math.nan
    diff = np.abs(theta - ref)
    return float(diff.max()), float(diff[-1].max())


def _timed(run, repeats):
    """Median wall time of ``repeats`` calls of ``run`` and the last result."""
    times, result = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        result = run()
        times.append(time.perf_counter() - start)
    return statistics.median(times), result


def reference_solution(model: Model, base: SimulationSection, window: float, rtol: float = 1e-11,
                       max_steps: int = 2_000_000):
    """Tight DOP853 reference and its spread against one at 10 x its rtol.

    Near round-off DOP853 can stop with "step size less than spacing between
    numbers" at a contact switch; the reference then loosens by 10 x (up to
    1e-8). Returns ``(result, spread in rad, wall time in s, rtol used)``.
    """
    from ..dynamics.simulate import simulate

    def run(tol):
        return simulate(model, _settings(base, window, method="DOP853", rtol=tol, atol=tol * 1e-2),
                        max_steps=max_steps)

    while True:
        start = time.perf_counter()
        ref = run(rtol)
        wall = time.perf_counter() - start
        loose = run(10 * rtol)
        if ref.success and loose.success:
            return ref, _errors(loose.theta, ref.theta)[0], wall, rtol
        if rtol >= 1e-8:
            raise RuntimeError(f"reference solution failed: {ref.message} / {loose.message}")
        rtol *= 10


def sweep_ours(model, base, window, methods, rtols, repeats, ref_theta, max_steps, verbose):
    """Time every method at every rtol (atol = rtol / 100) against ``ref_theta``.

    A method that fails at one rtol is not run at tighter ones (it would only
    burn its step budget again).
    """
    from ..dynamics.simulate import simulate

    points = []
    for method in methods:
        # the first call of a method compiles its kernels: keep it out of the timing
        simulate(model, _settings(base, window, method=method, rtol=1e-3, atol=1e-5),
                 max_steps=max_steps)
        for rtol in rtols:
            settings = _settings(base, window, method=method, rtol=rtol, atol=rtol * 1e-2)
            wall, r = _timed(lambda: simulate(model, settings, max_steps=max_steps), repeats)
            err, final = _errors(r.theta, ref_theta) if r.success else (math.nan, math.nan)
            points.append(Point("ours", method, rtol, wall, r.nfev, r.nsteps, err, final,
                                bool(r.success), r.message))
            _report(points[-1], verbose)
            if not r.success:
                break
    return points


def _report(p, verbose):
    if verbose:
        print(f"  {p.simulator:6} {p.method:12} {p.setting:8.1e} {p.wall_time:9.3f} s "
              f"err {p.max_error:9.2e}  {'ok' if p.success else p.message}", flush=True)


def sweep_mujoco(model, window, steps, repeats, ref_theta, verbose):
    """Time MuJoCo at every (integrator, step) of ``steps`` against ``ref_theta``."""
    samples = int(round(window / SAMPLE_INTERVAL)) + 1
    points = []
    for integrator, hs in steps.items():
        for h in hs:
            wall, r = _timed(lambda: run_mujoco(model, window, samples, h, integrator), repeats)
            err, final = _errors(r.theta, ref_theta) if r.success else (math.nan, math.nan)
            points.append(Point("mujoco", integrator, h, wall, 0, r.nsteps, err, final,
                                r.success, r.message))
            _report(points[-1], verbose)
    return points


def _front_time(points, target):
    """Log-log interpolated time to ``target`` on one method's Pareto front."""
    front, best = [], math.inf
    for p in sorted((p for p in points if p.success and math.isfinite(p.max_error)),
                    key=lambda p: p.wall_time):
        if p.max_error < best:
            front.append(p)
            best = p.max_error
    for i, p in enumerate(front):
        if p.max_error <= target:
            if i == 0 or p.max_error == target:
                return p.wall_time
            q = front[i - 1]
            s = (math.log(target) - math.log(q.max_error)) / (math.log(p.max_error) - math.log(q.max_error))
            return math.exp(math.log(q.wall_time) + s * (math.log(p.wall_time) - math.log(q.wall_time)))
    return math.nan


def time_at_error(points, target: float):
    """(wall time in s, method) of the cheapest method reaching ``max_error <= target``.

    Each method's own Pareto front (time ascending, error strictly falling)
    is interpolated linearly in log-log between its last point above
    ``target`` and its first at or below it (its cheapest point if that
    already reaches it); methods are not mixed. ``(nan, "")`` if none reaches it.
    """
    best = (math.nan, "")
    for method in dict.fromkeys(p.method for p in points):
        t = _front_time([p for p in points if p.method == method], target)
        if math.isfinite(t) and not t >= best[0]:
            best = (t, method)
    return best


def work_precision(model: Model, base: SimulationSection, *, window=None, collision=None,
                   quick=False, repeats=3, methods=SWEPT_METHODS, mujoco=True,
                   max_steps=50_000, verbose=False) -> WorkPrecision:
    """Run the whole work-precision sweep on ``model``; see the module doc.

    ``max_steps`` is the step budget of every run of ours (not the reference):
    a method needing more is recorded as failed at that tolerance. ``quick``
    sweeps fewer settings over ``QUICK_WINDOW`` with a looser reference, to
    finish in under two minutes. Without ``window`` (s) the full run compares
    over :func:`valid_window` (``collision``: the scene's collision section).
    """
    if window is not None:
        window_note = f"window 0..{window:g} s (given)"
    elif quick:
        window, window_note = QUICK_WINDOW, f"window 0..{QUICK_WINDOW:g} s (quick: fixed, no collision probe)"
    else:
        window, window_note = valid_window(model, base, collision)
    rtols = QUICK_RTOLS if quick else FULL_RTOLS
    steps = QUICK_STEPS if quick else FULL_STEPS
    ref, spread, ref_wall, ref_rtol = reference_solution(model, base, window, 1e-10 if quick else 1e-11)
    if verbose:
        print(window_note, flush=True)
        print(f"reference: DOP853 rtol {ref_rtol:g}, {ref_wall:.2f} s, "
              f"spread {spread:.2e} rad", flush=True)
    points = sweep_ours(model, base, window, methods, rtols, repeats, ref.theta, max_steps, verbose)
    mj_spread = ours_vs_mujoco = math.nan
    notes = [f"{window_note}; samples every {SAMPLE_INTERVAL:g} s",
             f"reference: DOP853 rtol {ref_rtol:g} (atol rtol/100), spread against rtol x10"]
    if mujoco:
        samples = ref.theta.shape[0]
        h_ref = min(min(hs) for hs in steps.values()) / 2
        mj_ref = run_mujoco(model, window, samples, h_ref, "RK4")
        mj_check = run_mujoco(model, window, samples, 2 * h_ref, "RK4")
        if mj_ref.success and mj_check.success:
            mj_spread = _errors(mj_check.theta, mj_ref.theta)[0]
            ours_vs_mujoco = _errors(ref.theta, mj_ref.theta)[0]
            if verbose:
                print(f"MuJoCo reference: RK4 step {h_ref:g} s, {mj_ref.wall_time:.2f} s, "
                      f"spread {mj_spread:.2e} rad", flush=True)
            points += sweep_mujoco(model, window, steps, repeats, mj_ref.theta, verbose)
        else:
            notes.append(f"MuJoCo reference at {h_ref:g} s failed: {mj_ref.message}")
    return WorkPrecision(window, points, spread, mj_spread, ours_vs_mujoco, ref_wall, notes)


def write_csv(report: WorkPrecision, path) -> None:
    """One row per point, with the window and reference figures repeated on every row."""
    from ..validate import write_atomic
    names = [f for f in Point.__dataclass_fields__]

    def write(f):
        w = csv.writer(f)
        w.writerow(names + ["window", "reference_spread", "mujoco_reference_spread", "ours_vs_mujoco"])
        for p in report.points:
            w.writerow([getattr(p, n) for n in names]
                       + [report.window, report.reference_spread, report.mujoco_reference_spread,
                          report.ours_vs_mujoco])
    write_atomic(path, write, "--out")


def plot(report: WorkPrecision, path) -> None:
    """Log-log max hinge-angle error against wall time, one line per solver."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 6))
    for key in dict.fromkeys((p.simulator, p.method) for p in report.points):
        pts = [p for p in report.points if (p.simulator, p.method) == key and p.success
               and math.isfinite(p.max_error) and p.max_error > 0]
        if pts:
            style = "--s" if key[0] == "mujoco" else "-o"
            ax.loglog([p.wall_time for p in pts], [p.max_error for p in pts], style,
                      label=f"{key[0]} {key[1]}")
    if math.isfinite(report.reference_spread) and report.reference_spread > 0:
        ax.axhline(report.reference_spread, color="grey", lw=0.8, ls=":",
                   label="reference spread (ours)")
    ax.set_xlabel("wall time, s (median)")
    ax.set_ylabel(f"max hinge-angle error over 0..{report.window:g} s, rad")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    from ..validate import save_figure
    try:
        save_figure(fig, path)
    finally:
        plt.close(fig)


def work_precision_text(report: WorkPrecision) -> str:
    """Text table and the time ratios against MuJoCo at 1e-3 and 1e-6 rad."""
    lines = [f"{'simulator':8} {'method':13} {'setting':>9} {'wall s':>9} {'nfev':>8} "
             f"{'steps':>8} {'max err':>9} {'final err':>9}  status"]
    for p in report.points:
        lines.append(f"{p.simulator:8} {p.method:13} {p.setting:9.1e} {p.wall_time:9.4f} "
                     f"{p.nfev:8d} {p.nsteps:8d} {p.max_error:9.2e} {p.final_error:9.2e}  "
                     f"{'ok' if p.success else 'FAIL: ' + p.message}")
    lines += report.notes
    lines.append(f"reference spread (DOP853, rtol x10): {report.reference_spread:.2e} rad; "
                 f"reference wall time {report.reference_wall_time:.2f} s")
    lines.append(f"MuJoCo reference spread (RK4, step x2): {report.mujoco_reference_spread:.2e} rad; "
                 f"ours vs MuJoCo (references): {report.ours_vs_mujoco:.2e} rad")
    ours = [p for p in report.points if p.simulator == "ours"]
    mj = [p for p in report.points if p.simulator == "mujoco"]
    t_mj3, m_mj3 = time_at_error(mj, 1e-3)
    for target in (1e-3, 1e-6):
        (t_ours, m_ours), (t_mj, m_mj) = time_at_error(ours, target), time_at_error(mj, target)
        lines.append(f"error {target:g} rad: ours {t_ours:.4g} s ({m_ours or 'none'}), MuJoCo "
                     f"{t_mj:.4g} s ({m_mj or 'not reached'}), ratio ours/MuJoCo {t_ours / t_mj:.3g}")
    t_ours6, m_ours6 = time_at_error(ours, 1e-6)
    lines.append(f"ours at 1e-6 rad / MuJoCo at 1e-3 rad: {t_ours6:.4g} / {t_mj3:.4g} s = "
                 f"{t_ours6 / t_mj3:.3g}")
    return "\n".join(lines)
