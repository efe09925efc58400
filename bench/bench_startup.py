"""First and later runs of ``panel-deploy simulate paper_4x4``, against the goals
(first run under 15 s, warm run under 3 s on this 2-core machine).

    python bench/bench_startup.py [--cold N] [--warm N] [--scene NAME] [--no-install]

- install: this checkout built as ``pip install`` builds it (a wheel, in pip's
  isolated build environment, which compiles the kernels into the package:
  see ``panel_deploy/_precompile.py``) and installed on its own into a new
  folder; the build time, then the first run of that install with
  ``NUMBA_CACHE_DIR`` pointing at an empty folder (median of ``--cold`` runs,
  each with its own folder): what a new user meets;
- JIT cold: the same command, numba's own cache locators (so nothing compiled
  at install is used) and an empty ``NUMBA_CACHE_DIR``: every kernel
  compiles, as in an editable checkout, and as the build itself does;
- warm: the command again on the cache the JIT cold run filled (median of
  ``--warm`` runs), which is what every later run costs;
- where the JIT cold run's time goes: import of the package, then each
  compiled kernel's own compile time (numba's ``numba:compile`` events, nested
  compiles subtracted, so the figures add up), measured in one more cold
  process that runs the command in-process.

Figures, not assertions: the machine is shared, so compare runs made side by
side in one session.
"""

from __future__ import annotations

import argparse
import glob
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from panel_deploy._numba_cache import NUMBA_LOCATORS

ROOT = Path(__file__).resolve().parent.parent

GOAL_COLD = 15.0  # s
GOAL_WARM = 3.0  # s

#: Runs the command in-process with a listener on numba's compile events and
#: prints JSON: import time, command time, per-kernel compile seconds.
PROFILE = r"""
import json, sys, time
t0 = time.perf_counter()
from collections import defaultdict
from numba.core import event
stack, own, count = [], defaultdict(float), defaultdict(int)

class Timer(event.Listener):
    def on_start(self, ev):
        f = ev.data["dispatcher"].py_func
        stack.append([f"{f.__module__}.{f.__qualname__}", time.perf_counter(), 0.0])

    def on_end(self, ev):
        name, start, nested = stack.pop()
        took = time.perf_counter() - start
        own[name] += took - nested
        count[name] += 1
        if stack:
            stack[-1][2] += took

event.register("numba:compile", Timer())
from panel_deploy.cli import main
t1 = time.perf_counter()
main(sys.argv[1:])
t2 = time.perf_counter()
print(json.dumps({"import": t1 - t0, "command": t2 - t1, "own": own, "count": count}),
      file=sys.stderr)
"""


def _env(cache_dir, **more):
    """numba's own locators unless told otherwise (``NUMBA_CACHE_LOCATOR_CLASSES=""``)."""
    env = {**os.environ, "NUMBA_CACHE_DIR": cache_dir, "NUMBA_CACHE_LOCATOR_CLASSES": NUMBA_LOCATORS}
    env.update(more)
    return {k: v for k, v in env.items() if v != ""}


def timed(argv, env, cwd=None):
    start = time.perf_counter()
    subprocess.run(argv, env=env, cwd=cwd, check=True, stdout=subprocess.DEVNULL,
                   stderr=subprocess.DEVNULL)
    return time.perf_counter() - start


def install(folder):
    """Build this checkout as pip does from a fresh clone (the files git would
    commit, no build folder) and install the wheel alone into ``folder``;
    returns the build's wall time (s)."""
    source, wheels = os.path.join(folder, "source"), os.path.join(folder, "wheels")
    files = subprocess.run(["git", "ls-files", "--cached", "--others", "--exclude-standard"],
                           cwd=ROOT, check=True, capture_output=True, text=True).stdout.split()
    for name in files:
        if (ROOT / name).is_file():
            os.makedirs(os.path.dirname(os.path.join(source, name)), exist_ok=True)
            shutil.copy2(ROOT / name, os.path.join(source, name))
    build = timed([sys.executable, "-m", "pip", "wheel", source, "--no-deps", "-q",
                   "-w", wheels], os.environ)
    subprocess.run([sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--target",
                    os.path.join(folder, "site"), *glob.glob(os.path.join(wheels, "*.whl"))],
                   check=True)
    return build


def profile(args, cache_dir):
    out = subprocess.run([sys.executable, "-c", PROFILE, *args], env=_env(cache_dir),
                         check=True, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                         text=True)
    return json.loads(out.stderr.strip().splitlines()[-1])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cold", type=int, default=1, help="first runs of the install, and JIT cold runs")
    ap.add_argument("--warm", type=int, default=5, help="warm runs")
    ap.add_argument("--scene", default="paper_4x4")
    ap.add_argument("--top", type=int, default=25, help="kernels listed")
    ap.add_argument("--no-profile", action="store_true", help="skip the per-kernel breakdown")
    ap.add_argument("--no-install", action="store_true", help="skip the build and install")
    a = ap.parse_args(argv)
    # a path: a package installed with --target has no share/ folder on sys.prefix
    args = ["simulate", str(ROOT / "config" / "scenes" / f"{a.scene}.yaml")]
    command = [sys.executable, "-m", "panel_deploy.cli", *args]
    with tempfile.TemporaryDirectory() as tmp:
        if not a.no_install:
            build = install(tmp)
            site = {"PYTHONPATH": os.path.join(tmp, "site"), "NUMBA_CACHE_LOCATOR_CLASSES": ""}
            first = [timed(command, _env(os.path.join(tmp, f"first{i}"), **site), cwd=tmp)
                     for i in range(a.cold)]
        cold = [timed(command, _env(os.path.join(tmp, f"cold{i}"))) for i in range(a.cold)]
        warm = [timed(command, _env(os.path.join(tmp, "cold0"))) for _ in range(a.warm)]
        prof = None if a.no_profile else profile(args, os.path.join(tmp, "profile"))
    print(f"panel-deploy simulate {a.scene}, {os.cpu_count()} cores, "
          f"load average {os.getloadavg()[0]:.2f}")
    if not a.no_install:
        print(f"build as pip install does (compiles the kernels): {build:6.1f} s")
        print(f"first run of that install:    median {statistics.median(first):6.2f} s of "
              f"{len(first)} ({', '.join(f'{t:.2f}' for t in first)}), goal < {GOAL_COLD:g} s")
    print(f"JIT cold (empty NUMBA_CACHE_DIR, numba's locators): median "
          f"{statistics.median(cold):6.1f} s of {len(cold)} ({', '.join(f'{t:.1f}' for t in cold)})")
    print(f"warm:                         median {statistics.median(warm):6.2f} s of {len(warm)} "
          f"({', '.join(f'{t:.2f}' for t in warm)}), goal < {GOAL_WARM:g} s")
    if prof is None:
        return 0
    own, count = prof["own"], prof["count"]
    total = sum(own.values())
    print(f"\nprofiled JIT cold run: import {prof['import']:.2f} s, command {prof['command']:.1f} s, "
          f"of which compiling {total:.1f} s in {sum(count.values())} compiles "
          f"of {len(own)} functions")
    print("  own s   share  compiles  function (numba's own overloads under numba.*)")
    for name in sorted(own, key=own.get, reverse=True)[:a.top]:
        print(f"{own[name]:7.2f}  {own[name] / total:6.1%}  {count[name]:8d}  {name}")
    rest = sorted(own, key=own.get, reverse=True)[a.top:]
    if rest:
        print(f"{sum(own[k] for k in rest):7.2f}  {sum(own[k] for k in rest) / total:6.1%}"
              f"  {sum(count[k] for k in rest):8d}  ({len(rest)} more)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
