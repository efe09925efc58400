"""Timing of the fold design: enumeration, packing check and the DP count.

    python bench/bench_fold.py

Prints wall times (median of repeats where a run is cheap) for 4 x 4, 6 x 6, the largest arrays whose circuits can all be
enumerated and checked within a minute, and the DP count for 8 x 8 and larger.
"""

import argparse
import statistics
import time

from panel_deploy.fold import circuits, count_circuits, find_stowed_state

BUDGET = 60.0


def timed(fn, repeats):
    times, result = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), result


def check_all(rows, cols):
    packed = 0
    for circ in circuits(rows, cols):
        st, _ = find_stowed_state(rows, cols, circ)
        packed += st is not None
    return packed


def main():
    print(f"{'array':>7} {'circuits':>10} {'enumerate s':>12} {'pack all s':>11} {'packable':>9}")
    for rows, cols, reps in [(4, 4, 5), (4, 6, 3), (5, 6, 1), (6, 6, 1)]:
        t_enum, n = timed(lambda: sum(1 for _ in circuits(rows, cols)), reps)
        t_pack, packed = timed(lambda: check_all(rows, cols), reps)
        print(f"{rows}x{cols:<5} {n:>10} {t_enum:>12.4f} {t_pack:>11.3f} {packed:>9}")
    # Largest next sizes: enumerate and check until the budget is used up.
    for rows, cols in [(6, 7), (6, 8)]:
        t0 = time.perf_counter()
        n = packed = 0
        for circ in circuits(rows, cols):
            n += 1
            packed += find_stowed_state(rows, cols, circ)[0] is not None
            if time.perf_counter() - t0 > BUDGET:
                break
        total = count_circuits(rows, cols)
        dt = time.perf_counter() - t0
        status = "all" if n == total else f"{n} of {total}"
        print(f"{rows}x{cols:<5} {total:>10} {'(with pack)':>12} {dt:>11.1f} {packed:>9}  ({status} in budget)")
    print(f"\n{'array':>7} {'circuits (DP)':>26} {'count s':>9}")
    for rows, cols in [(8, 8), (10, 10), (12, 12), (8, 20)]:
        t, n = timed(lambda: count_circuits(rows, cols), 3 if rows * cols <= 100 else 1)
        print(f"{rows}x{cols:<5} {n:>26} {t:>9.3f}")


if __name__ == "__main__":
    argparse.ArgumentParser(description=__doc__.splitlines()[0]).parse_args()
    main()
