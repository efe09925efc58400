"""``panel-deploy fold``: one design (of a scene, or a circuit index), or an array's designs."""

from __future__ import annotations

import itertools
import json

from ..build import scene_design
from ..errors import DesignError, SceneError
from ..fold import design, designs
from ..fold.circuits import ENUMERATION_LIMIT, count_circuits
from ..fold.report import design_dict, design_text, designs_summary, designs_text
from ..progress import Progress
from .args import scene_of

#: Circuits listed when --limit is not given.
DEFAULT_LIMIT = 50


def fold_command(args) -> int:
    """Print the design of ``--scene`` or of ``--rows/--cols [--circuit]``, or the
    list of an array's designs; ``--plot`` draws the design (for a list, the
    first packable one); ``--scene --rank`` ranks the scene's packing circuits
    (:func:`~panel_deploy.ranking.rank_circuits`). Exit 0, or 1 if the
    design asked for does not pack (for a ranking: if no circuit was screened)."""
    if args.scene and args.rank:
        return _rank(scene_of(args, resolve=False), args)
    if args.scene:
        scene = scene_of(args)
        index = scene.fold.circuit if isinstance(scene.fold.circuit, int) else None
        return _report(scene_design(scene), index, args)
    if args.rows is None or args.cols is None:
        raise SceneError("--rows/--cols", "give --rows and --cols, or --scene FILE")
    rows, cols = args.rows, args.cols
    try:
        if args.circuit is not None:
            return _report(design(rows, cols, args.circuit), args.circuit, args)
        return _list(rows, cols, DEFAULT_LIMIT if args.limit is None else args.limit, args)
    except DesignError as e:
        raise SceneError("--circuit" if args.circuit is not None else "--rows/--cols",
                         str(e)) from None


def _report(d, index, args) -> int:
    print(json.dumps(design_dict(d, index), indent=1) if args.json else design_text(d, index))
    if args.plot:
        _plot(d, args.plot)
    return 0 if d.stowed is not None else 1


def _list(rows, cols, limit, args) -> int:
    count = count_circuits(rows, cols)
    examined = count if rows * cols <= ENUMERATION_LIMIT else min(limit, count)
    with Progress(examined, f"fold {rows} x {cols}", "circuits") as bar:
        out = designs_summary(rows, cols, limit, progress=bar.update)
    if args.plot:
        found = [x for _, x in itertools.islice(designs(rows, cols), max(limit, 1))]
        plotted = next((x for x in found if x.stowed is not None), found[0] if found else None)
        if plotted is None:
            raise SceneError("--plot", f"nothing to plot: the {rows} x {cols} array has no circuit")
        _plot(plotted, args.plot)
    print(json.dumps(out, indent=1) if args.json else designs_text(out))
    return 0


def _rank(scene, args) -> int:
    from ..ranking import rank_circuits
    from ..optimise.parallel import task_map

    arr = scene.array
    with (task_map(scene.optimisation.workers, args.dask) as screen,
          Progress(None, f"rank {arr.rows} x {arr.cols}", "circuits") as bar):
        ranking = rank_circuits(scene, progress=lambda _: bar.update(), task_map=screen)
    print(json.dumps(ranking.to_dict(), indent=1) if args.json else ranking.text())
    return 0 if ranking.best is not None else 1


def _plot(d, path) -> None:
    from ..fold.plot import plot_design
    plot_design(d, path)
