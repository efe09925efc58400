"""Scene loading: defaults, the shipped scenes, and every class of bad input."""

import copy
import json
import re
from pathlib import Path

import numpy as np
import pytest

from panel_deploy.cli import main
from panel_deploy.errors import SceneError
from panel_deploy.scene import describe_schema, load_scene, scene_from_dict

ROOT = Path(__file__).resolve().parent.parent
PAPER = ROOT / "config" / "scenes" / "paper_4x4.yaml"
MINIMAL = {"array": {"rows": 4, "cols": 4, "length": 0.1, "width": 0.1,
                     "thickness": 0.005, "mass": 0.02}}


def with_(path, value):
    data = copy.deepcopy(MINIMAL)
    *head, last = path.split(".")
    node = data
    for key in head:
        node = node.setdefault(key, {})
    node[last] = value
    return data


def test_paper_scene_loads_with_reference_values():
    s = load_scene(PAPER)
    assert (s.array.rows, s.array.cols) == (4, 4)
    assert s.array.unit_mass == pytest.approx(0.02)
    assert s.hinges.stiffness == 0.1 and s.hinges.damping_ratio * 0.1 == pytest.approx(0.0043)
    assert s.gravity == (0.0, -9.81, 0.0)
    assert s.fold.ground == (1, 2) and len(s.fold.circuit) == 16
    assert s.optimisation.bounds == (0.001, 0.2)


def test_every_shipped_scene_loads():
    scenes = sorted((ROOT / "config" / "scenes").glob("*.yaml"))
    assert scenes
    for path in scenes:
        assert load_scene(path).array.rows >= 1


def test_defaults_and_density():
    s = scene_from_dict(MINIMAL)
    assert s.simulation.method == "RK23" and s.simulation.samples == 301
    d = with_("array.density", 1000.0)
    del d["array"]["mass"]
    assert scene_from_dict(d).array.unit_mass == pytest.approx(1000 * 0.1 * 0.1 * 0.005)


@pytest.mark.parametrize("path, value, expected", [
    ("array.rows", "four", "array.rows: expected an integer"),
    ("array.rows", 2.5, "array.rows: expected an integer"),
    ("array.length", -0.1, "array.length: expected a number > 0"),
    ("array.thickness", 0, "array.thickness: expected a number > 0"),
    ("array.mass", True, "array.mass: expected a number"),
    ("array.density", 1000.0, "array.mass: give exactly one"),
    ("array.cols", 3, "array: 4 x 3 = 12"),  # even: must load, checked below
    ("array.colour", "red", "array.colour: unknown key"),
    ("simulation.rtol", -1, "simulation.rtol: expected a number > 0, got -1"),
    ("simulation.method", "Euler", "simulation.method: expected one of RK23"),
    ("simulation.samples", 2, "simulation.samples: expected an integer >= 3"),
    ("simulation.t_end", float("nan"), "simulation.t_end: expected a finite number"),
    ("simulation.flat_tolerance", 0, "simulation.flat_tolerance: expected a number > 0"),
    ("closure.method", "lagrange", "closure.method: expected one of penalty, exact"),
    ("fold.ground", [0, 1], "fold.ground: expected a cell"),
    ("fold.circuit", "zigzag", "fold.circuit: expected auto, a circuit index or a list of cells"),
    ("fold.circuit_choice", "ranking", "fold.circuit_choice: expected a mapping, got str"),
    ("fold.merge", [[[1, 2]]], "fold.merge[0]: expected a pair of cells"),  # the item named
    ("fold.merge", 3, "fold.merge: expected auto, none or a list of cell pairs"),
    # issue 26: accepted silently before (the same hinge merged twice)
    ("fold.merge", [[[1, 1], [1, 2]], [[2, 1], [2, 2]], [[1, 2], [1, 1]]],
     "fold.merge[2]: pair [[1, 1], [1, 2]] is given twice (first as fold.merge[0])"),
    ("closure.cut_hinge", [[[1, 1], [1, 2]], [[1, 1], [1, 2]]],
     "closure.cut_hinge[1]: pair [[1, 1], [1, 2]] is given twice"),
    # issue 26: ran 40 s to a step-budget failure reporting an approach speed of 8388 m/s
    ("array.mass", 1e-9, "array.mass: 1e-09 kg in a 0.1 x 0.1 x 0.005 m panel is 2e-05 kg/m^3; "
                         "expected >= 0.1 (limit: lighter than any solid"),
    ("collision.tolerance", 0.05, "collision.tolerance: expected a number <= 0.02, got 0.05 "
                                  "(limit: the collision check's broad phase"),
    ("collision.tolerance", 0, "collision.tolerance: expected a number >= 1e-09, got 0 "
                               "(limit: panels touching in the stowed stacks are 0 apart"),
    ("gravity", [0, -9.81], "gravity: expected a list of 3 numbers"),
    ("optimisation.bounds", [0.2, 0.001], "optimisation.bounds: lower bound 0.2 is above"),
    ("optimisation.k0", 0.5, "optimisation.k0: 0.5 is outside bounds"),
    ("optimisation.damping_ratio_bounds", [0, 0.3],
     "optimisation.damping_ratio_bounds: expected 0 < lower < upper"),
    ("optimisation.damping_ratio_bounds", [0.1, 0.3],
     "optimisation.damping_ratio_bounds: the search starts from hinges.damping_ratio = 0.043"),
    ("hinges.groups", [[]], "hinges.groups[0]: a group needs at least one hinge"),
    ("contact", [1, 2], "contact: expected a mapping"),
    # issue 31: the air around the array
    ("air.density", -1.2, "air.density: expected a number >= 0, got -1.2"),
    ("air.density", 1000.0, "air.density: expected a number <= 100, got 1000 (limit: a gas"),
    ("air.density", "sea level", "air.density: expected a number, got str"),
    ("air.drag_coefficient", -1, "air.drag_coefficient: expected a number >= 0, got -1"),
    ("air.drag_coefficient", 20, "air.drag_coefficient: expected a number <= 5, got 20 "
                                 "(limit: a flat plate"),
    ("air.viscosity", 1.8e-5, "air.viscosity: unknown key (expected one of density, "
                              "drag_coefficient)"),
    ("air", 1.2, "air: expected a mapping"),
    # panel friction
    ("contact.friction", -0.3, "contact.friction: expected a number >= 0, got -0.3"),
    ("contact.friction", 30, "contact.friction: expected a number <= 10, got 30 (limit: Coulomb"),
    ("contact.friction", "dry", "contact.friction: expected a number, got str"),
    ("contact.friction_speed", 0, "contact.friction_speed: expected a number > 0, got 0"),
    ("contact.friction_speed", 1e-9, "contact.friction_speed: expected a number >= 1e-06, got 1e-09"),
    ("contact.friction_speed", float("inf"), "contact.friction_speed: expected a finite number"),
    ("contact.pressure", "yes", "contact.pressure: expected true or false, got str"),
    ("velocity", 3, "velocity: unknown section"),
])
def test_bad_values_name_the_key(path, value, expected):
    data = with_(path, value)
    if path == "array.cols":  # 4 x 3 is even and valid; make it odd
        data["array"]["rows"] = 3
        expected = "array: 3 x 3 = 9 panels is odd"
    with pytest.raises(SceneError) as e:
        scene_from_dict(data)
    assert str(e.value).startswith(expected), str(e.value)


