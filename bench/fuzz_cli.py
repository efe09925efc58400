"""Deeper run of the CLI fuzz test (test/test_fuzz_cli.py): same properties, larger budget.

    python bench/fuzz_cli.py [--examples N] [--seed S] [--only PROPERTY ...]

Runs every property of the test module (or those named) with N examples each
(random, not the CI's fixed set), then prints the cases tried, the outcomes by
property and exit code, the most frequent error lines, the slowest clean
failure (exit 2), and for the signals at random times the longest wait from
the signal to the exit.
A broken contract (traceback, several lines, non-finite answer) is shrunk by
hypothesis and printed; the script then exits 1.
"""

from __future__ import annotations

import argparse
import collections
import contextlib
import io
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "test"))

import hypothesis  # noqa: E402
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

import test_fuzz_cli as fz  # noqa: E402

PROPERTIES = ["scene mutations", "--set values", "scene bytes", "result bytes",
              "trajectory bytes", "trajectory arrays", "aliases", "declared sizes", "chunk sizes",
              "same path", "output names", "signals", "stdout targets", "node remaps",
              "foreign recordings"]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--examples", type=int, default=300, help="examples per property")
    p.add_argument("--seed", type=int, default=None, help="hypothesis seed (default: random)")
    p.add_argument("--only", nargs="+", metavar="PROPERTY", choices=PROPERTIES,
                   help=f"run only these properties, of: {', '.join(PROPERTIES)}")
    args = p.parse_args(argv)

    from panel_deploy.cli import main as cli
    tmp = Path(tempfile.mkdtemp())
    with contextlib.redirect_stdout(io.StringIO()):
        cli(["simulate", str(fz.PAPER), "--out", str(tmp / "t.npz"), *fz.FAST,
             "--set", "simulation.samples=9"])
    trajectory = (tmp / "t.npz").read_bytes()
    result_text = fz.make_result_text()
    fz.warm_kernels(tmp / "x.mcap")

    deep = settings(max_examples=args.examples, deadline=None, database=None,
                    suppress_health_check=list(HealthCheck))
    mutation = fz.mutation
    properties = {
        "scene mutations": given(st.lists(mutation, min_size=1, max_size=3), fz.commands)(
            fz.case_scene_mutation),
        "--set values": given(st.lists(st.tuples(st.sampled_from(fz.KEYS), fz.yaml_text),
                                       min_size=1, max_size=3), fz.commands)(fz.case_set_values),
        "scene bytes": given(fz.corruptions, st.sampled_from(["export", "fold"]))(
            fz.case_scene_bytes),
        "result bytes": given(fz.corruptions)(lambda ops: fz.case_result_bytes(ops, result_text)),
        "trajectory bytes": given(fz.corruptions)(
            lambda ops: fz.case_trajectory_bytes(ops, trajectory)),
        "trajectory arrays": given(fz.array_names, fz.arrays)(
            lambda name, value: fz.case_trajectory_arrays(name, value, trajectory)),
        "aliases": given(fz.alias_shapes, fz.alias_places, fz.alias_keys)(
            lambda shape, where, key: fz.case_aliases(*shape, where, key, trajectory,
                                                      result_text)),
        "declared sizes": given(fz.array_names, fz.declared_shapes, st.integers(0, 200))(
            lambda name, shape, held: fz.case_declared_size(name, shape, held, trajectory)),
        "chunk sizes": given(fz.chunk_sizes, st.integers(0, 2**20))(fz.case_chunk_size),
        "same path": given(st.sampled_from(sorted(fz.SAME_PATH)), st.sampled_from(fz.PATH_FORMS))(
            fz.case_same_path),
        "output names": given(st.sampled_from(sorted(fz.OUTPUT_FLAGS)), fz.output_names)(
            fz.case_output_name),
        "signals": given(fz.signals, fz.signal_delays)(fz.case_signal),
        "stdout targets": given(st.sampled_from(sorted(fz.STDOUT_OUTPUTS)),
                                st.sampled_from(fz.STDOUT_NAMES), fz.stdout_sinks)(
            fz.case_stdout_target),
        "node remaps": given(st.sampled_from(["__ns", "__node"]), fz.remap_values)(fz.case_remap),
        "foreign recordings": given(fz.oddities, st.integers(0, 2**16))(
            fz.case_foreign_recording),
    }
    assert list(properties) == PROPERTIES
    properties = {k: v for k, v in properties.items() if not args.only or k in args.only}
    broken = []
    start = time.perf_counter()
    for label, prop in properties.items():
        first = len(fz.LOG)
        test = deep(prop)
        if args.seed is not None:
            test = hypothesis.seed(args.seed)(test)
        try:
            test()
        except fz.Broken as e:
            broken.append((label, str(e)))
        for i in range(first, len(fz.LOG)):
            fz.LOG[i] = (label, *fz.LOG[i][1:])
    wall = time.perf_counter() - start

    print(f"{len(fz.LOG)} cases in {wall:.0f} s ({args.examples} examples per property, "
          f"shrinking included)")
    by = collections.Counter((kind, code) for kind, code, *_ in fz.LOG)
    codes = sorted({code for _, code in by},
                   key=lambda c: (0, c, "") if isinstance(c, int) else (1, 0, str(c)))
    print(f"{'property':20s} " + " ".join(f"{'exit ' + str(c):>8s}" for c in codes))
    for label in properties:
        print(f"{label:20s} " + " ".join(f"{by[(label, c)]:8d}" for c in codes))
    errors = collections.Counter(
        line.split(": error: ", 1)[-1].split(":")[0][:50] for _, code, _, line, _ in fz.LOG
        if code == 2)
    print("most frequent exit-2 fields:", ", ".join(f"{k} ({n})" for k, n in errors.most_common(12)))
    clean = [x for x in fz.LOG if x[1] == 2]
    if clean:
        kind, _, seconds, line, argv = max(clean, key=lambda x: x[2])
        print(f"slowest clean failure: {seconds:.2f} s ({kind}): {line}")
    signalled = [x for x in fz.LOG if x[0] == "signals"]
    if signalled:
        waits = sorted(x[2] for x in signalled)
        kind, code, seconds, line, argv = max(signalled, key=lambda x: x[2])
        print(f"signals: {len(signalled)} runs; from the signal to the exit: median "
              f"{waits[len(waits) // 2]:.2f} s, 95th percentile {waits[int(0.95 * len(waits))]:.2f} "
              f"s, longest {seconds:.2f} s ({argv[0]} at {argv[1]} s, exit {code})")
    slowest = max(fz.LOG, key=lambda x: x[2])
    print(f"slowest case: {slowest[2]:.2f} s ({slowest[0]}, exit {slowest[1]})")
    for label, message in broken:
        print(f"BROKEN ({label}): {message}")
    return 1 if broken else 0


if __name__ == "__main__":
    sys.exit(main())
