"""The search space: hinge groups sharing one stiffness, bounds, start point.

The solvers work on ``x = log10 k`` per group. Stiffness bounds span
decades (paper: 0.001 to 0.2 N m/rad) and the paper's optimum has hinges ten
times softer than the rest, so equal steps in log k are equal relative
changes of the spring, which is what the deployment responds to (time
scales go as 1/sqrt(k)).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import OptimisationError


@dataclass(frozen=True)
class StiffnessProblem:
    """Groups of hinges, bounds and start point of one optimisation.

    Build with :meth:`from_model`, which validates everything.

    Attributes
    ----------
    groups : tuple of tuple of int
        Hinge indices sharing one stiffness; every hinge is in exactly one group.
    hinge_names : tuple of str
    bounds : (float, float)
        Lower and upper stiffness, N m/rad, 0 < lower < upper.
    k0 : (n_groups,) ndarray
        Starting stiffness of every group, N m/rad.
    """

    groups: tuple
    hinge_names: tuple
    bounds: tuple
    k0: np.ndarray

    @classmethod
    def from_model(cls, model, bounds, k0, groups=None) -> "StiffnessProblem":
        """Validate and build.

        Parameters
        ----------
        model : Model
        bounds : (lower, upper)
            N m/rad.
        k0 : float, (n_groups,) or (n_hinges,) array_like
            N m/rad. Per hinge (e.g. a previous result's K), the hinges of
            one group must agree.
        groups : sequence of sequence of (int or str), optional
            Hinge indices or names sharing one stiffness; hinges in no group
            get a group of their own. Default:
            ``model.metadata["hinge_groups"]``, else one group per hinge.

        Raises
        ------
        OptimisationError
            Naming the field (``bounds``, ``k0``, ``groups[i]``).
        """
        names = tuple(h.name for h in model.hinges)
        groups = _check_groups(groups if groups is not None
                               else model.metadata.get("hinge_groups"), names)
        lo, hi = _check_bounds(bounds)
        k0 = np.asarray(k0, dtype=float)
        if k0.ndim == 0:
            k0 = np.full(len(groups), float(k0))
        elif k0.shape == (len(names),):
            k0 = _per_group(k0, groups, names)
        if k0.shape != (len(groups),):
            raise OptimisationError(f"k0: expected one value, {len(groups)} (one per group) or "
                                    f"{len(names)} (one per hinge), got shape {k0.shape}")
        if not np.all(np.isfinite(k0)) or np.any(k0 < lo) or np.any(k0 > hi):
            raise OptimisationError(f"k0: {np.array2string(k0, precision=4)} N m/rad is outside "
                                    f"bounds [{lo:g}, {hi:g}]")
        return cls(groups, names, (lo, hi), k0)

    @property
    def n(self) -> int:
        """Number of variables (groups)."""
        return len(self.groups)

    @property
    def x_bounds(self) -> list:
        """Bounds of x = log10 k, one (lower, upper) per group."""
        lo, hi = self.bounds
        return [(math.log10(lo), math.log10(hi))] * self.n

    def k_of(self, x) -> np.ndarray:
        """Stiffness per hinge (N m/rad), shape (n_hinges,), of x = log10 k per group."""
        lo, hi = self.bounds
        kg = np.clip(10.0 ** np.asarray(x, dtype=float), lo, hi)
        k = np.empty(len(self.hinge_names))
        for g, idx in enumerate(self.groups):
            k[list(idx)] = kg[g]
        return k

    def x_of(self, k) -> np.ndarray:
        """log10 of each group's stiffness from a per-hinge (or per-group) K."""
        k = np.asarray(k, dtype=float)
        kg = k if k.shape == (self.n,) else np.array([k[idx[0]] for idx in self.groups])
        return np.log10(kg)

    def group_names(self) -> list:
        """Hinge names of every group."""
        return [[self.hinge_names[i] for i in g] for g in self.groups]


def _per_group(k, groups, names):
    """One value per group from per-hinge ``k``, whose group members must agree."""
    for gi, idx in enumerate(groups):
        for i in idx[1:]:
            if not math.isclose(k[i], k[idx[0]], rel_tol=1e-9):
                raise OptimisationError(
                    f"k0: hinges {names[idx[0]]} and {names[i]} share groups[{gi}] but start at "
                    f"{k[idx[0]]:g} and {k[i]:g} N m/rad")
    return np.array([k[idx[0]] for idx in groups])


def _check_bounds(bounds):
    try:
        lo, hi = (float(b) for b in bounds)
    except (TypeError, ValueError):
        raise OptimisationError(f"bounds: expected [lower, upper] in N m/rad, got {bounds!r}") from None
    if not (math.isfinite(lo) and math.isfinite(hi)):
        raise OptimisationError(f"bounds: expected finite numbers, got [{lo:g}, {hi:g}]")
    if lo >= hi:
        raise OptimisationError(f"bounds: lower bound {lo:g} must be below upper bound {hi:g}")
    if lo <= 0:
        raise OptimisationError(f"bounds: lower bound must be > 0 N m/rad (the search is in "
                                f"log k; a zero spring comes from snap_to_springs), got {lo:g}")
    return lo, hi


def _check_groups(groups, names):
    n = len(names)
    if groups is None:
        return tuple((i,) for i in range(n))
    index = {name: i for i, name in enumerate(names)}
    seen = {}
    out = []
    for gi, group in enumerate(groups):
        if isinstance(group, (str, int)):
            raise OptimisationError(f"groups[{gi}]: expected a list of hinges, got {group!r}")
        members = []
        for h in group:
            if isinstance(h, str):
                if h not in index:
                    raise OptimisationError(f"groups[{gi}]: no hinge named {h!r} "
                                            f"(hinges are: {', '.join(names)})")
                i = index[h]
            elif isinstance(h, (int, np.integer)) and not isinstance(h, bool) and 0 <= h < n:
                i = int(h)
            else:
                raise OptimisationError(f"groups[{gi}]: {h!r} is not a hinge index 0..{n - 1} "
                                        f"or hinge name")
            if i in seen:
                raise OptimisationError(f"groups[{gi}]: hinge {names[i]!r} is already in "
                                        f"groups[{seen[i]}]")
            seen[i] = gi
            members.append(i)
        if not members:
            raise OptimisationError(f"groups[{gi}]: empty group (a group needs at least one hinge)")
        out.append(tuple(sorted(members)))
    out += [(i,) for i in range(n) if i not in seen]
    return tuple(sorted(out))
