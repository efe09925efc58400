"""Recording and replay cost on the paper scene (2 s at 200 Hz, 401 samples).
Prints medians (wall clock, 2 shared cores), measured side by side.

    python bench/bench_record.py [--repeats N] [--process]

- ``simulate`` against ``simulate --record`` in this process, interleaved
  (the numba kernels compiled and the modules imported once, before timing):
  the job itself, which is what the recording adds to; goal <= 1.2x.
  ``--process`` also times both as whole commands (a new interpreter each,
  imports and compiled-kernel loading included).
- File size per simulated second at the default rate, and per sample.
- ``replay --save OUT.rrd`` of the recording (read, forward kinematics,
  energies, the collision check over every sample, rerun logging), and
  rerun's own ``rerun mcap convert`` of the same file for comparison.
"""

from __future__ import annotations

import argparse
import io
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from contextlib import redirect_stdout
from pathlib import Path

from panel_deploy.cli import main
from panel_deploy.record import open_recording


def _job(argv) -> float:
    start = time.perf_counter()
    with redirect_stdout(io.StringIO()):
        main(argv)
    return time.perf_counter() - start


def _process(argv) -> float:
    start = time.perf_counter()
    subprocess.run([sys.executable, "-m", "panel_deploy.cli", *argv], check=False,
                   capture_output=True)
    return time.perf_counter() - start


def _line(label, plain, recorded):
    a, b = statistics.median(plain), statistics.median(recorded)
    ratios = statistics.median(r / p for p, r in zip(plain, recorded))
    print(f"{label}: simulate {a:.3f} s, simulate --record {b:.3f} s: ratio of medians "
          f"{b / a:.3f}, median of paired ratios {ratios:.3f} ({len(plain)} pairs)")


def main_bench(repeats: int, process: bool) -> None:
    work = Path(tempfile.mkdtemp(prefix="bench_record_"))
    mcap = work / "paper.mcap"
    plain_args = ["simulate", "paper_4x4"]
    record_args = [*plain_args, "--record", str(mcap)]
    _job(plain_args), _job(record_args)  # compile and import before timing
    plain, recorded = [], []
    for _ in range(repeats):
        plain.append(_job(plain_args))
        recorded.append(_job(record_args))
    _line("in process", plain, recorded)
    if process:
        plain, recorded = [], []
        for _ in range(max(3, repeats // 3)):
            plain.append(_process(plain_args))
            recorded.append(_process(record_args))
        _line("whole command", plain, recorded)

    recording = open_recording(mcap)
    size = mcap.stat().st_size
    seconds = recording.end_time
    samples = recording.count("/joint_states")
    print(f"file: {size / 1e3:.1f} kB for {seconds:g} s simulated ({samples} samples, "
          f"{sum(recording.count(t) for t in recording.topics)} messages): "
          f"{size / seconds / 1e3:.1f} kB per simulated second, {size / samples / 1e3:.2f} kB per sample")

    rrd = work / "paper.rrd"
    replay = [_job(["replay", str(mcap), "--save", str(rrd)]) for _ in range(max(3, repeats // 2))]
    print(f"replay --save .rrd of the {seconds:g} s deployment: {statistics.median(replay):.3f} s "
          f"(median of {len(replay)}; .rrd {rrd.stat().st_size / 1e3:.0f} kB)")
    rerun = Path(sys.executable).parent / "rerun"
    rerun = str(rerun) if rerun.exists() else shutil.which("rerun")
    if rerun:
        convert = []
        for _ in range(3):
            start = time.perf_counter()
            subprocess.run([rerun, "mcap", "convert", str(mcap), "-o", str(work / "convert.rrd")],
                           check=True, capture_output=True)
            convert.append(time.perf_counter() - start)
        print(f"rerun mcap convert of the same file: {statistics.median(convert):.3f} s (median of 3)")
    shutil.rmtree(work)


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=11, help="timed pairs (default 11)")
    parser.add_argument("--process", action="store_true", help="also time whole commands")
    args = parser.parse_args()
    main_bench(args.repeats, args.process)
