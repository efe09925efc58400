"""The compiled Rosenbrock-W integrator (ROS34PW2) and its stiff Jacobian: a stiff
overdamped hinge against its closed form, the W-method's order with any matrix,
the stiff Jacobian against finite differences, the automatic choice, failures."""

import dataclasses
import re

import numpy as np
import pytest

from panel_deploy.dynamics import compiled, erk, hinges, kernels, rosenbrock, simulate, stiff
from panel_deploy.dynamics.compiled import SQUARINGS, choose_scheme, radius_bound, stiffness
from panel_deploy.dynamics.kernels import state_vector
from panel_deploy.dynamics.pack import pack
from panel_deploy.errors import ModelError
from panel_deploy.model import State
from panel_deploy.scene import SimulationSection

from test_dynamics_helpers import near, overdamped_plate, plate_on_hinge, random_branched, ring_2x2, scratch


def test_stiff_overdamped_hinge_matches_closed_form():
    """I theta'' = -k theta - c theta' with roots -1e5 and -10 1/s (no gravity, no
    contact: exactly linear). DOPRI5 would need >= 1e5 * T / 3.3 steps."""
    model, lam, exact = overdamped_plate(1e5)
    T = 0.2
    state = State(0.0, np.array([1.0]), np.zeros(1))
    P = pack(model)
    assert choose_scheme(P, state_vector([1.0], [0.0])) == "ros34pw2"
    r = simulate(model, SimulationSection(t_end=T, method="compiled", rtol=1e-6, atol=1e-9,
                                          samples=41), state)
    assert r.success, r.message
    assert r.scheme == "ros34pw2"
    assert np.abs(r.theta[:, 0] - exact(r.t)).max() < 1e-5
    explicit_steps = T * np.abs(lam).max() / 3.3
    assert r.nsteps < explicit_steps / 20


@pytest.mark.parametrize("pair", ["tsit5", "dopri5"])
def test_compiled_hands_over_to_ros34pw2_once_its_pair_is_held_at_its_stability_limit(pair, monkeypatch):
    """Roots -5e3 and -10 1/s: too mild at the start for choose_scheme (3.3 / 5e3 s
    is above STIFF_STEP), but from the first steps on the slow root alone would let
    the steps grow far past the explicit pair's stability limit, ~3.3 / 5e3 s."""
    monkeypatch.setattr(compiled, "EXPLICIT_PAIR", pair)
    model, lam, exact = overdamped_plate()
    P = pack(model)
    y0 = state_vector([1.0], [0.0])
    assert choose_scheme(P, y0) == pair
    T = 1.0
    explicit_steps = T * np.abs(lam).max() / erk.PAIRS[pair].stiff_ratio
    settings = SimulationSection(t_end=T, method=pair, rtol=1e-6, atol=1e-9, samples=41)
    state = State(0.0, y0[:1], y0[1:2])
    held = simulate(model, settings, state)
    assert held.success and held.scheme == pair and held.nsteps > 0.9 * explicit_steps
    r = simulate(model, dataclasses.replace(settings, method="compiled"), state)
    assert r.success, r.message
    switch = re.fullmatch(pair + r", then ros34pw2 from t = (\S+) s", r.scheme)
    assert switch and 0.0 < float(switch[1]) < 0.05, r.scheme
    assert r.nsteps < held.nsteps / 3 and r.njev > 0
    assert np.abs(r.theta[:, 0] - exact(r.t)).max() < 1e-5
    assert np.abs(held.theta[:, 0] - exact(held.t)).max() < 1e-5


@pytest.mark.parametrize("jacobian", ["exact", "zero"])
def test_w_method_local_error_is_fourth_order_with_any_matrix(jacobian):
    """Halving h divides the one-step error of an order-3 method by ~16, whatever
    matrix is in W (the W-method property); checked on the nonlinear plate."""
    model = plate_on_hinge(gravity=(0.0, 0.0, 9.81))
    P = pack(model)
    y = state_vector([1.0], [0.5])
    f = kernels.rhs(P, y, scratch(P))
    if jacobian == "exact":
        J = kernels.rhs_jacobian(P, y, f, scratch(P))
        A, B = J[1:2, :1].copy(), J[1:2, 1:2].copy()
    else:
        A, B = np.zeros((1, 1)), np.zeros((1, 1))
    K = np.empty((7, 4))
    settings = SimulationSection(t_end=1.0, method="DOP853", rtol=1e-13, atol=1e-14, samples=2)
    errors = []
    for h in (4e-3, 2e-3, 1e-3):
        y1, err, ok = rosenbrock.step(P, y, f, h, A, B, K, scratch(P))
        assert ok
        ref = simulate(model, dataclasses.replace(settings, t_end=h),
                       State(0.0, y[:1], y[1:2]))
        errors.append(abs(y1[0] - ref.theta[-1, 0]) + h * abs(y1[1] - ref.omega[-1, 0]))
    for e0, e1 in zip(errors, errors[1:]):
        assert 10 < e0 / e1 < 24


