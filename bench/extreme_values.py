"""Every scene key pushed to extreme values through the CLI: one line or an answer, in seconds.

    python bench/extreme_values.py

For every key of the scene schema and each of 0, -1, 1e-300, 1e300, 1e-9, 1e9
and 0.5, runs ``simulate paper_4x4`` (short, unless the key is a simulation
key) and ``export paper_4x4`` in-process with ``--set KEY=VALUE``, and prints
the cases run, every broken contract (a traceback, an exit code other than
0/1/2, an exit 2 without exactly one stderr line, a NaN in a successful
summary) and the slowest cases. Writes only into a temporary folder.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import tempfile
import time
from dataclasses import fields

from panel_deploy.cli import main
from panel_deploy.scene import SECTIONS
from panel_deploy.validate import first_non_finite_value

VALUES = ("0", "-1", "1e-300", "1e300", "1e-9", "1e9", "0.5")
SHORT = ["--set", "simulation.t_end=0.02", "--set", "simulation.samples=5"]


def run(argv):
    """(exit code, stdout, stderr lines, s) of one in-process run; exceptions propagate."""
    out, err = io.StringIO(), io.StringIO()
    start = time.perf_counter()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main(argv)
        except SystemExit as e:
            code = e.code
    return code, out.getvalue(), [x for x in err.getvalue().splitlines() if x.strip()], \
        time.perf_counter() - start


def sweep(folder) -> int:
    keys = [f"{name}.{f.name}" for name, cls in SECTIONS.items() for f in fields(cls)]
    broken, timings = [], []
    for key in keys:
        for value in VALUES:
            cases = (["simulate", "paper_4x4", "--json"] + ([] if key.startswith("simulation.") else SHORT),
                     ["export", "paper_4x4", "--mjcf", f"{folder}/m.xml"])
            for command in cases:
                argv = [*command, "--set", f"{key}={value}"]
                try:
                    code, out, err, wall = run(argv)
                except BaseException as e:  # the contract: never a traceback
                    broken.append((argv, f"traceback {type(e).__name__}: {e}"))
                    continue
                if code not in (0, 1, 2):
                    broken.append((argv, f"exit {code}"))
                elif code == 2 and len(err) != 1:
                    broken.append((argv, f"exit 2 with {len(err)} lines"))
                elif code == 0 and command[0] == "simulate" and first_non_finite_value(json.loads(out)):
                    broken.append((argv, "a non-finite number in a successful summary"))
                timings.append((wall, command[0], f"{key}={value}", code))
    print(f"{len(timings)} cases over {len(keys)} keys x {len(VALUES)} values x (simulate, export)")
    codes = {c: sum(1 for t in timings if t[3] == c) for c in (0, 1, 2)}
    print("exit 0: {0}, exit 1: {1}, exit 2: {2}".format(*codes.values()))
    for argv, what in broken:
        print("BROKEN", " ".join(argv), "->", what)
    timings.sort(reverse=True)
    print("slowest:", "; ".join(f"{w:.2f} s {cmd} {kv} (exit {c})" for w, cmd, kv, c in timings[:5]))
    slowest_refusal = max((t for t in timings if t[3] == 2), default=None)
    if slowest_refusal:
        print(f"slowest refusal (exit 2): {slowest_refusal[0]:.2f} s {slowest_refusal[1]} "
              f"{slowest_refusal[2]}")
    return 1 if broken else 0


if __name__ == "__main__":
    argparse.ArgumentParser(description=__doc__.splitlines()[0]).parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        raise SystemExit(sweep(tmp))
