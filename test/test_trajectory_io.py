"""The trajectory file (``simulate --out``): named columns read with numpy alone, checked
against the model's forward kinematics and against the ``/joint_states`` that rosbags reads
from the recording of the same run; version 2 files; docs/formats.md's example and units."""

import io
import json
import re
import zipfile
from contextlib import redirect_stdout
from pathlib import Path

import numpy as np
import pytest
import yaml
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_typestore

from panel_deploy.build import build_model
from panel_deploy.cli import main
from panel_deploy.dynamics.report import contact_energy_error, total_energy
from panel_deploy.kinematics import forward_kinematics
from panel_deploy.scene import scene_from_dict
from panel_deploy.trajectory_io import COLUMNS, FORMAT_VERSION, UNITS, load_trajectory

ROOT = Path(__file__).resolve().parent.parent
DOC = ROOT / "docs" / "formats.md"
V2 = Path(__file__).resolve().parent / "data" / "trajectory_v2.npz"
#: The stored run of ``V2``: written by the format-2 code with these arguments
#: (rtol and atol: the scene's then).
V2_ARGS = ["simulate", "paper_4x4", "--set", "simulation.t_end=0.5", "--set",
           "simulation.samples=11", "--set", "hinges.overrides={r1c1-r2c1: 0.2}",
           "--set", "simulation.rtol=1e-4", "--set", "simulation.atol=1e-6"]


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """One run written both ways: ``--out`` (npz) and ``--record`` (MCAP)."""
    folder = tmp_path_factory.mktemp("run")
    npz, mcap = folder / "traj.npz", folder / "traj.mcap"
    with redirect_stdout(io.StringIO()):
        assert main(["simulate", "paper_4x4", "--set", "simulation.t_end=0.6",
                     "--set", "simulation.samples=121", "--set", "hinges.overrides={r1c1-r2c1: 0.2}",
                     "--out", str(npz), "--record", str(mcap)]) == 0
    return npz, mcap