@pytest.mark.parametrize("closure", ["penalty", "exact"])
def test_stiff_jacobian_holds_the_stiff_spectrum(closure):
    """The most negative eigenvalues of [[0, I], [A, B]] from the stiff part agree with
    the finite-difference Jacobian, with a hinge in contact (theta < 0)."""
    model = ring_2x2(closure)
    P = pack(model)
    n = P.n
    y = state_vector([-0.01, 1.0, 1.0], [0.5, -0.3, 0.2])
    assert hinges.contact_mode(y[0]) == 0
    Jfd = kernels.rhs_jacobian(P, y, kernels.rhs(P, y, scratch(P)), scratch(P))[:2 * n, :2 * n]
    A, B, ok = stiff.stiff_jacobian(P, y, near(P))
    assert ok
    Jst = np.block([[np.zeros((n, n)), np.eye(n)], [A, B]])
    ev_fd = np.sort(np.linalg.eigvals(Jfd).real)[:2]
    ev_st = np.sort(np.linalg.eigvals(Jst).real)[:2]
    assert ev_fd[0] < -1e3
    np.testing.assert_allclose(ev_st, ev_fd, rtol=0.05)


def test_auto_keeps_the_explicit_pair_for_a_mild_model():
    model = plate_on_hinge(c=0.02)
    P = pack(model)
    y0 = state_vector([1.0], [0.0])
    assert 3.3 / stiffness(P, y0) > 2e-4
    r = simulate(model, SimulationSection(t_end=0.05, method="compiled", samples=6),
                 State(0.0, y0[:1], y0[1:2]))
    assert r.success and r.scheme == "tsit5"


def test_radius_bound_is_never_below_the_spectral_radius():
    """radius_bound is an upper bound on |eigenvalues| of any matrix, near it
    for a well-conditioned one, finite and not 0 for entries that a plain
    power would overflow or underflow, 0 for the zero matrix."""
    rng = np.random.default_rng(4)
    for scale in (1e-200, 1e-3, 1.0, 1e5, 1e200):
        for J in (rng.normal(size=(30, 30)), np.triu(rng.normal(size=(30, 30)), -1),
                  np.diag(rng.uniform(-1, 1, 30)) + np.diag(rng.normal(size=29) * 1e3, 1)):
            rho = np.abs(np.linalg.eigvals(scale * J)).max()
            bound = radius_bound(scale * J)
            assert np.isfinite(bound) and bound >= rho * (1 - 1e-12), (scale, bound, rho)
    S = rng.normal(size=(40, 40))
    S = S + S.T  # normal: |S^m|_F <= sqrt(N) rho^m
    rho = np.abs(np.linalg.eigvalsh(S)).max()
    assert rho <= radius_bound(S) <= rho * 40 ** (0.5 / 2 ** SQUARINGS) * (1 + 1e-12)
    shift = np.diag(np.ones(9), 1)  # nilpotent: a bound of a power before the zero one
    assert 0.0 < radius_bound(shift) <= np.linalg.norm(np.linalg.matrix_power(shift, 8)) ** (1 / 8)
    assert radius_bound(np.zeros((3, 3))) == 0.0


@pytest.mark.parametrize("root", [1e2, 1e4, 1e5, 1e7])
def test_choose_scheme_decides_as_the_eigenvalues_do(root):
    """The bound only spares the eigenvalues where it rules stiffness out:
    the scheme is the one the spectral radius picks."""
    model, lam, _ = overdamped_plate(root)
    P = pack(model)
    y0 = state_vector([1.0], [0.0])
    stiff_at_start = stiffness(P, y0) * compiled.STIFF_STEP > 3.3
    assert choose_scheme(P, y0) == ("ros34pw2" if stiff_at_start else compiled.EXPLICIT_PAIR)


@pytest.mark.parametrize("closure", ["penalty", "exact"])
def test_ros34pw2_energy_balance_with_damping(closure):
    model = random_branched(0, closure=closure)
    state = State(0.0, np.full(model.n_coords, 0.02), np.zeros(model.n_coords))
    r = simulate(model, SimulationSection(t_end=0.05, method="ros34pw2", rtol=1e-8, atol=1e-10,
                                          samples=21), state)
    assert r.success, r.message
    assert r.scheme == "ros34pw2" and r.njev > 0 and r.nlu >= r.nsteps
    E = r.energy
    total = E["kinetic"] + E["spring"] + E["gravity"] + E["dissipated"] - E["constraint_work"]
    assert E["dissipated"][-1] > 1e-2 * abs(total[0])
    assert np.abs(total - total[0]).max() < 1e-5 * abs(total[0])


def test_ros34pw2_failures_are_data():
    model = random_branched(0)
    state = State(0.0, np.full(model.n_coords, 0.3), np.zeros(model.n_coords))
    settings = SimulationSection(t_end=0.1, method="ros34pw2", samples=11)
    r = simulate(model, settings, state, gap_limit=1e-9)
    assert not r.success and "gap" in r.message
    closed = State(0.0, np.full(model.n_coords, 0.02), np.zeros(model.n_coords))
    r = simulate(model, settings, closed, max_steps=3)
    assert not r.success and "budget" in r.message
    assert np.all(np.isfinite(r.theta))
    with pytest.raises(ModelError, match="^simulation.method: expected one of .* got 'rodas'"):
        simulate(model, SimulationSection(t_end=0.1, method="rodas"), state)
