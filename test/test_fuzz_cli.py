"""Fuzz test of the command line's error contract (issue 19), with hypothesis.

Random scene mutations, random ``--set`` values, random byte corruptions of
scene, result and trajectory files, random output file names, run through
:func:`panel_deploy.cli.main` in-process. Each run must end with exit 0 or 1 and a finite answer, or exit 2
with exactly one line on stderr; never a traceback (any other exception fails).
Issue 26 adds hostile files: YAML aliases (up to billion laughs) in every
place YAML is read, ``.npy`` headers and MCAP chunks declaring sizes they do
not hold (answered within seconds), and outputs naming an input file by
another path (refused, the input unchanged).

SIGINT or SIGTERM at a random moment of a recorded simulation (a child
process) must end it within :data:`PROMPT_S` with exit 130 and the one line
``panel-deploy: interrupted``, or find it already done (0 or 1).

The example budget is fixed and the examples derandomised, so CI runs the same
cases every time in well under a minute; ``bench/fuzz_cli.py`` runs the same
properties with a larger budget and reports outcomes by class.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hostile import alias_flow, mcap_with_chunk, npy_declaring, npz_with

from panel_deploy.cli import main
from panel_deploy.record import messages
from panel_deploy.record.writer import Recorder
from panel_deploy.scene import SECTIONS
from panel_deploy.validate import first_non_finite_value

PAPER = Path(__file__).resolve().parent.parent / "config" / "scenes" / "paper_4x4.yaml"
PAPER_TEXT = PAPER.read_text()
PAPER_DATA = yaml.safe_load(PAPER_TEXT)
#: Every schema key path, plus a few that do not exist.
KEYS = sorted([f"{name}.{f}" for name, cls in SECTIONS.items() for f in cls.__dataclass_fields__]
              + ["gravity", "name", "description", "bogus", "array.bogus", "simulation"])
#: Short runs: the properties test the contract, not the physics.
FAST = ["--set", "simulation.t_end=0.003", "--set", "simulation.samples=4",
        "--set", "simulation.method=compiled"]

CI = settings(max_examples=60, deadline=None, derandomize=True, database=None,
              suppress_health_check=list(HealthCheck))

#: Outcomes of every run (kind, exit code, seconds, first stderr line): read by bench/fuzz_cli.py.
LOG: list = []


class Broken(AssertionError):
    """The contract broken: a traceback, a non-finite answer, or a multi-line error."""


def run_cli(kind: str, argv) -> tuple[int, str, str]:
    """Run ``panel-deploy argv`` in-process; check the contract; log the outcome."""
    out, err = io.StringIO(), io.StringIO()
    start = time.perf_counter()
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                code = main([str(a) for a in argv])
            except SystemExit as e:  # argparse's one-line errors
                code = e.code
    except Exception as e:  # noqa: BLE001 - a traceback is exactly what we look for
        raise Broken(f"{kind}: traceback {type(e).__name__}: {e} for {argv}") from e
    seconds = time.perf_counter() - start
    out, err = out.getvalue(), err.getvalue()
    lines = err.strip().splitlines()
    LOG.append((kind, code, seconds, lines[0] if lines else "", argv))
    if code == 2:
        if len(lines) != 1 or not lines[0].startswith("panel-deploy"):
            raise Broken(f"{kind}: exit 2 needs one line on stderr, got {err!r} for {argv}")
    elif code in (0, 1):
        if "--json" in argv:
            bad = first_non_finite_value(json.loads(out))
            if bad is not None and json.loads(out).get("success", True):
                raise Broken(f"{kind}: non-finite answer {bad} for {argv}")
        elif any(w in out for w in (" nan", "(nan", " inf ")):
            raise Broken(f"{kind}: non-finite answer in {out!r} for {argv}")
    else:
        raise Broken(f"{kind}: exit code {code} for {argv}: {err!r}")
    return code, out, err


# --- strategies ---

finite = st.floats(allow_nan=False, allow_infinity=False)
values = st.recursive(
    st.none() | st.booleans() | st.integers(-10**6, 10**6) | st.floats()
    | st.sampled_from([0, 1, 3, 1e-300, 1e300, -1, 0.5, 1e-9, 50_001, "auto", "none", "penalty",
                       "exact", "RK45", "global", [1, 2], [[1, 1], [1, 2]], [0, 0, 0]])
    | st.text(max_size=8),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=5), inner,
                                                                 max_size=3),
    max_leaves=6)
yaml_text = st.one_of(
    st.text(max_size=20),
    values.map(lambda v: yaml.safe_dump(v, default_flow_style=True).strip()),
    st.sampled_from([".nan", ".inf", "-.inf", "1e400", "[", "{a: 1, a: 2}", "*x", "!!python/none",
                     "[" * 60 + "]" * 60, "0x1F", "1_000", "~", "''"]))


def _set(data, key, value):
    *parents, last = key.split(".")
    node = data
    for p in parents:
        if not isinstance(node.get(p), dict):
            node[p] = {}
        node = node[p]
    node[last] = value


def _corrupt(data: bytes, draw_ops) -> bytes:
    b = bytearray(data)
    for op, pos, byte in draw_ops:
        if not b:
            break
        i = pos % len(b)
        if op == "flip":
            b[i] ^= 1 << (byte % 8)
        elif op == "set":
            b[i] = byte
        elif op == "cut":
            del b[i:]
        elif op == "insert":
            b[i:i] = bytes([byte]) * 3
        elif op == "delete":
            del b[i:i + 1 + byte % 16]
    return bytes(b)


corruptions = st.lists(st.tuples(st.sampled_from(["flip", "set", "cut", "insert", "delete"]),
                                 st.integers(0, 10**7), st.integers(0, 255)), min_size=1, max_size=4)


# --- the cases (plain functions: bench/fuzz_cli.py wraps them with another budget) ---

def case_scene_mutation(mutations, command):
    data = yaml.safe_load(PAPER_TEXT)
    for key, value in mutations:
        _set(data, key, value)
    with tempfile.TemporaryDirectory() as tmp:
        scene = Path(tmp) / "s.yaml"
        scene.write_text(yaml.safe_dump(data))
        _command(command, scene, tmp)


def case_set_values(items, command):
    with tempfile.TemporaryDirectory() as tmp:
        extra = [a for key, text in items for a in ("--set", f"{key}={text}")]
        _command(command, PAPER, tmp, extra)


def case_scene_bytes(ops, command):
    with tempfile.TemporaryDirectory() as tmp:
        scene = Path(tmp) / "s.yaml"
        scene.write_bytes(_corrupt(PAPER_TEXT.encode(), ops))
        _command(command, scene, tmp)


def _command(command, scene, tmp, extra=()):
    if command == "simulate":
        run_cli("simulate", ["simulate", scene, "--json", *FAST, *extra])
    elif command == "export":
        run_cli("export", ["export", scene, "--mjcf", Path(tmp) / "m.xml", *extra])
    else:
        run_cli("fold", ["fold", "--scene", scene, "--json", *extra])


def case_result_bytes(ops, result_text):
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "k.yaml"
        path.write_bytes(_corrupt(result_text.encode(), ops))
        run_cli("result", ["simulate", PAPER, "--json", "--stiffness", path, *FAST])


def case_trajectory_bytes(ops, trajectory: bytes):
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "t.npz"
        path.write_bytes(_corrupt(trajectory, ops))
        run_cli("trajectory", ["collide", path, "--json"])


def case_trajectory_arrays(name, value, trajectory: bytes):
    with tempfile.TemporaryDirectory() as tmp:
        src = Path(tmp) / "src.npz"
        src.write_bytes(trajectory)
        with np.load(src) as z:
            data = {k: z[k] for k in z.files}
        data[name] = value
        path = Path(tmp) / "t.npz"
        np.savez(path, **data)
        run_cli("trajectory", ["collide", path, "--json"])


#: Longest a run on a hostile file may take, s (an alias bomb took minutes and gigabytes).
HOSTILE_SECONDS = 10.0


def _quick(kind):
    seconds, argv = LOG[-1][2], LOG[-1][4]
    if seconds > HOSTILE_SECONDS:
        raise Broken(f"{kind}: {seconds:.1f} s for {argv}")


def _scene_with(key, flow) -> str:
    """The paper scene as YAML text with ``key`` set to the YAML text ``flow`` (aliases and all)."""
    data = yaml.safe_load(PAPER_TEXT)
    _set(data, key, "FLOW_GOES_HERE")
    return yaml.safe_dump(data).replace("FLOW_GOES_HERE", flow)


def case_aliases(levels, width, where, key, trajectory: bytes, result_text: str):
    """``alias_flow(levels, width)`` (width ** levels values written out) at ``key`` of a
    scene file, a --set, a result file's hinge, a trajectory's stored scene or the
    scene message of a recording."""
    flow = alias_flow(levels, width)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "input"
        if where == "scene":
            path.write_text(_scene_with(key, flow))
            run_cli("aliases", ["simulate", path, "--json", *FAST])
        elif where == "--set":
            run_cli("aliases", ["simulate", PAPER, "--json", *FAST, "--set", f"{key}={flow}"])
        elif where == "result":
            path.write_text(result_text.replace("{k: 0.05, c: 0.00215}", flow, 1))
            run_cli("aliases", ["simulate", PAPER, "--json", "--stiffness", path, *FAST])
        elif where == "trajectory":
            path.write_bytes(trajectory)
            with np.load(path) as z:
                data = {k: z[k] for k in z.files}
            data["scene_yaml"] = np.array(_scene_with(key, flow))
            np.savez(Path(tmp) / "t.npz", **data)
            run_cli("aliases", ["collide", Path(tmp) / "t.npz", "--json"])
        else:
            with Recorder(Path(tmp) / "r.mcap") as rec:
                rec.write("/panel_deploy/model", messages.STRING,
                          messages.string(_scene_with(key, flow)), 0)
                rec.write("/joint_states", messages.JOINT_STATE,
                          messages.joint_state(["a"], 0.0, [0.0], [0.0], [0.0]), 0)
            run_cli("aliases", ["collide", Path(tmp) / "r.mcap", "--json"])
    _quick("aliases")


def case_declared_size(name, shape, held, trajectory: bytes):
    """Member ``name`` of a trajectory replaced by a header declaring ``shape`` and ``held`` bytes."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "t.npz"
        path.write_bytes(npz_with(trajectory, f"{name}.npy", npy_declaring(shape, bytes(held))))
        run_cli("declared sizes", ["collide", path, "--json"])
    _quick("declared sizes")


