"""The search space: hinge groups sharing one stiffness, bounds, start point.

The solvers work on ``x = log10 k`` per group. Stiffness bounds span
decades (paper: 0.001 to 0.2 N m/rad) and the paper's optimum has hinges ten
times softer than the rest, so equal steps in log k are equal relative
changes of the spring, which is what the deployment responds to (time
scales go as 1/sqrt(k)).

Damping follows stiffness, c = beta k (paper section 3.3). beta is the
model's c/k unless the damping ratio is a design variable too: the paper
(section 5) names lubricants of different viscosity in the hinges as the way
to control damping, so one beta shared by every hinge (one lubricant) is
then the last entry of x, as log10 beta.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import OptimisationError
from .evaluate import damping_ratio


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
    ratio : (n_hinges,) ndarray
        c/k of every hinge, s: the model's, or beta0 when the damping ratio
        is a variable.
    damping_bounds : (float, float) or None
        Lower and upper c/k (s), 0 < lower < upper, when the damping ratio
        shared by all hinges is a variable; None when c/k is the model's.
    """

    groups: tuple
    hinge_names: tuple
    bounds: tuple
    k0: np.ndarray
    ratio: np.ndarray
    damping_bounds: tuple | None = None

    @classmethod
    def from_model(cls, model, bounds, k0, groups=None,
                   damping_bounds=None) -> "StiffnessProblem":
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
            ``model.hinge_groups``, else one group per hinge.
        damping_bounds : (lower, upper), optional
            s. Makes one c/k shared by every hinge a variable, starting at
            the model's (median) c/k, which must lie within them.

        Raises
        ------
        OptimisationError
            Naming the field (``bounds``, ``k0``, ``groups[i]``,
            ``damping_ratio_bounds``).
        """
        names = tuple(h.name for h in model.hinges)
        groups = _check_groups(groups if groups is not None
                               else model.hinge_groups or None, names)
        lo, hi = _check_bounds(bounds, "bounds", "N m/rad")
        ratio = damping_ratio(model)
        if damping_bounds is not None:
            damping_bounds = _check_bounds(damping_bounds, "damping_ratio_bounds", "s")
            beta0 = float(np.median(ratio))
            # The model holds c = (c/k) k, and c / k gives back c/k only to
            # rounding: a scene's c/k on a bound (checked there) comes back an
            # ulp past it.
            if np.isclose(beta0, damping_bounds, rtol=1e-12, atol=0.0).any():
                beta0 = float(np.clip(beta0, *damping_bounds))
            if not damping_bounds[0] <= beta0 <= damping_bounds[1]:
                raise OptimisationError(
                    f"damping_ratio_bounds: the search starts from the hinges' c/k = {beta0:g} s "
                    f"(hinges.damping_ratio), which is outside [{damping_bounds[0]:g}, "
                    f"{damping_bounds[1]:g}]")
            ratio = np.full(len(names), beta0)
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
        return cls(groups, names, (lo, hi), k0, ratio, damping_bounds)

    @property
    def n(self) -> int:
        """Number of variables: the groups, plus one if the damping ratio is a variable."""
        return len(self.groups) + self.damping_variable

    @property
    def x0(self) -> np.ndarray:
        """The start point: log10 of K_0 per group (and of the start c/k),
        within :attr:`x_bounds` (c/k comes back from c = (c/k) k to rounding,
        and log10 of an array may round apart from log10 of a number)."""
        lo, hi = np.array(self.x_bounds).T
        return np.clip(self.x_of(self.k0, self.ratio[0] * self.k0), lo, hi)

    @property
    def x_bounds(self) -> list:
        """Bounds of x, one (lower, upper) per variable: log10 k per group, then log10 c/k."""
        out = [tuple(np.log10(self.bounds))] * len(self.groups)
        if self.damping_variable:
            out.append(tuple(np.log10(self.damping_bounds)))
        return out

    def k_of(self, x) -> np.ndarray:
        """Stiffness per hinge (N m/rad), shape (n_hinges,), of x."""
        lo, hi = self.bounds
        kg = np.clip(10.0 ** np.asarray(x[:len(self.groups)], dtype=float), lo, hi)
        k = np.empty(len(self.hinge_names))
        for g, idx in enumerate(self.groups):
            k[list(idx)] = kg[g]
        return k

    def c_of(self, x) -> np.ndarray:
        """Damping per hinge (N m s/rad), shape (n_hinges,), of x: c = beta k."""
        if not self.damping_variable:
            return self.ratio * self.k_of(x)
        beta = float(np.clip(10.0 ** float(x[-1]), *self.damping_bounds))
        return beta * self.k_of(x)

    def x_of(self, k, c=None) -> np.ndarray:
        """x of a per-hinge (or per-group) K and, if the damping ratio is a
        variable, its damping ``c`` (same shape as ``k``; its median c/k)."""
        k = np.asarray(k, dtype=float)
        kg = k if k.shape == (len(self.groups),) else np.array([k[idx[0]] for idx in self.groups])
        x = np.log10(kg)
        if not self.damping_variable:
            return x
        if c is None:
            raise OptimisationError("c: the damping ratio is a variable, so x needs the damping "
                                    "as well as K")
        beta = float(np.median(np.asarray(c, dtype=float) / k))
        return np.append(x, math.log10(beta))

    @property
    def damping_variable(self) -> bool:
        """The damping ratio shared by all hinges is searched for."""
        return self.damping_bounds is not None

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


def _check_bounds(bounds, name, unit):
    try:
        lo, hi = (float(b) for b in bounds)
    except (TypeError, ValueError):
        raise OptimisationError(f"{name}: expected [lower, upper] in {unit}, got {bounds!r}") from None
    if not (math.isfinite(lo) and math.isfinite(hi)):
        raise OptimisationError(f"{name}: expected finite numbers, got [{lo:g}, {hi:g}]")
    if lo >= hi:
        raise OptimisationError(f"{name}: lower bound {lo:g} must be below upper bound {hi:g}")
    if lo <= 0:
        raise OptimisationError(f"{name}: lower bound must be > 0 {unit} (the search is in "
                                f"log scale), got {lo:g}")
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