def _numpy_only(path):
    """Every member of the file as numpy gives it, no code of ours involved."""
    with np.load(path, allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


def _joint_states(mcap):
    """(stamps ns, names, positions, velocities) of /joint_states, read by rosbags alone."""
    store = get_typestore(Stores.ROS2_JAZZY)
    stamps, names, position, velocity = [], None, [], []
    with Reader(mcap) as reader:
        for connection, stamp, raw in reader.messages():
            if connection.topic == "/joint_states":
                msg = store.deserialize_cdr(raw, connection.msgtype)
                names = list(msg.name)
                stamps.append(stamp)
                position.append(msg.position)
                velocity.append(msg.velocity)
    return np.array(stamps), names, np.array(position), np.array(velocity)


def test_named_columns_are_the_recorded_joint_states_of_the_same_run(run):
    npz, mcap = run
    z = _numpy_only(npz)
    assert int(z["format_version"]) == FORMAT_VERSION == 5
    stamps, names, position, velocity = _joint_states(mcap)
    assert np.array_equal(stamps, np.round(z["t"] * 1e9).astype(np.int64))
    joints, cut = [str(x) for x in z["joint_names"]], [str(x) for x in z["cut_hinge_names"]]
    assert len(joints) == z["theta"].shape[1] == z["omega"].shape[1] == 11
    assert len(cut) == z["cut_theta"].shape[1] == 1
    assert sorted(joints + cut) == sorted(names)  # every hinge once, by name
    for column, name in enumerate(joints):
        assert np.array_equal(z["theta"][:, column], position[:, names.index(name)]), name
        assert np.array_equal(z["omega"][:, column], velocity[:, names.index(name)]), name
    for column, name in enumerate(cut):
        assert np.allclose(z["cut_theta"][:, column], position[:, names.index(name)],
                           rtol=0, atol=1e-12), name
    # the motion is not trivial: the named columns would be told apart if swapped
    assert np.ptp(z["theta"][:, joints.index("r1c1-r2c1")]) > 0.5
    assert not np.allclose(z["theta"][:, 1], z["theta"][:, 2])


def test_named_bodies_and_hinges_are_the_models(run):
    npz, _ = run
    z = _numpy_only(npz)
    model = build_model(scene_from_dict(yaml.safe_load(str(z["scene_yaml"]))))
    joints, bodies = [str(x) for x in z["joint_names"]], [str(x) for x in z["body_names"]]
    hinges = [str(x) for x in z["hinge_names"]]
    # The model's own coordinate order may differ from the file's: go by names only.
    theta_of = {name: z["theta"][:, i] for i, name in enumerate(joints)}
    for j in (0, 60, 120):
        theta = np.array([theta_of[model.hinges[h].name][j] for h in model.joints])
        R, p = forward_kinematics(model, theta)[:2]
        for b, body in enumerate(model.bodies):
            stored = bodies.index(body.name)
            assert np.allclose(z["position"][j, stored], p[b], rtol=0, atol=1e-9), body.name
            assert np.allclose(z["rotation"][j, stored], R[b], rtol=0, atol=1e-9), body.name
    k = dict(zip(hinges, z["stiffness"]))
    c = dict(zip(hinges, z["damping"]))
    assert k["r1c1-r2c1"] == 0.2 and k["r1c1-r1c2"] == 0.1
    assert c["r1c1-r2c1"] == pytest.approx(0.043 * 0.2) and c["r4c3-r4c4"] == pytest.approx(0.0043)
    assert json.loads(str(z["units"])) == UNITS and json.loads(str(z["columns"])) == COLUMNS


def test_docs_example_runs_on_a_file_and_prints_its_values(run, tmp_path, monkeypatch):
    npz, _ = run
    block = re.search(r"```python\n(.*?)```", DOC.read_text(), re.S).group(1)
    assert len(block.strip().splitlines()) <= 10
    (tmp_path / "traj.npz").write_bytes(npz.read_bytes())
    monkeypatch.chdir(tmp_path)
    out = io.StringIO()
    with redirect_stdout(out):
        exec(compile(block, str(DOC), "exec"), {})
    stored = load_trajectory(npz)
    model, result = stored.model, stored.result
    i = [model.hinges[h].name for h in model.joints].index("r1c1-r2c1")
    b = [x.name for x in model.bodies].index("r4c4")
    assert out.getvalue().splitlines() == [
        f"t = {result.t[-1]:.3f} s",
        f"r1c1-r2c1: {result.theta[-1, i]:.6f} rad",
        f"r4c4 centroid: {np.round(result.position[-1, b], 6).tolist()} m"]


def test_docs_state_every_unit_and_column_name_as_the_code_does():
    rows = {}
    for line in DOC.read_text().split("## Recording")[0].splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if line.startswith("| `") and len(cells) == 4:
            rows[cells[0].strip("`")] = cells
    for name, unit in UNITS.items():
        if name not in ("gap_limit", "wall_time"):  # scalars: stated in the text beside them
            assert rows[name][3] == unit, name
    for name, labels in COLUMNS.items():
        assert rows[name][2].startswith(f"`{labels}`"), name


def test_a_version_2_file_loads_with_its_columns_mapped_from_its_scene(tmp_path):
    """The stored format-2 run re-simulated by this version: the same motion by hinge name.

    To 1e-5 rad: the re-run differs from the stored one by rounding, amplified
    within the run's atol of 1e-6 (5.7e-7 rad since the kernels fuse multiply-adds,
    ``dynamics._jit``), while a column taken from another hinge differs by 1.75e-4
    rad or more."""
    z = _numpy_only(V2)
    assert int(z["format_version"]) == 2 and "joint_names" not in z
    old = load_trajectory(V2)
    assert old.version == 2
    names = [old.model.hinges[h].name for h in old.model.joints]
    npz = tmp_path / "v3.npz"
    with redirect_stdout(io.StringIO()):
        main([*V2_ARGS, "--out", str(npz)])
    new = _numpy_only(npz)
    for i, name in enumerate(names):
        column = [str(x) for x in new["joint_names"]].index(name)
        assert np.allclose(old.result.theta[:, i], new["theta"][:, column], rtol=0, atol=1e-5), name
    assert np.array_equal(old.stiffness, new["stiffness"])
    assert np.allclose(old.damping, new["damping"], rtol=1e-12)  # c followed k in version 2


def test_collide_reads_a_version_2_file_as_the_format_2_code_did(capsys):
    assert main(["collide", str(V2), "--json"]) == 0
    first = json.loads(capsys.readouterr().out)["first_collision"]
    # what the format-2 code printed for this run: 0.3896 s between these two bodies
    assert sorted(first["pair"]) == ["r1c2+r1c3", "r2c2+r2c3"] and round(first["t"], 4) == 0.3896


def _rewrite(src, dst, **changes):
    data = _numpy_only(src)
    data.update(changes)
    np.savez_compressed(dst, **data)
    return str(dst)


@pytest.mark.parametrize("change, expected", [
    (lambda z: {"joint_names": z["joint_names"][[1, 0, *range(2, 11)]]},
     "joint_names[0] is 'r1c3-r1c4'; the stored scene's model has 'r1c1-r1c2' there (11 names)"),
    (lambda z: {"body_names": z["body_names"][:-1]},
     "body_names[11] is nothing; the stored scene's model has 'r4c4' there (12 names)"),
    (lambda z: {"cut_hinge_names": np.array([1.0])}, "cut_hinge_names: expected a 1-d array of text"),
    (lambda z: {"damping": z["damping"][:3]}, "damping has shape (3,); the stored scene's model has 12"),
    (lambda z: {"damping": np.full(12, np.nan)}, "damping[0] = nan: expected a finite number >= 0"),
    (lambda z: {"format_version": np.array(6)}, "format_version 6, expected one of 2, 3, 4, 5"),
    (lambda z: {"contact_onsets": z["contact_onsets"][:, :8]}, "contact_onsets has 8 columns, expected 9"),
    (lambda z: {"contact_onsets": z["contact_onsets"][:-1]}, "contact_onsets has 120 samples, t has 121"),
    (lambda z: {"contact_onsets": np.where(np.arange(9) == 1, np.nan, z["contact_onsets"])},
     "contact_onsets[0]: speed nan and pair -1: expected a finite speed >= 0"),
    (lambda z: {"contact_onsets": np.where(np.arange(9) == 2, 3.0, z["contact_onsets"])},
     "contact_onsets[0, 2] = 3: the stored scene's model has 0 contact pairs"),
])
def test_names_that_do_not_fit_the_stored_scene_are_one_line(run, tmp_path, capsys, change, expected):
    npz, _ = run
    bad = _rewrite(npz, tmp_path / "bad.npz", **change(_numpy_only(npz)))
    assert main(["collide", bad]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and expected in err[0], err


def test_a_version_3_file_loads_without_contact_onsets(run, tmp_path):
    npz, _ = run
    data = _numpy_only(npz)
    del data["contact_onsets"]
    data["format_version"] = np.array(3)
    np.savez_compressed(tmp_path / "v3.npz", **data)
    stored = load_trajectory(tmp_path / "v3.npz")
    assert stored.version == 3
    assert np.all(stored.result.contact_onsets[:, 2] == -1) and len(stored.result.contact_onsets) == 121


def test_a_version_4_file_balances_the_contacts_stored_energy(run, tmp_path):
    """Before version 5 a file had no record of the work done on the panel
    contacts' springs: its energy balance counts their stored energy, part of
    ``spring``, as the code that wrote it did."""
    npz, _ = run
    data = _numpy_only(npz)
    current = load_trajectory(npz).result
    del data["energy_contact"], data["energy_contact_work"]
    data["format_version"] = np.array(4)
    np.savez_compressed(tmp_path / "v4.npz", **data)
    old = load_trajectory(tmp_path / "v4.npz").result
    E = old.energy
    assert "contact_work" not in E
    expected = E["kinetic"] + E["spring"] + E["gravity"] + E["dissipated"] - E["constraint_work"]
    assert np.array_equal(total_energy(E), expected)
    assert contact_energy_error(old) is None
    # this run's panels never touch at a sample: nothing stored, no work, the same balance
    assert not np.any(current.energy["contact"]) and not np.any(current.energy["contact_work"])
    assert np.array_equal(total_energy(current.energy), expected)


def test_a_version_3_file_without_its_names_is_refused(run, tmp_path, capsys):
    npz, _ = run
    data = _numpy_only(npz)
    del data["joint_names"]
    np.savez_compressed(tmp_path / "x.npz", **data)
    assert main(["collide", str(tmp_path / "x.npz")]) == 2
    assert "missing arrays joint_names" in capsys.readouterr().err


def test_rosbag2_files_are_named_for_what_they_are(tmp_path, capsys):
    folder = tmp_path / "bag"
    folder.mkdir()
    (folder / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
    db3 = tmp_path / "bag_0.db3"
    db3.write_bytes(b"SQLite format 3\x00" + bytes(100))
    for path in (folder, db3):
        assert main(["collide", str(path)]) == 2
        err = capsys.readouterr().err
        assert "ros2 bag convert" in err and len(err.strip().splitlines()) == 1, err
    assert zipfile.is_zipfile(V2)
