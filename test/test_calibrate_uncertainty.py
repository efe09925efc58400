"""Standard errors, intervals and identifiability of a least-squares optimum,
on Jacobians whose answer is known."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import t as student_t

from panel_deploy.calibrate import Measured
from panel_deploy.calibrate.data import still_hinges
from panel_deploy.calibrate.uncertainty import uncertainty


def linear_fit(J, noise=0.01, seed=0):
    """Residuals of the least-squares optimum of a linear model with Jacobian J."""
    rng = np.random.default_rng(seed)
    y = rng.normal(0.0, noise, len(J))
    x, *_ = np.linalg.lstsq(J, y, rcond=None)
    return y - J @ x


def test_standard_errors_of_a_linear_fit_are_the_textbook_ones():
    rng = np.random.default_rng(1)
    J = rng.normal(size=(400, 2))
    r = linear_fit(J)
    u = uncertainty(J, r, [0.0, 0.5], ("a", "t"), [True, False])
    cov = r @ r / 398 * np.linalg.inv(J.T @ J)
    se_x = np.sqrt(np.diag(cov))
    assert u.se[1] == pytest.approx(se_x[1])
    assert u.se[0] == pytest.approx(se_x[0])  # value exp(0) = 1 times se in log space
    q = student_t.ppf(0.975, 398)
    assert (u.lower[0], u.upper[0]) == pytest.approx((np.exp(-q * se_x[0]), np.exp(q * se_x[0])))
    assert (u.lower[1], u.upper[1]) == pytest.approx((0.5 - q * se_x[1], 0.5 + q * se_x[1]))
    assert u.correlation[0, 1] == pytest.approx(cov[0, 1] / se_x[0] / se_x[1])
    assert not u.problems and u.warnings == []


def test_collinear_parameters_are_named_with_the_reason():
    rng = np.random.default_rng(2)
    a = rng.normal(size=300)
    J = np.column_stack([a, 2 * a + 1e-9 * rng.normal(size=300), rng.normal(size=300)])
    u = uncertainty(J, linear_fit(J), [0.0, 0.0, 0.0], ("damping", "drag", "stiffness"),
                    [True, True, True])
    assert set(u.problems) == {"damping", "drag"}
    assert "only a combination of" in u.problems["drag"] and "condition number" in u.problems["drag"]
    assert u.warnings[0].startswith("damping is not identifiable from these data")


def test_a_parameter_without_effect_and_one_with_a_large_error_are_flagged():
    rng = np.random.default_rng(3)
    J = np.column_stack([rng.normal(size=200), np.zeros(200), 1e-3 * rng.normal(size=200)])
    r = linear_fit(J, noise=1.0)
    u = uncertainty(J, r, [0.0, 0.0, 0.0], ("k", "c", "cd"), [True, True, True])
    assert u.problems["c"] == "the residuals do not change with it at all"
    assert "relative standard error" in u.problems["cd"]
    assert "k" not in u.problems



def test_hinges_that_stay_put_are_found():
    t = np.linspace(0.0, 0.1, 11)
    moving = np.column_stack([np.pi - t, np.full_like(t, np.pi), np.pi - 0.001 * t])
    runs = [Measured("a", ("h1", "h2", "h3"), t, moving, 0.0),
            Measured("b", ("h2",), t, np.full((11, 1), np.pi), 0.0)]
    assert still_hinges(runs, 0.01) == {"h2", "h3"}
