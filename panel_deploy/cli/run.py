"""``panel-deploy run SCENE``: the ROS 2 node graph in one process."""

from __future__ import annotations

from ..errors import SceneError
from .args import scene_of


def run_command(args) -> int:
    """Deploy the scene live through the node graph (optimising first with
    ``--optimise``). Exit 0 when the deployment reached flat with no collision
    before it by the collision monitor's verdict (:func:`..nodes.graph.run_graph`), 1 if
    not: unlike ``simulate``, whose exit code says only whether the run succeeded."""
    from ..nodes import load
    if not args.rate > 0:
        raise SceneError("--rate", f"expected a rate > 0 Hz, got {args.rate}")
    if not args.real_time_factor >= 0:
        raise SceneError("--real-time-factor", f"expected a number >= 0, got {args.real_time_factor}")
    scene = scene_of(args)  # a bad scene is one line here, before any node starts
    return load("graph").run_graph(scene, optimise=args.optimise,
                                   real_time_factor=args.real_time_factor, rate_hz=args.rate,
                                   as_json=args.json, record=args.record,
                                   namespace=args.namespace)
