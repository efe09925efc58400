"""One step of the Rosenbrock-W method ROS34PW2, compiled, for the deployment ODE.

ROS34PW2 (Rang & Angermann, BIT 45, 2005): 4 stages, order 3 with an embedded
order-2 solution, L-stable, stiffly accurate, and a W-method: its order does
not depend on the matrix J used in ``W = I - h gamma J``. So J need only
hold the stiff terms, for stability: :func:`stiff.stiff_jacobian` gives
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

With ``A = -M^-1 K``, ``B = -M^-1 C`` and K, C diagonal plus rank r
(:func:`stiff.stiff_terms`: hinge springs and contact on the diagonal, one
row per cut hinge and five more per penalty closure), that system times M is
``(M + h gamma C + h^2 gamma^2 K) v = ...``: the mass matrix plus a joint-space
diagonal, which the articulated-body algorithm factors in O(n), plus rank r,
added by the Woodbury identity: :func:`step_terms`, O(n r^2) per step with no
n x n matrix formed (for many rows, as a pressed stack's contact points, the
n x n matrix formed and factored instead), which the compiled loop takes where
:func:`articulated.applies`; else :func:`step` with the dense blocks, an
n x n LU per step. For the exact closure that W leaves out the constraint's
projection of A and B (the dense blocks hold it): a W-method's order does not
depend on its matrix, and the projection's own rates are the Baumgarte
terms' (1 / T: 1e3 1/s at the default T = 1 ms), below those of the hinge
stops and the panel contact that W holds (test_dynamics_articulated checks
the path against a dense reference).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from . import articulated, kernels, stiff
from ._jit import FLOAT_MATH

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


@njit(cache=True, **FLOAT_MATH)
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


@njit(cache=True, **FLOAT_MATH)
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


@njit(cache=True, **FLOAT_MATH)
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


@njit(cache=True, **FLOAT_MATH)
def _jac_times(n, A, B, u, out):
    """Write J u for the block Jacobian to out[:2 n] (its energy rows are zero)."""
    for i in range(n):
        out[i] = u[n + i]
        s = 0.0
        for j in range(n):
            s += A[i, j] * u[j] + B[i, j] * u[n + j]
        out[n + i] = s


@njit(cache=True, **FLOAT_MATH)
def terms(P, y, near):
    """The stiff Jacobian at y for :func:`step_terms`: (S, I6, Jb, hb, Kd, Cd,
    U, kk, cc), the terms of :func:`stiff.stiff_terms` with the joint screws S,
    the spatial inertias I6 of the mass matrix (:mod:`.articulated`) and the
    body inertias (Jb, hb) they are made of (:func:`kernels.body_inertias`)."""
    kin, Kd, Cd, U, kk, cc = stiff.stiff_terms(P, y, near)
    R, p, _, _, S = kin
    Jb, hb = kernels.body_inertias(P, R, p)
    return S, articulated.inertias(P, Jb, hb), Jb, hb, Kd, Cd, U, kk, cc


#: Rows of U per coordinate above which :func:`_w_factor` forms and factors the
#: n x n matrix instead of the Woodbury capacitance: that costs ~r^2 n + r^3 / 3
#: a step against ~n^3 / 3 + sum(nnz^2) for the dense one. The stowed stack of a
#: 10 x 10 array presses up to ~240 contact points on 85 coordinates.
DENSE_ROWS = 0.5


@njit(cache=True, **FLOAT_MATH)
def _w_factor(P, hg, S, Jb, hb, Kd, Cd, U, kk, cc):
    """Factor ``M W = H + U^T diag(wq) U`` with ``H = M + diag(hg Cd + hg^2 Kd)``
    and ``wq = hg cc + hg^2 kk``.

    Returns (UA, D, Z, wq, LU, piv, dense, ok). With at most :data:`DENSE_ROWS`
    rows per coordinate (dense False): the factor (UA, D) of H, O(n) by
    :func:`articulated.factor`, ``Z = H^-1 U^T`` as rows (r, n), and the LU of
    the Woodbury capacitance ``1 + diag(wq) U Z^T`` (r, r), in the form without
    ``diag(wq)^-1`` (a weight may be zero). With more (dense True): the LU of
    ``M W`` itself (n, n), by :func:`_w_dense`; UA, D, Z are then empty.
    """
    n = P.n
    r = U.shape[0]
    arm = np.empty(n)
    for i in range(n):
        arm[i] = hg * Cd[i] + hg * hg * Kd[i]
    wq = np.empty(r)
    for q in range(r):
        wq[q] = hg * cc[q] + hg * hg * kk[q]
    if r > DENSE_ROWS * n:
        LU, piv, ok = _w_dense(P, arm, S, Jb, hb, U, wq)
        return np.empty((0, 6)), np.empty(0), np.empty((0, n)), wq, LU, piv, True, ok
    UA, D, ok = articulated.factor(P, S, Jb, hb, arm)
    Z = np.empty((r, n))
    cap = np.zeros((r, r))
    if not ok:
        return UA, D, Z, wq, cap, np.arange(r), False, False
    articulated.solve_rows(P, S, UA, D, U, Z, np.empty((r, n + 1, 6)))
    for q in range(r):
        for c in range(r):
            s = 0.0
            for i in range(n):
                s += U[q, i] * Z[c, i]
            cap[q, c] = wq[q] * s
        cap[q, q] += 1.0
    LU, piv, ok = lu_factor(cap)
    return UA, D, Z, wq, LU, piv, False, ok


@njit(cache=True, **FLOAT_MATH)
def _w_dense(P, arm, S, Jb, hb, U, wq):
    """LU of ``M + diag(arm) + U^T diag(wq) U`` (n, n): (LU, piv, ok), M by
    composite bodies (:func:`kernels.mass_matrix`). A contact row is non-zero
    only on the paths from its two bodies to the root, so its outer product
    costs nnz^2, not n^2."""
    n = P.n
    W = kernels.mass_matrix(P, S, Jb, hb)
    for i in range(n):
        W[i, i] += arm[i]
    idx = np.empty(n, np.int64)
    for q in range(U.shape[0]):
        m = 0
        for i in range(n):
            if U[q, i] != 0.0:
                idx[m] = i
                m += 1
        for a in range(m):
            ua = wq[q] * U[q, idx[a]]
            for b in range(m):
                W[idx[a], idx[b]] += ua * U[q, idx[b]]
    return lu_factor(W)


@njit(cache=True, **FLOAT_MATH)
def _w_solve(P, S, factor, U, g, v, work, proj, yq):
    """Write to v (n,) the solution of ``M W v = g`` from :func:`_w_factor`'s
    factor; work (n + 1, 6), proj and yq (r,) are scratch."""
    UA, D, Z, wq, LU, piv, dense, _ = factor
    if dense:
        lu_solve(LU, piv, g, v)
        return
    articulated.solve(P, S, UA, D, g, v, work)
    for q in range(U.shape[0]):
        s = 0.0
        for i in range(v.shape[0]):
            s += U[q, i] * v[i]
        proj[q] = wq[q] * s
    lu_solve(LU, piv, proj, yq)
    for q in range(U.shape[0]):
        c = yq[q]
        for i in range(v.shape[0]):
            v[i] -= c * Z[q, i]


@njit(cache=True, **FLOAT_MATH)
def _add_stiff(Kd, U, kk, x, scale, out, proj):
    """out += scale (diag(Kd) + U^T diag(kk) U) x; proj is (r,) scratch."""
    for q in range(U.shape[0]):
        s = 0.0
        for i in range(x.shape[0]):
            s += U[q, i] * x[i]
        proj[q] = scale * kk[q] * s
    for i in range(x.shape[0]):
        out[i] += scale * Kd[i] * x[i]
    for q in range(U.shape[0]):
        for i in range(x.shape[0]):
            out[i] += proj[q] * U[q, i]


@njit(cache=True, **FLOAT_MATH)
def _stage_state(y, K, st, out):
    """Write stage st's state ``y + sum_q alpha_{st q} K[q]`` to out (st > 0)."""
    for i in range(y.shape[0]):
        s = y[i]
        for q in range(st):
            if _ALPHA[st, q] != 0.0:
                s += _ALPHA[st, q] * K[q, i]
        out[i] = s


