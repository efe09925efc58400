"""Air drag on the panel faces (panel_deploy.dynamics.air) against a fine grid,
closed forms and a swinging panel's torque."""

import dataclasses

import numpy as np
import pytest

from panel_deploy.dynamics import air, kernels
from panel_deploy.dynamics.pack import pack
from panel_deploy.model import AirParameters

from test_dynamics_helpers import near, plate_on_hinge


def face_drag_reference(v0, a, b, A, B, n=1500):
    """|u| u, s |u| u, r |u| u summed over an n x n midpoint grid of the face
    (error O(1/n^2), and O(1/n) only in the cells the kink u = 0 crosses)."""
    s = (np.arange(n) + 0.5) / n * 2 * A - A
    r = (np.arange(n) + 0.5) / n * 2 * B - B
    S, R = np.meshgrid(s, r, indexing="ij")
    g = np.abs(v0 + a * S + b * R) * (v0 + a * S + b * R) * (4 * A * B / n**2)
    return np.array([g.sum(), (S * g).sum(), (R * g).sum()])


@pytest.mark.parametrize("seed", range(4))
def test_face_drag_integral_matches_a_fine_grid(seed):
    # the zero line u = 0 crosses the face for most draws: the kink is inside
    rng = np.random.default_rng(seed)
    v0, a, b = rng.normal(size=3) * (1.0, 20.0, 20.0)
    A, B = rng.uniform(0.02, 0.1, 2)
    got = np.array(air.face_drag(v0, a, b, A, B))
    assert np.abs(got - face_drag_reference(v0, a, b, A, B)).max() < 1e-6 * np.abs(got).max()
    assert np.allclose(air.face_drag(-v0, -a, -b, A, B), -got, rtol=1e-12, atol=0)


def test_face_drag_closed_forms():
    A, B = 0.1, 0.05
    area = 4 * A * B
    # pure translation along the normal: the flat-plate drag 1/2 rho C_d A |v| v, no moment
    assert air.face_drag(-3.0, 0.0, 0.0, A, B) == pytest.approx((-9.0 * area, 0.0, 0.0))
    # spin about the body's x axis (b = w_x): int r |b r| b r dA = 2A b|b| B^4 / 2, no force
    I0, Is, Ir = air.face_drag(0.0, 0.0, 4.0, A, B)
    assert (I0, Is) == pytest.approx((0.0, 0.0), abs=1e-15)
    assert Ir == pytest.approx(2 * A * 16.0 * B**4 / 2, rel=1e-12)
    # a tiny rotation on a translation: no 1 / a cancellation (u keeps its sign)
    assert air.face_drag(1.0, 1e-14, 0.0, A, B) == pytest.approx((area, 0.0, 0.0), abs=1e-15)


@pytest.mark.parametrize("theta", [0.3, 1.2, 2.8])
@pytest.mark.parametrize("omega", [3.0, -5.0])
def test_drag_torque_on_a_swinging_panel_is_the_closed_form(theta, omega):
    """Plate of width w, length L on a hinge at its edge: 1/2 rho C_d w omega |omega|
    times the integral of r^3 from 0 to L = rho C_d w omega |omega| L^4 / 8, opposing omega."""
    rho, cd = 1.2, 1.17
    still = plate_on_hinge(k=0.0, c=0.0)
    windy = dataclasses.replace(still, air=AirParameters(rho, cd))
    th, om = np.array([theta]), np.array([omega])
    P_air, P_still = pack(windy), pack(still)
    _, Q_air, *_, diss_air, _ = kernels.mass_and_bias(P_air, th, om, near(P_air))
    _, Q_still, *_, diss_still, _ = kernels.mass_and_bias(P_still, th, om, near(P_still))
    w, L = still.hinges[0].length, still.bodies[1].size[0]
    closed = -rho * cd * w * omega * abs(omega) * L**4 / 8
    assert Q_air[0] - Q_still[0] == pytest.approx(closed, rel=1e-12)
    # the power the drag takes is its torque times the rate, counted as dissipation
    assert diss_air - diss_still == pytest.approx(-closed * omega, rel=1e-12)
