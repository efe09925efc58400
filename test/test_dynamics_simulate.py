"""simulate(): one hinged plate against its scalar ODE, energy balance, failure path."""

import dataclasses

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

from panel_deploy.build import build_model
from panel_deploy.dynamics import Status, simulate, simulate_segments
from panel_deploy.dynamics.report import balance_error, total_energy
from panel_deploy.dynamics.result import ENERGY_LIMIT, PER_SAMPLE, concatenate
from panel_deploy.errors import ModelError
from panel_deploy.kinematics import axis_rotation
from panel_deploy.model import AirParameters, State
from panel_deploy.scene import SimulationSection, load_scene, resolve_scene

from test_dynamics_helpers import overdamped_plate, plate_on_hinge, random_branched


def plate_reference(model, theta0, t):
    """I_h thetadd = -k theta - c thetadot + gravity torque about the fixed hinge axis."""
    h = model.hinges[0]
    body = model.bodies[1]
    r0 = body.flat_position - h.point
    I_h = h.axis @ (body.inertia + body.mass * (r0 @ r0 * np.eye(3) - np.outer(r0, r0))) @ h.axis

    def f(_, x):
        r = axis_rotation(h.axis, x[0]) @ r0
        tau_g = h.axis @ np.cross(r, body.mass * model.gravity)
        return [x[1], (-h.k_hinge * x[0] - h.c_hinge * x[1] + tau_g) / I_h]

    return solve_ivp(f, (0, t[-1]), [theta0, 0.0], t_eval=t, rtol=1e-12, atol=1e-12).y


@pytest.mark.parametrize("method", ["RK45", "dopri5", "tsit5", "ros34pw2", "Radau"])
@pytest.mark.parametrize("gravity", [(0.0, 0.0, 0.0), (0.0, 0.0, 9.81)])
def test_plate_matches_scalar_ode(method, gravity):
    # damping keeps the plate inside [0, pi] (no contact): zeta ~ 1 without gravity;
    # with gravity pulling it up the equilibrium is at ~0.1 rad
    model = plate_on_hinge(c=0.0043 if any(gravity) else 0.02, gravity=gravity)
    state = State(0.0, np.array([1.0]), np.zeros(1))
    r = simulate(model, SimulationSection(t_end=0.3, method=method, rtol=1e-9, atol=1e-11,
                                          samples=61), state)
    assert r.success, r.message
    ref = plate_reference(model, 1.0, r.t)
    assert r.theta.min() > 0
    assert np.abs(r.theta[:, 0] - ref[0]).max() < 1e-6
    assert np.abs(r.omega[:, 0] - ref[1]).max() < 1e-4
    # the plate's centroid stays on its circle about the hinge line
    h = model.hinges[0]
    r0 = model.bodies[1].flat_position - h.point
    expected = h.point + np.array([axis_rotation(h.axis, th) @ r0 for th in ref[0]])
    assert np.abs(r.position[:, 1] - expected).max() < 1e-7


@pytest.mark.parametrize("method", ["RK45", "compiled"])
def test_parallel_springs_add(method):
    # two springs of k, c on one hinge line act as one of 2 k, 2 c
    model = plate_on_hinge(k=0.05, c=0.01, springs=2)
    state = State(0.0, np.array([1.0]), np.zeros(1))
    r = simulate(model, SimulationSection(t_end=0.3, method=method, rtol=1e-9, atol=1e-11,
                                          samples=61), state)
    assert r.success, r.message
    single = plate_on_hinge(k=0.1, c=0.02)
    assert np.abs(r.theta[:, 0] - plate_reference(single, 1.0, r.t)[0]).max() < 1e-6
    assert r.energy["spring"][0] == pytest.approx(0.5 * 0.1 * 1.0**2)


def undamped(model):
    hinges = tuple(dataclasses.replace(h, c=0.0) for h in model.hinges)
    closure = dataclasses.replace(model.closure, c_M=0.0, c_N=0.0)
    return dataclasses.replace(model, hinges=hinges, c_s=0.0, closure=closure)