def test_the_least_density_holds_for_density_and_mass_alike():
    d = with_("array.density", 0.05)
    del d["array"]["mass"]
    with pytest.raises(SceneError, match=r"^array.density: expected a number >= 0.1, got 0.05 "
                                         r"\(limit: lighter than any solid"):
        scene_from_dict(d)
    # an aerogel panel of the paper's size, and the lightest mass accepted there
    assert scene_from_dict(with_("array.mass", 1e-5)).array.unit_mass == 1e-5
    d["array"]["density"] = 0.16
    assert scene_from_dict(d).array.unit_mass == pytest.approx(0.16 * 0.1 * 0.1 * 0.005)


def test_air_is_off_by_default_and_reaches_the_model():
    from panel_deploy.build import build_model
    s = scene_from_dict(MINIMAL)
    assert (s.air.density, s.air.drag_coefficient) == (0.0, 1.17)
    assert build_model(s).air.pressure_coefficient == 0.0
    air = build_model(scene_from_dict(with_("air.density", 1.2))).air
    assert (air.density, air.drag_coefficient) == (1.2, 1.17)
    assert "air.density" in describe_schema() and "air.drag_coefficient" in describe_schema()


def test_friction_is_off_by_default_and_reaches_the_model():
    from panel_deploy.build import build_model
    from panel_deploy.dynamics.pack import pack
    s = scene_from_dict(MINIMAL)
    assert (s.contact.friction, s.contact.friction_speed) == (0.0, 1e-3)
    sets = with_("contact.friction", 0.4)
    sets["contact"]["friction_speed"] = 0.002
    model = build_model(scene_from_dict(sets))
    assert (model.mu_p, model.friction_speed) == (0.4, 0.002)
    assert model.contact_pairs and np.all(pack(model).contact[:, 10:] == [0.4, 0.002, 0.0])
    assert "contact.friction" in describe_schema() and "contact.friction_speed" in describe_schema()


