"""The monitor's between-sample search, compiled (:mod:`.monitor`, "Between samples").

:func:`refine_interval` checks one interval (t_0, t_1] in a single call: the
mid-point of the touching pairs, then the depth-first bisection of the
others, left half first, so that mid-points are visited in time order. Same
steps, order and decisions as stated in :mod:`.monitor`; only the distances
between samples are :func:`.geometry.box_signed_distance` instead of FCL's
certified ones (the two agree to ``CERTIFY_TOL``), so that no step goes back
to Python. An interval of a 1 kHz stream on the paper scene takes up to a
few hundred bisection steps (poses, hinge-line radii and the exact distances
of the open pairs), ~150 us each from Python: tens of ms for one 1 ms
interval. Where a found pair first touched, or where a pair pressed in at
the mid-point crossed the tolerance, the monitor locates afterwards (a few
pairs per deployment; nothing in the search depends on it).

The search is one loop over an explicit stack rather than a recursion of
small kernels: every compiled function that reaches the kinematics kernel
recompiles it on a first run (seconds each).

Arguments shared by the kernels (tuples, so that numba specialises once):

``geo`` = ``(P, half, pa, pb, coords, length, chain_a, chain_b, parents, points, axes, tree, lca, reach_a, reach_b)``
    ``P`` :func:`~panel_deploy.dynamics.pack.pack` of the model, ``half``
    (nb, 3) the boxes' half edges (m), ``pa``, ``pb`` (P,) the pairs' bodies,
    then :class:`.motion.PairSpeedBound`'s tables.
``seg`` = ``(t0, h, theta0, A, B, C)``
    :attr:`.motion.HermiteSegment.coefficients`.
``lim`` = ``(threshold, resolution, time_resolution, prune, second_order)``
    -tolerance (m), the depth slack (m), the time resolution (s), whether
    the whole interval's pairs are first screened by
    :func:`.motion.speed_caps` (:func:`refine_interval`), and whether the
    pairs the speed bound leaves open get the second-order bound of
    :mod:`.motion`.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..dynamics.kernels import body_states
from .geometry import box_signed_distance
from .motion import (_accel_bound, _accel_of, _rate_bound, _speed_bound, hinge_radii_of, needed_radii,
                     pair_speeds, speed_caps)

# Columns of the search's stack frames (refine_interval): the slots of a node's
# ends, its stage, and how many pairs it bounds.
LO, HI, STAGE, COUNT = 0, 1, 2, 3
# Stages: to be bounded, left half searched, done.
BOUND, LEFT_DONE, DONE = 0, 1, 2
#: Shortest interval the search splits, as a fraction of the time resolution:
#: with it no search is deeper than log2((t_1 - t_0) / (MIN_SPLIT time_resolution))
#: levels (63 for a one-hour interval at 1 us), so its stack stays a few kB.
MIN_SPLIT = 1e-6
#: Levels of stack that :func:`stack` may be asked for at most.
MAX_DEPTH = 128


@njit(cache=True)
def states(geo, seg, t):
    """Rotations (nb, 3, 3), centroids (nb, 3) m, centroid velocities (nb, 3)
    m/s and angular velocities (nb, 3) rad/s of the bodies at instant t (s),
    the angles and rates computed as :meth:`.motion.HermiteSegment.__call__` does."""
    t0, h, th0, A, B, C = seg
    s = (t - t0) / h
    theta = np.empty(th0.shape[0])
    omega = np.empty(th0.shape[0])
    for i in range(th0.shape[0]):
        theta[i] = th0[i] + s * (C[i] + s * (B[i] / 2.0 + s * A[i] / 3.0))
        omega[i] = (C[i] + s * (B[i] + s * A[i])) / h
    return body_states(geo[0], theta, omega)


@njit(cache=True)
def poses(geo, seg, t):
    """Rotations (nb, 3, 3) and centroids (nb, 3), m, of the bodies at instant t (s)."""
    R, p, _, _ = states(geo, seg, t)
    return R, p


@njit(cache=True)
def _distances(geo, R, p, rows, out):
    """Write into ``out[rows]`` the signed distances (m) of the pairs ``rows``
    with the bodies at (R, p)."""
    half, pa, pb = geo[1], geo[2], geo[3]
    for k in rows:
        x, y = pa[k], pb[k]
        out[k] = box_signed_distance(R[x], p[x], half[x], R[y], p[y], half[y])


@njit(cache=True)
def _visit(threshold, tm, rows, S, found_t, last_touch, order, n_found):
    """Take the distances ``S[rows]`` (m) at instant tm (s), in time order: a
    pair below the threshold is found at tm (appended to ``order``, counted in
    ``n_found[0]``), one at sd >= 0 touched last at tm."""
    for k in rows:
        if not np.isnan(found_t[k]):
            continue
        if S[k] < threshold:
            found_t[k] = tm
            order[n_found[0]] = k
            n_found[0] += 1
        elif S[k] >= 0.0:
            last_touch[k] = tm


def stack(capacity, n_pairs, nb, n):
    """Room for :func:`refine_interval`'s search ``capacity`` levels deep, for
    ``n_pairs`` pairs and radii tables (nb, n): instants (s), distances (m)
    and radii (m) of the capacity + 2 slots, the frames and pairs of the
    levels, and the pairs' speeds V (m/s, :func:`.motion.pair_speeds`, both
    views) at the slots."""
    slots = capacity + 2
    return (np.empty(slots), np.empty((slots, n_pairs)), np.empty((slots, nb, n)),
            np.empty((capacity, 4), np.int64), np.empty((capacity, n_pairs), np.int64),
            np.empty((slots, 2, n_pairs)))


@njit(cache=True)
def refine_interval(geo, seg, lim, t1, D0, D1, radii0, radii1, colliding, work):
    """First collision instant in (t_0, t_1] of every pair, and the last instant
    the search saw it at sd >= 0.

    ``seg`` starts at t_0 (s) and ends at t_1 (s); ``D0``, ``D1`` (P,) are the
    sample distances (m), ``radii0``, ``radii1`` the samples' full radii
    tables (m), ``colliding`` (P,) the pairs colliding at t_0 (not searched)
    and ``work`` a :func:`stack`.

    Returns ``(found_t, last_touch, order, pressed, steps, midpoint)``: per
    pair the instant (s) found (nan if not) and the last touch (s, nan for
    none); the pairs found, in the order found, of which the first
    ``pressed`` were touching at both ends and are found at the mid-point
    (they crossed the tolerance in (t_0, mid-point]); the bisection steps and
    whether the touching pairs were checked at the mid-point. ``steps`` is
    -1 when the search needed a deeper ``work``; then nothing else holds.

    Broad phase (``prune``): on the whole interval, most pairs are far
    apart and close at once, yet their speed bound costs O(path length)
    each, O(n^3) in all for n panels. There a pair is bounded only if
    :func:`.motion.speed_caps` (O(1) a pair) leaves it open; as the cap is
    at least the bound, a pair it closes the bound closes too, so the
    search, its distances and what it finds are the same to the bit.
    """
    _, half, pa, pb, coords, length, chain_a, chain_b, parents, points, axes, tree, lca, reach_a, reach_b = geo
    t0, h, _, A, B, C = seg
    threshold, resolution, time_resolution, prune, second_order = lim
    t_at, S_at, R_at, frame, given, V_at = work
    n_pairs = D0.shape[0]
    found_t = np.full(n_pairs, np.nan)
    last_touch = np.full(n_pairs, np.nan)
    order = np.empty(n_pairs, dtype=np.int64)
    n_found = np.zeros(1, dtype=np.int64)
    # Pairs touching at both ends get the mid-point only (module docstring of
    # .monitor); the others are searched: given[0], from both samples' slots.
    m = 0.5 * (t0 + t1)
    pressed = np.empty(n_pairs, dtype=np.int64)
    n_pressed, n_rows = 0, 0
    for k in range(n_pairs):
        if D0[k] >= 0.0:
            last_touch[k] = t0
        S_at[0, k], S_at[1, k] = D0[k], D1[k]
        if colliding[k]:
            continue
        if abs(D0[k]) <= -threshold and abs(D1[k]) <= -threshold:
            pressed[n_pressed] = k
            n_pressed += 1
        else:
            given[0, n_rows] = k
            n_rows += 1
    if n_pressed:
        R, p = poses(geo, seg, m)
        S = np.empty(n_pairs)
        _distances(geo, R, p, pressed[:n_pressed], S)
        for k in pressed[:n_pressed]:
            if S[k] < threshold:
                found_t[k] = m
                order[n_found[0]] = k
                n_found[0] += 1
    located = n_found[0]

    # Depth-first bisection. Node d (depth d) spans the instants of slots
    # frame[d, LO] and frame[d, HI] and bounds the pairs given[d] (the first
    # frame[d, COUNT]); it puts its open pairs in given[d + 1], for both
    # halves, and its mid-point in slot d + 2 (slots 0 and 1: the samples).
    # A node's rows and slot outlive its subtree, which writes deeper ones.
    nb, n = radii0.shape
    for x in range(nb):
        for c in range(n):
            R_at[0, x, c], R_at[1, x, c] = radii0[x, c], radii1[x, c]
    t_at[0], t_at[1] = t0, t1
    frame[0, LO], frame[0, HI], frame[0, STAGE], frame[0, COUNT] = 0, 1, BOUND, n_rows
    steps = 0
    d = 0
    while d >= 0:
        lo, hi, slot = frame[d, LO], frame[d, HI], d + 2
        if frame[d, STAGE] == DONE:
            d -= 1
            continue
        if frame[d, STAGE] == LEFT_DONE:
            # The mid-point, then the right half.
            sub = given[d + 1, :frame[d + 1, COUNT]]
            _visit(threshold, t_at[slot], sub, S_at[slot], found_t, last_touch, order, n_found)
            frame[d, STAGE] = DONE
            frame[d + 1, LO], frame[d + 1, HI], frame[d + 1, STAGE] = slot, hi, BOUND
            d += 1
            continue
        a, b = t_at[lo], t_at[hi]
        sub = given[d, :frame[d, COUNT]]
        w = _rate_bound(A, B, C, (a - t0) / h, (b - t0) / h, h)
        if prune and d == 0:
            # Only the samples' radii tables are full, as the caps need.
            cap = speed_caps(w, b - a, R_at[lo], R_at[hi], sub, tree, lca, reach_a, reach_b, pa, pb)
            kept = np.empty(sub.shape[0], dtype=np.int64)
            n_kept = 0
            for i in range(sub.shape[0]):
                k = sub[i]
                if (S_at[lo, k] + S_at[hi, k] - cap[i] * (b - a)) / 2.0 < threshold - resolution:
                    kept[n_kept] = k
                    n_kept += 1
            sub = kept[:n_kept]
        L = _speed_bound(w, b - a, R_at[lo], R_at[hi], sub, coords, length, chain_a, chain_b, pa, pb)
        n_open = 0
        for i in range(sub.shape[0]):
            k = sub[i]
            Sa, Sb = S_at[lo, k], S_at[hi, k]
            # A pair with Sb below the threshold is being located, not bounded:
            # stop at the time resolution. Every other open pair closes once
            # L (b - a) / 2 <= resolution, as both its ends are >= threshold,
            # or once the interval is below MIN_SPLIT of the time resolution:
            # stamps of a few hundred ns (or times whose float spacing is
            # about the interval) would otherwise be halved forever.
            if ((Sa + Sb - L[i] * (b - a)) / 2.0 < threshold - resolution and np.isnan(found_t[k])
                    and not (Sb < threshold and b - a <= time_resolution)
                    and b - a > MIN_SPLIT * time_resolution and a < 0.5 * (a + b) < b):
                if d + 1 == frame.shape[0]:
                    return found_t, last_touch, order[:0], 0, -1, False
                given[d + 1, n_open] = k
                n_open += 1
        if n_open and second_order:
            # What L leaves open, the second-order bound may close (.motion):
            # each half of the interval from its own end's V.
            sub = given[d + 1, :n_open]
            if d == 0:
                for slot_end, t_end in ((0, t0), (1, t1)):
                    R, p, v, om = states(geo, seg, t_end)
                    pair_speeds(R, p, v, om, half, pa, pb, sub, V_at[slot_end])
            acc = _accel_bound(w, _accel_of(A, B, (a - t0) / h, (b - t0) / h, h), b - a, R_at[lo], R_at[hi],
                               sub, coords, length, chain_a, chain_b, pa, pb)
            tau = 0.5 * (b - a)
            kept = 0
            for i in range(n_open):
                k = sub[i]
                grow_a, grow_b = 0.5 * acc[0, i] * tau, 0.5 * acc[1, i] * tau
                lower = min(S_at[lo, k] - tau * min(V_at[lo, 0, k] + grow_a, V_at[lo, 1, k] + grow_b),
                            S_at[hi, k] - tau * min(V_at[hi, 0, k] + grow_a, V_at[hi, 1, k] + grow_b))
                if lower < threshold - resolution:
                    given[d + 1, kept] = k
                    kept += 1
            n_open = kept
        if n_open == 0:
            frame[d, STAGE] = DONE
            continue
        sub = given[d + 1, :n_open]
        m = 0.5 * (a + b)
        R, p, v, om = states(geo, seg, m)
        _distances(geo, R, p, sub, S_at[slot])
        if second_order:
            pair_speeds(R, p, v, om, half, pa, pb, sub, V_at[slot])
        radii = hinge_radii_of(R, p, half, parents, points, axes, needed_radii(sub, coords, length, pa, pb, nb, n))
        for x in range(nb):
            for c in range(n):
                R_at[slot, x, c] = radii[x, c]
        t_at[slot] = m
        steps += 1
        frame[d, STAGE] = LEFT_DONE
        frame[d + 1, LO], frame[d + 1, HI], frame[d + 1, STAGE], frame[d + 1, COUNT] = lo, slot, BOUND, n_open
        d += 1
    _visit(threshold, t1, given[0, :n_rows], D1, found_t, last_touch, order, n_found)
    return found_t, last_touch, order[:n_found[0]], located, steps, n_pressed > 0
