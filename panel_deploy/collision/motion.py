"""Motion between two samples, and how fast a pair's distance can change.

Between samples t_a and t_b the hinge angles are taken to follow the cubic
Hermite interpolant of (theta, omega) at the two ends (third-order accurate,
the same order as the paper's RK23 dense output). Every guarantee of the
between-sample refinement is a guarantee for that interpolated motion.

Speed bound. Seen from body A, body B moves only through the hinges on the
tree path A = b_0, b_1, ..., b_m = B (joints j_1..j_m, j_k between b_{k-1}
and b_k), so a point y of B moves at |sum_k omega_k u_k x (y - p_k)| <=
sum_k |omega_k| r_k, r_k the distance of y from hinge line k. Hinge j_k lies
on an edge of b_k, and b_k also carries j_{k+1}, so r_k <= sum_{l>=k} diag(b_l)
in every configuration (the chain radius); tighter, r_k at the interval's
ends plus how far it can grow in between (:meth:`PairSpeedBound.__call__`).
The same holds seen from B with the bodies before k. The signed distance of
two convex bodies changes by at most the largest point displacement, so
|d sd/dt| <= L = min of the two sums (m/s).

Second-order bound. L ignores that the hinges of a fold turn against each
other: two panels riding together in a stack, whose distance changes by
centimetres a second, get tens of m/s from the fast hinges near the tree's
root. At an instant, though, the speed of B's points seen from A is known
exactly: V = the largest |v_B(y) - v_A(y)| over B's corners (the relative
velocity is affine in y, so its norm is largest at a corner;
:func:`pair_speeds`). Over the interval it grows no faster than the
acceleration of B's points seen from A. Differentiating
v(y) = sum_k omega_k u_k x (y - p_k), with u_k and p_k fixed in b_{k-1}
(which turns at Omega_{k-1} = sum_{l<k} omega_l u_l) and p_k taken at the
foot of y on line k (|y - p_k| = rho_k), gives
|a(y)| <= A = sum_k rho_k (|alpha_k| + w_k (3 W_{<k} + w_k)), W_{<k} the
sum of the rate bounds w_l of the joints between A and k and alpha_k the
bound on |d omega_k / dt| (:func:`_accel_bound`). So over the interval
|d sd/dt| <= V(t_a) + A (t - t_a), and <= V(t_b) + A (t_b - t), in either
view (B seen from A, A from B: each view its own V and A); what the
search uses where L alone cannot close a pair (:mod:`.refine`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..model import Model


class PairSpeedBound:
    """Bound on how fast each pair's signed distance can change (module docstring).

    Parameters
    ----------
    model : Model
    pairs : (P, 2) array_like of int
    """

    def __init__(self, model: Model, pairs):
        self.model = model
        pairs = np.asarray(pairs, dtype=int).reshape(-1, 2)
        self.a, self.b = pairs[:, 0], pairs[:, 1]
        self.half = np.array([np.asarray(b.size, dtype=float) / 2.0 for b in model.bodies])
        diag = 2.0 * np.linalg.norm(self.half, axis=1)
        # The tree path of each pair (speed bound, module docstring) and, for
        # speed_caps, its lowest common ancestor and the bodies with the
        # coordinate joining each to its parent, parents first.
        self.tree = (np.array(model.order, dtype=np.int64), np.array(model.parent, dtype=np.int64),
                     np.array(model.body_joint, dtype=np.int64))
        self.coords, self.length, self.chain_a, self.chain_b, self.lca = pair_paths(
            np.ascontiguousarray(self.a, dtype=np.int64), np.ascontiguousarray(self.b, dtype=np.int64),
            self.tree[1], self.tree[2], diag)
        # The largest chain of each side: its first (a's side) or last (b's) joint's.
        self.reach_a = self.chain_a.max(axis=1, initial=0.0)
        self.reach_b = self.chain_b.max(axis=1, initial=0.0)
        self.parents = np.array([model.hinges[h].body_a for h in model.joints], dtype=int)
        self.points = np.array([model.hinges[h].point - model.bodies[model.hinges[h].body_a].flat_position
                                for h in model.joints]).reshape(-1, 3)
        self.axes = np.array([model.hinges[h].axis for h in model.joints]).reshape(-1, 3)
        self._every = np.ones((model.n_bodies, len(model.joints)), dtype=bool)

    def radii(self, rotation, position) -> np.ndarray:
        """Largest distance (m) of each body's corners from each hinge line, (nb, n_coords)."""
        return hinge_radii_of(np.asarray(rotation, dtype=float), np.asarray(position, dtype=float),
                              self.half, self.parents, self.points, self.axes, self._every)

    def __call__(self, rate_bound, h, radii_a, radii_b, rows) -> np.ndarray:
        """Largest |d sd/dt| (m/s) over an interval of length h (s) of the pairs ``rows``.

        ``rate_bound`` is max |omega| per coordinate over the interval
        (rad/s), ``radii_a``, ``radii_b`` :meth:`radii` at its two ends. The
        distance rho_k of a body's points from hinge line k changes no faster
        than the chain bound of the joints beyond k, so over the interval
        rho_k <= (rho_k(a) + rho_k(b) + h Lambda_k) / 2, and never more than
        the chain radius.
        """
        return _speed_bound(rate_bound, float(h), radii_a, radii_b, np.asarray(rows, dtype=np.int64),
                            self.coords, self.length, self.chain_a, self.chain_b, self.a, self.b)

    def acceleration(self, rate_bound, accel, h, radii_a, radii_b, rows) -> np.ndarray:
        """Largest acceleration (m/s^2) of b's points seen from a and of a's seen
        from b, (2, len(rows)), over an interval of length h (s) on which the
        coordinates turn at most at ``rate_bound`` (rad/s) and accelerate at most
        at ``accel`` (rad/s^2); radii as :meth:`__call__`'s."""
        return _accel_bound(rate_bound, accel, float(h), radii_a, radii_b, np.asarray(rows, dtype=np.int64),
                            self.coords, self.length, self.chain_a, self.chain_b, self.a, self.b)

    def speeds(self, rotation, position, velocity, angular_velocity, rows) -> np.ndarray:
        """V (m/s) of the pairs ``rows``, (2, len(rows)): the largest speed of
        b's corners seen from a, then of a's seen from b, the bodies at
        (rotation, position) moving at (velocity, angular_velocity), (nb, 3)
        each, m/s and rad/s, ground frame."""
        rows = np.asarray(rows, dtype=np.int64)
        out = np.zeros((2, len(self.a)))
        pair_speeds(np.asarray(rotation, float), np.asarray(position, float), np.asarray(velocity, float),
                    np.asarray(angular_velocity, float), self.half, self.a, self.b, rows, out)
        return out[:, rows]