def case_chunk_size(declared, zeros):
    """A recording whose one chunk declares ``declared`` bytes and holds ``zeros`` zeros."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "r.mcap"
        path.write_bytes(mcap_with_chunk(declared, zeros))
        run_cli("declared sizes", ["collide", path, "--scene", PAPER, "--json"])
    _quick("declared sizes")


#: Command lines whose output (``{same}``) names one of their inputs, and that input's file.
SAME_PATH = {
    "simulate --out": (["simulate", "{scene}", "--out", "{same}"], "s.yaml"),
    "simulate --record": (["simulate", "{scene}", "--record", "{same}"], "s.yaml"),
    "simulate --stiffness --out": (["simulate", "{scene}", "--stiffness", "{result}", "--out",
                                    "{same}"], "k.yaml"),
    "optimise --start --out": (["optimise", "{scene}", "--start", "{result}", "--out", "{same}"],
                               "k.yaml"),
    "export --mjcf": (["export", "{scene}", "--mjcf", "{same}"], "s.yaml"),
    "fold --plot": (["fold", "--scene", "{scene}", "--plot", "{same}"], "s.yaml"),
    "replay --save": (["replay", "{mcap}", "--save", "{same}"], "x.mcap"),
    "replay --png": (["replay", "{mcap}", "--png", "{same}"], "x.mcap"),
}
#: Other names of one file: itself, through ``..``, ``//``, a symbolic or a hard link.
PATH_FORMS = ("same", "dotdot", "slashes", "symlink", "hardlink")


def _other_name(path: Path, form: str) -> Path | str:
    if form == "dotdot":
        return path.parent / "sub" / ".." / path.name
    if form == "slashes":
        return f"{path.parent}//{path.name}"
    if form in ("symlink", "hardlink"):
        other = path.parent / f"{form}-{path.name}"
        (os.symlink if form == "symlink" else os.link)(path, other)
        return other
    return path


def case_same_path(command, form):
    """An output that names an input file: refused (exit 2, one line), every file unchanged."""
    argv, name = SAME_PATH[command]
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        files = {"scene": tmp / "s.yaml", "result": tmp / "k.yaml", "mcap": tmp / "x.mcap"}
        files["scene"].write_text(PAPER_TEXT)
        files["result"].write_text("hinges: {}\n")
        files["mcap"].write_bytes(b"\x89MCAP0\r\n")
        (tmp / "sub").mkdir()
        same = _other_name(tmp / name, form)
        before = {p: p.read_bytes() for p in tmp.iterdir() if p.is_file()}
        code, _, err = run_cli("same path", [a.format(same=same, **files) for a in argv])
        if code != 2 or "is also the input" not in err:
            raise Broken(f"same path: {command} on {same} gave exit {code}: {err!r}")
        after = {p: p.read_bytes() for p in tmp.iterdir() if p.is_file()}
        if after != before:
            raise Broken(f"same path: {command} on {same} changed the files")


def _array(v):
    try:
        return np.array(v)
    except ValueError:  # ragged nesting
        return np.array(str(v))


arrays = st.one_of(
    values.map(_array),
    st.tuples(st.integers(0, 5), st.integers(0, 13), st.sampled_from([np.nan, np.inf, 1e300, 0.0]))
    .map(lambda s: np.full((s[0], s[1]), s[2])))
array_names = st.sampled_from(["t", "theta", "omega", "rotation", "position", "constraint_gap",
                               "closure_sigma_min", "energy_kinetic", "stiffness", "scene_yaml",
                               "format_version", "success", "status", "message", "method"])


alias_shapes = st.tuples(st.integers(1, 12), st.integers(1, 12))  # levels, width
alias_places = st.sampled_from(["scene", "--set", "result", "trajectory", "model"])
alias_keys = st.sampled_from(["array.rows", "array.length", "hinges.overrides", "gravity", "name",
                              "fold.merge", "simulation", "optimisation.bounds"])
dimensions = st.sampled_from([0, 1, 3, 9, 50_000, 50_001, 10**6, 10**12, 2**62]) | st.integers(0, 10**13)
declared_shapes = st.lists(dimensions, max_size=3).map(tuple)
chunk_sizes = st.sampled_from([0, 1, 1000, 2**25, 2**25 + 1, 2**30, 2**64 - 1]) | st.integers(0, 2**64 - 1)
#: Commands with an output file, and the flag that names it.
OUTPUT_FLAGS = {"--out": ["simulate", str(PAPER), "--json", *FAST],
                "--record": ["simulate", str(PAPER), "--json", *FAST],
                "--mjcf": ["export", str(PAPER)],
                "--plot": ["fold", "--rows", "2", "--cols", "2", "--json"]}
output_names = st.one_of(
    st.text(max_size=300),
    st.tuples(st.integers(240, 300), st.sampled_from(["", ".npz", ".png", ".xyz"]))
    .map(lambda n: "n" * n[0] + n[1]),
    st.sampled_from([".", "..", "/", "\n", "a\nb.png", "x.PNG", "x.", ".png", "d/x.npz",
                     "\x1b[2J.xml", "x.rrd"]))


def case_output_name(flag, name):
    """An output flag given ``name`` in a fresh folder (names, not folders, are fuzzed)."""
    with tempfile.TemporaryDirectory() as tmp:
        run_cli("output", [*OUTPUT_FLAGS[flag], flag, f"{tmp}/{name}"])


# --- issue 32: standard output as a target, node remaps, foreign recordings ---

CLI = str(Path(sys.executable).parent / "panel-deploy")
#: Outputs that can stream to standard output, and how to recognise what came out.
STDOUT_OUTPUTS = {
    "--record": (["simulate", str(PAPER), *FAST], lambda b: b.startswith(b"\x89MCAP0\r\n")),
    "--out": (["simulate", str(PAPER), *FAST], lambda b: b.startswith(b"PK")),
    "--mjcf": (["export", str(PAPER)], lambda b: b.lstrip().startswith(b"<")),
}
STDOUT_NAMES = ("-", "/dev/stdout", "link to /proc/self/fd/1")
stdout_sinks = st.sampled_from(["pipe", "file"])


def case_stdout_target(flag, name, sink):
    """``flag`` writing standard output by ``name``, standard output a pipe or a file:
    exit 0 with the whole output there and the human lines on stderr, or exit 2 in one line."""
    argv, looks_right = STDOUT_OUTPUTS[flag]
    with tempfile.TemporaryDirectory() as tmp:
        target = name
        if name.startswith("link"):
            target = Path(tmp) / "out"
            os.symlink("/proc/self/fd/1", target)
        out_file = Path(tmp) / "stdout.bin"
        start = time.perf_counter()
        with open(out_file, "wb") as f:
            proc = subprocess.run([CLI, *argv, flag, str(target)], stderr=subprocess.PIPE,
                                  stdout=f if sink == "file" else subprocess.PIPE, timeout=300)
        out = out_file.read_bytes() if sink == "file" else proc.stdout
        err = proc.stderr.decode(errors="replace")
        lines = err.strip().splitlines()
        LOG.append(("stdout", proc.returncode, time.perf_counter() - start,
                    lines[0] if lines else "", [flag, name, sink]))
        if proc.returncode == 2:
            if len(lines) != 1 or out:
                raise Broken(f"stdout: exit 2 with {err!r} and {len(out)} bytes for {flag} {name}")
        elif proc.returncode in (0, 1):
            if not looks_right(out):
                raise Broken(f"stdout: {flag} {name} ({sink}) wrote {out[:40]!r}; stderr {err!r}")
            if "Traceback" in err:
                raise Broken(f"stdout: traceback for {flag} {name}: {err}")
            if name.startswith("link") and not os.path.islink(target):
                raise Broken(f"stdout: the link {target} was replaced")
        else:
            raise Broken(f"stdout: exit {proc.returncode} for {flag} {name}: {err!r}")


#: Remap rules a node executable is started with: names that are no ROS names.
remap_values = st.one_of(
    st.text(st.characters(blacklist_characters="\x00"), min_size=1, max_size=40),  # argv has no NUL
    st.integers(256, 400).map(lambda n: "/" + "a" * n),
    st.sampled_from(["/ärray", "/a//b", "a b", "/1a", "~x", "/a/", "", "\n", "ä", "/{x}"]))


def case_remap(key, value):
    """``collision_monitor --ros-args -r key:=value`` with a value that is no valid
    name: exit 2 and one line (a valid one would start the node: not drawn)."""
    from rclpy.validate_namespace import validate_namespace
    from rclpy.validate_node_name import validate_node_name

    try:
        (validate_namespace if key == "__ns" else validate_node_name)(value)
        return  # a valid name starts the node; not this property's case
    except Exception:  # noqa: BLE001 - rclpy's own invalid-name exceptions
        pass
    start = time.perf_counter()
    proc = subprocess.run([str(Path(sys.executable).parent / "collision_monitor"), "--ros-args",
                           "-r", f"{key}:={value}"], capture_output=True, timeout=60)
    err = proc.stderr.decode(errors="replace")
    lines = err.strip().splitlines()
    LOG.append(("remaps", proc.returncode, time.perf_counter() - start,
                lines[0] if lines else "", [key, value]))
    if proc.returncode != 2 or len(lines) != 1 or not lines[0].startswith("panel-deploy: error"):
        raise Broken(f"remaps: -r {key}:={value!r}: exit {proc.returncode}, {err!r}")


#: Oddities of recordings from other tools, each harmless to the joint states.
ODDITIES = ("shuffled", "repeated", "inf effort", "big message", "unknown compression")
oddities = st.lists(st.sampled_from(ODDITIES), min_size=1, max_size=3, unique=True)


def foreign_recording(path, odd, seed) -> None:
    """A short paper deployment's tree joint states by our writer, with ``odd``."""
    rng = np.random.default_rng(seed)
    t, names, theta = FOREIGN
    rows = list(range(len(t)))
    if "shuffled" in odd:
        rng.shuffle(rows)
    with Recorder(path, chunk_span=0.01) as rec:
        if "big message" in odd:
            rec.write("/camera/raw", messages.STRING,
                      messages.string(rng.bytes(int(rng.integers(1, 4 << 20))).hex()), 0)
        for j in rows:
            effort = np.full(len(names), np.inf if "inf effort" in odd else 0.0)
            msg = messages.joint_state(names, t[j], theta[j], np.zeros(0), effort)
            for _ in range(2 if "repeated" in odd else 1):
                rec.write("/joint_states", messages.JOINT_STATE, msg, round(t[j] * 1e9))
    if "unknown compression" in odd:
        data = path.read_bytes()
        path.write_bytes(data.replace(b"\x04\x00\x00\x00zstd", b"\x04\x00\x00\x00zzz1", 1))


