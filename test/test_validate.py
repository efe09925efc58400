"""The shared checks of panel_deploy.validate: YAML loader, output paths, atomic writes, finiteness."""

import os
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from hostile import alias_bomb

from panel_deploy.errors import PanelDeployError, SceneError
from panel_deploy.validate import (MAX_YAML_DEPTH, MAX_YAML_EXPANDED, check_finite,
                                   check_output_path, first_non_finite_value, load_yaml, read_text,
                                   save_figure, write_atomic, yaml_problem)


@pytest.mark.parametrize("text, problem", [
    ("a: 1\na: 2\n", "duplicate key 'a' (first given at line 1)"),
    ("simulation: {rtol: 1}\narray: {}\nsimulation: {atol: 1}\n", "duplicate key 'simulation'"),
    ("x: " + "[" * (MAX_YAML_DEPTH + 5) + "]" * (MAX_YAML_DEPTH + 5), "nested deeper than"),
    ("x: " + "[" * 5000 + "]" * 5000, "nested deeper than"),  # no RecursionError
])
def test_yaml_loader_refuses_duplicates_and_depth(text, problem):
    with pytest.raises(yaml.YAMLError, match=problem.replace("(", r"\(").replace(")", r"\)")):
        load_yaml(text)


def test_yaml_loader_reads_what_safe_load_reads():
    text = "a: [1, 2.5, {b: c}]\nd: &x {e: 1}\nf: {<<: *x, g: 2}\n"
    assert load_yaml(text) == yaml.safe_load(text)
    # aliases that stay within the bound are read as ever
    assert load_yaml(alias_bomb(levels=4, width=9)) == yaml.safe_load(alias_bomb(levels=4, width=9))


def test_yaml_alias_bombs_are_refused_at_once():
    text = alias_bomb()  # 9 ** 9 = 387 million values written out, from 500 bytes
    assert len(text) < 500
    start = time.perf_counter()
    with pytest.raises(yaml.YAMLError, match=f"aliases expand it beyond {MAX_YAML_EXPANDED} "):
        load_yaml(text)
    assert time.perf_counter() - start < 0.5
    # recursive, or nesting deeper than the limit only once written out
    for text in ("a: &a [*a]\n", "a: &a {b: *a}\n",
                 "a: &a " + "[" * 20 + "]" * 20 + "\nb: " + "[" * 20 + "*a" + "]" * 20 + "\n"):
        with pytest.raises(yaml.YAMLError, match=f"aliases nest it deeper than {MAX_YAML_DEPTH}"):
            load_yaml(text)


@pytest.mark.parametrize("text, problem", [
    ("a: 2001-02-30\n", "line 1, column 4: cannot read '2001-02-30' (day is out of range for month)"),
    ("a: " + "1" * 5000, "cannot read '11111111111111111111111"),  # more digits than int() reads
])
def test_scalars_that_do_not_convert_are_yaml_errors(text, problem):
    with pytest.raises(yaml.YAMLError) as e:
        load_yaml(text)
    assert problem in yaml_problem(e.value) and len(yaml_problem(e.value)) < 200


def test_output_path_checks(tmp_path):
    assert check_output_path(None, "--out") is None
    assert check_output_path(tmp_path / "a.npz", "--out") == tmp_path / "a.npz"
    for path, message in ((tmp_path / "missing" / "a.npz", "does not exist"),
                          (tmp_path, "is a folder"), ("", "empty string")):
        with pytest.raises(SceneError, match=f"^--out: .*{message}"):
            check_output_path(path, "--out")
    (tmp_path / "file").write_text("x")
    with pytest.raises(SceneError, match="is not a folder"):
        check_output_path(tmp_path / "file" / "a.npz", "--out")


def test_output_path_is_checked_by_creating_the_atomic_writes_temporary_file(tmp_path):
    # issue 26: each of these passed the check and failed after the work
    name_max = os.pathconf(tmp_path, "PC_NAME_MAX")
    for path, message in ((tmp_path / ("a" * (name_max + 45)), "File name too long"),
                          (Path("/proc/x.rrd"), "folder /proc does not take new files")):
        with pytest.raises(SceneError, match=f"^--save: cannot write .*{message}"):
            check_output_path(path, "--save")
    # issue 32: a name the file system takes is not refused for the temporary name's affixes
    for length in (name_max - 20, name_max - 5, name_max):
        assert check_output_path(tmp_path / ("a" * length), "--save")
    assert not list(tmp_path.iterdir())  # the probe leaves nothing behind