@pytest.mark.parametrize("method", ["DOP853", "compiled"])
def test_energy_conserved_without_damping(method):
    """Branched tree with a penalty loop, gravity and contact springs, no dampers."""
    model = undamped(random_branched(0))
    state = State(0.0, np.full(model.n_coords, 0.02), np.zeros(model.n_coords))
    r = simulate(model, SimulationSection(t_end=0.05, method=method, rtol=1e-10, atol=1e-12,
                                          samples=21), state)
    assert r.success, r.message
    E = total_energy(r.energy)
    assert np.ptp(r.energy["kinetic"]) > 1e-3 * abs(E[0])  # it does move
    assert np.all(r.energy["dissipated"] == 0)
    assert np.abs(E - E[0]).max() < 1e-6 * abs(E[0])


@pytest.mark.parametrize("closure", ["penalty", "exact"])
def test_dissipated_energy_closes_balance(closure):
    model = random_branched(0, closure=closure)
    state = State(0.0, np.full(model.n_coords, 0.02), np.zeros(model.n_coords))
    r = simulate(model, SimulationSection(t_end=0.05, method="compiled", rtol=1e-10,
                                          atol=1e-12, samples=21), state)
    assert r.success, r.message
    E = total_energy(r.energy)
    assert r.energy["dissipated"][-1] > 1e-2 * abs(E[0])
    assert np.abs(E - E[0]).max() < 1e-6 * abs(E[0])


AIR = AirParameters(1.2, 1.17)


def swing(model, method="compiled", t_end=1.0):
    """The panel of ``plate_on_hinge`` released at theta = 0.3 rad, at rest."""
    state = State(0.0, np.array([0.3]), np.zeros(1))
    r = simulate(model, SimulationSection(t_end=t_end, method=method, rtol=1e-10, atol=1e-12,
                                          samples=101), state)
    assert r.success, r.message
    return r


@pytest.mark.parametrize("method", ["RK45", "Radau", "dopri5", "tsit5", "ros34pw2"])
def test_air_drag_only_removes_energy(method):
    """A pendulum (no spring, no damper; gravity across the horizontal hinge axis,
    equilibrium at theta = pi/2, swinging within (0, pi)) loses energy to the air
    alone, and the balance counts it as dissipated."""
    still = plate_on_hinge(k=0.0, c=0.0, gravity=(0.0, 0.0, 9.81))
    r = swing(dataclasses.replace(still, air=AIR), method)
    assert 0 < r.theta.min() and r.theta.max() < np.pi
    mechanical = r.energy["kinetic"] + r.energy["spring"] + r.energy["gravity"]
    assert np.all(np.diff(r.energy["dissipated"]) >= 0)
    assert r.energy["dissipated"][-1] > 1e-3 * abs(total_energy(r.energy)[0])
    assert balance_error(r) < 1e-6 < ENERGY_LIMIT
    without = swing(still, method)
    assert np.all(without.energy["dissipated"] == 0)
    assert mechanical[-1] < (without.energy["kinetic"] + without.energy["gravity"])[-1]


@pytest.mark.parametrize("closure", ["penalty", "exact"])
def test_air_drag_closes_the_balance_with_either_closure(closure):
    model = dataclasses.replace(random_branched(0, closure=closure), air=AIR)
    state = State(0.0, np.full(model.n_coords, 0.02), np.zeros(model.n_coords))
    r = simulate(model, SimulationSection(t_end=0.05, method="compiled", rtol=1e-10,
                                          atol=1e-12, samples=21), state)
    assert r.success, r.message
    E = total_energy(r.energy)
    assert np.abs(E - E[0]).max() < 1e-6 * abs(E[0])
    dampers = simulate(random_branched(0, closure=closure),
                       SimulationSection(t_end=0.05, method="compiled", rtol=1e-10, atol=1e-12,
                                         samples=21), state)
    assert r.energy["dissipated"][-1] > dampers.energy["dissipated"][-1]