@njit(cache=True)
def pair_paths(a, b, parent, joint, diag):
    """The tree paths of the body pairs (a[p], b[p]), (P,) each, given every
    body's ``parent`` (-1 for the ground), ``joint`` (the coordinate joining
    it to its parent) and ``diag`` (its box's diagonal, m).

    The path of a pair is b_0 = a, ..., b_m = b, joint j_k between b_{k-1}
    and b_k. Returns ``(coords, length, chain_a, chain_b, lca)``: (P, M)
    with M the longest path, row p filled to its m (zeros after): the
    coordinates of j_1..j_m; (P,) m; (P, M) sum_{l >= k} diag(b_l) and
    sum_{l < k} diag(b_l) (m; each summed from its first body on); and (P,)
    the lowest common ancestor of a and b.
    """
    nb, P = parent.shape[0], a.shape[0]
    depth = np.zeros(nb, dtype=np.int64)
    for x in range(nb):
        y = x
        while parent[y] >= 0:
            depth[x] += 1
            y = parent[y]
    lca = np.empty(P, dtype=np.int64)
    M = 0
    for p in range(P):
        x, y = a[p], b[p]
        while depth[x] > depth[y]:
            x = parent[x]
        while depth[y] > depth[x]:
            y = parent[y]
        while x != y:
            x, y = parent[x], parent[y]
        lca[p] = x
        M = max(M, depth[a[p]] + depth[b[p]] - 2 * depth[x])
    coords = np.zeros((P, M), dtype=np.int64)
    length = np.empty(P, dtype=np.int64)
    chain_a = np.zeros((P, M))
    chain_b = np.zeros((P, M))
    bodies = np.empty(M + 1, dtype=np.int64)
    for p in range(P):
        up_a, up_b = depth[a[p]] - depth[lca[p]], depth[b[p]] - depth[lca[p]]
        m = up_a + up_b
        length[p] = m
        x = a[p]
        for k in range(up_a + 1):   # a up to the common ancestor
            bodies[k] = x
            x = parent[x]
        y = b[p]
        for k in range(m, up_a, -1):   # b up to just below it, filled from the end
            bodies[k] = y
            y = parent[y]
        for k in range(1, m + 1):
            # j_k carries the deeper of b_{k-1} and b_k
            coords[p, k - 1] = joint[bodies[k - 1]] if k <= up_a else joint[bodies[k]]
        acc = 0.0
        for k in range(m, 0, -1):
            acc += diag[bodies[k]]
            chain_a[p, k - 1] = acc
        acc = 0.0
        for k in range(m):
            acc += diag[bodies[k]]
            chain_b[p, k] = acc
    return coords, length, chain_a, chain_b, lca


