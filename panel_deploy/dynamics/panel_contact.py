"""Panel-to-panel contact in the compiled dynamics (:mod:`panel_deploy.contacts`).

The pairs of ``P.contact`` that may touch come from a candidate list kept for
the run (:func:`near_pairs`) and cheap tests that rule the rest out
(:func:`touching`); the touching pairs' points come from the box geometry
(:func:`panel_deploy.boxes.contact`) and push by :func:`contact_law`.

Every kernel that reaches the panel contacts takes their candidate list
``near`` as a required argument: numba compiles a kernel apart for each way
it is called (an omitted argument, None and a tuple are three types), and a
default of None let the install compile the largest kernels two or three
times over for each kind of model.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..boxes import interference
from ..boxes import scratch as box_scratch
from ..boxes import separating_axis
from . import spatial as sp
from ._jit import FLOAT_MATH


#: Depth (m) over which a panel contact comes in: below it the spring force
#: is k d^2 / (2 D) and the damping c d / D, so that the push and its
#: stiffness grow from zero at first touch. A contact in full at once makes
#: the push (and the Jacobian) jump, and a step across it must shrink to
#: where the jump no longer matters. A face pressed with up to 50 N (k_p =
#: 1e7 N/m) sits on the ramp, a tenth of the collision tolerance deep at most.
CONTACT_RAMP = 1e-5


@njit(cache=True, **FLOAT_MATH)
def contact_law(depth, speed, k, c):
    """One contact point at depth > 0 (m) approaching at speed (m/s), see
    ``CONTACT_RAMP``: its push (N, never a pull), the spring's share of it
    (N) and energy (J), and d spring / d depth (N/m) and the damping (N s/m)
    at that depth; k and c are the full stiffness (N/m) and damping (N s/m)."""
    D = CONTACT_RAMP
    if depth < D:
        spring, energy, stiffness, damping = (0.5 * k * depth * depth / D, k * depth ** 3 / (6.0 * D),
                                              k * depth / D, c * depth / D)
    else:
        spring, stiffness, damping = k * (depth - 0.5 * D), k, c
        energy = k * (0.5 * depth * depth - 0.5 * D * depth + D * D / 6.0)
    return max(0.0, spring + damping * speed), spring, energy, stiffness, damping


@njit(cache=True, inline="always", **FLOAT_MATH)
def _boxes(P, R, p):
    """The axis-aligned box around every body at poses (R, p): (n + 1, 2, 3),
    its lower and upper corners (m), once per call for :func:`_pair_apart`."""
    out = np.empty((P.n + 1, 2, 3))
    for i in range(P.n + 1):
        for k in range(3):
            e = (abs(R[i, k, 0]) * P.half[i, 0] + abs(R[i, k, 1]) * P.half[i, 1]
                 + abs(R[i, k, 2]) * P.half[i, 2])
            out[i, 0, k] = p[i, k] - e
            out[i, 1, k] = p[i, k] + e
    return out


@njit(cache=True, inline="always", **FLOAT_MATH)
def _box_gap(box, a, b):
    """The gap (m) between the :func:`_boxes` of bodies a and b along the
    ground axis that parts them most (< 0: they overlap)."""
    gap = -np.inf
    for k in range(3):
        gap = max(gap, box[a, 0, k] - box[b, 1, k], box[b, 0, k] - box[a, 1, k])
    return gap


@njit(cache=True, inline="always", **FLOAT_MATH)
def _pair_apart(contact, r, box, margin=0.0):
    """Whether the :func:`_boxes` of pair r of ``P.contact`` are apart by at
    least ``margin`` (m; boxes that only touch are apart, a contact needs
    some depth): the test that spares most pairs of a large array the
    separating axes."""
    return _box_gap(box, int(contact[r, 0]), int(contact[r, 1])) >= margin


#: Margin of the candidate list of panel contact pairs (:func:`near_pairs`),
#: m: a pair is listed while its boxes are less than this apart, and the list
#: is rebuilt once any box corner has moved half of it. Measured on the 10 x
#: 10 array (3569 pairs, panels 0.1 m): 5 mm lists 30-330 pairs and is rebuilt
#: every ~10 right-hand sides in the stowed stacks.
NEAR_MARGIN = 0.005


@njit(cache=True, **FLOAT_MATH)
def near_pairs(P):
    """An empty candidate list of the pairs of ``P.contact`` for
    :func:`.kernels.rhs`, a tuple:

    0. the :func:`_boxes` it was built at (n + 1, 2, 3), NaN until its first use;
    1. the listed pairs (q, 3): each one's row of ``P.contact`` and its two
       bodies, so that the pairs its slack spares need no read of that
       table (10 x 10: 3569 rows of 13, out of the first-level cache; 0.7 us
       of an evaluation's 20 at 0.1 s), and 2. their count (1,);
    3. each pair's last separating axis (q,) (:func:`boxes.separating_axis`);
    4. the bodies' rotations (n + 1, 3, 3) and 5. centres (n + 1, 3), m, when
       it was built, and 6. how far any point of each body has moved since (n + 1,), m;
    7. each listed pair's slack (q,), m, in the order of 1.: how much further
       its two bodies may move together (by 6.) and stay apart, as the last
       test of the pair found it (-inf from each rebuild on);
    8. the fastest contact onset the last :func:`panel_contacts` call met
       (9,), laid out as ``result.ONSET_COLUMNS``, its time NaN (the call
       does not know it) and its speed 0 for none: the step loops take the
       onsets of an accepted step from its last evaluation
       (:func:`take_onsets`), which was at the step's end.

    Mutable scratch of one run, never shared between runs: 0.-7. only spare
    :func:`panel_contacts` the tests of pairs that cannot touch, so a run
    gives the same result to the bit with it as without."""
    q = P.contact.shape[0]
    return (np.full((P.n + 1, 2, 3), np.nan), np.empty((q, 3), np.int64), np.zeros(1, np.int64),
            np.zeros(q, np.int64), np.empty((P.n + 1, 3, 3)), np.empty((P.n + 1, 3)),
            np.empty(P.n + 1), np.full(q, -np.inf), np.zeros(9))


#: Rounding allowance of a pair's slack (:func:`near_pairs`), m: a pair skipped
#: on its slack is apart by more than this, far beyond the separating-axis
#: test's rounding (~1e-16 m on panels of 0.1-1 m), so that test would find it
#: apart too.
SLACK_ROUNDING = 1e-9


@njit(cache=True, inline="always", **FLOAT_MATH)
def _near_rows(P, box, R, p, near):
    """The pairs whose :func:`_boxes` ``box`` may overlap (m, 3: each one's row
    of ``P.contact`` and its two bodies), from
    the candidate list ``near`` (:func:`near_pairs`), rebuilt first if a box
    corner moved more than NEAR_MARGIN / 2 since it was built, and each
    body's motion since then at poses (R, p). A pair left out was
    NEAR_MARGIN apart along some axis then, and each of its boxes has moved
    at most half of that since: it is apart now, as :func:`_pair_apart`
    (``>=``) would find it."""
    contact = P.contact
    built, rows, count, R0, p0, moved, slack = near[0], near[1], near[2], near[4], near[5], near[6], near[7]
    half = 0.5 * NEAR_MARGIN
    stale = False
    for x, x0 in zip(box.ravel(), built.ravel()):
        if not abs(x - x0) <= half:  # NaN: not built yet
            stale = True
            break
    if stale:
        built[:] = box
        R0[:] = R
        p0[:] = p
        slack[:] = -np.inf
        m = 0
        for r in range(contact.shape[0]):
            if not _pair_apart(contact, r, box, NEAR_MARGIN):
                rows[m, 0], rows[m, 1], rows[m, 2] = r, int(contact[r, 0]), int(contact[r, 1])
                m += 1
        count[0] = m
    for i in range(P.n + 1):
        # |dp| + |dR|_F |h| bounds the motion of every point p + R u, |u| <= |h|
        dp, dR = 0.0, 0.0
        for k in range(3):
            dp += (p[i, k] - p0[i, k]) ** 2
            for m in range(3):
                dR += (R[i, k, m] - R0[i, k, m]) ** 2
        h = P.half[i]
        moved[i] = math.sqrt(dp) + math.sqrt(dR) * math.sqrt(h[0] * h[0] + h[1] * h[1] + h[2] * h[2])
    return rows[:count[0]]


@njit(cache=True, inline="always", **FLOAT_MATH)
def touching(P, R, p, near):
    """The rows of ``P.contact`` whose pairs may touch at poses
    (R, p): every other pair is apart, and :func:`pair_points` would find
    no point of it; and for each, its axis of least overlap (m, 4): the
    unit axis and the centre offset along it, m (:func:`boxes.separating_axis`,
    for :func:`pair_points`).

    Of the pairs on the candidate list ``near`` (:func:`near_pairs`): those
    whose bodies have moved less than their slack since their last test are
    apart; the rest get the box test, then the separating axes, the one that separated
    the pair last first (while an array deploys, most pairs whose boxes
    overlap are apart: 221 of 222 on 10 x 10 at 0.1 s), and the gap found
    sets the slack. One loop here, not a call a pair: passing the list to a
    function costs ~60 ns a call in reference counts, more than the test.
    """
    contact = P.contact
    box = _boxes(P, R, p)
    rows = _near_rows(P, box, R, p, near)
    axes, moved, slack = near[3], near[6], near[7]
    out = np.empty(rows.shape[0], np.int64)
    least = np.empty((rows.shape[0], 4))
    m = 0
    for j in range(rows.shape[0]):
        r, a, b = rows[j, 0], rows[j, 1], rows[j, 2]
        if moved[a] + moved[b] < slack[j]:
            continue
        gap = _box_gap(box, a, b)
        if not gap >= 0.0:  # NaN poses as well: the contact is left to find them
            k, overlap, axis, along = separating_axis(R[a], p[a], contact[r, 2:5], R[b], p[b],
                                                      contact[r, 5:8], axes[r])
            if k < 0:
                out[m] = r
                least[m, 0], least[m, 1], least[m, 2] = axis
                least[m, 3] = along
                m += 1
                continue
            axes[r], gap = k, -overlap
        # apart by gap now, so by gap - (moved now + moved later) later
        slack[j] = gap - moved[a] - moved[b] - SLACK_ROUNDING
    return out[:m], least[:m]


@njit(cache=True, inline="always", **FLOAT_MATH)
def pair_points(P, r, R, p, least, work):
    """Contact points of pair r of ``P.contact`` (:func:`boxes.contact`): their
    number and the normal from the pair's first body towards its second;
    points, depths and weights are left in work. For the pairs :func:`touching`
    returns, with their axis of least overlap ``least`` (4,) from it."""
    contact = P.contact
    a, b = int(contact[r, 0]), int(contact[r, 1])
    return interference(R[a], p[a], contact[r, 2:5], R[b], p[b], contact[r, 5:8],
                        (least[0], least[1], least[2]), least[3], work, contact[r, 12] != 0.0)


@njit(cache=True, inline="always", **FLOAT_MATH)
def panel_contacts(P, R, p, w, vo, f, near):
    """Subtract the panel-contact wrenches from f (n + 1, 6), the bias wrenches
    about the ground origin; returns the contact energy (J), the power its
    dampers dissipate (W) and the power its springs take from the bodies (W).

    Per contact point of a pair of ``P.contact`` (:mod:`panel_deploy.contacts`,
    :func:`panel_deploy.boxes.contact`) at depth d > 0, approaching at s (the
    normal speed of the pair's first body's point there relative to the
    second's), a push ``max(0, k d + c s)`` along the normal on the two
    bodies, k and c its weight's share of k_p and c_p: a spring and damper that never
    pulls (one that pulled would glue parting panels together), both coming
    in over the first ``CONTACT_RAMP`` of depth (:func:`contact_law`). The
    spring takes the power spring s and stores its energy; the rest of the
    push's work, (push - spring) s >= 0, is dissipated (s is d's rate up to
    the motion of the point). The two powers are the push's whole work on
    the bodies, exactly; the stored energy is a function of the poses that
    jumps where a pair changes the features it touches by.
    With a friction coefficient mu (``contact[r, 10]``) > 0, the point's
    :func:`_friction` opposes the slip, and dissipates all its work.
    0, 0, 0 where ``P.contact`` has no rows (no panel contact);
    ``near`` is the run's candidate list (:func:`near_pairs`), which also
    gets the fastest onset met (its item 8).

    An onset is a contact point shallower than CONTACT_RAMP (where the
    force is not yet in full), its speed the approach speed there: a
    contact stops an impact within a step or two, so the speed of its
    shallow points at the steps' ends is the impact's (the samples would
    miss it: the contact absorbed a 4.2 m/s impact between two samples,
    issue 33). Every shallow point, not a pair's first: a face coming down
    may touch first at one slow point, its fast corners a step later (the
    paper scene's r1c2+r1c3 on r2c4, 50 us samples: one point at 0.000 m/s,
    the next sample another at 0.097 m/s; r4c1 on r4c4 was missed so, one
    point pressing a step before its four), and a pair resting in light
    contact can still be struck.
    """
    contact = P.contact
    if contact.shape[0] == 0:
        return 0.0, 0.0, 0.0
    energy = 0.0
    power = 0.0
    spring_power = 0.0
    work = box_scratch()
    points, depths, weights = work[-3], work[-2], work[-1]
    onset = near[8]
    onset[0], onset[1] = np.nan, 0.0
    rows, least = touching(P, R, p, near)
    for j in range(rows.shape[0]):
        r = rows[j]
        count, normal = pair_points(P, r, R, p, least[j], work)
        a, b = int(contact[r, 0]), int(contact[r, 1])
        mu, v_f = contact[r, 10], contact[r, 11]
        for q in range(count):
            depth = depths[q]
            x = (points[q, 0], points[q, 1], points[q, 2])
            relative = sp.sub(sp.point_velocity(w, vo, a, x), sp.point_velocity(w, vo, b, x))
            speed = sp.dot(normal, relative)
            if depth < CONTACT_RAMP and speed > onset[1]:
                onset[1], onset[2] = speed, r
                onset[3], onset[4], onset[5] = x
                onset[6], onset[7], onset[8] = normal
            push, spring, e, _, _ = contact_law(depth, speed, weights[q] * contact[r, 8],
                                                 weights[q] * contact[r, 9])
            energy += e
            spring_power += spring * speed
            power += (push - spring) * speed
            force = sp.scale(normal, push)  # on b, as the friction: f holds minus the force on a
            if mu > 0.0:
                friction, loss = _friction(sp.sub(relative, sp.scale(normal, speed)), mu * push, v_f)
                force = sp.add(force, friction)
                power += loss
            sp.add_wrench(f, a, sp.ZERO3, force, x)
            sp.add_wrench(f, b, sp.ZERO3, sp.scale(force, -1.0), x)
    return energy, power, spring_power


@njit(cache=True, inline="always", **FLOAT_MATH)
def _friction(slip, limit, v_f):
    """Regularised Coulomb friction at a contact point slipping at ``slip``
    (3-tuple, m/s: the first body's point relative to the second's, in the
    contact plane) under a normal push of mu times ``limit`` (N): the force
    on the second body, ``limit slip / sqrt(|slip|^2 + v_f^2)`` (N), and the
    power it dissipates (W). Below the slip speed v_f (m/s) it is a damper
    of ``limit / v_f`` (N s/m), so that sticking is a slow creep and the
    force is smooth: Coulomb's law jumps at zero slip, and a step that
    crosses it errs by O(h)."""
    v2 = sp.dot(slip, slip)
    scale = limit / math.sqrt(v2 + v_f * v_f)
    return sp.scale(slip, scale), scale * v2


@njit(cache=True, **FLOAT_MATH)
def take_onsets(near, t, record):
    """Into ``record`` (9,), laid out as ``result.ONSET_COLUMNS``, the fastest
    contact onset of the last :func:`panel_contacts` call with the candidate
    list ``near`` (:func:`near_pairs`), at time t (s), if faster than the one
    already there (record[1]; 0 for none)."""
    onset = near[8]
    if onset[1] > record[1]:
        record[:] = onset
        record[0] = t
