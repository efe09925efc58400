"""The O(n) path (articulated-body algorithm, structured W-solve) against the
dense one (CRBA mass matrix, numpy solves, dense Jacobian blocks): a random
branched tree with hinges in contact, and the 5 x 6 packing of issue 33 (26
coordinates, one cut hinge) closed by penalty and exactly."""

from pathlib import Path

import numpy as np
import pytest
from numba import njit
from scipy.integrate import solve_ivp

from panel_deploy.build import build_model
from panel_deploy.dynamics import articulated, closure, kernels, rosenbrock, simulate, stiff
from panel_deploy.dynamics.pack import EXACT, PENALTY, TREE, pack
from panel_deploy.model import AirParameters, Body, Model, State, box_inertia
from panel_deploy.scene import SimulationSection, load_scene

from test_dynamics_helpers import SIZE, hinge, near, scratch

SCENE = Path(__file__).resolve().parent.parent / "config" / "scenes" / "paper_4x4.yaml"


def random_tree(n=24, seed=0):
    """n + 1 bodies, each hinged to a random earlier one (a branched tree), random
    inertia, gravity and air."""
    rng = np.random.default_rng(seed)
    bodies = []
    for i in range(n + 1):
        m = rng.uniform(0.01, 0.05)
        X = rng.normal(size=(3, 3))
        bodies.append(Body(f"b{i}", (), SIZE.copy(), m, box_inertia(m, SIZE) + 1e-6 * X @ X.T,
                           rng.uniform(-0.3, 0.3, 3)))
    hinges = [hinge(f"h{i}", int(rng.integers(0, i)), i, rng.uniform(-0.3, 0.3, 3),
                    rng.normal(size=3), k=rng.uniform(0.05, 0.2), c=rng.uniform(0.001, 0.01))
              for i in range(1, n + 1)]
    return Model.build(bodies, hinges, 0, k_s=500.0, c_s=0.3, gravity=(0.3, -9.81, 1.0),
                       air=AirParameters(1.2, 1.17))


def packing_5x6(closure="penalty"):
    """The 5 x 6 first packing circuit of bench/bench_scaling.py."""
    sets = ["array.rows=5", "array.cols=6", "fold.circuit=3", "fold.ground=null",
            f"closure.method={closure}"]
    return build_model(load_scene(SCENE, sets))


MODELS = {"tree": random_tree, "5x6": packing_5x6, "5x6 exact": lambda: packing_5x6("exact")}


@pytest.fixture(scope="module", params=list(MODELS))
def model(request):
    return MODELS[request.param]()


def states(model, count, seed=1, spread=0.05):
    """Near the stowed state (the loop closed), some tree hinges past a limit."""
    rng = np.random.default_rng(seed)
    stowed = State.stowed(model).theta
    n = model.n_coords
    for _ in range(count):
        theta = stowed + rng.normal(0.0, spread, n)
        yield kernels.state_vector(theta, rng.normal(0.0, 2.0, n))


def test_models_take_the_articulated_path(model):
    P = pack(model)
    assert articulated.applies(P.n)
    assert P.method == (TREE if not model.cut_hinges else
                        PENALTY if model.closure.method == "penalty" else EXACT)


@njit
def _buffer_rows(b):
    return b.R.shape[0], b.IA.shape[0], b.closure[1].shape


def test_one_scratch_serves_every_evaluation_of_a_run(model):
    """The O(n) path fills the arrays of the run's scratch (buffers.Buffers)
    in place: at states one after another, rhs with one scratch equals rhs
    with a new one each time, to the bit, and the arrays are sized for the
    model (n joints, 5 constraints per cut hinge of the exact closure, none
    for the penalty one); a model on the dense path gets none."""
    P = pack(model)
    run = scratch(P)
    mc = 5 * len(P.cut_a) if P.method == EXACT else 0
    assert _buffer_rows(run[1]) == (P.n + 1, P.n, (mc, P.n))
    for y in states(model, 6):
        assert np.array_equal(kernels.rhs(P, y, run), kernels.rhs(P, y, scratch(P)))
    dense = pack(random_tree(n=articulated.MIN_N - 1))
    assert not articulated.applies(dense.n)
    assert _buffer_rows(scratch(dense)[1]) == (1, 0, (0, 0))



