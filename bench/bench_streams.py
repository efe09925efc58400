"""The collision monitor under a real array's streams: noise, partial sensing, rate.

    python bench/bench_streams.py [--seeds N]

1. Noise: encoder angles with Gaussian noise sigma (1e-4, 1e-3, 3e-3 rad) on
   every hinge, 1 kHz, positions only, checked with ``collision.noise`` 0
   (blind) and sigma (aware). False alarms: on the paper design with c/k
   0.19 s, which deploys to flat without a collision in 2 s, the share of
   runs reporting any collision and the events per 1000 samples. Detection:
   on the uniform design, which collides at 0.416 s, whether the first event
   names a pair that collides in the clean run within 5 ms of its first
   collision, and its delay after that first collision (median, ms).
2. Partial sensing: per-update cost (solving the loop, then the check) of
   the 1 kHz uniform deployment carrying every hinge, all but the cut hinge,
   and all but one tree hinge of the loop; mean and p99 in ms and the rate
   the monitor keeps up with (1 / mean; goal >= 1 kHz).
3. Eq. (7) against the stream's rate: V from the stream's own samples and on
   the scene's 5 ms grid (``collision.speed_interval``), and the normal speed.

Wall clock on 2 shared cores: medians, compare within one run.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from panel_deploy.collision import CollisionSettings, StreamCheck, check_trajectory
from panel_deploy.dynamics import simulate
from panel_deploy.dynamics.report import hinge_states
from panel_deploy.configure import DynamicsParameters, configure
from panel_deploy.scene import load_scene, resolve_scene

SIGMAS = (1e-4, 1e-3, 3e-3)
#: A first event counts as the true impact if its pair collides this soon after
#: the clean first collision (the impact brings several pairs together).
WINDOW = 0.005


def deployment(scene, rate_hz, t_end, damping_ratio=-1.0):
    s, model = configure(scene, DynamicsParameters(rate_hz=rate_hz, t_end=t_end,
                                                   damping_ratio=damping_ratio))
    return s, model, simulate(model, s.simulation)


def feed(model, settings, t, theta):
    """Events of a positions-only stream and the samples checked."""
    stream = StreamCheck(model, settings)
    events = []
    for j in range(len(t)):
        events += stream.update(t[j], theta[j])
    return events


def noise(scene, seeds):
    print("1. noise: 1 kHz, positions only, Gaussian noise on every hinge")
    s, model, quiet = deployment(scene, 1000.0, 2.0, damping_ratio=0.19)
    _, _, hit = deployment(scene, 1000.0, 0.5)
    clean = feed(model, CollisionSettings.from_scene(s), hit.t, hit.theta)
    t0 = clean[0].t
    real = {e.names for e in clean if e.t <= t0 + WINDOW}
    print(f"   clean: c/k 0.19 s no collision in {len(quiet.t)} samples: "
          f"{not check_trajectory(model, quiet, CollisionSettings.from_scene(s)).collided}; "
          f"uniform: first collision {clean[0].names} at {t0:.4f} s, "
          f"{len(real)} pairs collide within {WINDOW * 1e3:g} ms of it")
    print(f"   {'sigma rad':>9s} {'check':>6s} {'false-alarm runs':>16s} {'events/1000 samples':>19s} "
          f"{'true first pair':>15s} {'delay ms':>8s} {'ms/sample':>9s}")
    for sigma in SIGMAS:
        for label, assumed in (("blind", 0.0), ("aware", sigma)):
            settings = CollisionSettings.from_scene(s, noise=assumed)
            alarms, events, right, delays, cost = 0, 0, 0, [], []
            for seed in range(seeds):
                rng = np.random.default_rng(seed)
                start = time.perf_counter()
                found = feed(model, settings, quiet.t, quiet.theta + rng.normal(0, sigma, quiet.theta.shape))
                cost.append((time.perf_counter() - start) / len(quiet.t))
                alarms += bool(found)
                events += len(found)
                first = feed(model, settings, hit.t, hit.theta + rng.normal(0, sigma, hit.theta.shape))
                if first and first[0].names in real and first[0].t >= t0 - 1e-3:
                    right += 1
                    delays.append(first[0].t - t0)
            delay = f"{np.median(delays) * 1e3:8.2f}" if delays else f"{'-':>8s}"
            print(f"   {sigma:9.0e} {label:>6s} {alarms:>9d} of {seeds:<4d} "
                  f"{1000 * events / (seeds * len(quiet.t)):19.2f} {right:>8d} of {seeds:<4d} {delay} "
                  f"{np.median(cost) * 1e3:9.3f}")


def partial(scene, seeds):
    print("\n2. partial sensing: 1 kHz uniform deployment, positions and rates, per update")
    s, model, result = deployment(scene, 1000.0, 0.5)
    names, theta, omega, _ = hinge_states(model, result)
    settings = CollisionSettings.from_scene(s)
    cut = names[model.n_coords]
    print(f"   {'carried':34s} {'mean ms':>8s} {'p99 ms':>8s} {'keeps up with':>13s} {'first collision':>16s}")
    for label, left_out in (("every hinge", None), (f"all but the cut hinge {cut}", cut),
                            ("all but r2c1-r3c1 (loop, tree)", "r2c1-r3c1")):
        carried = [n for n in names if n != left_out]
        rows = [names.index(n) for n in carried]
        runs = []
        for _ in range(max(1, seeds // 2)):
            stream = StreamCheck(model, settings)
            d = np.empty(len(result.t))
            first = None
            for j in range(len(result.t)):
                start = time.perf_counter()
                th, om = stream.coordinates(carried, theta[j, rows], omega[j, rows])
                events = stream.update(result.t[j], th, om)
                d[j] = time.perf_counter() - start
                first = first or (events[0] if events else None)
            runs.append((d.mean(), np.percentile(d, 99)))
        mean, p99 = np.median(np.array(runs), axis=0)
        print(f"   {label:34s} {mean * 1e3:8.3f} {p99 * 1e3:8.3f} {1 / mean:10.0f} Hz "
              f"{first.t:9.4f} s {'-'.join(first.names)}")


def approach(scene):
    print("\n3. Eq. (7) against the stream's rate (uniform design, first collision)")
    print(f"   {'rate Hz':>7s} {'V own samples':>13s} {'V on 5 ms grid':>14s} {'normal speed':>12s}  m/s")
    for rate in (200.0, 500.0, 1000.0, 2000.0):
        s, model, result = deployment(scene, rate, 0.5)
        own = check_trajectory(model, result, CollisionSettings.from_scene(s))
        grid = check_trajectory(model, result, CollisionSettings.from_scene(s, speed_interval=0.005))
        print(f"   {rate:7.0f} {own.v:13.3f} {grid.v:14.3f} {own.first_collision.normal_speed:12.3f}")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=5, help="noisy runs per noise level")
    args = parser.parse_args(argv)
    scene = load_scene(resolve_scene("paper_4x4"))
    noise(scene, args.seeds)
    partial(scene, args.seeds)
    approach(scene)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