# The kernels of this module run at every bisection step of the between-sample
# refinement (thousands per deployment); as numpy expressions on these small
# arrays they cost more than the exact distances they decide on.

@njit(cache=True)
def hinge_radii_of(rotation, position, half, parents, points, axes, need):
    """:meth:`PairSpeedBound.radii` where ``need`` (nb, n_coords) is True, 0 elsewhere.

    A bisection step needs the radii of the open pairs' bodies about their
    paths' hinges only (:func:`needed_radii`); each entry is computed as in
    the full table, to the bit.
    """
    nb, n = rotation.shape[0], parents.shape[0]
    out = np.zeros((nb, n))
    # The corners' offsets from their body's centroid, term by term, shared by every hinge.
    offset = np.empty((nb, 8, 3, 3))
    for b in range(nb):
        if not need[b].any():
            continue
        for m in range(8):
            for i in range(3):
                for j in range(3):
                    sign = 1.0 if (m >> (2 - j)) & 1 else -1.0
                    offset[b, m, i, j] = rotation[b, i, j] * sign * half[b, j]
    corner, point, axis = np.empty(3), np.empty(3), np.empty(3)
    for k in range(n):
        if not need[:, k].any():
            continue
        R = rotation[parents[k]]
        for i in range(3):
            point[i] = position[parents[k], i]
            axis[i] = 0.0
            for j in range(3):
                point[i] += R[i, j] * points[k, j]
                axis[i] += R[i, j] * axes[k, j]
        for b in range(nb):
            if not need[b, k]:
                continue
            far = 0.0
            for m in range(8):
                for i in range(3):
                    corner[i] = position[b, i] - point[i]
                    for j in range(3):
                        corner[i] += offset[b, m, i, j]
                along = corner[0] * axis[0] + corner[1] * axis[1] + corner[2] * axis[2]
                far = max(far, corner[0] ** 2 + corner[1] ** 2 + corner[2] ** 2 - along * along)
            out[b, k] = math.sqrt(far)
    return out


@njit(cache=True)
def needed_radii(rows, coords, length, a, b, nb, n):
    """The (body, coordinate) entries, (nb, n) bool, of the radii that
    :func:`_speed_bound` reads for the pairs ``rows``."""
    need = np.zeros((nb, n), dtype=np.bool_)
    for i in range(rows.shape[0]):
        p = rows[i]
        for k in range(length[p]):
            need[a[p], coords[p, k]] = True
            need[b[p], coords[p, k]] = True
    return need


