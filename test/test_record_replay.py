"""``panel-deploy replay``: the .rrd it saves read back with rerun, the PNG strip, --serve on 127.0.0.1."""

import os
import signal
import socket
import subprocess
import sys
import time
from collections import defaultdict
from pathlib import Path

import numpy as np
import pytest
import yaml
from hostile import file_size_limit

from panel_deploy.build import build_model
from panel_deploy.cli import main
from panel_deploy.scene import load_scene, resolve_scene


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    path = tmp_path_factory.mktemp("replay") / "paper.mcap"
    assert main(["simulate", "paper_4x4", "--record", str(path)]) == 0
    return path


@pytest.fixture(scope="module")
def model():
    return build_model(load_scene(resolve_scene("paper_4x4")))


def _entities(rrd):
    """entity -> {component: [values]}, and entity -> set of sim_time stamps (ns)."""
    from rerun.chunk import RrdReader

    values, times = defaultdict(lambda: defaultdict(list)), defaultdict(set)
    reader = RrdReader(rrd)
    assert reader.blueprints(), "the .rrd carries its blueprint"
    for chunk in reader.stream():
        batch = chunk.to_record_batch()
        for name in batch.schema.names:
            if name == "sim_time":
                times[chunk.entity_path] |= {x.value for x in batch.column(name)}
            elif ":" in name:
                values[chunk.entity_path][name] += [x for x in batch.column(name).to_pylist() if x]
    return values, times


def test_saved_rrd_has_every_panel_moving_one_frame_per_sample(recording, model, tmp_path, capsys):
    rrd = tmp_path / "paper.rrd"
    assert main(["replay", str(recording), "--save", str(rrd)]) == 0
    assert "401 frames" in capsys.readouterr().out
    values, times = _entities(rrd)
    stamps = {round(k * 5e6) for k in range(401)}  # 200 Hz, ns
    import rerun as rr
    for body in model.bodies:
        entity = "/world/panels/" + rr.escape_entity_path_part(body.name)
        assert np.allclose(values[entity]["Boxes3D:half_sizes"][0][0], np.asarray(body.size) / 2)
        assert len(values[entity]["Transform3D:translation"]) == 401
        assert times[entity] == stamps
    for name in ("kinetic", "spring", "gravity", "total"):
        assert times[f"/energy/{name}"] == stamps
    hinges = [e for e in values if e.startswith("/hinges/")]
    assert len(hinges) == len(model.hinges) and all(times[e] == stamps for e in hinges)
    d_times = sorted(times["/distance/d"])  # up to the first collision (revealed at 0.42 s)
    assert len(d_times) > 70 and d_times[-1] < round(0.42e9)
    texts = values["/events"]["TextLog:text"]
    assert texts and "r1c2+r1c3" in texts[0][0] and "r2c2+r2c3" in texts[0][0]
    assert times["/events"] == {round(0.42e9)}  # the sample that reveals the first collision
    # The recording's own monitor, read back: its events and its verdict.
    said = values["/monitor"]["TextLog:text"]
    assert any("r1c2+r1c3" in s[0] and "approach speed" in s[0] for s in said)
    assert any(s[0].startswith("verdict: collision between") for s in said)
    # events at the collision's own time (between samples), the verdict at the end
    assert min(times["/monitor"]) == pytest.approx(0.416e9, abs=1e6)
    assert max(times["/monitor"]) == round(2e9)


def test_png_strip(recording, tmp_path, capsys):
    from PIL import Image

    png = tmp_path / "strip.png"
    assert main(["replay", str(recording), "--png", str(png), "--at", "0,0.1,0.2,0.3,0.4"]) == 0
    assert "5 frames" in capsys.readouterr().out
    with Image.open(png) as image:
        width, height = image.size
        assert width > 4 * height  # five frames side by side
        pixels = np.asarray(image.convert("RGB"))
    assert (pixels.std(axis=(0, 1)) > 5).all()  # something was drawn


