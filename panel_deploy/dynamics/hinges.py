"""The hinge law of the compiled dynamics, Eq. (2)-(4) of the paper.

The contact elements act in parallel with the hinge spring (paper, text below
Eq. 4): ``tau = -k theta - c omega`` plus, past a limit, ``-k_s (theta - pi) -
c_s omega`` (theta > pi) or ``-k_s theta - c_s omega`` (theta < 0). So the
hinge spring keeps acting in contact; the printed Eq. (4) drops ``-k theta``
for theta > pi, a difference of k pi against the k_s term, which dominates
within the 0.1 % penetration it allows. A scene's ``contact.stop_ramp`` brings
k_s and c_s in smoothly over its first radians past the limit
(:func:`stop_engagement`); 0 is the paper's law.
"""

from __future__ import annotations

import math

from numba import njit

from ._jit import FLOAT_MATH


@njit(cache=True, **FLOAT_MATH)
def hinge_law(theta, omega, k, c, k_s, c_s, ramp):
    """Torque (N m), stored energy (J) and damper power (W) of one hinge, Eq. (2)-(4),
    the stop's spring and damper coming in over the first ``ramp`` rad past a
    limit (:func:`stop_engagement`; 0: at once, the paper's law)."""
    tau = -k * theta - c * omega
    energy = 0.5 * k * theta * theta
    power = c * omega * omega
    if theta > math.pi or theta < 0.0:
        d = theta - math.pi if theta > math.pi else theta
        a = abs(d)
        if a < ramp:
            x = a / ramp
            spring = k_s * ramp * x ** 3 * (1.0 - 0.5 * x)
            energy += k_s * ramp * ramp * x ** 4 * (0.25 - 0.1 * x)
        else:
            spring = k_s * (a - 0.5 * ramp)
            energy += 0.5 * k_s * a * a - k_s * ramp * (0.5 * a - 0.15 * ramp)
        damping = c_s * stop_engagement(a, ramp)
        tau -= math.copysign(spring, d) + damping * omega
        power += damping * omega * omega
    return tau, energy, power


@njit(cache=True, inline="always", **FLOAT_MATH)
def stop_engagement(depth, ramp):
    """The share (0..1) of k_s and c_s acting at ``depth`` rad past a limit:
    ``3 x^2 - 2 x^3`` of ``x = depth / ramp`` within the ramp, 1 beyond it.

    The paper's stop (ramp 0) takes its whole damper at first touch, so its
    torque jumps there by c_s omega and an explicit step that crosses the
    limit errs by O(h); hinges chattering on their stops in a stowed stack
    then cost most of a run's rejected steps (issue 33, 10 x 10). With the
    ramp the spring's torque is twice continuously differentiable in theta
    (its stiffness is k_s times this share) and the damper's once, as Hunt
    and Crossley's impact law removes the jump of a linear dashpot at first
    touch.
    """
    if depth >= ramp:
        return 1.0
    x = depth / ramp
    return x * x * (3.0 - 2.0 * x)


@njit(cache=True, **FLOAT_MATH)
def contact_mode(theta):
    """0 below the flat limit, 1 within [0, pi], 2 past the folded limit."""
    return 0 if theta < 0.0 else (2 if theta > math.pi else 1)
