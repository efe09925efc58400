"""One step of the Rosenbrock-W method ROS34PW2, compiled, for the deployment ODE.

ROS34PW2 (Rang & Angermann, BIT 45, 2005): 4 stages, order 3 with an embedded
order-2 solution, L-stable, stiffly accurate, and a W-method: its order does
not depend on the matrix J used in ``W = I - h gamma J``. So J need only
hold the stiff terms, for stability: :func:`kernels.stiff_jacobian` gives
them at about the cost of one RHS call, against 2 n calls for a
finite-difference Jacobian (which, reused over steps to save them, went
stale at contact changes and forced ~1e-6 s steps on the paper scene).

Why a linearly implicit method: the paper scene's stiff modes are overdamped
(real eigenvalues down to about -7e4 1/s from the penalty dampers c_M, c_N
acting on light bodies, and -2e4 1/s from the contact dampers c_s), so an
explicit method is held to steps of ~4e-5 s by stability, not accuracy.

Structure used: the Jacobian of ``y = (theta, omega, E_diss, W_c)`` is
``[[0, I, 0], [A, B, 0], [0, 0, 0]]`` with ``A = d qdd / d theta``, ``B = d
qdd / d omega`` (the energy rows feed nothing back and are taken as zero,
which a W-method allows). Then ``W [x; v] = [r_x; r_v]`` reduces to the n x n
system ``(I - h gamma B - h^2 gamma^2 A) v = r_v + h gamma A r_x``, ``x = r_x
+ h gamma v``.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from . import kernels

GAMMA = 4.3586652150845900e-01
_ALPHA = np.array([
    [0.0, 0.0, 0.0],
    [8.7173304301691801e-01, 0.0, 0.0],
    [8.4457060015369423e-01, -1.1299064236484185e-01, 0.0],
    [0.0, 0.0, 1.0],
])
_GAMMA = np.array([
    [0.0, 0.0, 0.0],
    [-8.7173304301691801e-01, 0.0, 0.0],
    [-9.0338057013044082e-01, 5.4180672388095326e-02, 0.0],
    [2.4212380706095346e-01, -1.2232505839045147e+00, 5.4526025533510214e-01],
])
_B = np.array([2.4212380706095346e-01, -1.2232505839045147e+00, 1.5452602553351020e+00,
               4.3586652150845900e-01])
_B_HAT = np.array([3.7810903145819369e-01, -9.6042292212423178e-02, 5.0000000000000000e-01,
                   2.1793326075422950e-01])
#: Order of the embedded solution: the error estimate is O(h^3).
ERROR_ORDER = 3


@njit(cache=True)
def lu_factor(S):
    """In-place LU with partial pivoting of a small dense matrix; returns (LU, piv, ok).

    Plain loops: for n ~ 10 a LAPACK call costs more in overhead than the
    ~n^3/3 flops.
    """
    n = S.shape[0]
    piv = np.arange(n)
    for k in range(n):
        p = k
        big = abs(S[k, k])
        for i in range(k + 1, n):
            if abs(S[i, k]) > big:
                big = abs(S[i, k])
                p = i
        if big == 0.0 or not np.isfinite(big):
            return S, piv, False
        if p != k:
            for j in range(n):
                S[k, j], S[p, j] = S[p, j], S[k, j]
            piv[k], piv[p] = piv[p], piv[k]
        inv = 1.0 / S[k, k]
        for i in range(k + 1, n):
            S[i, k] *= inv
            l = S[i, k]
            if l != 0.0:
                for j in range(k + 1, n):
                    S[i, j] -= l * S[k, j]
    return S, piv, True


@njit(cache=True)
def lu_solve(LU, piv, b, x):
    """Write to x (n,) the solution of ``S x = b`` from lu_factor's (LU, piv); b is not changed."""
    n = LU.shape[0]
    for i in range(n):
        x[i] = b[piv[i]]
    for i in range(n):
        for k in range(i):
            x[i] -= LU[i, k] * x[k]
    for i in range(n - 1, -1, -1):
        for k in range(i + 1, n):
            x[i] -= LU[i, k] * x[k]
        x[i] /= LU[i, i]


@njit(cache=True)
def _solve_w(n, hg, A, LU, piv, r, z, work):
    """Write to z the solution of ``(I - hg J) z = r`` for the block Jacobian of the
    module docstring; work is (n,) scratch."""
    for i in range(n):
        s = 0.0
        for j in range(n):
            s += A[i, j] * r[j]
        work[i] = r[n + i] + hg * s
    lu_solve(LU, piv, work, z[n:2 * n])
    for i in range(n):
        z[i] = r[i] + hg * z[n + i]
    for i in range(2 * n, r.shape[0]):
        z[i] = r[i]


@njit(cache=True)
def _jac_times(n, A, B, u, out):
    """Write J u for the block Jacobian to out[:2 n] (its energy rows are zero)."""
    for i in range(n):
        out[i] = u[n + i]
        s = 0.0
        for j in range(n):
            s += A[i, j] * u[j] + B[i, j] * u[n + j]
        out[n + i] = s


@njit(cache=True)
def step(P, y, f, h, A, B, K):
    """One ROS34PW2 step of length h from y (f = rhs(P, y)) with Jacobian blocks A, B.

    Stages go to K (4, N). Returns (y1, err, ok): the order-3 solution, the
    difference to the embedded order-2 one, and False if ``W`` is singular
    (the caller shortens the step).
    """
    n = P.n
    N = y.shape[0]
    hg = h * GAMMA
    S = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            S[i, j] = -hg * B[i, j] - hg * hg * A[i, j]
        S[i, i] += 1.0
    LU, piv, ok = lu_factor(S)
    if not ok:
        return y.copy(), np.full(N, np.inf), False
    # scratch allocated once per step, not per stage: small-array allocations
    # cost more than the arithmetic here
    yi = np.empty(N)
    r = np.empty(N)
    u = np.empty(N)
    Ju = np.empty(2 * n)
    work = np.empty(n)
    for st in range(4):
        if st == 0:
            fi = f
        else:
            for i in range(N):
                s = y[i]
                for q in range(st):
                    if _ALPHA[st, q] != 0.0:
                        s += _ALPHA[st, q] * K[q, i]
                yi[i] = s
            fi = kernels.rhs(P, yi)
        for i in range(N):
            r[i] = h * fi[i]
        if st > 0:
            for i in range(N):
                s = 0.0
                for q in range(st):
                    s += _GAMMA[st, q] * K[q, i]
                u[i] = s
            _jac_times(n, A, B, u, Ju)
            for i in range(2 * n):
                r[i] += h * Ju[i]
        _solve_w(n, hg, A, LU, piv, r, K[st], work)
    y1 = np.empty(N)
    err = np.empty(N)
    for i in range(N):
        s = y[i]
        e = 0.0
        for q in range(4):
            s += _B[q] * K[q, i]
            e += (_B[q] - _B_HAT[q]) * K[q, i]
        y1[i] = s
        err[i] = e
    return y1, err, True
