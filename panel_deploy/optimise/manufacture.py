"""From an optimum to hinges that can be built: snapping, re-verification, tolerance.

The paper (section 4) rounded the optimised stiffnesses up to springs it
could make (some hinges carry two springs in parallel) and built the hinges
more than ten times softer than the rest with no spring at all.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field, replace

import numpy as np

from ..errors import OptimisationError
from .evaluate import damping_ratio, evaluate, run_deployment
from .parallel import Evaluator, Job, make_backend


@dataclass(frozen=True)
class SpringAssignment:
    """Buildable stiffness of every hinge.

    Attributes
    ----------
    k : (n_hinges,) ndarray
        Snapped stiffness, N m/rad (0 for hinges built without a spring).
    springs : tuple of tuple of float
        The springs in parallel at each hinge (empty for k = 0).
    zeroed : (n_hinges,) bool ndarray
        Hinges set to zero for being much softer than the rest.
    capped : (n_hinges,) bool ndarray
        Hinges whose optimum exceeds the stiffest combination (given that).
    """

    k: np.ndarray
    springs: tuple
    zeroed: np.ndarray
    capped: np.ndarray


def soft_hinges(k, zero_ratio=10.0) -> np.ndarray:
    """Hinges more than ``zero_ratio`` times softer than all the others.

    The largest set S such that ``zero_ratio * max(k[S]) < min(k[not S])``
    (S may be empty; the stiffest hinge is never in S). Boolean mask.
    """
    k = np.asarray(k, dtype=float)
    order = np.argsort(k, kind="stable")
    ks = k[order]
    cut = 0
    for m in range(1, len(k)):
        if zero_ratio * ks[m - 1] < ks[m]:
            cut = m
    mask = np.zeros(len(k), dtype=bool)
    mask[order[:cut]] = True
    return mask


def snap_to_springs(k, springs, *, max_parallel=2, zero_ratio=10.0, mode="up") -> SpringAssignment:
    """Round each hinge's stiffness to a combination of available springs.

    Parameters
    ----------
    k : (n_hinges,) array_like
        Optimised stiffness, N m/rad.
    springs : sequence of float
        Stiffness of the springs that can be made, N m/rad (each usable
        more than once); springs in parallel add up.
    max_parallel : int
        Most springs one hinge can carry.
    zero_ratio : float or None
        Hinges more than this many times softer than all the others get no
        spring (:func:`soft_hinges`); None keeps every hinge sprung.
    mode : "up" or "nearest"
        "up" (the paper) takes the softest combination at least k (the
        stiffest combination if none is); "nearest" the closest in log k.

    Raises
    ------
    OptimisationError
        Empty or non-positive ``springs``, bad ``max_parallel`` or ``mode``.
    """
    springs = sorted(float(s) for s in springs)
    if not springs or springs[0] <= 0:
        raise OptimisationError(f"springs: expected a non-empty list of stiffnesses > 0 N m/rad, "
                                f"got {springs!r}")
    if not isinstance(max_parallel, int) or max_parallel < 1:
        raise OptimisationError(f"max_parallel: expected an integer >= 1, got {max_parallel!r}")
    if mode not in ("up", "nearest"):
        raise OptimisationError(f"mode: expected up or nearest, got {mode!r}")
    k = np.asarray(k, dtype=float)
    combos = sorted({c for r in range(1, max_parallel + 1)
                     for c in itertools.combinations_with_replacement(springs, r)},
                    key=lambda c: (sum(c), len(c)))
    values = np.array([sum(c) for c in combos])
    zeroed = soft_hinges(k, zero_ratio) if zero_ratio is not None else np.zeros(len(k), bool)
    out_k, out_springs = np.zeros(len(k)), []
    capped = np.zeros(len(k), dtype=bool)
    for i, ki in enumerate(k):
        if zeroed[i] or ki <= 0:
            out_springs.append(())
            continue
        if mode == "up":
            above = np.nonzero(values >= ki * (1 - 1e-12))[0]
            j = above[0] if above.size else len(values) - 1
            capped[i] = not above.size
        else:
            j = int(np.argmin(np.abs(np.log(values / ki))))
        out_k[i] = values[j]
        out_springs.append(combos[j])
    return SpringAssignment(out_k, tuple(out_springs), zeroed, capped)


def verify(model, k, scene, *, tighten=10.0, refine=2, c=None, evaluation=run_deployment):
    """Re-simulate K independently: tolerances / ``tighten``, samples x ``refine``.

    Returns the :class:`~panel_deploy.optimise.evaluate.Evaluation` under
    the tighter settings (rtol and atol divided by ``tighten``, max_step
    unchanged, ``(samples - 1) * refine + 1`` samples).
    """
    sim = scene.simulation
    finer = scene.replace(simulation=replace(
        sim, rtol=sim.rtol / tighten, atol=sim.atol / tighten,
        samples=(sim.samples - 1) * int(refine) + 1))
    return evaluate(model, k, finer, c=c, evaluation=evaluation)


@dataclass
class ToleranceReport:
    """How many of N perturbed copies of K stay collision-free and reach flat.

    ``stiffness_tol`` and ``damping_tol`` are the relative half-widths of the
    uniform perturbations applied independently to every hinge.
    """

    n: int
    stiffness_tol: float
    damping_tol: float
    collision_free: int
    reached_flat: int
    feasible: int
    evaluations: list = field(repr=False, default_factory=list)

    def feasible_interval(self, confidence=0.95) -> tuple:
        """Clopper-Pearson interval of the fraction of built copies that deploy.

        With 20 of 20 copies feasible the fraction is at least 0.83 at 95 %
        confidence, not 1: the count alone overstates what it shows.
        """
        from scipy.stats import binomtest  # scipy.stats takes ~0.3 s to import; only needed here

        ci = binomtest(self.feasible, self.n).proportion_ci(confidence, method="exact")
        return float(ci.low), float(ci.high)

    def to_dict(self) -> dict:
        return {"n": self.n, "stiffness_tol": self.stiffness_tol, "damping_tol": self.damping_tol,
                "collision_free": self.collision_free, "reached_flat": self.reached_flat,
                "feasible": self.feasible, "feasible_interval_95": list(self.feasible_interval())}


def tolerance_check(model, k, scene, *, c=None, n=20, stiffness_tol=0.05, damping_tol=0.05,
                    seed=0, workers=None, dask_address=None,
                    evaluation=run_deployment, progress=None) -> ToleranceReport:
    """Re-simulate ``n`` copies of K with every k and c off by up to the tolerances.

    Each hinge gets ``k (1 + e_k)`` and ``c (1 + e_c)`` with e_k, e_c
    drawn uniformly from ``[-stiffness_tol, stiffness_tol]`` and
    ``[-damping_tol, damping_tol]``; ``c`` (N m s/rad, per hinge) defaults
    to beta k with beta the model's c/k. Runs on the same backends as
    :func:`~panel_deploy.optimise.search.optimise`. ``progress``, if given,
    is called with the number of copies done after each batch.
    """
    if not isinstance(n, int) or n < 1:
        raise OptimisationError(f"n: expected an integer >= 1, got {n!r}")
    for name, tol in (("stiffness_tol", stiffness_tol), ("damping_tol", damping_tol)):
        if not 0 <= tol < 1:
            raise OptimisationError(f"{name}: expected a fraction in [0, 1), got {tol!r}")
    k = np.asarray(k, dtype=float)
    c = damping_ratio(model) * k if c is None else np.asarray(c, dtype=float)
    rng = np.random.default_rng(seed)
    ks = [k * (1 + rng.uniform(-stiffness_tol, stiffness_tol, k.shape)) for _ in range(n)]
    cs = [c * (1 + rng.uniform(-damping_tol, damping_tol, c.shape)) for _ in range(n)]
    backend = make_backend(Job(model, scene, evaluation),
                           scene.optimisation.workers if workers is None else workers,
                           dask_address)
    # Batches of a few per worker: enough to keep them busy, small enough to report.
    batch = 2 * max(1, getattr(backend, "workers", 1))
    evaluator = Evaluator(backend, n)
    evs = []
    try:
        for i in range(0, n, batch):
            evs += evaluator.map(ks[i:i + batch], cs[i:i + batch])
            if progress is not None:
                progress(len(evs))
    finally:
        backend.close()
    return ToleranceReport(n, stiffness_tol, damping_tol,
                           sum(not e.outcome.collided and e.outcome.simulated for e in evs),
                           sum(e.outcome.reached_flat for e in evs),
                           sum(e.outcome.feasible for e in evs), evs)