def test_contact_pressure_is_off_by_default_and_reaches_the_model():
    from panel_deploy.build import build_model
    from panel_deploy.dynamics.pack import pack
    assert scene_from_dict(MINIMAL).contact.pressure is False
    assert not build_model(scene_from_dict(MINIMAL)).contact_pressure
    model = build_model(scene_from_dict(with_("contact.pressure", True)))
    assert model.contact_pressure and model.contact_pairs and np.all(pack(model).contact[:, 12] == 1.0)
    assert "contact.pressure" in describe_schema()


def test_cli_bad_air_is_one_line_before_any_work(capsys):
    assert main(["simulate", str(PAPER), "--set", "air.density=-1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["panel-deploy: error: --set air.density: expected a number >= 0, got -1"]


def test_missing_required_keys():
    with pytest.raises(SceneError, match="^array: required section is missing"):
        scene_from_dict({"simulation": {}})
    data = copy.deepcopy(MINIMAL)
    del data["array"]["thickness"]
    with pytest.raises(SceneError, match="^array.thickness: required key is missing"):
        scene_from_dict(data)
    with pytest.raises(SceneError, match="a scene must be a mapping"):
        scene_from_dict([1, 2])


def test_file_errors(tmp_path):
    with pytest.raises(SceneError, match="scene file not found"):
        load_scene(tmp_path / "nope.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("array: {rows: 4, cols: [\n")
    with pytest.raises(SceneError, match=r"malformed YAML at line \d+"):
        load_scene(bad)
    wrong = tmp_path / "wrong.yaml"
    wrong.write_text("array: {rows: 4, cols: 4, length: 0.1, width: 0.1, thickness: -1, mass: 1}\n")
    with pytest.raises(SceneError, match=r"^wrong.yaml: array.thickness: expected a number > 0"):
        load_scene(wrong)


def test_cli_bad_scene_is_one_line_exit_2(tmp_path, capsys):
    bad = tmp_path / "bad.yaml"
    bad.write_text("array: {rows: 4, cols: 4, length: 0.1, width: 0.1, thickness: 0.005, mass: 0.02}\n"
                   "simulation: {rtol: -1}\n")
    assert main(["simulate", str(bad)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["panel-deploy: error: bad.yaml: simulation.rtol: expected a number > 0, got -1"]
    assert main(["simulate", str(tmp_path / "missing.yaml")]) == 2
    assert "scene file not found" in capsys.readouterr().err


def test_schema_lists_every_section():
    text = describe_schema()
    for key in ("array.rows", "closure.k_M", "simulation.rtol", "optimisation.bounds", "gravity"):
        assert key in text


def test_a_scene_takes_a_calibration_section_and_refuses_one_that_is_no_mapping():
    data = dict(load_scene(PAPER).data)
    assert scene_from_dict({**data, "calibration": {"fitted": ["damping"]}}).data["calibration"]
    with pytest.raises(SceneError, match="calibration: expected a mapping"):
        scene_from_dict({**data, "calibration": [1, 2]})
    assert "calibration" in describe_schema()


def test_overrides_set_keys_before_validation():
    s = load_scene(PAPER, ["gravity=[0, 0, 0]", "simulation.t_end=0.5",
                           "optimisation.bounds=[0.01, 0.1]"])
    assert s.gravity == (0.0, 0.0, 0.0) and s.simulation.t_end == 0.5
    assert s.optimisation.bounds == (0.01, 0.1)
    assert s.data["simulation"]["t_end"] == 0.5        # what a saved trajectory rebuilds from
    assert load_scene(PAPER).simulation.t_end == 2.0   # the file itself is untouched


@pytest.mark.parametrize("item, expected", [
    ("simulation.t_end=-1", "simulation.t_end: expected a number > 0"),
    ("simulation.bogus=1", "simulation.bogus: unknown key"),
    ("gravity.x=1", "gravity: cannot set gravity.x: not a mapping"),
    ("t_end", "expected an override KEY.PATH=VALUE"),
    ("simulation..t_end=1", "expected an override KEY.PATH=VALUE"),
    ("simulation.t_end=[1", "--set simulation.t_end: value '[1' is not valid YAML"),
])
def test_bad_overrides_name_the_key(item, expected):
    with pytest.raises(SceneError, match=re.escape(expected)):
        load_scene(PAPER, [item])


def test_cli_set_reaches_the_scene(capsys):
    code = main(["simulate", str(PAPER), "--json", "--set", "simulation.t_end=0.05",
                 "--set", "simulation.samples=11"])
    out = json.loads(capsys.readouterr().out)
    assert code == 0 and out["t_end"] == 0.05
    assert main(["simulate", str(PAPER), "--set", "simulation.samples=1.5"]) == 2
    assert "simulation.samples: expected an integer" in capsys.readouterr().err
