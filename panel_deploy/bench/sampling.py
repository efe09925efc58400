"""Stiffness sets to scan: Latin hypercubes over a box in log10 k per hinge group.

Used by ``bench/scan_stiffness.py`` and ``bench/search_fidelity.py`` (their
options in ``bench/scan_args.py``); the box is the scene's bounds, narrowed
per group (:func:`group_limits`), or a neighbourhood of a result's K
(:func:`neighbourhood`).
"""

from __future__ import annotations

import numpy as np
from scipy.stats import qmc

from ..errors import OptimisationError


def neighbourhood(problem, k, spread):
    """Box of log10 k within ``spread`` decades of ``k``, clipped to the bounds.

    Parameters
    ----------
    problem : StiffnessProblem
    k : (n_hinges,) array_like
        N m/rad, e.g. from :func:`~panel_deploy.optimise.load_stiffness`.
    spread : float
        Half-width in decades of k (0.1 is about +-26 %).

    Returns
    -------
    lo, hi : (n_groups,) ndarray
        log10 of N m/rad.
    """
    if not spread > 0:
        raise OptimisationError(f"spread: expected a half-width > 0 in decades, got {spread!r}")
    x = problem.x_of(np.asarray(k, dtype=float))
    if not np.all(np.isfinite(x)):
        raise OptimisationError("k: a zero stiffness has no log10 neighbourhood")
    lo, hi = np.log10(problem.bounds)
    return np.clip(x - spread, lo, hi), np.clip(x + spread, lo, hi)


def group_limits(problem, items, default) -> np.ndarray:
    """Per-group stiffness limits (N m/rad) from ``HINGE=K`` items, else ``default``.

    ``HINGE`` is the name of any hinge of the group.
    """
    limits = np.full(problem.n, float(default))
    for item in items:
        name, _, value = item.partition("=")
        hits = [g for g, idx in enumerate(problem.groups)
                if name in (problem.hinge_names[i] for i in idx)]
        if not hits:
            raise OptimisationError(f"{item}: no hinge named {name!r} "
                                    f"(hinges: {', '.join(problem.hinge_names)})")
        try:
            limits[hits[0]] = float(value)
        except ValueError:
            raise OptimisationError(f"{item}: expected HINGE=K with K in N m/rad, "
                                    f"got K = {value!r}") from None
    return limits


def latin_hypercube(problem, lo, hi, n, seed=0) -> list:
    """``n`` per-hinge stiffness sets (N m/rad), a Latin hypercube in the log10 box [lo, hi]."""
    x = lo + (hi - lo) * qmc.LatinHypercube(d=problem.n, seed=seed).random(n)
    return [problem.k_of(xi) for xi in x]