def case_foreign_recording(odd, seed):
    """collide on a recording with ``odd``: the clean stream's first collision, or
    exit 2 in one line naming the compression when a chunk's is unknown."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "foreign.mcap"
        foreign_recording(path, odd, seed)
        code, out, err = run_cli("foreign", ["collide", path, "--scene", PAPER, "--json"])
    if "unknown compression" in odd:
        if code != 2 or "compression 'zzz1'" not in err:
            raise Broken(f"foreign: {odd}: exit {code}, {err!r}")
        return
    if code != 0:
        raise Broken(f"foreign: {odd}: exit {code}, {err!r}")
    if json.loads(out)["first_collision"]["pair"] != FOREIGN_PAIR:
        raise Broken(f"foreign: {odd}: first collision {json.loads(out)['first_collision']}")


def _foreign_stream():
    from panel_deploy.pipeline import simulate_scene
    from panel_deploy.scene import load_scene

    scene = load_scene(PAPER, ["simulation.t_end=0.5", "simulation.samples=101"])
    model, result, report = simulate_scene(scene)
    names = [model.hinges[h].name for h in model.joints]
    return (result.t, names, result.theta), list(report.first_collision.names)


FOREIGN, FOREIGN_PAIR = _foreign_stream()


#: The run of issue 26's report: a deployment recorded as it is computed
#: (numba loads its cached kernels during the first second).
SIGNALLED = ["simulate", str(PAPER), "--record"]
#: Longest wait for a signalled run to end once signalled, s (a warm run
#: takes 2 s in all).
PROMPT_S = 20.0
signals = st.sampled_from([signal.SIGTERM, signal.SIGINT])
signal_delays = st.floats(0.05, 1.2)


def _handles_signals(pid) -> bool:
    """Whether process ``pid`` has left Python's start-up for the command, whose
    handler of SIGTERM it then shows in /proc (Linux), or has ended."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return True
    caught = int(status.split("SigCgt:", 1)[1].split()[0], 16)
    return bool(caught >> (signal.SIGTERM - 1) & 1)