def test_the_entry_points_from_python_are_the_compiled_ones(model):
    """scipy's solvers call rhs_apart and rhs_jacobian_apart, which take the
    scratch's two parts apart: the same numbers as rhs and rhs_jacobian, to
    the bit."""
    P = pack(model)
    near_part, buffers = scratch(P)
    for y in states(model, 2):
        f = kernels.rhs(P, y, scratch(P))
        assert np.array_equal(kernels.rhs_apart(P, y, near_part, buffers), f)
        assert np.array_equal(kernels.rhs_jacobian_apart(P, y, near_part, buffers),
                              kernels.rhs_jacobian(P, y, f, scratch(P)))


def test_observe_takes_the_dense_energies_without_the_mass_matrix(model):
    """On the O(n) path observe sums the kinetic energy over the bodies: it is
    omega . M omega / 2 with the mass matrix of the dense path, and the other
    energies, the gap and the closure Jacobian are the dense path's."""
    P = pack(model)
    n = P.n
    assert articulated.applies(n)
    run = scratch(P)
    for y in states(model, 3):
        M, _, (R, p, w, vo, S), _, spring, contact, _, _, gravity = kernels.mass_and_bias(
            P, y[:n], y[n:2 * n], near(P))
        kinetic = 0.5 * y[n:2 * n] @ M @ y[n:2 * n]
        got = kernels.observe(P, y, run)
        assert got[0] == pytest.approx(kinetic, rel=1e-12)
        assert got[1:4] == pytest.approx((spring, contact, gravity), rel=1e-12, abs=1e-15)
        if P.method != TREE:
            assert got[4] == closure.largest_gap(P, R, p)
            assert np.array_equal(got[5], kernels.closure_jacobian(P, R, p, w, vo, S, np.zeros((0, 6)))[1])

def test_factor_solve_and_product_are_the_dense_ones(model):
    P = pack(model)
    n = P.n
    rng = np.random.default_rng(2)
    for y in states(model, 3):
        M, _, (R, p, _, _, S), *_ = kernels.mass_and_bias(P, y[:n], y[n:2 * n], near(P))
        Jb, hb = kernels.body_inertias(P, R, p)
        I6 = articulated.inertias(P, Jb, hb)
        arm = rng.uniform(0.0, 2.0, n) * np.diag(M)
        U, D, ok = articulated.factor(P, S, Jb, hb, arm)
        assert ok
        tau = rng.normal(size=n)
        x = np.empty(n)
        articulated.solve(P, S, U, D, tau, x, np.empty((n + 1, 6)))
        ref = np.linalg.solve(M + np.diag(arm), tau)
        assert np.abs(x - ref).max() < 1e-10 * np.abs(ref).max()
        # many right-hand sides in one pass: each row as the single solve, to the bit
        T = np.vstack([tau, rng.normal(size=(4, n))])
        X = np.empty_like(T)
        articulated.solve_rows(P, S, U, D, T, X, np.empty((len(T), n + 1, 6)))
        assert np.array_equal(X[0], x)
        for row, sol in zip(T[1:], X[1:]):
            articulated.solve(P, S, U, D, row, x, np.empty((n + 1, 6)))
            assert np.array_equal(sol, x)
        out = np.empty(n)
        articulated.times(P, S, I6, tau, out, np.empty((2, n + 1, 6)))
        assert np.abs(out - M @ tau).max() < 1e-12 * np.abs(M).max() * np.abs(tau).max()


