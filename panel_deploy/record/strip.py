"""``replay --png``: a strip of rendered frames of a recording (matplotlib 3D, headless).

One panel per requested instant, each showing every panel as a box of its
true size at the joint state nearest that instant (the ground panel in
orange, the others in blue, the panels of the first collision red from the
sample that reveals it on); all frames share one view and one scale.
"""

from __future__ import annotations

import numpy as np

from ..errors import SceneError
from .analysis import RecordedDeployment

#: Corners of a unit box centred on the origin, and its six faces as corner indices.
_CORNERS = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)])
_FACES = [(0, 1, 3, 2), (4, 5, 7, 6), (0, 1, 5, 4), (2, 3, 7, 6), (0, 2, 6, 4), (1, 3, 7, 5)]


def box_faces(size, rotation, position) -> list:
    """The six faces (4 corners each, m) of a box of edge lengths ``size`` posed in the world."""
    corners = position + (_CORNERS * np.asarray(size)) @ np.asarray(rotation).T
    return [corners[list(f)] for f in _FACES]


def render_strip(d: RecordedDeployment, times, out) -> list:
    """Draw the recording at ``times`` (s, counted like ``d.track.t``) into ``out`` (PNG).

    Returns the sample indices drawn.

    Raises
    ------
    SceneError
        An instant outside the recording (the message gives its span).
    """
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    from ..kinematics import forward_kinematics
    from .replay import collision_events

    t = d.track.t
    for x in times:
        if not t[0] - 1e-9 <= x <= t[-1] + 1e-9:
            raise SceneError("--at", f"{x:g} s is outside the recording ({t[0]:g} to {t[-1]:g} s)")
    samples = [int(np.argmin(np.abs(t - x))) for x in times]
    _, events = collision_events(d)
    hit = {b: int(e.sample) for e in events for b in e.bodies}
    model = d.model
    poses = [forward_kinematics(model, d.track.theta[j]) for j in samples]
    points = np.concatenate([np.concatenate([np.concatenate(box_faces(model.bodies[b].size, R[b], p[b]))
                                             for b in range(model.n_bodies)]) for R, p in poses])
    centre = (points.max(0) + points.min(0)) / 2
    half = (points.max(0) - points.min(0)).max() / 2
    fig = plt.figure(figsize=(2.6 * len(samples), 2.8))
    for k, (j, (R, p)) in enumerate(zip(samples, poses)):
        ax = fig.add_subplot(1, len(samples), k + 1, projection="3d")
        for b, body in enumerate(model.bodies):
            colour = ("tab:red" if b in hit and j >= hit[b] else
                      "tab:orange" if b == model.ground else "tab:blue")
            ax.add_collection3d(Poly3DCollection(box_faces(body.size, R[b], p[b]), facecolor=colour,
                                                 edgecolor="k", linewidths=0.3, alpha=0.9))
        for axis, c in zip((ax.set_xlim, ax.set_ylim, ax.set_zlim), centre):
            axis(c - half, c + half)
        ax.set_box_aspect((1, 1, 1), zoom=1.25)
        ax.view_init(elev=25, azim=-60)
        ax.set_axis_off()
        ax.set_title(f"t = {t[j]:.3f} s", fontsize=10)
    fig.tight_layout()
    from ..validate import save_figure
    try:
        save_figure(fig, out, "--png")
    finally:
        plt.close(fig)
    return samples
