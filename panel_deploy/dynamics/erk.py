"""Explicit embedded Runge-Kutta 5(4) pairs of seven stages, the last at the
step's end and the next step's first (FSAL), one step at a time, for the
compiled loop of :mod:`.compiled`. A pair is data (:class:`Pair`, in
:data:`PAIRS`): one step function and one compiled loop serve them all.

- ``dopri5``: Dormand and Prince (1980), scipy RK45's tableau.
- ``tsit5``: Tsitouras (2011), "Runge-Kutta pairs of order 5(4) satisfying
  only the first column simplifying assumption", Comput. Math. Appl. 62,
  770-775 (Table 1; the digits of OrdinaryDiffEq.jl's ``Tsit5``). Its fifth
  order solution's leading error terms are smaller than Dormand and Prince's:
  at the same tolerance it takes fewer steps, its stability region reaches
  3.5 against 3.3 along the negative real axis, and its error estimate is its
  own (docs/findings.md 5 measures both on the larger arrays).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from . import kernels
from ._jit import FLOAT_MATH


class Pair(NamedTuple):
    """A 5(4) pair of seven stages, FSAL.

    ``A`` (7, 6): rows 1-5 the stages' coefficients, row 6 the fifth-order
    weights (stage 7 is f at the step's end, so its weight is 0); row 0 and the
    upper triangle are zero. The sixth stage is at the step's end too (its
    coefficients sum to 1), which :func:`stiffness_ratio` needs.
    ``E`` (7,): weights of the error estimate, the difference of the two
    orders' solutions over h.
    ``stiff_ratio``: Hairer's test for a step at the stability limit: h |lambda|
    above this, just inside where the stability region leaves the negative
    real axis.
    """

    A: np.ndarray
    E: np.ndarray
    stiff_ratio: float


def _pair(rows, weights, error, stiff_ratio):
    A = np.zeros((7, 6))
    for i, row in enumerate(rows, start=1):
        A[i, :len(row)] = row
    A[6] = weights
    return Pair(A, np.array(error), stiff_ratio)


DOPRI5 = _pair(
    [[1 / 5],
     [3 / 40, 9 / 40],
     [44 / 45, -56 / 15, 32 / 9],
     [19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729],
     [9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656]],
    [35 / 384, 0.0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84],
    [71 / 57600, 0.0, -71 / 16695, 71 / 1920, -17253 / 339200, 22 / 525, -1 / 40],
    3.25)  # the edge at 3.31, Hairer's DOPRI5 code

TSIT5 = _pair(
    [[0.161],
     [-0.008480655492356989, 0.335480655492357],
     [2.8971530571054935, -6.359448489975075, 4.3622954328695815],
     [5.325864828439257, -11.748883564062828, 7.4955393428898365, -0.09249506636175525],
     [5.86145544294642, -12.92096931784711, 8.159367898576159, -0.071584973281401,
      -0.028269050394068383]],
    [0.09646076681806523, 0.01, 0.4798896504144996, 1.379008574103742, -3.290069515436081,
     2.324710524099774],
    [-0.00178001105222577714, -0.0008164344596567469, 0.007880878010261995, -0.1447110071732629,
     0.5823571654525552, -0.45808210592918697, 1 / 66],
    3.45)  # the edge at 3.51

#: Every pair by its ``simulation.method`` name.
PAIRS = {"dopri5": DOPRI5, "tsit5": TSIT5}


@njit(cache=True, **FLOAT_MATH)
def step(P, y, f, h, pair, K, scratch):
    """One step of length h of ``pair``; returns (y1, err, y6) and leaves
    rhs(y1) in K[6] and rhs(y6) in K[5]; y6 is the sixth stage's state, at
    the step's end like y1, for :func:`stiffness_ratio` (``scratch``: the
    run's :func:`kernels.scratch`)."""
    A, E = pair.A, pair.E
    N = y.shape[0]
    K[0] = f
    yi = np.empty(N)
    for st in range(1, 6):
        for i in range(N):
            s = y[i]
            for q in range(st):
                s += h * A[st, q] * K[q, i]
            yi[i] = s
        K[st] = kernels.rhs(P, yi, scratch)
    y1 = np.empty(N)
    for i in range(N):
        s = y[i]
        for q in range(6):
            s += h * A[6, q] * K[q, i]
        y1[i] = s
    K[6] = kernels.rhs(P, y1, scratch)
    err = np.empty(N)
    for i in range(N):
        s = 0.0
        for q in range(7):
            s += h * E[q] * K[q, i]
        err[i] = s
    return y1, err, yi


@njit(cache=True, **FLOAT_MATH)
def stiffness_ratio(K, y1, y6, h, m):
    """h |lambda| of the step just taken, estimated from its two evaluations
    at the step's end (Hairer & Wanner, Solving ODEs II, IV.2, and their
    DOPRI5 code): h ||f(y1) - f(y6)|| / ||y1 - y6|| over the first m
    components (the angles and rates: the energy integrals after them feed
    nothing back); 0 where y1 and y6 agree."""
    num = 0.0
    den = 0.0
    for i in range(m):
        num += (K[6, i] - K[5, i]) ** 2
        den += (y1[i] - y6[i]) ** 2
    return h * (num / den) ** 0.5 if den > 0.0 else 0.0