def test_step_budget_failure_returns_finite_partial_result():
    model = plate_on_hinge()
    r = simulate(model, SimulationSection(t_end=1.0, method="compiled", samples=101), max_steps=20)
    assert not r.success and r.status == Status.BUDGET_EXHAUSTED
    assert "budget" in r.message
    assert 1 <= len(r.t) < 101
    assert r.theta.shape == (len(r.t), 1) and r.position.shape[0] == len(r.t)
    assert np.all(np.isfinite(r.theta)) and np.all(np.isfinite(r.position))


@pytest.mark.parametrize("method", ["RK23", "compiled"])
def test_energy_drift_fails_the_run_at_its_first_sample_over_the_limit(method):
    # issue 33: every damper at 0 and a loose rtol created 26 % of the energy and
    # the run said "ok". An undamped plate swinging into its stiff stop at rtol 1e-2
    # drifts by ~10 % by 0.05 s; at rtol 1e-8 the same run keeps its energy.
    model = plate_on_hinge(c=0.0, c_s=0.0)
    state = State(0.0, np.array([1.0]), np.zeros(1))
    settings = SimulationSection(t_end=1.0, method=method, rtol=1e-2, atol=1e-4, samples=101)
    r = simulate(model, settings, state)
    assert not r.success and r.status == Status.ENERGY_DRIFT
    assert "energy balance error" in r.message and "tighten simulation.rtol" in r.message
    E = total_energy(r.energy)
    error = np.abs(E - E[0]) / abs(E[0])
    assert 2 <= len(r.t) < 101 and error[-1] > ENERGY_LIMIT and np.all(error[:-1] <= ENERGY_LIMIT)
    assert np.all(np.isfinite(r.theta)) and np.all(np.isfinite(r.position))
    # in blocks: the same samples, the failure in the last block
    blocks = list(simulate_segments(model, settings, state, segment_samples=3))
    assert not blocks[-1].success and blocks[-1].status == Status.ENERGY_DRIFT
    assert np.array_equal(np.concatenate([b.theta for b in blocks]), r.theta)
    tight = simulate(model, dataclasses.replace(settings, rtol=1e-8, atol=1e-10), state)
    assert tight.success, tight.message


@pytest.mark.parametrize("method", ["RK23", "compiled"])
def test_gap_blow_up_stops_the_run(method):
    model = random_branched(0)
    state = State(0.0, np.full(model.n_coords, 0.3), np.zeros(model.n_coords))
    r = simulate(model, SimulationSection(t_end=0.1, method=method, samples=11), state,
                 gap_limit=1e-9)
    assert not r.success and r.status == Status.GAP_EXCEEDED
    assert "gap" in r.message
    assert np.all(np.isfinite(r.theta)) and np.all(np.isfinite(r.energy["kinetic"]))


def test_step_size_collapse_has_its_own_status():
    # a tolerance below round-off: the first step cannot be accepted
    r = simulate(plate_on_hinge(), SimulationSection(t_end=0.1, method="compiled", rtol=1e-30,
                                                     atol=1e-30, samples=11))
    assert not r.success and r.status == Status.STEP_COLLAPSE
    assert np.all(np.isfinite(r.theta))


@pytest.mark.parametrize("method, k", [("compiled", 1e308), ("RK45", 1e308), ("Radau", 1e300)])
@pytest.mark.filterwarnings("ignore::RuntimeWarning")  # scipy's own step-size guesses overflow
def test_overflowing_forces_end_as_non_finite(method, k):
    # the spring torque k theta overflows at the start (compiled, RK45) or
    # in Radau's Newton iteration: a status, never an exception or NaN samples
    r = simulate(plate_on_hinge(k=k), SimulationSection(t_end=0.1, method=method, samples=11),
                 State(0.0, np.array([1.0]), np.zeros(1)))
    assert not r.success and r.status == Status.NON_FINITE
    assert len(r.t) >= 1 and np.all(np.isfinite(r.theta))