@njit(cache=True)
def _speed_bound(rate_bound, h, radii_a, radii_b, rows, coords, length, chain_a, chain_b, a, b):
    """:meth:`PairSpeedBound.__call__` (same arguments and units), one pair at a time.

    Seen from body a the joints beyond k move b's points; seen from b, those
    before k move a's. The chain bound Lambda_k sums w_l chain_l over those
    joints (suffix from a's side, prefix from b's)."""
    out = np.empty(rows.shape[0])
    for i in range(rows.shape[0]):
        p = rows[i]
        beyond, total_a = 0.0, 0.0
        for k in range(length[p] - 1, -1, -1):
            c = coords[p, k]
            w = rate_bound[c]
            rho = (radii_a[b[p], c] + radii_b[b[p], c] + h * beyond) / 2.0
            total_a += w * min(rho, chain_a[p, k])
            beyond += w * chain_a[p, k]
        before, total_b = 0.0, 0.0
        for k in range(length[p]):
            c = coords[p, k]
            w = rate_bound[c]
            rho = (radii_a[a[p], c] + radii_b[a[p], c] + h * before) / 2.0
            total_b += w * min(rho, chain_b[p, k])
            before += w * chain_b[p, k]
        out[i] = min(total_a, total_b)
    return out


@njit(cache=True)
def _accel_bound(rate_bound, accel, h, radii_a, radii_b, rows, coords, length, chain_a, chain_b, a, b):
    """Largest acceleration (m/s^2) of one body's points seen from the other,
    over an interval of length h (s), of the pairs ``rows`` (module
    docstring, "Second-order bound"): sum_k rho_k (alpha_k + w_k (3 W_{<k} +
    w_k)), (2, len(rows)): b's points seen from a, then a's seen from b.

    ``rate_bound`` and ``accel`` are max |omega| (rad/s) and max |d omega/dt|
    (rad/s^2) per coordinate over the interval; the other arguments and the
    bound rho_k on the radius over the interval are :func:`_speed_bound`'s.
    """
    out = np.empty((2, rows.shape[0]))
    for i in range(rows.shape[0]):
        p = rows[i]
        m = length[p]
        W = 0.0
        for k in range(m):
            W += rate_bound[coords[p, k]]
        # b's points seen from a: the joints from b's end (the radius grows by
        # those beyond k); a's points seen from b: from a's end
        view_a = _accel_view(p, m - 1, -1, -1, b[p], chain_a, W, rate_bound, accel, h, radii_a, radii_b, coords)
        view_b = _accel_view(p, 0, m, 1, a[p], chain_b, W, rate_bound, accel, h, radii_a, radii_b, coords)
        # sums of positive terms: rounding moves them by ~m eps of themselves
        out[0, i], out[1, i] = (1.0 + CAP_SLACK) * view_a, (1.0 + CAP_SLACK) * view_b
    return out


@njit(cache=True)
def _accel_view(p, first, stop, step, body, chain, W, rate_bound, accel, h, radii_a, radii_b, coords):
    """One view of :func:`_accel_bound` for pair p: the joints k = first,
    first + step, .. (not stop), from the far end of the path towards the
    observing body, so that the joints passed are those beyond k (whose
    chain bounds grow the radius of ``body`` about k) and W less them is
    W_{<k}, the joints between the observer and k."""
    grown, passed, total = 0.0, 0.0, 0.0
    for k in range(first, stop, step):
        c = coords[p, k]
        w = rate_bound[c]
        passed += w
        rho = min((radii_a[body, c] + radii_b[body, c] + h * grown) / 2.0, chain[p, k])
        total += rho * (accel[c] + w * (3.0 * max(W - passed, 0.0) + w))
        grown += w * chain[p, k]
    return total


