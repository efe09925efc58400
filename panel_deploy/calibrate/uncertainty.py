"""How well the data determine a fit: standard errors, 95 % intervals and
correlations from the Jacobian at the optimum, and which parameters the data
do not determine at all.

Linearised least squares: cov(x) = s^2 (J^T J)^-1 with s^2 the residual
variance ``sum r^2 / (m - p)``, so the noise assumed for the weights drops
out. Parameters fitted in log space (factors, C_d) get intervals
``exp(x +- q se_x)`` and a standard error ``value * se_x`` in their own
units; a release offset (s) ``x +- q se_x``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.stats import t as student_t

#: Singular values of the column-normalised Jacobian below this fraction of
#: the largest: a direction of parameter space the data do not see (the
#: finite differences are good to about 1e-2 of a column).
SINGULAR_TOL = 1e-3
#: |correlation| above this: two parameters the data cannot tell apart.
MAX_CORRELATION = 0.99
#: Relative standard error above this: the value says little.
MAX_RELATIVE_SE = 0.5


@dataclass(frozen=True)
class Uncertainty:
    """Standard errors and intervals of a fit's parameters.

    Attributes
    ----------
    names : tuple of str
    value : (p,) ndarray
        In the parameters' own units.
    se : (p,) ndarray
        Standard errors, own units.
    relative_se : (p,) ndarray
        se / |value| (for a log parameter: its standard error in log space).
    lower, upper : (p,) ndarray
        95 % interval, own units.
    correlation : (p, p) ndarray
    condition : float
        Condition number of the column-normalised Jacobian.
    problems : dict
        name -> why the data do not determine it (absent when they do).
    dof : int
        Residuals less parameters.
    """

    names: tuple
    value: np.ndarray
    se: np.ndarray
    relative_se: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    correlation: np.ndarray
    condition: float
    problems: dict
    dof: int

    @property
    def warnings(self) -> list:
        """One sentence per parameter the data do not determine."""
        return [warning(name, why) for name, why in self.problems.items()]

    def of(self, name: str) -> tuple:
        """``(standard error, lower, upper)`` of the parameter ``name``, own units."""
        i = self.names.index(name)
        return self.se[i], self.lower[i], self.upper[i]


def warning(name: str, why: str) -> str:
    """The sentence that says the data do not determine parameter ``name``, and why."""
    return f"{name} is not identifiable from these data: {why}"


def uncertainty(J, r, x, names, log) -> Uncertainty:
    """The :class:`Uncertainty` of a least-squares optimum ``x`` with
    residuals ``r`` and Jacobian ``J`` (m, p); ``log`` (p,) bool marks the
    parameters fitted as logarithms."""
    J, r, x = (np.asarray(a, dtype=float) for a in (J, r, x))
    log = np.asarray(log, dtype=bool)
    m, p = J.shape
    dof = max(m - p, 1)
    s2 = float(r @ r) / dof
    norms = np.linalg.norm(J, axis=0)
    scaled = J / np.where(norms > 0, norms, 1.0)
    U, sv, Vt = np.linalg.svd(scaled, full_matrices=False)
    condition = float(sv[0] / sv[-1]) if sv[-1] > 0 else np.inf
    # The pseudo-inverse drops unseen directions: their parameters are
    # reported as not identifiable, not given a huge but finite error.
    keep = sv > SINGULAR_TOL * sv[0]
    inverse = (Vt[keep].T / sv[keep] ** 2) @ Vt[keep]
    cov = s2 * inverse / np.outer(np.where(norms > 0, norms, 1.0), np.where(norms > 0, norms, 1.0))
    se_x = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    with np.errstate(divide="ignore", invalid="ignore"):
        correlation = cov / np.outer(se_x, se_x)
    correlation[~np.isfinite(correlation)] = 0.0
    np.fill_diagonal(correlation, 1.0)
    q = float(student_t.ppf(0.975, dof))
    # An interval of a parameter the data do not determine may overflow: inf is its answer.
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        value = np.where(log, np.exp(x), x)
        se = np.where(log, value * se_x, se_x)
        lower = np.where(log, np.exp(x - q * se_x), x - q * se_x)
        upper = np.where(log, np.exp(x + q * se_x), x + q * se_x)
        relative = np.where(log, se_x, se / np.abs(value))
    problems = _problems(names, norms, sv, Vt, keep, correlation, relative, log, condition)
    return Uncertainty(tuple(names), value, se, relative, lower, upper, correlation, condition,
                       problems, dof)


def _problems(names, norms, sv, Vt, keep, correlation, relative, log, condition) -> dict:
    problems = {}
    for i in np.flatnonzero(norms == 0):
        problems[names[i]] = "the residuals do not change with it at all"
    for k in np.flatnonzero(~keep):
        weights = np.abs(Vt[k])
        involved = [names[i] for i in np.argsort(-weights) if weights[i] > 0.1]
        direction = " and ".join(involved)
        for name in involved:
            problems.setdefault(name, f"only a combination of {direction} is determined "
                                      f"(singular value {sv[k] / sv[0]:.1e} of the largest, "
                                      f"condition number {condition:.3g})")
    p = len(names)
    for i in range(p):
        for j in range(i + 1, p):
            if abs(correlation[i, j]) > MAX_CORRELATION:
                why = (f"correlated with {{}} (r = {correlation[i, j]:+.4f}): the data "
                       "cannot tell the two apart")
                problems.setdefault(names[i], why.format(names[j]))
                problems.setdefault(names[j], why.format(names[i]))
    for i in range(p):
        if log[i] and relative[i] > MAX_RELATIVE_SE:
            problems.setdefault(names[i], f"relative standard error {relative[i] * 100:.0f} % "
                                          f"(above {MAX_RELATIVE_SE * 100:.0f} %)")
    return problems