def test_bad_state_is_misuse():
    model = plate_on_hinge()
    with pytest.raises(ModelError):
        simulate(model, SimulationSection(), State(0.0, np.zeros(2), np.zeros(2)))
    with pytest.raises(ModelError):
        simulate(model, SimulationSection(t_end=1.0), State(2.0, np.zeros(1), np.zeros(1)))


@pytest.mark.parametrize("method", ["RK45", "compiled"])
def test_segments_continue_one_run(method):
    # Blocks of 7 samples continue one integration: the grid and the samples
    # are the one-shot run's, bit for bit, and the closed form holds across
    # the block boundaries.
    model = plate_on_hinge(gravity=(0.0, 0.0, 9.81))
    settings = SimulationSection(t_end=0.5, method=method, rtol=1e-9, atol=1e-11, samples=51)
    whole = simulate(model, settings)
    blocks = list(simulate_segments(model, settings, segment_samples=7))
    assert [len(b.t) for b in blocks] == [8] + [7] * 6 + [1]
    t = np.concatenate([b.t for b in blocks])
    theta = np.concatenate([b.theta for b in blocks])
    np.testing.assert_array_equal(t, whole.t)
    np.testing.assert_array_equal(theta, whole.theta)
    np.testing.assert_allclose(theta[:, 0], plate_reference(model, np.pi, t)[0], atol=1e-7)
    assert all(b.success for b in blocks)
    # Dissipated energy is carried across blocks, not restarted.
    E = np.concatenate([b.energy["dissipated"] for b in blocks])
    np.testing.assert_array_equal(E, whole.energy["dissipated"])


def test_segments_stop_at_a_failure_and_share_one_budget():
    model = plate_on_hinge()
    settings = SimulationSection(t_end=1.0, method="compiled", samples=101)
    blocks = list(simulate_segments(model, settings, segment_samples=10, max_steps=25))
    assert all(b.success for b in blocks[:-1]) and not blocks[-1].success
    assert "budget" in blocks[-1].message
    assert sum(b.nsteps for b in blocks) <= 25
    assert sum(len(b.t) for b in blocks) < 101


@pytest.mark.parametrize("bad", [0, -3, 2.5, "10"])
def test_segment_size_is_checked(bad):
    with pytest.raises(ModelError, match="segment_samples"):
        next(simulate_segments(plate_on_hinge(), SimulationSection(), segment_samples=bad))


# --- blocks are one integration: joined, they are simulate() bit for bit ---


def assert_same_run(blocks, whole):
    joined = concatenate(blocks)
    for name in PER_SAMPLE:
        assert np.array_equal(getattr(joined, name), getattr(whole, name), equal_nan=True), name
    assert joined.energy.keys() == whole.energy.keys()
    for name in whole.energy:
        assert np.array_equal(joined.energy[name], whole.energy[name]), name
    for name in ("nfev", "njev", "nlu", "nsteps", "nswitches", "scheme", "gap_limit"):
        assert getattr(joined, name) == getattr(whole, name), name
    assert (joined.success, joined.status, joined.message) == (
        whole.success, whole.status, whole.message)
    assert all(b.success for b in blocks[:-1])


@pytest.fixture(scope="module")
def paper():
    scene = load_scene(resolve_scene("paper_4x4"))
    return build_model(scene), scene.simulation


