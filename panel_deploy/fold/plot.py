"""Drawing a fold design to PNG (matplotlib, Agg backend, imported on use)."""

from __future__ import annotations

from .design import FoldDesign


def plot_design(d: FoldDesign, path) -> None:
    """Draw a design: circuit, hinges, slits, merged bodies and the two stacks.

    Left panel: the flat array (row 1 at the top) with the circuit through the
    cell centres, hinges as thick lines on the shared edges (solid red on the
    top facet, dashed blue on the bottom facet, grey when the design does not
    pack), slits as thin dotted lines, and merged bodies outlined in green.
    Right panel: the two stacks side by side, top layer first, a ``v`` marking
    a face-down cell.

    Parameters
    ----------
    d : FoldDesign
    path : str or path-like
        Output PNG file.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    R, C = d.rows, d.cols
    st = d.stowed
    fig, (ax, ax2) = plt.subplots(
        1, 2, figsize=(4 + 0.9 * C + 3.2, 1.5 + max(0.9 * R, 0.32 * (st.layers if st else 0))),
        gridspec_kw={"width_ratios": [C + 1, 3.2]},
    )

    def xy(cell):
        return cell[1], R + 1 - cell[0]

    for r in range(1, R + 1):
        for c in range(1, C + 1):
            x, y = xy((r, c))
            ax.add_patch(plt.Rectangle((x - 0.5, y - 0.5), 1, 1, fc="#f4f1ea", ec="none"))
            ax.text(x - 0.42, y + 0.3, f"{r},{c}", fontsize=7, color="#777")

    def edge_line(u, v):
        (xu, yu), (xv, yv) = xy(u), xy(v)
        mx, my = (xu + xv) / 2, (yu + yv) / 2
        if yu == yv:
            return [mx, mx], [my - 0.5, my + 0.5]
        return [mx - 0.5, mx + 0.5], [my, my]

    for u, v in d.slits:
        ax.plot(*edge_line(u, v), color="#999", lw=1, ls=":")
    for u, v in d.hinges:
        xs, ys = edge_line(u, v)
        if st is None:
            ax.plot(xs, ys, color="#555", lw=3, solid_capstyle="butt")
            continue
        h = st.hinges[(u, v)]
        color = "#c62828" if h.facet == "top" else "#1565c0"
        style = "-" if h.facet == "top" else "--"
        width = 4 if h.angle else 2
        ax.plot(xs, ys, color=color, lw=width, ls=style, solid_capstyle="butt", zorder=3)

    pts = [xy(c) for c in d.circuit] + [xy(d.circuit[0])]
    ax.plot([p[0] for p in pts], [p[1] for p in pts], color="#444", lw=1, alpha=0.6)
    if d.ground is not None:
        gx, gy = xy(d.ground)
        ax.plot([gx], [gy], marker="s", color="#2e7d32", ms=8)

    for body in d.bodies:
        if len(body) < 2:
            continue
        cells = set(body)
        for cell in body:
            x, y = xy(cell)
            r, c = cell
            sides = {
                (r - 1, c): ([x - 0.5, x + 0.5], [y + 0.5, y + 0.5]),
                (r + 1, c): ([x - 0.5, x + 0.5], [y - 0.5, y - 0.5]),
                (r, c - 1): ([x - 0.5, x - 0.5], [y - 0.5, y + 0.5]),
                (r, c + 1): ([x + 0.5, x + 0.5], [y - 0.5, y + 0.5]),
            }
            for nb, (xs, ys) in sides.items():
                if nb not in cells:
                    ax.plot(xs, ys, color="#2e7d32", lw=1.5)

    ax.set_xlim(0.3, C + 0.7)
    ax.set_ylim(0.3, R + 0.7)
    ax.set_aspect("equal")
    ax.axis("off")
    verdict = "packs" if st else "does not pack"
    ax.set_title(f"{R} x {C} circuit ({verdict}), DoF {d.dof_cells} -> {d.dof_bodies}", fontsize=9)
    ax.legend(
        handles=[
            Line2D([], [], color="#c62828", lw=3, label="hinge, top facet"),
            Line2D([], [], color="#1565c0", lw=3, ls="--", label="hinge, bottom facet"),
            Line2D([], [], color="#c62828", lw=1.5, label="thin: stays flat"),
            Line2D([], [], color="#999", lw=1, ls=":", label="slit"),
            Line2D([], [], color="#2e7d32", lw=1.5, label="merged body"),
            Line2D([], [], color="#2e7d32", marker="s", ls="", label="ground"),
        ],
        loc="upper center",
        bbox_to_anchor=(0.5, 0.0),
        ncol=3,
        fontsize=7,
        frameon=False,
    )

    ax2.axis("off")
    if st is None:
        ax2.text(0, 1, "no two-stack package:\n" + d.reason.replace("; ", ";\n"), va="top",
                 fontsize=7, wrap=True, transform=ax2.transAxes)
    else:
        n = st.layers
        for s in (0, 1):
            for k, cell in enumerate(st.stack_order(s)):
                p = st.placements[cell]
                y = n - 1 - k
                ax2.add_patch(plt.Rectangle((s * 1.05, y), 1, 0.9, fc="#f4f1ea", ec="#555"))
                label = f"{cell[0]},{cell[1]}" + ("" if p.face_up else " v")
                ax2.text(s * 1.05 + 0.5, y + 0.45, label, ha="center", va="center", fontsize=7)
        ax2.set_xlim(-0.1, 2.15)
        ax2.set_ylim(-0.2, n + 0.6)
        f0, f1 = st.footprint
        ax2.set_title(
            f"stacks on ({f0[0]},{f0[1]}) ({f1[0]},{f1[1]}), top first", fontsize=9
        )
    fig.tight_layout()
    from ..validate import save_figure
    try:
        save_figure(fig, path)
    finally:
        plt.close(fig)
