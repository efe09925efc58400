"""First and later runs of ``panel-deploy simulate paper_4x4``, against the goals
(first run under 15 s, warm run under 3 s on this 2-core machine).

    python bench/bench_startup.py [--cold N] [--warm N] [--scene NAME]

- cold: a new interpreter with ``NUMBA_CACHE_DIR`` pointing at an empty
  folder, so every kernel compiles (median of ``--cold`` runs, each with its
  own folder);
- warm: the same command again on the cache the cold run filled (median of
  ``--warm`` runs), which is what every later run costs;
- where the cold run's time goes: import of the package, then each compiled
  kernel's own compile time (numba's ``numba:compile`` events, nested
  compiles subtracted, so the figures add up), measured in one more cold
  process that runs the command in-process.

Figures, not assertions: the machine is shared, so compare runs made side by
side in one session.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

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


def _env(cache_dir):
    return {**os.environ, "NUMBA_CACHE_DIR": cache_dir}


def timed(argv, cache_dir):
    start = time.perf_counter()
    subprocess.run(argv, env=_env(cache_dir), check=True, stdout=subprocess.DEVNULL,
                   stderr=subprocess.DEVNULL)
    return time.perf_counter() - start


def profile(args, cache_dir):
    out = subprocess.run([sys.executable, "-c", PROFILE, *args], env=_env(cache_dir),
                         check=True, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                         text=True)
    return json.loads(out.stderr.strip().splitlines()[-1])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cold", type=int, default=1, help="cold runs (each compiles everything)")
    ap.add_argument("--warm", type=int, default=5, help="warm runs")
    ap.add_argument("--scene", default="paper_4x4")
    ap.add_argument("--top", type=int, default=25, help="kernels listed")
    ap.add_argument("--no-profile", action="store_true", help="skip the per-kernel breakdown")
    a = ap.parse_args(argv)
    args = ["simulate", a.scene]
    command = [sys.executable, "-m", "panel_deploy.cli", *args]
    with tempfile.TemporaryDirectory() as tmp:
        cold = [timed(command, os.path.join(tmp, f"cold{i}")) for i in range(a.cold)]
        warm = [timed(command, os.path.join(tmp, "cold0")) for _ in range(a.warm)]
        prof = None if a.no_profile else profile(args, os.path.join(tmp, "profile"))
    print(f"panel-deploy simulate {a.scene}, {os.cpu_count()} cores, "
          f"load average {os.getloadavg()[0]:.2f}")
    print(f"cold (empty NUMBA_CACHE_DIR): median {statistics.median(cold):6.1f} s of {len(cold)} "
          f"({', '.join(f'{t:.1f}' for t in cold)}), goal < {GOAL_COLD:g} s")
    print(f"warm:                         median {statistics.median(warm):6.2f} s of {len(warm)} "
          f"({', '.join(f'{t:.2f}' for t in warm)}), goal < {GOAL_WARM:g} s")
    if prof is None:
        return 0
    own, count = prof["own"], prof["count"]
    total = sum(own.values())
    print(f"\nprofiled cold run: import {prof['import']:.2f} s, command {prof['command']:.1f} s, "
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