@njit(cache=True)
def pair_speeds(R, p, v, w, half, a, b, rows, out):
    """Write into ``out[:, rows]`` (2, P) each pair's V (m/s): the largest
    speed of b's corners seen from a, then of a's seen from b, the bodies at
    poses (R, p) with centroid velocities v (m/s) and angular velocities w
    (rad/s), all (nb, ...) in the ground frame, half edges ``half`` (nb, 3), m."""
    base, edge = np.empty(3), np.empty((3, 3))
    for k in rows:
        for view, (x, y) in enumerate(((a[k], b[k]), (b[k], a[k]))):
            # At y's corner q = p_y + sum_j s_j half_j R_y[:, j] the velocity seen
            # from x is v_y - v_x + w_x x (p_x - p_y) + sum_j s_j (w_y - w_x) x half_j R_y[:, j].
            d = p[x] - p[y]
            wx, dw = w[x], w[y] - w[x]
            base[0] = v[y, 0] - v[x, 0] + wx[1] * d[2] - wx[2] * d[1]
            base[1] = v[y, 1] - v[x, 1] + wx[2] * d[0] - wx[0] * d[2]
            base[2] = v[y, 2] - v[x, 2] + wx[0] * d[1] - wx[1] * d[0]
            for j in range(3):
                e0, e1, e2 = half[y, j] * R[y, 0, j], half[y, j] * R[y, 1, j], half[y, j] * R[y, 2, j]
                edge[j, 0] = dw[1] * e2 - dw[2] * e1
                edge[j, 1] = dw[2] * e0 - dw[0] * e2
                edge[j, 2] = dw[0] * e1 - dw[1] * e0
            far = 0.0
            for corner in range(8):
                speed = 0.0
                for i in range(3):
                    r = base[i]
                    for j in range(3):
                        r += edge[j, i] if (corner >> j) & 1 else -edge[j, i]
                    speed += r * r
                far = max(far, speed)
            out[view, k] = (1.0 + CAP_SLACK) * math.sqrt(far)


@njit(cache=True)
def _accel_of(A, B, sa, sb, h):
    """max |d omega / dt| (rad/s^2) over s in [sa, sb] of every coordinate of a
    :class:`HermiteSegment` (its coefficients A, B; length h, s): (2 A s + B) / h^2
    is linear in s, largest at an end."""
    out = np.empty(A.shape[0])
    for i in range(A.shape[0]):
        out[i] = max(abs(2.0 * A[i] * sa + B[i]), abs(2.0 * A[i] * sb + B[i])) / (h * h)
    return out


#: Relative slack of :func:`speed_caps` over the rounding of both bounds: each
#: is a sum of at most ~150 terms (12 x 12 panels), so rounding moves either by
#: under 1e-13 of itself.
CAP_SLACK = 1e-9


@njit(cache=True)
def speed_caps(rate_bound, h, radii_a, radii_b, rows, tree, lca, reach_a, reach_b, a, b):
    """An upper bound (m/s) on :func:`_speed_bound` of the pairs ``rows`` (same
    arguments; ``tree``, ``lca``, ``reach_a`` and ``reach_b`` are
    :class:`PairSpeedBound`'s), in O(1) a pair after O(nb^2) set-up, instead
    of O(path length) a pair.

    Seen from a, the bound sums w_k min(rho_k, chain_k) over the joints of
    the pair's path, rho_k = (r_k(t_a) + r_k(t_b) + h beyond_k) / 2 with r_k
    b's radius about hinge k. As beyond_k <= W reach (W the sum of w_k over
    the path, reach the largest chain), that sum is at most
    min(Q + h W^2 reach / 2, W reach) with Q the sum of w_k (r_k(t_a) +
    r_k(t_b)) / 2; likewise seen from b. W and Q are root sums of the tree
    (sum over the path = root sum at a + at b - 2 at their lowest common
    ancestor), so the radii tables must hold every hinge (the samples' do).
    ``CAP_SLACK`` keeps the cap above the computed bound despite rounding,
    so a pair the cap closes is closed by the bound too: the cap skips work,
    never changes a decision.
    """
    order, parent, coord = tree
    nb = radii_a.shape[0]
    W = np.zeros(nb)
    Q = np.zeros((nb, nb))  # Q[x, y]: sum of w_k (radius of x about hinge k) on y's root path
    for y in order:
        if parent[y] < 0:
            continue
        c = coord[y]
        W[y] = W[parent[y]] + rate_bound[c]
        for x in range(nb):
            Q[x, y] = Q[x, parent[y]] + rate_bound[c] * (radii_a[x, c] + radii_b[x, c]) / 2.0
    out = np.empty(rows.shape[0])
    for i in range(rows.shape[0]):
        p = rows[i]
        x, y, z = a[p], b[p], lca[p]
        # Root sums lose at most ~n eps of themselves to rounding, and their
        # difference that much of the larger ones.
        w = max(W[x] + W[y] - 2.0 * W[z], 0.0) + 1e-12 * (W[x] + W[y])
        q_a = max(Q[y, x] + Q[y, y] - 2.0 * Q[y, z], 0.0) + 1e-12 * (Q[y, x] + Q[y, y])
        q_b = max(Q[x, x] + Q[x, y] - 2.0 * Q[x, z], 0.0) + 1e-12 * (Q[x, x] + Q[x, y])
        side_a = min(q_a + h * w * w * reach_a[p] / 2.0, w * reach_a[p])
        side_b = min(q_b + h * w * w * reach_b[p] / 2.0, w * reach_b[p])
        out[i] = (1.0 + CAP_SLACK) * min(side_a, side_b)
    return out