def test_png_instant_outside_the_recording(recording, tmp_path, capsys):
    assert main(["replay", str(recording), "--png", str(tmp_path / "x.png"), "--at", "0,7"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("panel-deploy: error: --at: 7 s is outside the recording") and "\n" not in err


@pytest.mark.parametrize("target, limit, expected", [
    ("/dev/full", None, "cannot write /dev/full (No space left on device); the result is saved in "),
    ("old.rrd", 20_000, "cannot write old.rrd (File too large), nor a fallback file (File too "
                        "large); the result is lost"),  # ulimit -f: rerun's file sink hung here
])
def test_an_rrd_that_cannot_be_written_is_one_line(recording, tmp_path, target, limit, expected):
    (tmp_path / "old.rrd").write_bytes(b"the previous replay")
    cli = os.path.join(os.path.dirname(sys.executable), "panel-deploy")
    proc = subprocess.run([cli, "replay", str(recording), "--save", target], cwd=tmp_path,
                          preexec_fn=file_size_limit(limit), capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 2 and proc.stderr.startswith("panel-deploy: error: --save: " + expected)
    assert len(proc.stderr.strip().splitlines()) == 1, proc.stderr
    assert (tmp_path / "old.rrd").read_bytes() == b"the previous replay"
    left = sorted(p.name for p in tmp_path.iterdir())
    assert left[0] == "old.rrd" and len(left) == (1 if limit else 2)
    if not limit:  # the rescued .rrd is a whole one
        values, _ = _entities(tmp_path / left[1])
        assert values


def test_viewer_without_a_display_is_refused_before_any_work(tmp_path, monkeypatch, capsys):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    # a file that does not exist: the refusal comes before it is read
    assert main(["replay", str(tmp_path / "absent.mcap")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("panel-deploy: error: --spawn: no display") and "\n" not in err
    assert "--save" in err


def _listening(port):
    """Local addresses with a TCP socket listening on ``port`` (from /proc/net/tcp{,6})."""
    found = []
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        try:
            lines = open(table).read().splitlines()[1:]
        except OSError:
            continue
        for line in lines:
            local, state = line.split()[1], line.split()[3]
            address, hex_port = local.split(":")
            if state == "0A" and int(hex_port, 16) == port:
                found.append(address)
    return found


def test_serve_binds_loopback_only_and_stops_on_sigint(recording, tmp_path):
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    proc = subprocess.Popen([sys.executable, "-m", "panel_deploy.cli", "replay", str(recording),
                             "--serve", "--port", str(port)], cwd=tmp_path,  # not the checkout
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = proc.stdout.readline()
        assert f"rerun+http://127.0.0.1:{port}/proxy" in line, line + proc.stderr.read()
        deadline = time.monotonic() + 10
        while not _listening(port) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert _listening(port) == ["0100007F"]  # 127.0.0.1 and nothing else
        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=20) == 0
    finally:
        if proc.poll() is None:
            os.kill(proc.pid, signal.SIGKILL)
            proc.wait()


def test_compare_shows_a_scene_s_deployment_beside_the_recorded_one(recording, model, tmp_path,
                                                                     capsys):
    """The recording's own scene as the comparison: its model's boxes and hinge angles,
    at the same times, are the recorded ones (to the interpolation and tolerance)."""
    import rerun as rr
    from panel_deploy.record.analysis import read_deployment
    from panel_deploy.record.compare import compared

    rrd = tmp_path / "both.rrd"
    assert main(["replay", str(recording), "--compare", "paper_4x4", "--save", str(rrd)]) == 0
    assert "beside it: paper_4x4 released at 0.0000 s" in capsys.readouterr().err
    values, times = _entities(rrd)
    stamps = {round(k * 5e6) for k in range(401)}
    for body in model.bodies:
        entity = "/world/model/" + rr.escape_entity_path_part(body.name)
        assert len(values[entity]["Transform3D:translation"]) == 401 and times[entity] == stamps
    d = read_deployment(recording)
    beside = compared(d, d.scene, "paper_4x4")
    before = d.track.t <= 0.41  # up to the first collision: after it neither is physics
    assert np.abs(beside.theta[before] - np.asarray(d.track.theta)[before]).max() < 1e-4
    hinges = [e for e in values if e.startswith("/hinges/") and e.endswith("/model")]
    assert len(hinges) == model.n_coords


@pytest.mark.parametrize("args, parts", [
    (["--release", "0.1"], ["--release", "only with --compare"]),
    (["--compare", "free_vibration_rig"], ["--compare", "another array"]),
    (["--compare", "paper_4x4", "--png", "x.png"], ["--compare", "not in --png"]),
])
def test_compare_refusals_are_one_line(recording, tmp_path, capsys, args, parts):
    out = ["--save", str(tmp_path / "x.rrd")] if "--png" not in args else []
    assert main(["replay", str(recording), *args, *out]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and all(p in err[0] for p in parts), err


def test_compare_on_another_circuit_names_a_hinge_it_lacks(recording, tmp_path, capsys):
    """The same 4 x 4 array on circuit 0: as many bodies and hinges as the
    recording's, so the counts alone cannot say why it is another array."""
    data = yaml.safe_load(Path(resolve_scene("paper_4x4")).read_text())
    data["fold"]["circuit"] = 0
    scene = tmp_path / "circuit0.yaml"
    scene.write_text(yaml.safe_dump(data))
    assert main(["collide", str(recording), "--compare", str(scene)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "(12 bodies, 12 hinges against 12 and 12; the recording's " in err[0], err
    assert " is not in it)" in err[0]


def test_collide_compare_checks_the_scene_s_deployment_on_the_recording_s_times(recording,
                                                                                  capsys):
    import json

    assert main(["collide", str(recording), "--compare", "paper_4x4", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    ours, theirs = out["compared"]["first_collision"], out["first_collision"]
    assert out["compared"]["scene"] == "paper_4x4" and out["compared"]["release"] == 0.0
    assert ours["pair"] == theirs["pair"] and ours["sample"] == theirs["sample"]
    assert abs(ours["t"] - theirs["t"]) < 1e-4
    assert main(["collide", str(recording), "--release", "0.1"]) == 2
    assert "--release: only with --compare" in capsys.readouterr().err
