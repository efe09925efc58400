"""The explicit 5(4) pairs of the compiled loop (dynamics/erk.py): each pair's
tableau against the order conditions, its one-step error and error estimate
against a tight reference, and its stability edge against Hairer's test."""

import numpy as np
import pytest
from test_dynamics_helpers import near, plate_on_hinge, scratch

from panel_deploy.dynamics import erk, kernels, simulate
from panel_deploy.dynamics.pack import pack
from panel_deploy.model import State
from panel_deploy.scene import SimulationSection


def stages(pair):
    """(a (7, 7), b (7,), c (7,)) of the pair's Butcher tableau: stage 7 is
    f at the step's end."""
    a = np.zeros((7, 7))
    a[:, :6] = pair.A
    b = a[6].copy()
    return a, b, a.sum(axis=1)


@pytest.mark.parametrize("name", list(erk.PAIRS))
def test_the_tableau_meets_the_order_conditions(name):
    """The order conditions of the trees up to order 4 (Hairer, Norsett & Wanner
    I.2) and of the bushy tree of order 5 (to 1e-13, the
    digits Tsitouras' coefficients are given to), the error weights
    summing to zero (both solutions consistent), and the FSAL structure:
    stage 7 and stage 6 at the step's end (stiffness_ratio needs stage 6 there)."""
    a, b, c = stages(erk.PAIRS[name])
    assert b.sum() == pytest.approx(1, abs=1e-13)
    assert b @ c == pytest.approx(1 / 2, abs=1e-13)
    assert b @ c**2 == pytest.approx(1 / 3, abs=1e-13)
    assert b @ (a @ c) == pytest.approx(1 / 6, abs=1e-13)
    assert b @ c**3 == pytest.approx(1 / 4, abs=1e-13)
    assert (b * c) @ (a @ c) == pytest.approx(1 / 8, abs=1e-13)
    assert b @ (a @ c**2) == pytest.approx(1 / 12, abs=1e-13)
    assert b @ (a @ (a @ c)) == pytest.approx(1 / 24, abs=1e-13)
    assert b @ c**4 == pytest.approx(1 / 5, abs=1e-13)
    assert erk.PAIRS[name].E.sum() == pytest.approx(0, abs=1e-13)
    assert c[5] == pytest.approx(1, abs=1e-13) and c[6] == pytest.approx(1, abs=1e-13)
    assert np.all(np.triu(a) == 0)


@pytest.mark.parametrize("name", list(erk.PAIRS))
def test_one_step_errors_shrink_as_fifth_and_fourth_order(name):
    """Halving h divides the step's error by ~2^6 (order 5; 86-120 at these h,
    the next term still showing, against ~2^5 for order 4) and its error
    estimate by ~2^5 (the embedded order 4): the nonlinear plate in gravity,
    against DOP853 at rtol 1e-13."""
    model = plate_on_hinge(gravity=(0.0, 0.0, 9.81))
    P = pack(model)
    y = kernels.state_vector(np.array([1.0]), np.array([0.5]))
    f = kernels.rhs(P, y, scratch(P))
    K = np.empty((7, y.size))
    settings = SimulationSection(t_end=1.0, method="DOP853", rtol=1e-13, atol=1e-14, samples=2)
    errors, estimates = [], []
    for h in (4e-3, 2e-3, 1e-3):
        y1, err, _ = erk.step(P, y, f, h, erk.PAIRS[name], K, scratch(P))
        ref = simulate(model, SimulationSection(**{**settings.__dict__, "t_end": h}),
                       State(0.0, y[:1], y[1:2]))
        errors.append(abs(y1[0] - ref.theta[-1, 0]) + h * abs(y1[1] - ref.omega[-1, 0]))
        estimates.append(abs(err[0]) + h * abs(err[1]))
    for e0, e1 in zip(errors, errors[1:]):
        assert 50 < e0 / e1 < 130
    for e0, e1 in zip(estimates, estimates[1:]):
        assert 25 < e0 / e1 < 40


def amplification(pair, z):
    a, b, _ = stages(pair)
    return 1 + z * b @ np.linalg.solve(np.eye(7) - z * a, np.ones(7))


@pytest.mark.parametrize("name, edge", [("dopri5", 3.306), ("tsit5", 3.506)])
def test_stiff_ratio_lies_just_inside_the_stability_edge(name, edge):
    """|R(-x)| <= 1 up to the edge on the negative real axis (3.31 for
    Dormand and Prince's pair, 3.51 for Tsitouras'), > 1 just past it; Hairer's
    test fires a little inside it."""
    pair = erk.PAIRS[name]
    assert all(abs(amplification(pair, -x)) <= 1 for x in np.linspace(0, edge, 400))
    assert abs(amplification(pair, -(edge + 2e-3))) > 1
    assert 0.97 * edge < pair.stiff_ratio < edge
