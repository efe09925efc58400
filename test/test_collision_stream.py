"""panel_deploy.collision.stream and .sensing: a live stream as a real array sends it
(epoch and unfilled stamps, gaps, noise, hinges it does not carry), checked
against the clean batch check of the same deployment."""

import math
import resource

import numpy as np
import pytest

from panel_deploy.build import build_model
from panel_deploy.collision import CollisionSettings, StreamCheck, check_trajectory
from panel_deploy.collision.refine import MAX_DEPTH
from panel_deploy.collision.stream import KEEP, onset_fields
from panel_deploy.dynamics import simulate
from panel_deploy.dynamics.report import hinge_states
from panel_deploy.errors import TrajectoryError
from panel_deploy.configure import DynamicsParameters, configure
from panel_deploy.timing import Throttle
from panel_deploy.scene import load_scene, resolve_scene
from panel_deploy.sensing import LoopSolver

#: The paper scene's first collision (test_dynamics_paper pins it at 200 Hz).
FIRST_PAIR = ("r1c2+r1c3", "r2c2+r2c3")


@pytest.fixture(scope="module")
def scene():
    return load_scene(resolve_scene("paper_4x4"))


def _run(scene, rate_hz, t_end=0.5, closure=""):
    s, model = configure(scene, DynamicsParameters(t_end=t_end, rate_hz=rate_hz, closure=closure))
    return s, model, simulate(model, s.simulation)


@pytest.fixture(scope="module")
def khz(scene):
    """The paper deployment to just past its first collision at 1 kHz."""
    return _run(scene, 1000.0)


@pytest.fixture(scope="module")
def clean(khz):
    s, model, result = khz
    return check_trajectory(model, result, CollisionSettings.from_scene(s)).first_collision


def _feed(model, settings, t, theta, omega=None):
    stream = StreamCheck(model, settings)
    first = None
    for j in range(len(t)):
        events = stream.update(t[j], theta[j], None if omega is None else omega[j])
        if events and first is None:
            first = events[0]
    return stream, first


def test_stream_matches_the_batch_check_and_restarts(scene):
    s, model, result = _run(scene, 200.0)
    settings = CollisionSettings.from_scene(s)
    batch = check_trajectory(model, result, settings)
    stream = StreamCheck(model, settings)
    for _ in range(2):  # the second pass starts again at t = 0: a new deployment
        for j in range(len(result.t)):
            stream.update(result.t[j], result.theta[j], result.omega[j])
        first = stream.check.first_events[0]
        assert first.names == batch.first_collision.names and first.t == batch.first_collision.t
        level, message, values = stream.verdict()
        assert level == 2 and values["first_collision_pair"] == list(first.names)
        assert values["approach_speed"] == pytest.approx(batch.v, rel=1e-12)
    assert stream.deployments == 2
    with pytest.raises(TrajectoryError, match="header.stamp"):
        stream.update(result.t[50], result.theta[50], result.omega[50])


def test_every_verdict_value_is_finite_or_none(scene):
    """No ``inf`` on /diagnostics: a distance not computed yet (or beyond the broad
    phase) is None, as ``d`` is before there is one."""
    s, model, result = _run(scene, 200.0)
    stream = StreamCheck(model, CollisionSettings.from_scene(s))
    seen = set()
    for j in range(len(result.t)):
        stream.update(result.t[j], result.theta[j], result.omega[j])
        values = stream.verdict()[2]
        for key, value in values.items():
            for x in (value if isinstance(value, list) else [value]):
                if isinstance(x, float):
                    assert math.isfinite(x), (key, x, j)
        seen.add(values["distance_now"] is None)
    assert False in seen  # a distance is reported where one is computed


def test_epoch_stamps_with_sub_microsecond_spacing_stay_bounded(khz, clean):
    """Wall-clock stamps (1.76e9 s) arriving in bursts 0.3 us apart: the
    between-sample search used to halve such intervals forever (1 GB stacks)."""
    s, model, result = khz
    rng = np.random.default_rng(1)
    ns = 1_764_000_000_000_000_000 + np.cumsum(rng.choice([300, 1000, 500_000, 2_000_000],
                                                           size=len(result.t)))
    stamps = ns // 10**9 + (ns % 10**9) * 1e-9
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    stream, first = _feed(model, CollisionSettings.from_scene(s), stamps, result.theta)
    grown_mb = (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before) / 1024
    assert len(stream.check.monitor._stack[3]) <= MAX_DEPTH
    assert grown_mb < 50
    assert stream.check.checked == len(result.t)
    assert stream.origin == stamps[0] and first is not None
    # Times count from the first stamp: a deployment time, not an epoch.
    assert 0 < first.t < 2.0


