"""The scene and sampling options of the stiffness scans (scan_stiffness.py, search_fidelity.py)."""

from __future__ import annotations

import argparse

import numpy as np

from panel_deploy.bench.sampling import group_limits, latin_hypercube, neighbourhood
from panel_deploy.build import build_model
from panel_deploy.optimise import StiffnessProblem, load_stiffness
from panel_deploy.scene import load_scene, resolve_scene


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
