"""bags/: the sample recordings decode, stay small, and still show what the current code computes."""

import math
from pathlib import Path

import pytest

from panel_deploy.record import messages as m
from panel_deploy.record import open_recording
from panel_deploy.record.analysis import read_deployment
from panel_deploy.pipeline import simulate_scene
from panel_deploy.scene import load_scene, resolve_scene

BAGS = Path(__file__).resolve().parent.parent / "bags"
SAMPLE = 0.005  # s, the recordings' sample spacing


def _current(overrides=(), stiffness=None):
    scene = load_scene(resolve_scene("paper_4x4"), overrides)
    stiffness = stiffness and str(BAGS.parent / stiffness)
    return simulate_scene(scene, stiffness)


@pytest.mark.parametrize("name", ["paper_4x4_uniform.mcap", "paper_4x4_feasible.mcap"])
def test_bag_decodes_and_is_small(name):
    path = BAGS / name
    assert path.stat().st_size < 5e6
    recording = open_recording(path)
    assert recording.truncated is None and sorted(recording.topics) == sorted(m.TOPICS)
    for topic, typename in recording.topics.items():
        assert len(recording.messages(topic, typename)) == recording.count(topic)
        # empty: the optimiser's (none ran), the contact onsets (the paper's model has no
        # panel contact), and the collision's in the collision-free bag
        empty = {"/optimiser/progress", "/optimiser/result", "/dynamics/contact_onsets"} | (
            {"/panel_deploy/collision_events", "/panel_deploy/collision_markers"}
            if "feasible" in name else set())
        assert bool(recording.count(topic)) == (topic not in empty), topic
    d = read_deployment(path)
    assert len(d.track.t) == 401 and d.scene.name == "paper_4x4"


def test_uniform_bag_collides_where_the_current_code_says():
    model, result, report = _current()
    first = report.first_collision
    recording = open_recording(BAGS / "paper_4x4_uniform.mcap")
    events = recording.messages("/panel_deploy/collision_events", m.COLLISION_EVENT)
    event = events[0][1]
    assert (event.body_a, event.body_b) == first.names, "regenerate: python bench/make_bags.py"
    assert abs(event.t - first.t) <= SAMPLE, "regenerate: python bench/make_bags.py"
    assert math.isclose(event.approach_speed, report.v, rel_tol=0.05)


def test_feasible_bag_deploys_flat_without_collision_as_the_current_code_says():
    model, result, report = _current(["hinges.damping_ratio=0.19"],
                                     "bench/results/paper_4x4_damping019.yaml")
    assert report.first_collision is None
    recording = open_recording(BAGS / "paper_4x4_feasible.mcap")
    assert recording.count("/panel_deploy/collision_events") == 0, \
        "regenerate: python bench/make_bags.py"
    outcome = recording.metadata["outcome"]
    from panel_deploy.dynamics.report import hinge_release_report
    flat = hinge_release_report(model, result)["flat_at"]
    assert abs(float(outcome["time_to_flat"]) - flat) <= SAMPLE, "regenerate: python bench/make_bags.py"
