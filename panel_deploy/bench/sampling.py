"""Stiffness sets to scan: Latin hypercubes over a box in log10 k per hinge group.

Used by ``bench/scan_stiffness.py`` and ``bench/search_fidelity.py``; the box
is the scene's bounds, narrowed per group (``--min``/``--max``), or a
neighbourhood of a result's K (``--around``/``--spread``).
"""

from __future__ import annotations

import argparse

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


def add_arguments(parser: argparse.ArgumentParser, n: int, spread: float) -> None:
    """The scene and sampling options every scan takes (see :func:`sample`)."""
    parser.add_argument("scene", nargs="?", default="paper_4x4")
    parser.add_argument("--n", type=int, default=n, help="stiffness sets to sample")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--workers", type=int, default=0)
    parser.add_argument("--min", action="append", default=[], metavar="HINGE=K",
                        help="lower limit of that hinge's group, N m/rad")
    parser.add_argument("--max", action="append", default=[], metavar="HINGE=K",
                        help="upper limit of that hinge's group, N m/rad")
    parser.add_argument("--around", metavar="RESULT.yaml", help="sample near this result's K")
    parser.add_argument("--spread", type=float, default=spread, help="decades of k, with --around")
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")


def sample(args):
    """The stiffness sets ``args`` (of :func:`add_arguments`) ask for.

    Returns
    -------
    scene, model, problem
        As loaded and built from ``args.scene`` and ``args.set``.
    ks : list of (n_hinges,) ndarray
        N m/rad.
    box : (lo, hi)
        The sampled box, log10 of N m/rad per group.
    description : str
        One line saying what was sampled.
    """
    from ..build import build_model
    from ..optimise import StiffnessProblem, load_stiffness
    from ..scene import load_scene, resolve_scene

    scene = load_scene(resolve_scene(args.scene), args.set)
    model = build_model(scene)
    opt = scene.optimisation
    problem = StiffnessProblem.from_model(model, opt.bounds, opt.k0)
    if args.around:
        lo, hi = neighbourhood(problem, load_stiffness(args.around, model), args.spread)
        where = f"within {args.spread} decades of {args.around}"
    else:
        lo = np.log10(group_limits(problem, args.min, opt.bounds[0]))
        hi = np.log10(group_limits(problem, args.max, opt.bounds[1]))
        where = "scene bounds" + (" narrowed by --min/--max" if args.min or args.max else "")
    ks = latin_hypercube(problem, lo, hi, args.n, args.seed)
    return scene, model, problem, ks, (lo, hi), f"{args.n} K, Latin hypercube seed {args.seed}, {where}"