def test_unfilled_stamps_are_refused_not_new_deployments(khz):
    s, model, result = khz
    stream = StreamCheck(model, CollisionSettings.from_scene(s))
    stream.update(0.0, result.theta[0])
    for j in range(1, 50):
        with pytest.raises(TrajectoryError, match="header.stamp"):
            stream.update(0.0, result.theta[j])
        stream.refuse("header.stamp")
    level, message, values = stream.verdict()
    assert stream.deployments == 1 and level == 1
    assert values["refused"] == 49 and "49 joint states refused" in message


def test_a_gap_is_counted_and_reported(khz, clean):
    s, model, result = khz
    keep = (result.t < clean.t - 0.09) | (result.t > clean.t + 0.01)  # 100 ms missing over the impact
    stream, first = _feed(model, CollisionSettings.from_scene(s), result.t[keep], result.theta[keep],
                          result.omega[keep])
    level, message, values = stream.verdict()
    assert stream.gaps == 1 and values["largest_gap"] == pytest.approx(0.101, abs=1.5e-3)
    assert first is not None and level == 2
    clean_stream, _ = _feed(model, CollisionSettings.from_scene(s), result.t, result.theta,
                            result.omega)
    assert clean_stream.gaps == 0 and clean_stream.verdict()[0] == 2


def test_skipped_samples_are_counted_never_gaps_and_d_is_an_upper_bound(khz, clean):
    """The monitor's rule above its capacity, skipping all it may: at most a
    5 ms span (the scene's sample interval) between checked 1 kHz samples, the
    first collision found as at 200 Hz, the verdict says how many were
    skipped, and d is never below the full check's."""
    s, model, result = khz
    settings = CollisionSettings.from_scene(s)
    full, _ = _feed(model, settings, result.t, result.theta, result.omega)
    stream, first, checked = StreamCheck(model, settings), None, 0
    for j, t in enumerate(result.t):
        if stream.skip(t, 0.005):
            continue
        checked += 1
        events = stream.update(t, result.theta[j], result.omega[j])
        first = first or (events[0] if events else None)
    assert not StreamCheck(model, settings).skip(0.0, 1.0)  # a deployment's first is checked
    assert stream.skipped + checked == len(result.t) and stream.gaps == 0
    assert len(result.t) / 6 <= checked <= len(result.t) / 5 + 2  # 5 or 6 ms apart
    assert first is not None and set(first.names) == set(FIRST_PAIR)
    assert first.t == pytest.approx(clean.t, abs=1e-3)
    level, message, values = stream.verdict()
    assert level == 2 and values["skipped"] == stream.skipped == len(result.t) - checked
    d_full, d_skipped = full.check.d, stream.check.d
    assert d_skipped >= d_full - 1e-12
    # Before the collision, the same rule gives a WARN verdict that names the skips.
    early = StreamCheck(model, settings)
    for j in np.flatnonzero(result.t < 0.3):
        if not early.skip(result.t[j], 0.005):
            early.update(result.t[j], result.theta[j], result.omega[j])
    level, message, values = early.verdict()
    assert level == 1 and "skipped to keep up" in message and "upper bound" in message


def test_approach_speed_on_a_fixed_grid_is_rate_independent(scene):
    """Eq. (7) over 5 ms whatever the rate: 200 Hz and 1 kHz streams agree,
    and on the 200 Hz grid it is Eq. (7) of the samples themselves."""
    speeds = {}
    for rate in (200.0, 1000.0):
        s, model, result = _run(scene, rate)
        plain = check_trajectory(model, result, CollisionSettings.from_scene(s))
        gridded = check_trajectory(model, result, CollisionSettings.from_scene(s, speed_interval=0.005))
        assert gridded.first_collision.names == plain.first_collision.names == FIRST_PAIR
        speeds[rate] = (plain.v, gridded.v)
    assert speeds[200.0][1] == pytest.approx(speeds[200.0][0], rel=1e-9)
    assert speeds[200.0][0] == pytest.approx(4.23, abs=0.01)
    assert abs(speeds[1000.0][0] - speeds[200.0][0]) > 0.1          # Eq. (7) of the samples
    assert speeds[1000.0][1] == pytest.approx(speeds[200.0][1], rel=0.01)  # on the 5 ms grid


@pytest.mark.parametrize("sigma", [1e-4, 1e-3, 3e-3])
def test_noise_aware_check_has_no_false_alarm_and_finds_the_impact(khz, clean, sigma):
    s, model, result = khz
    clean_stream, _ = _feed(model, CollisionSettings.from_scene(s), result.t, result.theta)
    impact = {e.names for e in clean_stream.check.monitor.events if e.t <= clean.t + 0.005}
    rng = np.random.default_rng(7)
    noisy = result.theta + rng.normal(0.0, sigma, result.theta.shape)
    _, first = _feed(model, CollisionSettings.from_scene(s, noise=sigma), result.t, noisy)
    assert first is not None and first.names in impact
    # The depth noise can fake grows with sigma: about 1 ms later per mrad at 4 m/s.
    assert 0.0 <= first.t - clean.t <= 1e-3 * (1.0 + 1e3 * sigma)


