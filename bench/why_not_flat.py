"""Why a deployment never lies flat: the state it ends in, with collisions ignored.

Simulates the scene (its own settings, or the stiffness and damping of a result
file) to ``--t-end`` without stopping at collisions and prints how close to flat
each second of the run came, the first flat sample, and at the end:

- the hinges pressed onto their flat stop (theta < 0), with the stop's torque
  k_s |theta| (N m): hinges the loop pushes past flat while others are still
  folded, the sign of a non-flat equilibrium of the springs;
- the most folded hinges, with their spring torque k theta and the torque of
  the weight on that tree coordinate (-dV/dtheta of the panels' potential
  energy with the loop cut, N m);
- the energy the springs still hold, sum k theta^2 / 2, against the weight's
  potential energy of flat minus that of the end state (J): when the second
  exceeds the first, flat lies higher than where the array hangs, and springs
  of these stiffnesses cannot bring it there;
- the largest hinge rate, rad/s (small: the array has stopped there).

    python bench/why_not_flat.py [SCENE] [--stiffness RESULT.yaml] [--k K --damping-ratio C/K]
                                 [--t-end 10] [--set KEY=VALUE ...]
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace

import numpy as np

from panel_deploy.build import build_model
from panel_deploy.dynamics import simulate
from panel_deploy.dynamics.report import hinge_angles
from panel_deploy.errors import PanelDeployError
from panel_deploy.kinematics import forward_kinematics
from panel_deploy.optimise import load_stiffness
from panel_deploy.ranking import resolve_circuit
from panel_deploy.optimise.io import load_damping
from panel_deploy.scene import load_scene, resolve_scene

#: Central-difference step of the weight's torque, rad.
STEP = 1e-6


def weight_potential(model, gravity, theta):
    """Potential energy of the panels' weight (J) at tree angles ``theta``."""
    _, position = forward_kinematics(model, theta)
    return -float(sum(b.mass * (p @ gravity) for b, p in zip(model.bodies, position)))


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scene", nargs="?", default="array_5x6")
    p.add_argument("--stiffness", metavar="RESULT.yaml", help="k (and c) of every hinge")
    p.add_argument("--k", type=float, help="one stiffness for every hinge, N m/rad")
    p.add_argument("--damping-ratio", type=float, help="c/k of every hinge, s")
    p.add_argument("--t-end", type=float, default=10.0, help="s")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    args = p.parse_args(argv)
    try:
        scene = resolve_circuit(load_scene(resolve_scene(args.scene), args.set))
        sim = scene.simulation
        sim = replace(sim, t_end=args.t_end,
                      samples=round((sim.samples - 1) * args.t_end / sim.t_end) + 1)
        model = build_model(scene)
        ratio = np.array([h.c for h in model.hinges]) / model.stiffness
        k = model.stiffness
        c = ratio * k
        if args.stiffness:
            k = load_stiffness(args.stiffness, model)
            given = load_damping(args.stiffness, model)
            c = ratio * k if given is None else given
        if args.k is not None:
            k = np.full(len(model.hinges), args.k)
            c = ratio * k
        if args.damping_ratio is not None:
            c = args.damping_ratio * k
        model = model.with_stiffness(k, c)
        result = simulate(model, sim)
    except PanelDeployError as e:
        sys.exit(f"why_not_flat: {e}")
    names, order, theta = hinge_angles(model, result)
    spread = np.abs(theta).max(axis=1)
    flat = np.flatnonzero(spread <= sim.flat_tolerance)
    per_second = [float(spread[(result.t >= s) & (result.t < s + 1)].min())
                  for s in range(int(np.ceil(args.t_end)))]
    print(f"{scene.name}{' with ' + ', '.join(args.set) if args.set else ''}: {len(names)} hinges, "
          f"c/k {np.median(c / k):.3g} s, {result.message}")
    print("closest to flat in each second (rad): " + " ".join(f"{s:.2f}" for s in per_second))
    print(f"first flat: {f'{result.t[flat[0]]:.3f} s' if len(flat) else 'never'}")
    end = theta[-1]
    kh = k[order]
    stopped = [(n, model.k_s * -a) for n, a in zip(names, end) if a < 0]
    print(f"at {result.t[-1]:g} s, {len(stopped)} hinges on the flat stop (stop torque, N m): "
          + ", ".join(f"{n} {t:.3f}" for n, t in sorted(stopped, key=lambda s: -s[1])))
    gravity = np.asarray(scene.gravity, dtype=float)
    tree = result.theta[-1]
    eye = np.eye(len(tree))
    weight_torque = {model.hinges[h].name: -(weight_potential(model, gravity, tree + STEP * e)
                                             - weight_potential(model, gravity, tree - STEP * e))
                     / (2 * STEP) for h, e in zip(model.joints, eye)}
    for j in np.argsort(-np.abs(end))[:5]:
        w = weight_torque.get(names[j])
        print(f"  {names[j]:14s} theta {end[j]:+.3f} rad  k {kh[j]:.4f} N m/rad  k theta "
              f"{kh[j] * end[j]:+.4f} N m  weight {'(cut hinge)' if w is None else f'{w:+.4f} N m'}")
    held = 0.5 * float(np.sum(kh * end ** 2))
    lift = weight_potential(model, gravity, np.zeros_like(tree)) - weight_potential(model, gravity, tree)
    print(f"springs hold {held:.4f} J; the weight's energy of flat minus the end state {lift:+.4f} J; "
          f"largest hinge rate {np.abs(result.omega[-1]).max():.2e} rad/s")


if __name__ == "__main__":
    main()
