"""The hinge law (panel_deploy.dynamics.hinges) against the paper's Eq. (2)-(4)
and the ramped stop's closed forms."""

import numpy as np
import pytest

from panel_deploy.dynamics import hinges

from test_dynamics_helpers import paper_hinge_law


def test_hinge_law_without_a_ramp_is_the_paper_law():
    rng = np.random.default_rng(3)
    for theta in np.concatenate([rng.uniform(-0.1, np.pi + 0.1, 200), [0.0, np.pi, -1e-9, np.pi + 1e-9]]):
        omega, k, c = rng.normal(), rng.uniform(0.01, 1), rng.uniform(0, 0.01)
        tau, energy, _ = hinges.hinge_law(theta, omega, k, c, 1000.0, 0.5, 0.0)
        assert (tau, energy) == pytest.approx(paper_hinge_law(theta, omega, k, c, 1000.0, 0.5), rel=1e-14, abs=1e-300)


@pytest.mark.parametrize("limit, side", [(0.0, -1.0), (np.pi, 1.0)])
def test_a_ramped_stop_is_smooth_conservative_and_fully_in_past_its_ramp(limit, side):
    k_s, c_s, ramp, k = 1000.0, 0.5, 1e-3, 0.1
    depths = np.linspace(0.0, 3 * ramp, 301)[1:]
    theta = limit + side * depths

    def stop(th, om=0.0, r=ramp):
        tau, e, pw = hinges.hinge_law(th, om, k, 0.0, k_s, c_s, r)
        return tau + k * th, e - 0.5 * k * th * th, pw    # the stop's share alone

    tau = np.array([stop(t)[0] for t in theta])
    energy = np.array([stop(t)[1] for t in theta])
    # the torque is minus the slope of the stored energy (a spring, not a source)
    h = 1e-8
    slope = np.array([(stop(t + h)[1] - stop(t - h)[1]) / (2 * h) for t in theta])
    assert np.abs(tau + slope).max() < 1e-6 * k_s * ramp
    # no jump at first touch: torque, stiffness and damping all start from zero
    first = limit + side * 1e-9
    assert abs(stop(first)[0]) < 1e-12 and stop(first, 1.0)[2] < 1e-9
    # stiffness continuous where the ramp ends (one-sided slopes agree)
    edge, d = limit + side * ramp, 1e-7
    inner = (stop(edge)[0] - stop(edge - side * d)[0]) / d
    outer = (stop(edge + side * d)[0] - stop(edge)[0]) / d
    assert inner == pytest.approx(outer, rel=1e-3) and abs(outer) == pytest.approx(k_s, rel=1e-3)
    # past the ramp: the paper's stop moved ramp / 2 deeper, with its full damper
    beyond = depths > ramp
    assert np.allclose(tau[beyond], -side * k_s * (depths[beyond] - ramp / 2), rtol=1e-12)
    for t, dep in zip(theta[beyond][::20], depths[beyond][::20]):
        assert stop(t, 2.0)[0] - stop(t)[0] == pytest.approx(-c_s * 2.0, rel=1e-12)
        assert stop(t, 2.0)[2] == pytest.approx(c_s * 4.0, rel=1e-12)
    # the engagement's share: half at mid-ramp, all from its end
    assert hinges.stop_engagement(ramp / 2, ramp) == 0.5
    assert hinges.stop_engagement(ramp, ramp) == hinges.stop_engagement(1.0, ramp) == 1.0
    assert energy.min() >= 0.0 and np.all(np.diff(energy) > 0)