def test_atomic_write_leaves_no_part_file_and_rescues_the_content(tmp_path, monkeypatch):
    target = tmp_path / "out" / "r.yaml"
    target.parent.mkdir()
    write_atomic(target, lambda f: f.write("k: 1\n"), "--out")
    assert target.read_text() == "k: 1\n" and os.listdir(target.parent) == ["r.yaml"]
    (tmp_path / "plain").write_text("")  # the mode open() gives, not mkstemp's 0600
    assert target.stat().st_mode == (tmp_path / "plain").stat().st_mode
    # The folder disappears while the work runs: the content goes to a fallback file.
    gone = tmp_path / "gone" / "r.yaml"
    monkeypatch.chdir(tmp_path)
    with pytest.raises(PanelDeployError, match=r"^--out: cannot write .*saved in (\S+)$") as e:
        write_atomic(gone, lambda f: f.write("k: 2\n"), "--out")
    rescued = str(e.value).rsplit("saved in ", 1)[1]
    assert open(rescued).read() == "k: 2\n" and rescued.startswith(str(tmp_path))
    # A write that fails half-way leaves no temporary file behind.

    def explode(f):
        f.write("half")
        raise KeyboardInterrupt
    with pytest.raises(KeyboardInterrupt):
        write_atomic(target, explode, "--out")
    assert os.listdir(target.parent) == ["r.yaml"] and target.read_text() == "k: 1\n"


def test_a_pipe_is_written_in_place_not_replaced(tmp_path):
    # as /dev/null or /dev/stdout would be: a rename over it would replace the device
    import stat
    import threading
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    got = []
    reader = threading.Thread(target=lambda: got.append(fifo.read_text()))
    reader.start()
    write_atomic(fifo, lambda f: f.write("k: 1\n"), "--out")
    reader.join(5)
    assert got == ["k: 1\n"] and stat.S_ISFIFO(fifo.stat().st_mode)
    assert os.listdir(tmp_path) == ["pipe"]


def test_fold_plot_is_written_atomically_and_rescued(tmp_path, monkeypatch):
    from panel_deploy import fold
    from panel_deploy.fold.plot import plot_design
    d = fold.design(4, 4)
    plot_design(d, tmp_path / "fold.png")
    assert (tmp_path / "fold.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert os.listdir(tmp_path) == ["fold.png"]
    monkeypatch.chdir(tmp_path)
    with pytest.raises(PanelDeployError, match=r"^--plot: cannot write .*saved in (\S+)$") as e:
        plot_design(d, tmp_path / "gone" / "fold.svg")
    assert open(str(e.value).rsplit("saved in ", 1)[1], "rb").read().lstrip().startswith(b"<?xml")


def test_save_figure_takes_the_format_from_the_suffix(tmp_path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig = plt.figure()
    save_figure(fig, tmp_path / "a.pdf")
    plt.close(fig)
    assert (tmp_path / "a.pdf").read_bytes()[:5] == b"%PDF-"


def test_read_text_errors_are_one_line(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_bytes(b"hinges: \xff\xfe\n")
    with pytest.raises(PanelDeployError, match="is not UTF-8 text"):
        read_text(bad, "stiffness file")
    with pytest.raises(PanelDeployError, match="is a folder"):
        read_text(tmp_path, "stiffness file")


def test_non_finite_values_are_named_with_their_first_index():
    a = np.zeros((4, 3))
    check_finite("theta", a)
    a[2, 1] = np.nan
    a[3, 0] = np.inf
    with pytest.raises(PanelDeployError, match=r"^f.npz: theta\[2, 1\] is nan"):
        check_finite("theta", a, "f.npz")
    assert first_non_finite_value({"a": 1.0, "b": {"c": [1.0, float("inf")]}}) == "b.c[1] = inf"
    assert first_non_finite_value({"a": [1.0], "n": None}) is None
