"""The Dormand-Prince 5(4) pair (scipy RK45's tableau: stages A, weights B,
error weights E), one step at a time, for the compiled loop of
:mod:`.compiled`."""

from __future__ import annotations

import numpy as np
from numba import njit

from . import kernels
from ._jit import FLOAT_MATH

A = np.array([
    [0.0, 0.0, 0.0, 0.0, 0.0],
    [1 / 5, 0.0, 0.0, 0.0, 0.0],
    [3 / 40, 9 / 40, 0.0, 0.0, 0.0],
    [44 / 45, -56 / 15, 32 / 9, 0.0, 0.0],
    [19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729, 0.0],
    [9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656],
])
B = np.array([35 / 384, 0.0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84])
E = np.array([71 / 57600, 0.0, -71 / 16695, 71 / 1920, -17253 / 339200, 22 / 525, -1 / 40])


@njit(cache=True, **FLOAT_MATH)
def step(P, y, f, h, K, near):
    """One Dormand-Prince step of length h; returns (y1, err, y6) and leaves
    rhs(y1) in K[6] and rhs(y6) in K[5]; y6 is the sixth stage's state, at
    the step's end like y1, for :func:`stiffness_ratio` (``near``: the run's
    candidate list, :func:`panel_contact.near_pairs`)."""
    N = y.shape[0]
    K[0] = f
    yi = np.empty(N)
    for st in range(1, 6):
        for i in range(N):
            s = y[i]
            for q in range(st):
                s += h * A[st, q] * K[q, i]
            yi[i] = s
        K[st] = kernels.rhs(P, yi, near)
    y1 = np.empty(N)
    for i in range(N):
        s = y[i]
        for q in range(6):
            s += h * B[q] * K[q, i]
        y1[i] = s
    K[6] = kernels.rhs(P, y1, near)
    err = np.empty(N)
    for i in range(N):
        s = 0.0
        for q in range(7):
            s += h * E[q] * K[q, i]
        err[i] = s
    return y1, err, yi


#: Hairer's test for a DOPRI5 step at its stability limit: h |lambda| above
#: this (the stability region's edge on the negative real axis is at ~3.3).
STIFF_RATIO = 3.25


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