def case_signal(signum, delay):
    """``SIGNALLED`` in a child process, sent ``signum`` ``delay`` s after its start,
    or once past Python's own start-up (up to 0.15 s on a busy machine), which
    meets a signal as Python does (SIGTERM kills, SIGINT prints a traceback)."""
    name = signal.Signals(signum).name
    with tempfile.TemporaryDirectory() as tmp:
        argv = [*SIGNALLED, str(Path(tmp) / "x.mcap")]
        start = time.perf_counter()
        proc = subprocess.Popen([sys.executable, "-m", "panel_deploy.cli", *argv], cwd=tmp,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        while not _handles_signals(proc.pid):
            time.sleep(0.002)
        time.sleep(max(0.0, delay - (time.perf_counter() - start)))
        with contextlib.suppress(ProcessLookupError):
            proc.send_signal(signum)
        sent = time.perf_counter()
        try:
            _, err = proc.communicate(timeout=PROMPT_S)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.communicate()
            raise Broken(f"signal: {name} at {sent - start:.3f} s: still running {PROMPT_S:g} s "
                         "later") from None
    code, lines = proc.returncode, err.strip().splitlines()
    LOG.append(("signal", code, time.perf_counter() - sent, lines[0] if lines else "",
                [name, f"{sent - start:.3f}", *argv]))
    if "Traceback" in err or code not in (0, 1, 130) or (code == 130 and lines != [
            "panel-deploy: interrupted"]):
        raise Broken(f"signal: {name} at {sent - start:.3f} s: exit {code}, stderr {err[-500:]!r}")


# --- fixtures: one valid result file and one valid trajectory ---

@pytest.fixture(scope="module")
def result_text():
    return make_result_text()


def make_result_text() -> str:
    """A valid result file for the paper scene (k 0.05, c/k 0.043 at every hinge)."""
    from panel_deploy.build import build_model
    from panel_deploy.scene import load_scene
    names = [h.name for h in build_model(load_scene(PAPER)).hinges]
    return ("format: panel_deploy.stiffness/1\nscene: paper_4x4\nhinges:\n"
            + "".join(f"  {n}: {{k: 0.05, c: 0.00215}}\n" for n in names))


@pytest.fixture(scope="module")
def signalled_kernels(tmp_path_factory):
    """The kernels of :data:`SIGNALLED` compiled, so that a signal meets their loading."""
    warm_kernels(tmp_path_factory.mktemp("signals") / "x.mcap")


def warm_kernels(record) -> None:
    with contextlib.redirect_stdout(io.StringIO()):
        assert main([*SIGNALLED, str(record)]) in (0, 1)


@pytest.fixture(scope="module")
def trajectory(tmp_path_factory):
    path = tmp_path_factory.mktemp("fuzz") / "t.npz"
    assert main(["simulate", str(PAPER), "--out", str(path), *FAST,
                 "--set", "simulation.samples=9"]) == 0
    return path.read_bytes()


# --- the properties ---

#: Values a schema key may well accept, so that runs also get past validation.
plausible = st.floats(1e-3, 5.0) | st.integers(1, 6)
mutation = st.tuples(st.sampled_from(KEYS), plausible | values)
commands = st.sampled_from(["export", "fold", "simulate"])


@CI
@given(st.lists(mutation, min_size=1, max_size=3), commands)
def test_fuzz_scene_mutations(mutations, command):
    case_scene_mutation(mutations, command)


@CI
@given(st.lists(st.tuples(st.sampled_from(KEYS), yaml_text), min_size=1, max_size=3), commands)
def test_fuzz_set_values(items, command):
    case_set_values(items, command)


@CI
@given(corruptions, st.sampled_from(["export", "fold"]))
def test_fuzz_scene_bytes(ops, command):
    case_scene_bytes(ops, command)


@settings(CI, max_examples=40)
@given(ops=corruptions)
def test_fuzz_result_bytes(result_text, ops):
    case_result_bytes(ops, result_text)


@CI
@given(ops=corruptions)
def test_fuzz_trajectory_bytes(trajectory, ops):
    case_trajectory_bytes(ops, trajectory)


@CI
@given(name=array_names, value=arrays)
def test_fuzz_trajectory_arrays(trajectory, name, value):
    case_trajectory_arrays(name, value, trajectory)


@settings(CI, max_examples=40)
@given(shape=alias_shapes, where=alias_places, key=alias_keys)
def test_fuzz_aliases(trajectory, result_text, shape, where, key):
    case_aliases(*shape, where, key, trajectory, result_text)


@settings(CI, max_examples=40)
@given(name=array_names, shape=declared_shapes, held=st.integers(0, 200))
def test_fuzz_declared_sizes(trajectory, name, shape, held):
    case_declared_size(name, shape, held, trajectory)


@settings(CI, max_examples=20)
@given(declared=chunk_sizes, zeros=st.integers(0, 2**20))
def test_fuzz_chunk_sizes(declared, zeros):
    case_chunk_size(declared, zeros)


@settings(CI, max_examples=40)
@given(command=st.sampled_from(sorted(SAME_PATH)), form=st.sampled_from(PATH_FORMS))
def test_fuzz_same_path_outputs(command, form):
    case_same_path(command, form)


@CI
@given(st.sampled_from(sorted(OUTPUT_FLAGS)), output_names)
def test_fuzz_output_names(flag, name):
    case_output_name(flag, name)


@settings(CI, max_examples=20)
@given(signum=signals, delay=signal_delays)
def test_fuzz_signals_at_random_times(signalled_kernels, signum, delay):
    case_signal(signum, delay)


@settings(CI, max_examples=6)
@given(flag=st.sampled_from(sorted(STDOUT_OUTPUTS)), name=st.sampled_from(STDOUT_NAMES),
       sink=stdout_sinks)
def test_fuzz_standard_output_targets(flag, name, sink):
    case_stdout_target(flag, name, sink)


@settings(CI, max_examples=8)
@given(key=st.sampled_from(["__ns", "__node"]), value=remap_values)
def test_fuzz_node_remaps(key, value):
    case_remap(key, value)


@settings(CI, max_examples=15)
@given(odd=oddities, seed=st.integers(0, 2**16))
def test_fuzz_foreign_recordings(odd, seed):
    case_foreign_recording(odd, seed)


def test_the_contract_check_can_fail(monkeypatch):
    """run_cli catches what it is there for: a traceback, and an exit 2 of several lines."""
    import panel_deploy.cli as cli
    monkeypatch.setattr(cli, "_schema", lambda args: 1 / 0)
    with pytest.raises(Broken, match="traceback ZeroDivisionError"):
        run_cli("self", ["schema"])

    def two_lines(args):
        print("panel-deploy: error: a\nb", file=__import__("sys").stderr)
        return 2
    monkeypatch.setattr(cli, "_schema", two_lines)
    with pytest.raises(Broken, match="one line"):
        run_cli("self", ["schema"])