def test_noise_blind_check_raises_false_alarms(khz, clean):
    """What the noise parameter is for: the same stream with noise 0 reports a
    collision long before the real one."""
    s, model, result = khz
    noisy = result.theta + np.random.default_rng(7).normal(0.0, 1e-3, result.theta.shape)
    _, first = _feed(model, CollisionSettings.from_scene(s, refine=False), result.t, noisy)
    assert first is not None and first.t < clean.t - 0.05


def test_a_tolerance_that_takes_touching_panels_for_colliding_is_refused():
    # issue 33: at tolerance 0 the stowed stacks, whose panels touch (distance 0),
    # collided the moment they moved; the scene key and the library refuse it alike
    from panel_deploy.errors import SceneError
    from panel_deploy.scene import MIN_COLLISION_TOLERANCE
    for bad in (0.0, -1e-4, 1e-12, math.nan):
        with pytest.raises(SceneError, match="collision.tolerance: expected a number >= 1e-09"):
            CollisionSettings(tolerance=bad)
    assert CollisionSettings(tolerance=MIN_COLLISION_TOLERANCE).tolerance == 1e-9


def test_noise_setting_is_checked():
    with pytest.raises(Exception, match="collision.noise"):
        CollisionSettings(noise=-1e-3)
    with pytest.raises(Exception, match="collision.noise"):
        CollisionSettings(noise=math.inf)
    with pytest.raises(Exception, match="collision.noise: expected a standard deviation of at most"):
        CollisionSettings(noise=0.1001)
    assert CollisionSettings(noise=0.1).noise == 0.1  # the scene key's whole range is accepted


@pytest.fixture(scope="module")
def exact(scene):
    """The exact closure, so that the loop closes to rounding and the solved
    angles can be compared with the simulated ones."""
    return _run(scene, 500.0, t_end=0.45, closure="exact")


def test_loop_solver_recovers_every_loop_hinge(exact):
    s, model, result = exact
    names, theta, omega, _ = hinge_states(model, result)
    n = model.n_coords
    loop = [h for h in names[:n] if h not in ("r3c2-r4c2", "r2c2-r3c2")]
    for dropped in loop:
        solver = LoopSolver(model, [h for h in names if h != dropped])
        assert [solver.tree_names[i] for i in solver.missing] == [dropped]
        cut = [names.index(c) for c in solver.cut_names]
        worst = worst_rate = 0.0
        for j in range(0, len(result.t), 5):
            th, om = solver.solve(theta[j, solver.known], theta[j, cut], omega[j, solver.known],
                                  omega[j, cut])
            worst = max(worst, np.abs(th - theta[j, :n]).max())
            worst_rate = max(worst_rate, np.abs(om - omega[j, :n]).max())
        assert worst < 1e-7, dropped
        assert worst_rate < 1e-4 * max(1.0, np.abs(omega).max()), dropped


def test_loop_solver_names_what_it_cannot_solve(exact):
    s, model, result = exact
    names = hinge_states(model, result)[0]
    with pytest.raises(TrajectoryError, match="'r2c2-r3c2'.*on no loop"):
        LoopSolver(model, [h for h in names if h != "r2c2-r3c2"])
    loop = [h for h in names[:model.n_coords] if h not in ("r3c2-r4c2", "r2c2-r3c2")]
    # Seven unknowns against the six closure equations of one loop.
    with pytest.raises(TrajectoryError, match="do not determine"):
        LoopSolver(model, [h for h in names if h not in loop[:7]])


def test_stream_without_a_loop_hinge_gives_the_same_verdict(khz, clean):
    s, model, result = khz
    names, theta, omega, _ = hinge_states(model, result)
    carried = [h for h in names if h != "r2c1-r3c1"]
    rows = [names.index(h) for h in carried]
    stream = StreamCheck(model, CollisionSettings.from_scene(s))
    first = None
    for j in range(len(result.t)):
        th, om = stream.coordinates(carried, theta[j, rows], omega[j, rows])
        events = stream.update(result.t[j], th, om)
        first = first or (events[0] if events else None)
    assert stream.solved == ["r2c1-r3c1"]
    assert first.names == clean.names and abs(first.t - clean.t) <= 1e-3


