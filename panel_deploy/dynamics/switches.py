"""Contact switches of the tree hinges: where a hinge crosses theta = 0 or pi
and Eq. (4) changes the torque law, located so that no step straddles one
(the integrators of :mod:`.integrate`; see its docstring for which are left
alone, and why)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from . import hinges
from ._jit import FLOAT_MATH

#: Switches closer than this fraction of a step to either end are not relocated.
EDGE = 1e-3


@njit(cache=True, **FLOAT_MATH)
def modes(theta):
    out = np.empty(theta.shape[0], dtype=np.int64)
    for i in range(theta.shape[0]):
        out[i] = hinges.contact_mode(theta[i])
    return out


@njit(cache=True, **FLOAT_MATH)
def boundary(m_old, m_new):
    return 0.0 if min(m_old, m_new) == 0 else math.pi


@njit(cache=True, **FLOAT_MATH)
def hermite(th0, w0, th1, w1, h, s):
    """Cubic Hermite interpolant of theta at fraction s of a step of length h."""
    s2 = s * s
    s3 = s2 * s
    return ((2 * s3 - 3 * s2 + 1) * th0 + (s3 - 2 * s2 + s) * h * w0
            + (-2 * s3 + 3 * s2) * th1 + (s3 - s2) * h * w1)


def locates(P, settings) -> bool:
    """Whether a run locates the contact switches: ``settings.events``, and the
    stops of the paper's law (``P.stop_ramp`` 0), whose torque jumps at the
    switch; with a ramp it has no kink there to locate."""
    return bool(settings.events) and P.stop_ramp == 0.0


@njit(cache=True, **FLOAT_MATH)
def first_switch(n, y0, y1, h, tol):
    """Fraction of the step (0..1) at which the first tree hinge changes contact
    mode, by bisection on the cubic Hermite interpolant of theta; 2.0 if none.

    Crossings that stay within ``tol`` (rad) of the limit are ignored: the kink
    they cause is below the integration tolerance, and a hinge held on its limit
    (e.g. locked by the loop at the singular stowed state) crosses it at
    round-off amplitude on every step.
    """
    best = 2.0
    for i in range(n):
        m0 = hinges.contact_mode(y0[i])
        m1 = hinges.contact_mode(y1[i])
        if m0 == m1:
            continue
        b = boundary(m0, m1)
        g0 = y0[i] - b
        if max(abs(g0), abs(y1[i] - b)) <= tol:
            continue
        lo, hi = 0.0, 1.0
        for _ in range(50):
            mid = 0.5 * (lo + hi)
            g = hermite(y0[i], y0[n + i], y1[i], y1[n + i], h, mid) - b
            if (g > 0) == (g0 > 0):
                lo = mid
            else:
                hi = mid
        best = min(best, hi)
    return best


def refine_switch(sol, n, y_old, y_new, t_old, t_new, frac):
    """Switch time from the solver's own dense output (better than the Hermite guess)."""
    from scipy.optimize import brentq

    m0 = modes(y_old[:n])
    m1 = modes(y_new[:n])
    best = t_old + frac * (t_new - t_old)
    for i in np.flatnonzero(m0 != m1):
        b = boundary(m0[i], m1[i])
        g = lambda t: sol(t)[i] - b  # noqa: E731
        if np.sign(g(t_old)) != np.sign(g(t_new)):
            best = min(best, brentq(g, t_old, t_new, xtol=1e-14))
    return best
