"""Compile the kernels of the main jobs into the package, ahead of its first run.

    python -m panel_deploy._precompile SCENE.yaml

``setup.py`` runs this on the package it is building (``build/lib``), so that
``pip install`` ships the kernels compiled for this machine in numba's cache
(``__pycache__`` next to the sources, see :mod:`panel_deploy._numba_cache`)
and a user's first ``simulate`` loads them instead of spending a minute
compiling. It runs the jobs themselves, through the command line, on the
paper scene: that way the kernels are compiled for exactly the types the jobs
call them with, and a job added later needs one line here. Outputs go to a
temporary folder; a job's exit code 1 (a deployment that collides) is a
normal outcome here.
"""

from __future__ import annotations

import contextlib
import io
import sys
import tempfile
from pathlib import Path

from ._numba_cache import COMPILED_MARKER


#: The paper's panels as a 5 x 6 array (its first packing circuit), with panel
#: contact: above ``articulated.MIN_N`` coordinates, where the stiff runs take
#: the O(n) loop.
LARGER = ["--set", "array.rows=5", "--set", "array.cols=6", "--set", "fold.circuit=3",
          "--set", "fold.ground=null", "--set", "contact.panels=true", "--t-end", "0.01"]


def jobs(scene: str, folder: Path) -> list[list[str]]:
    """The command lines whose kernels are compiled: every main job that runs
    kernels, both compiled integrators and the scipy path, and the larger
    arrays' O(n) Rosenbrock loop. Air and panel contact need no job of their
    own: a model without them has their fields empty, not None, so numba
    types every model alike (:class:`panel_deploy.dynamics.pack.Packed`)."""
    trajectory, recording = str(folder / "run.npz"), str(folder / "run.mcap")
    return [
        ["simulate", scene, "--out", trajectory, "--record", recording],
        ["collide", trajectory],
        ["collide", recording],
        # the exact closure is not stiff: the explicit pairs' loop
        ["simulate", scene, "--closure", "exact", "--t-end", "0.05"],
        # scipy's path: Radau calls the right-hand side and its Jacobian
        ["simulate", scene, "--method", "Radau", "--t-end", "0.01"],
        ["simulate", scene, *LARGER],
    ]


def main(argv=None) -> int:
    from .cli import main as cli

    (scene,) = sys.argv[1:] if argv is None else argv
    with tempfile.TemporaryDirectory() as tmp:
        for job in jobs(scene, Path(tmp)):
            with contextlib.redirect_stdout(io.StringIO()):
                code = cli(job)
            if code not in (0, 1):
                print(f"panel_deploy._precompile: {' '.join(job)} exited {code}", file=sys.stderr)
                return code
    COMPILED_MARKER.write_text("kernels compiled by panel_deploy._precompile\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