def test_live_check_keeps_bounded_rows(khz):
    s, model, result = khz
    stream = StreamCheck(model, CollisionSettings.from_scene(s, refine=False))
    t = np.arange(2 * KEEP + 10) * 1e-4
    still = np.repeat(result.theta[:1], len(t), axis=0)
    for j in range(len(t)):
        stream.update(t[j], still[j])
    report = stream.check.report()
    assert KEEP <= len(report.t) <= 2 * KEEP
    assert report.samples_checked == len(t) == stream.check.checked
    assert report.t[-1] == pytest.approx(t[-1])


def test_throttle_holds_back_and_counts():
    now = [0.0]
    throttle = Throttle(1.0, clock=lambda: now[0])
    assert throttle("stamp") == 0
    assert [throttle("stamp") for _ in range(5)] == [None] * 5
    assert throttle("gap") == 0  # kinds are throttled apart
    now[0] = 1.5
    assert throttle("stamp") == 5


def test_a_stream_of_a_model_with_panel_contact_checks_its_contact_onsets():
    """With every pair of the paper scene in contact, r1c2+r1c3 comes down on
    r2c4 and r4c1 on r4c4 at ~0.1 m/s at 0.2836 s, and the contact holds them
    apart (test_contacts):
    joint states alone cannot show it. Fed each interval's onset, beside its
    joint state (a recording) or after it (a live monitor), the stream finds
    the impact the batch check finds; without the onsets, or with some
    missing, its clean verdict is not OK and says why (the paper's model has
    no contact: OK without them)."""
    contact = load_scene(resolve_scene("paper_4x4"), ["contact.panels=true", "simulation.t_end=0.3",
                                                      "simulation.samples=61"])
    model = build_model(contact)
    result = simulate(model, contact.simulation)
    settings = CollisionSettings.from_scene(contact)
    batch = check_trajectory(model, result, settings)
    assert batch.first_collision.impact and set(batch.first_collision.names) in (
        {"r1c2+r1c3", "r2c4"}, {"r4c1", "r4c4"})
    fields = [onset_fields(model, row) for row in result.contact_onsets]
    beside, after = StreamCheck(model, settings), StreamCheck(model, settings)
    for j, t in enumerate(result.t):
        beside.update(t, result.theta[j], result.omega[j], fields[j])
        after.update(t, result.theta[j], result.omega[j])
        after.onset(t, *fields[j])
    for stream in (beside, after):
        first = stream.check.first_events[0]
        assert (first.names, first.t, first.impact) == (batch.first_collision.names,
                                                         batch.first_collision.t, True)
        assert stream.check.report().n_valid == batch.n_valid
        level, text, values = stream.verdict()
        assert level == 2 and values["onsets"] == len(result.t) - 1, text
    with pytest.raises(TrajectoryError, match="body_a: 'r1c1' and 'r1c1' are not a contact pair"):
        after.onset(0.1, "r1c1", "r1c1", *fields[-1][2:])
    with pytest.raises(TrajectoryError, match="speed: not finite") as refused:
        after.onset(0.1, *batch.first_collision.names, 0.1, math.nan, (0, 0, 0), (0, 0, 1))
    after.refuse(str(refused.value).split(":")[0], onset=True)  # as the node counts it
    level, text, values = after.verdict()
    assert values["refused_onsets"] == 1 and values["refused"] == 0
    assert "1 contact onsets refused (speed: 1)" in text and "joint states refused" not in text

    clean = load_scene(resolve_scene("paper_4x4"), ["contact.panels=true", "simulation.t_end=0.1",
                                                    "simulation.samples=21"])
    model = build_model(clean)
    result = simulate(model, clean.simulation)
    fields = [onset_fields(model, row) for row in result.contact_onsets]
    stream, first = _feed(model, CollisionSettings.from_scene(clean), result.t, result.theta,
                          result.omega)
    level, text, values = stream.verdict()
    assert first is None and level == 1 and values["onsets"] == 0
    assert "no contact onsets came: an impact the contact absorbs does not show in joint states" in text
    assert stream.verdict(onsets_in_flight=True)[0] == 0  # a live monitor's, still coming
    for j in range(len(result.t) - 3):  # all but the last three intervals' onsets
        stream.onset(result.t[j], *fields[j])
    level, text, values = stream.verdict()
    assert level == 1 and "the contact onsets of 3 of 20 sample intervals did not come" in text
    for j in range(len(result.t) - 3, len(result.t)):
        stream.onset(result.t[j], *fields[j])
    assert stream.verdict()[:2] == (0, "no collision")
    plain = load_scene(resolve_scene("paper_4x4"), ["simulation.t_end=0.1", "simulation.samples=21"])
    model = build_model(plain)
    result = simulate(model, plain.simulation)
    verdict = _feed(model, CollisionSettings.from_scene(plain), result.t, result.theta,
                    result.omega)[0].verdict()
    assert verdict[:2] == (0, "no collision") and "onsets" not in verdict[2]