def test_the_up_pass_gives_the_quadratic_forms_of_the_inverse(model):
    """a . H^-1 b is the sum of the innovations' products over D, from the
    pass up alone (what the exact closure's J M^-1 J^T is taken from), and
    the pass down after it is solve_rows."""
    P = pack(model)
    n = P.n
    rng = np.random.default_rng(4)
    y = next(states(model, 1))
    M, _, (R, p, _, _, S), *_ = kernels.mass_and_bias(P, y[:n], y[n:2 * n], near(P))
    U, D, ok = articulated.factor(P, S, *kernels.body_inertias(P, R, p), np.zeros(n))
    assert ok
    T = rng.normal(size=(4, n))
    E = np.empty_like(T)
    work = np.empty((len(T), n + 1, 6))
    articulated.up_rows(P, S, U, D, T, E, work)
    ref = T @ np.linalg.solve(M, T.T)
    assert np.abs((E / D) @ E.T - ref).max() < 1e-10 * np.abs(ref).max()
    articulated.down_rows(P, S, U, D, E, work)
    X = np.empty_like(T)
    articulated.solve_rows(P, S, U, D, T, X, work)
    assert np.array_equal(E, X)


@pytest.mark.parametrize("rows_per_coordinate", [0.2, 2.0])
def test_w_solve_is_the_dense_solve(model, rows_per_coordinate):
    """``M W v = g`` by Woodbury on the articulated factor (few rows) and by the
    dense LU (rows > DENSE_ROWS n, as in a pressed stack) against numpy, with
    sparse random rows like contact rows (zero off two paths to the root)."""
    P = pack(model)
    n = P.n
    rng = np.random.default_rng(3)
    y = next(states(model, 1))
    M, _, (R, p, _, _, S), *_ = kernels.mass_and_bias(P, y[:n], y[n:2 * n], near(P))
    Jb, hb = kernels.body_inertias(P, R, p)
    r = int(rows_per_coordinate * n)
    U = rng.normal(size=(r, n)) * (rng.uniform(size=(r, n)) < 0.3)
    Kd, Cd = rng.uniform(0, 100, n), rng.uniform(0, 1, n)
    kk, cc = rng.uniform(0, 1e4, r), rng.uniform(0, 10, r)
    hg = 1e-3
    factor = rosenbrock._w_factor(P, hg, S, Jb, hb, Kd, Cd, U, kk, cc)
    assert factor[-2] == (r > rosenbrock.DENSE_ROWS * n) and factor[-1]
    g = rng.normal(size=n)
    v = np.empty(n)
    rosenbrock._w_solve(P, S, factor, U, g, v, np.empty((n + 1, 6)), np.empty(r), np.empty(r))
    W = M + np.diag(hg * Cd + hg ** 2 * Kd) + U.T @ np.diag(hg * cc + hg ** 2 * kk) @ U
    ref = np.linalg.solve(W, g)
    assert np.abs(v - ref).max() < 1e-9 * np.abs(ref).max()


def test_factor_reports_a_singular_mass_matrix():
    model = random_tree(n=20)
    P = pack(model)._replace(mass=np.zeros(20), inertia=np.zeros((20, 3, 3)))
    y = next(states(model, 1))
    assert np.all(np.isnan(kernels.rhs(P, y, scratch(P))))


def dense_dynamics(P, y):
    """qdd, the dissipation, the constraint forces' power and the panel
    contacts' springs' power by numpy: ``M^-1 Q`` from the CRBA mass
    matrix, plus for the exact closure ``M^-1 J^T lambda`` with lambda from
    ``J qdd = -gamma - 2 cdot / T - c / T^2`` (Baumgarte), J M^-1 J^T regularised
    as the package does."""
    n = P.n
    M, Q, (R, p, w, vo, S), acc, _, _, contact_power, dissipation, _ = kernels.mass_and_bias(
        P, y[:n], y[n:2 * n], near(P))
    qdd = np.linalg.solve(M, Q)
    if P.method != EXACT:
        return qdd, dissipation, 0.0, contact_power
    c, J, gamma = closure.closure_jacobian(P, R, p, w, vo, S, acc)
    Y = np.linalg.solve(M, J.T)
    G = J @ Y
    G += np.eye(len(c)) * (P.regularisation * np.diag(G).max() + 1e-300)
    T = P.baumgarte
    cdot = J @ y[n:2 * n]
    lam = np.linalg.solve(G, -gamma - 2.0 / T * cdot - c / T ** 2 - J @ qdd)
    return qdd + Y @ lam, dissipation, lam @ cdot, contact_power