@pytest.mark.parametrize("method, scheme, t_end, samples, block", [
    ("compiled", "ros34pw2", 0.5, 101, 7),  # the paper scene is stiff at the start
    ("dopri5", "dopri5", 0.5, 101, 7),
    ("tsit5", "tsit5", 0.5, 101, 7),
    ("RK45", "RK45", 0.05, 21, 4),
    ("Radau", "Radau", 0.03, 13, 4),
])
def test_paper_segments_are_simulate_bit_for_bit(paper, method, scheme, t_end, samples, block):
    model, sim = paper
    settings = dataclasses.replace(sim, method=method, t_end=t_end, samples=samples)
    whole = simulate(model, settings)
    assert whole.success, whole.message
    assert (whole.method, whole.scheme) == (method, scheme)
    blocks = list(simulate_segments(model, settings, segment_samples=block))
    last = samples - 1
    assert [len(b.t) for b in blocks] == (
        [block + 1] + [block] * ((last - 1) // block - 1) + [last - (last - 1) // block * block])
    assert all(b.nsteps > 0 for b in blocks)
    assert sum(b.nsteps for b in blocks) == whole.nsteps
    assert_same_run(blocks, whole)


def test_a_run_that_hands_over_is_simulate_bit_for_bit_in_blocks():
    """The hand-over from tsit5 to ROS34PW2 of method compiled (at ~0.017 s here)
    falls inside the second block; the blocks after it continue on ROS34PW2."""
    model, _, _ = overdamped_plate()
    settings = SimulationSection(t_end=0.5, method="compiled", rtol=1e-6, atol=1e-9, samples=51)
    state = State(0.0, np.array([1.0]), np.zeros(1))
    whole = simulate(model, settings, state)
    assert whole.success and whole.scheme.startswith("tsit5, then ros34pw2 from t = ")
    blocks = list(simulate_segments(model, settings, state, segment_samples=1))
    assert blocks[0].scheme == "tsit5" and blocks[-1].scheme == whole.scheme
    assert_same_run(blocks, whole)


def test_ros34pw2_steps_past_a_block():
    # A long ROS34PW2 step fills several 1-sample blocks at once: the blocks it
    # filled ahead cost no steps, and the run is still simulate()'s.
    model = plate_on_hinge(c=0.02)
    state = State(0.0, np.array([1.0]), np.zeros(1))
    settings = SimulationSection(t_end=0.3, method="ros34pw2", rtol=1e-4, atol=1e-6, samples=61)
    whole = simulate(model, settings, state)
    blocks = list(simulate_segments(model, settings, state, segment_samples=1))
    assert [len(b.t) for b in blocks] == [2] + [1] * 59
    assert any(b.nsteps == 0 for b in blocks)
    assert_same_run(blocks, whole)


@pytest.mark.parametrize("method, t_end, max_steps", [
    ("compiled", 0.5, 700), ("dopri5", 0.5, 2000), ("RK45", 0.05, 600)])
def test_paper_segments_fail_where_simulate_fails(paper, method, t_end, max_steps):
    model, sim = paper
    # the budgets are sized for rtol 1e-4 (stated: the scene's rtol may change)
    settings = dataclasses.replace(sim, method=method, t_end=t_end, samples=101, rtol=1e-4,
                                   atol=1e-6)
    whole = simulate(model, settings, max_steps=max_steps)
    assert not whole.success and "budget" in whole.message
    assert 8 < len(whole.t) < 101  # it fails after the first block
    blocks = list(simulate_segments(model, settings, segment_samples=7, max_steps=max_steps))
    assert not blocks[-1].success and blocks[-1].status == Status.BUDGET_EXHAUSTED
    assert sum(b.nsteps for b in blocks) == whole.nsteps == max_steps
    assert_same_run(blocks, whole)


def test_the_scene_schema_offers_exactly_the_registered_integrators():
    from panel_deploy.dynamics.integrate import METHODS
    from panel_deploy.scene import INTEGRATORS
    assert tuple(METHODS) == INTEGRATORS
    assert all(m.name == name and m.description for name, m in METHODS.items())


@pytest.mark.parametrize("method", ["compiled", "RK45"])
def test_a_division_by_an_underflowed_zero_ends_as_non_finite(method):
    # 1 / T^2 of the exact closure's stabilisation with T = 1e-300: numba and
    # python raise ZeroDivisionError; the run fails as data, not with a traceback
    model = random_branched(0, closure="exact")
    model = dataclasses.replace(model, closure=dataclasses.replace(model.closure, baumgarte=1e-300))
    state = State(0.0, np.full(model.n_coords, 0.02), np.zeros(model.n_coords))
    r = simulate(model, SimulationSection(t_end=0.01, method=method, samples=5), state)
    assert not r.success and r.status == Status.NON_FINITE
    assert np.all(np.isfinite(r.theta))


@pytest.mark.parametrize("method", ["compiled", "RK45"])
def test_a_run_on_pace_to_need_a_hundred_budgets_ends_early(method):
    # max_step 1e-7 s over 1 s needs 1e7 steps, 500 budgets of 20 000: that
    # shows at the first pace check (1000 steps), not at step 20 000
    model = plate_on_hinge()
    state = State(0.0, np.array([1.0]), np.zeros(1))
    settings = SimulationSection(t_end=1.0, method=method, max_step=1e-7, samples=11)
    r = simulate(model, settings, state, max_steps=20_000)
    assert not r.success and r.status == Status.BUDGET_EXHAUSTED
    assert "on pace to need over 100 times the step budget" in r.message
    assert r.nsteps == 1000
    # 1e-5 s: 1e5 steps, 5 budgets: it runs to the end of its budget
    r = simulate(model, dataclasses.replace(settings, max_step=1e-5), state, max_steps=20_000)
    assert not r.success and "on pace" not in r.message and r.nsteps == 20_000


def test_a_tolerance_below_double_precision_ends_in_seconds_not_minutes():
    # steps of ~1e-14 s: the pace shows at the first check
    model = plate_on_hinge()
    state = State(0.0, np.array([1.0]), np.zeros(1))
    r = simulate(model, SimulationSection(t_end=1.0, method="compiled", rtol=1e-13, atol=1e-300,
                                          samples=11), state)
    assert not r.success and r.status == Status.BUDGET_EXHAUSTED and "on pace" in r.message
    assert r.nsteps == 2_000_000 // 100


@pytest.mark.parametrize("ramp", [0.0, 4e-4, 4e-3])
def test_plate_settles_on_its_stop_where_the_stop_law_balances_gravity(ramp):
    """Gravity lays the plate on its flat stop (theta < 0): it settles where the
    hinge spring, the stop's spring (contact.stop_ramp: within the ramp, past
    it, or none) and gravity's torque about the hinge line balance."""
    model = dataclasses.replace(plate_on_hinge(k_s=10.0, c_s=0.05, gravity=(0.0, 0.0, -9.81)),
                                stop_ramp=ramp)
    h, body = model.hinges[0], model.bodies[1]
    r0 = body.flat_position - h.point

    def torque(theta):
        a, D = -theta, ramp
        x = a / D if D else 1.0
        stop = 10.0 * D * (x**3 - 0.5 * x**4) if a < D else 10.0 * (a - 0.5 * D)
        tau_g = h.axis @ np.cross(axis_rotation(h.axis, theta) @ r0, body.mass * model.gravity)
        return -h.k_hinge * theta + stop + tau_g

    rest = brentq(torque, -0.05, 0.0)
    r = simulate(model, SimulationSection(t_end=3.0, method="compiled", rtol=1e-9, atol=1e-12,
                                          samples=31), State(0.0, np.array([0.2]), np.zeros(1)))
    assert r.success, r.message
    assert r.theta[:, 0].min() < 0                      # it did fall onto the stop
    assert r.theta[-1, 0] == pytest.approx(rest, abs=1e-9)
    assert abs(r.omega[-1, 0]) < 1e-8
    E = total_energy(r.energy)
    assert np.abs(E - E[0]).max() < 1e-6 * np.ptp(r.energy["gravity"])