class HermiteSegment:
    """Cubic Hermite interpolant of theta between two samples.

    Parameters
    ----------
    t0, t1 : float
        Sample instants, s, t1 > t0.
    theta0, theta1 : (n,) array_like
        Hinge angles, rad.
    omega0, omega1 : (n,) array_like
        Hinge rates, rad/s.
    """

    def __init__(self, t0, theta0, omega0, t1, theta1, omega1):
        self.t0, self.h = float(t0), float(t1) - float(t0)
        h = self.h
        th0, th1 = np.asarray(theta0, float), np.asarray(theta1, float)
        w0, w1 = np.asarray(omega0, float), np.asarray(omega1, float)
        # d theta / ds = A s^2 + B s + C on s in [0, 1]
        self._A = 6.0 * (th0 - th1) + 3.0 * h * (w0 + w1)
        self._B = 6.0 * (th1 - th0) - h * (4.0 * w0 + 2.0 * w1)
        self._C = h * w0
        self._th0 = th0

    def __call__(self, t):
        """Angles (rad) and rates (rad/s) at instant t, each (n,)."""
        s = (t - self.t0) / self.h
        A, B, C = self._A, self._B, self._C
        theta = self._th0 + s * (C + s * (B / 2.0 + s * A / 3.0))
        omega = (C + s * (B + s * A)) / self.h
        return theta, omega

    @property
    def coefficients(self) -> tuple:
        """``(t0, h, theta0, A, B, C)``: start (s), length (s), angles at the start
        (rad) and d theta / ds = A s^2 + B s + C (rad) on s = (t - t0) / h in [0, 1]."""
        return self.t0, self.h, np.ascontiguousarray(self._th0), self._A, self._B, self._C

    def rate_bound(self, ta, tb) -> np.ndarray:
        """max |omega| over [ta, tb] of every coordinate, rad/s, shape (n,)."""
        return _rate_bound(self._A, self._B, self._C, (ta - self.t0) / self.h,
                           (tb - self.t0) / self.h, self.h)

    def accel_bound(self, ta, tb) -> np.ndarray:
        """max |d omega / dt| over [ta, tb] of every coordinate, rad/s^2, shape (n,)."""
        return _accel_of(self._A, self._B, (ta - self.t0) / self.h, (tb - self.t0) / self.h, self.h)


@njit(cache=True)
def _rate_bound(A, B, C, sa, sb, h):
    """:meth:`HermiteSegment.rate_bound` on s in [sa, sb]: |omega| = |C + s (B + s A)| / h
    is largest at an end or at the parabola's vertex -B / (2 A) if that lies inside."""
    out = np.empty(A.shape[0])
    for i in range(A.shape[0]):
        best = max(abs(C[i] + sa * (B[i] + sa * A[i])), abs(C[i] + sb * (B[i] + sb * A[i])))
        if A[i] != 0.0:
            s = -B[i] / (2.0 * A[i])
            if sa < s < sb:
                best = max(best, abs(C[i] + s * (B[i] + s * A[i])))
        out[i] = best / h
    return out