def test_rhs_is_the_dense_solve(model):
    """The ABA forward dynamics, exact closure included, against numpy's dense
    solves, with the dissipation and the closure work rows."""
    P = pack(model)
    n = P.n
    for y in states(model, 4):
        qdd, dissipation, power, contact_power = dense_dynamics(P, y)
        f = kernels.rhs(P, y, scratch(P))
        assert np.abs(f[n:2 * n] - qdd).max() < 1e-9 * np.abs(qdd).max()
        assert np.array_equal(f[:n], y[n:2 * n])
        assert f[2 * n] == dissipation
        assert f[2 * n + 1] == pytest.approx(power, rel=1e-8, abs=1e-12)
        assert f[2 * n + 2] == contact_power
        assert (power != 0.0) == (P.method == EXACT)


@pytest.mark.parametrize("h", [1e-5, 1e-4, 1e-3])
def test_structured_w_step_is_the_dense_step(model, h):
    """One ROS34PW2 step with the O(n) W-solve against the step with the dense blocks
    A = -M^-1 K, B = -M^-1 C of the same K, C (stiff.stiff_jacobian). (For the
    exact closure the dense blocks add the constraint's projection, which the
    O(n) W leaves out: a W-method's order does not depend on its matrix; the
    simulation test below checks that path.)"""
    P = pack(model)
    if P.method == EXACT:
        pytest.skip("the dense blocks of the exact closure are another W")
    N = 2 * P.n + kernels.ACCUMULATORS
    for y in states(model, 3):
        f = kernels.rhs(P, y, scratch(P))
        A, B, ok = stiff.stiff_jacobian(P, y, near(P))
        assert ok
        y_dense, e_dense, ok_dense = rosenbrock.step(P, y, f, h, A, B, np.empty((7, N)), scratch(P))
        y_aba, e_aba, ok_aba = rosenbrock.step_terms(P, y, f, h, rosenbrock.terms(P, y, near(P)),
                                                     np.empty((7, N)), scratch(P))
        assert ok_dense and ok_aba
        # the error estimate is a difference of stages: its round-off scales with the step
        scale = np.abs(y_dense - y).max()
        assert np.abs(y_aba - y_dense).max() < 1e-9 * scale
        assert np.abs(e_aba - e_dense).max() < 1e-9 * scale
        assert np.abs(e_dense).max() > 1e-6 * scale


def dense_rhs(P):
    """The deployment ODE with numpy's dense solves (:func:`dense_dynamics`), for scipy."""
    n = P.n

    def fun(t, y):
        qdd, *integrands = dense_dynamics(P, y)
        return np.concatenate([y[n:2 * n], qdd, integrands])
    return fun


def test_short_simulation_follows_the_dense_reference(model):
    """ROS34PW2 on the O(n) path against DOP853 on the dense ODE, 10 ms from a
    perturbed stowed state (both well inside their tolerances of each other)."""
    P = pack(model)
    n = P.n
    y0 = next(states(model, 1, seed=5, spread=0.02))
    y0[n:2 * n] *= 0.1
    t = np.linspace(0.0, 0.01, 11)
    ref = solve_ivp(dense_rhs(P), (0.0, 0.01), y0, method="DOP853", t_eval=t, rtol=1e-10, atol=1e-12)
    assert ref.success
    r = simulate(model, SimulationSection(t_end=0.01, method="ros34pw2", rtol=1e-7, atol=1e-9,
                                          samples=11), State(0.0, y0[:n], y0[n:2 * n]))
    assert r.success, r.message
    moved = np.abs(ref.y[:n, -1] - y0[:n]).max()
    assert moved > 1e-4
    assert np.abs(r.theta - ref.y[:n].T).max() < 1e-5 * moved