@njit(cache=True, **FLOAT_MATH)
def _stage_argument(K, st, out):
    """Write stage st's Jacobian-product argument ``sum_q gamma_{st q} K[q]`` to out (st > 0)."""
    for i in range(out.shape[0]):
        s = 0.0
        for q in range(st):
            s += _GAMMA[st, q] * K[q, i]
        out[i] = s


@njit(cache=True, inline="always", **FLOAT_MATH)
def _solution(y, K):
    """The order-3 solution and its difference to the embedded order-2 one."""
    N = y.shape[0]
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
    return y1, err


@njit(cache=True, **FLOAT_MATH)
def step(P, y, f, h, A, B, K, scratch):
    """One ROS34PW2 step of length h from y (f = rhs(P, y)) with Jacobian blocks A, B.

    Stages go to K (4, N). Returns (y1, err, ok): the order-3 solution, the
    difference to the embedded order-2 one, and False if ``W`` is singular
    (the caller shortens the step).
    ``scratch``: the run's :func:`kernels.scratch`.
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
            _stage_state(y, K, st, yi)
            fi = kernels.rhs(P, yi, scratch)
        for i in range(N):
            r[i] = h * fi[i]
        if st > 0:
            _stage_argument(K, st, u)
            _jac_times(n, A, B, u, Ju)
            for i in range(2 * n):
                r[i] += h * Ju[i]
        _solve_w(n, hg, A, LU, piv, r, K[st], work)
    y1, err = _solution(y, K)
    return y1, err, True


@njit(cache=True, **FLOAT_MATH)
def step_terms(P, y, f, h, jac, K, scratch):
    """:func:`step` with the stiff Jacobian as the terms of :func:`terms`, in O(n r).

    Solves the reduced system times M, ``(M + hg C + hg^2 K) v = h M f_v - h
    (K u_x + C u_v) - hg K r_x`` (u the stage's Jacobian-product argument, r_x
    = h (f_x + u_v)), by :func:`_w_factor`, its ``M f_v`` by
    :func:`articulated.times`: the same as :func:`step` with ``A = -M^-1 K``,
    ``B = -M^-1 C``, to round-off (test_dynamics_articulated).
    """
    S, I6, Jb, hb, Kd, Cd, U, kk, cc = jac
    n = P.n
    N = y.shape[0]
    hg = h * GAMMA
    factor = _w_factor(P, hg, S, Jb, hb, Kd, Cd, U, kk, cc)
    if not factor[-1]:
        return y.copy(), np.full(N, np.inf), False
    yi = np.empty(N)
    rx = np.empty(n)
    u = np.zeros(N)
    work6 = np.empty((2, n + 1, 6))
    g = np.empty(n)
    kx = np.empty(n)
    proj = np.empty(U.shape[0])
    yq = np.empty(U.shape[0])
    for st in range(4):
        fi = f
        if st > 0:  # u stays zero at stage 0
            _stage_state(y, K, st, yi)
            fi = kernels.rhs(P, yi, scratch)
            _stage_argument(K, st, u)
        z = K[st]
        articulated.times(P, S, I6, fi[n:2 * n], g, work6)
        for i in range(n):
            g[i] *= h
            rx[i] = h * (fi[i] + u[n + i])
            kx[i] = h * u[i] + hg * rx[i]
        _add_stiff(Kd, U, kk, kx, -1.0, g, proj)
        _add_stiff(Cd, U, cc, u[n:2 * n], -h, g, proj)
        v = z[n:2 * n]
        _w_solve(P, S, factor, U, g, v, work6[0], proj, yq)
        for i in range(n):
            z[i] = rx[i] + hg * v[i]
        for i in range(2 * n, N):
            z[i] = h * fi[i]
    y1, err = _solution(y, K)
    return y1, err, True
