"""A recording process killed with SIGKILL mid-run: the file, left under its partial name,
is read back up to its last complete chunk, and at most 0.5 s of computed simulated time is
missing from it; collide and replay say it was cut, rerun reads it with --recover."""

import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest

import numpy as np

from panel_deploy.build import build_model
from panel_deploy.record import hinge_track, joint_states, open_recording
from panel_deploy.scene import load_scene, resolve_scene

#: The child runs ``panel-deploy simulate --record`` and prints the time of every
#: sample as the simulation hands it out (computed), before it is recorded.
CHILD = """
import sys
from panel_deploy.dynamics import deployment as live
from panel_deploy.cli import main

iterate = live.Deployment.__iter__
def printing(self):
    for sample in iterate(self):
        print(repr(sample.t), flush=True)
        yield sample
live.Deployment.__iter__ = printing
sys.exit(main(["simulate", "paper_4x4", "--t-end", "10", "--set", "simulation.samples=2001",
                "--record", sys.argv[1]]))
"""


def test_sigkill_mid_run_loses_at_most_half_a_second(tmp_path):
    path = tmp_path / "killed.mcap"
    # cwd: not the checkout, which ``-c`` would import instead of the package under
    # test (in CI its kernels then compiled first: 135 s instead of 10)
    proc = subprocess.Popen([sys.executable, "-c", CHILD, str(path)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, cwd=tmp_path)
    computed = 0.0
    try:
        for line in proc.stdout:
            computed = float(line)
            if computed >= 1.5:
                os.kill(proc.pid, signal.SIGKILL)
                break
    finally:
        if proc.poll() is None:
            os.kill(proc.pid, signal.SIGKILL)
        rest, err = proc.communicate(timeout=60)
    assert proc.returncode == -signal.SIGKILL, err
    computed = max([computed] + [float(x) for x in rest.split()])
    assert 1.5 <= computed < 9.0, "killed mid-run"

    assert not path.exists()  # never renamed into place
    (partial,) = tmp_path.glob("killed.*.part.mcap")  # the name README gives
    recording = open_recording(partial)
    assert recording.truncated  # no footer: the process never closed the file
    states = joint_states(recording)
    model = build_model(load_scene(resolve_scene("paper_4x4")))
    track = hinge_track(states, model, partial)
    assert np.allclose(np.diff(track.t), 0.005, atol=1e-9)  # every sample up to the cut
    assert np.allclose(track.theta[0], model.theta_stowed)
    assert computed - track.t[-1] <= 0.5, (computed, track.t[-1])
    assert recording.count("/robot_description") == recording.count("/panel_deploy/model") == 1
    assert recording.count("/tf") == recording.count("/panel_deploy/panels") == len(track.t)
    assert {"scene", "model", "integrator", "run"} <= set(recording.metadata)

    # The mcap library's own stream reader agrees on what is there before the cut.
    from mcap.stream_reader import StreamReader
    from mcap.records import Message

    messages = 0
    try:
        for record in StreamReader(open(partial, "rb"), validate_crcs=True).records:
            messages += isinstance(record, Message)
    except Exception:
        pass  # the cut
    assert messages == sum(recording.count(t) for t in recording.topics)

    # collide and replay work on it and say (one line on stderr) that it was cut
    cli = str(Path(sys.executable).parent / "panel-deploy")
    for argv in (["collide", partial], ["replay", partial, "--save", tmp_path / "cut.rrd"]):
        proc = subprocess.run([cli, *map(str, argv)], capture_output=True, text=True, timeout=120)
        notes = [line for line in proc.stderr.splitlines() if "is truncated" in line]
        assert proc.returncode in (0, 1) and len(notes) == 1, proc.stderr
        assert "without the MCAP footer" in notes[0] and f"{track.t[-1]:.4f} s" in notes[0]

    # README's recovery: rerun converts it only with --recover (without, an empty file, exit 0)
    rerun = shutil.which("rerun") or str(Path(sys.executable).parent / "rerun")
    if not os.path.exists(rerun):
        pytest.skip("no rerun CLI")
    sizes = {}
    for flags in ([], ["--recover"]):
        out = tmp_path / f"recovered{len(flags)}.rrd"
        subprocess.run([rerun, "mcap", "convert", *flags, str(partial), "-o", str(out)],
                       capture_output=True, timeout=120, check=True)
        sizes[len(flags)] = out.stat().st_size
    assert sizes[0] < 10_000 and sizes[1] > 100 * sizes[0], sizes
