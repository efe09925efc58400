"""Where numba keeps the compiled kernels, and one line on stderr while it compiles them.

The kernels are compiled for the machine they run on (``cache=True``): the
first run compiles and stores them, later runs load them. Numba puts the
cache in ``__pycache__`` next to the sources; when the package folder is
not writable (a system or read-only site-packages) :func:`configure` points
``NUMBA_CACHE_DIR`` at a per-user folder instead, unless the user chose one.
This has to happen before the first ``@njit(cache=True)`` is decorated,
since numba picks a function's cache folder then: ``panel_deploy/__init__``
calls it before any kernel module is imported.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

#: The installed package folder, where numba caches by default.
PACKAGE_DIR = Path(__file__).resolve().parent

NOTICE = "panel-deploy: compiling kernels for this machine, first run only (a minute or two)"


def user_cache_dir(environ=os.environ) -> Path:
    """Per-user cache folder (XDG_CACHE_HOME, else ~/.cache) for the kernels."""
    base = environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "panel_deploy" / "numba"


def chosen_cache_dir(package_dir=PACKAGE_DIR, environ=os.environ) -> str | None:
    """The ``NUMBA_CACHE_DIR`` to set, or None to leave numba's own choice.

    None when the user set ``NUMBA_CACHE_DIR`` or the package folder is
    writable (numba then caches next to the sources); else
    :func:`user_cache_dir`.
    """
    if environ.get("NUMBA_CACHE_DIR") or os.access(package_dir, os.W_OK):
        return None
    return str(user_cache_dir(environ))


def configure() -> None:
    """Set ``NUMBA_CACHE_DIR`` to :func:`chosen_cache_dir` when that is not None.

    Through the environment, so that worker processes inherit it; numba's
    config is updated too when numba was imported first.
    """
    path = chosen_cache_dir()
    if path is None:
        return
    os.environ["NUMBA_CACHE_DIR"] = path
    config = sys.modules.get("numba.core.config")
    if config is not None:
        config.CACHE_DIR = path


_announced = False


def announce_compilation(stream=None) -> None:
    """Print :data:`NOTICE` once per process on stderr when numba starts compiling.

    A numba compile event fires only on a cache miss, so a warm run stays
    silent. Called by the kernel modules at import (importing numba here
    would cost every command its half-second import).
    """
    from numba.core import event

    global _announced
    if _announced:
        return
    _announced = True

    class _Notice(event.Listener):
        said = False

        def on_start(self, ev):
            if not self.said:
                self.said = True
                print(NOTICE, file=stream or sys.stderr, flush=True)

        def on_end(self, ev):
            pass

    event.register("numba:compile", _Notice())
