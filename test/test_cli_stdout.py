"""Standard output as a target (issue 32): ``-``, ``/dev/stdout``, a pipe, a link to
``/proc/self/fd/1``; the binary streams there and every human line goes to stderr. A
link to a file is written through, never replaced."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from panel_deploy.record.reader import open_recording

CLI = str(Path(sys.executable).parent / "panel-deploy")
SHORT = ["--t-end", "0.1"]


def cli(*args, stdout=subprocess.PIPE, cwd=None):
    return subprocess.run([CLI, *map(str, args)], stdout=stdout, stderr=subprocess.PIPE,
                          cwd=cwd, timeout=300)


def test_a_link_to_standard_output_redirected_to_a_file(tmp_path):
    link = tmp_path / "out"
    link.symlink_to("/proc/self/fd/1")
    target = tmp_path / "rec.mcap"
    with open(target, "wb") as f:
        proc = cli("simulate", "paper_4x4", *SHORT, "--record", link, stdout=f)
    assert proc.returncode == 0, proc.stderr
    assert link.is_symlink() and str(link.readlink()) == "/proc/self/fd/1"  # not replaced
    assert target.read_bytes().startswith(b"\x89MCAP0\r\n")
    assert open_recording(target).count("/joint_states") == 401
    assert b"first flat" in proc.stderr  # the summary went to stderr


@pytest.mark.parametrize("name", ["-", "/dev/stdout"])
def test_a_recording_piped_to_standard_output(tmp_path, name):
    proc = cli("simulate", "paper_4x4", *SHORT, "--record", name)
    assert proc.returncode == 0, proc.stderr
    path = tmp_path / "piped.mcap"
    path.write_bytes(proc.stdout)
    recording = open_recording(path)
    assert recording.truncated is None and recording.count("/joint_states") == 401
    assert b"first flat" in proc.stderr and b"first flat" not in proc.stdout


def test_a_trajectory_to_standard_output(tmp_path):
    proc = cli("simulate", "paper_4x4", *SHORT, "--out", "-")
    assert proc.returncode == 0, proc.stderr
    path = tmp_path / "t.npz"
    path.write_bytes(proc.stdout)
    with np.load(path) as z:
        assert z["theta"].shape == (401, 11)


def test_a_rerun_file_to_standard_output(tmp_path):
    proc = cli("replay", Path(__file__).resolve().parent.parent / "bags" / "paper_4x4_uniform.mcap",
               "--save", "/dev/stdout")
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith(b"RRF2") and b"frames" in proc.stderr
    path = tmp_path / "r.rrd"
    path.write_bytes(proc.stdout)
    verify = subprocess.run([str(Path(sys.executable).parent / "rerun"), "rrd", "verify",
                             str(path)], capture_output=True, text=True, timeout=120)
    assert verify.returncode == 0, verify.stderr


def test_a_link_to_a_file_is_written_through(tmp_path):
    target = tmp_path / "target.npz"
    target.write_text("old")
    link = tmp_path / "link.npz"
    link.symlink_to(target)
    proc = cli("simulate", "paper_4x4", *SHORT, "--out", link)
    assert proc.returncode == 0, proc.stderr
    assert link.is_symlink() and link.resolve() == target
    with np.load(target) as z:
        assert z["theta"].shape == (401, 11)


def test_two_outputs_to_standard_output_are_refused():
    proc = cli("simulate", "paper_4x4", *SHORT, "--out", "-", "--record", "/dev/stdout")
    assert proc.returncode == 2 and proc.stdout == b""
    assert proc.stderr.decode().strip().splitlines() == [
        "panel-deploy: error: --record: standard output is also --out: one output can stream there"]


def test_a_long_name_the_file_system_takes_is_not_refused_for_its_affixes(tmp_path):
    name = "r" * (255 - len(".mcap")) + ".mcap"  # 255 bytes: the longest name
    proc = cli("simulate", "paper_4x4", *SHORT, "--record", tmp_path / name, "--out",
               tmp_path / ("t" * 251 + ".npz"))
    assert proc.returncode == 0, proc.stderr
    assert open_recording(tmp_path / name).count("/joint_states") == 401
    assert sorted(p.name for p in tmp_path.iterdir()) == [name, "t" * 251 + ".npz"]
