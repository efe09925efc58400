"""Where numba keeps the compiled kernels, and one line on stderr while it compiles them.

The kernels are compiled for the machine they run on (``cache=True``) and
stored in numba's cache, in ``__pycache__`` next to the sources.
``pip install`` compiles them ahead of time: the build (``setup.py``) runs
:mod:`panel_deploy._precompile` on the package it is about to install, which
fills those ``__pycache__`` folders, and marks the package with
:data:`COMPILED_MARKER`. In a package so marked, :func:`configure` makes numba
look there first for the package's own kernels (the locator
:class:`panel_deploy._kernel_locator.CompiledKernelsLocator`), even when
``NUMBA_CACHE_DIR`` is set: they are part of the installation, not a cache the
user keeps. Anything the build did not compile, and every kernel of an
editable or ``colcon --symlink-install`` checkout, compiles on first use and is
cached as numba does by default. When the package folder is not writable (a
system or read-only site-packages) numba cannot use it, so :func:`configure`
points ``NUMBA_CACHE_DIR`` at a per-user folder, unless the user chose one.

numba stamps a cached kernel with its own source file only, so a kernel
that calls into another file (the integrator's loop into the dynamics, the
collision search into the kinematics) would load stale after that file
changed: in a checkout, an edited right-hand side would leave the compiled
loops running the old one. This package's locators stamp each of its kernels with
:func:`kernel_sources_stamp`, a hash of every file in
:data:`KERNEL_SOURCES`: any change to one recompiles them all on first use.
A process given numba's own locators (``NUMBA_CACHE_LOCATOR_CLASSES``, which
:func:`configure` leaves alone) stamps the kernels numba's way; where it
shares their folder, each side finds the other's stamp stale and compiles
once more.

This has to happen before the first ``@njit(cache=True)`` is decorated,
since numba picks a function's cache folder then: ``panel_deploy/__init__``
calls it before any kernel module is imported.
"""

from __future__ import annotations

import hashlib
import os
import sys
from pathlib import Path

#: The installed package folder, where numba caches by default.
PACKAGE_DIR = Path(__file__).resolve().parent

#: Written by the build once :mod:`panel_deploy._precompile` has filled the caches.
COMPILED_MARKER = PACKAGE_DIR / "_kernels_compiled"

#: numba's own cache locators, in numba's order.
NUMBA_LOCATORS = ("UserProvidedCacheLocator,InTreeCacheLocator,UserWideCacheLocator,"
                  "IPythonCacheLocator,ZipCacheLocator")

#: This package's locators (:mod:`panel_deploy._kernel_locator`: the kernels
#: compiled at install, then the user's folder, then next to the sources), then
#: numba's for other packages; a user's own ``NUMBA_CACHE_LOCATOR_CLASSES`` is left alone.
LOCATORS = ",".join([*(f"panel_deploy._kernel_locator.{name}" for name in
                       ("CompiledKernelsLocator", "UserDirKernelsLocator", "InTreeKernelsLocator")),
                     NUMBA_LOCATORS])

#: The package's files that hold compiled kernels or constants compiled into
#: them, relative to the package: the sources of :func:`kernel_sources_stamp`
#: (test_startup checks that every file with a kernel is here).
KERNEL_SOURCES = ("boxes.py", "collision/geometry.py", "collision/monitor.py",
                  "collision/motion.py", "collision/refine.py", "dynamics/_jit.py",
                  "dynamics/air.py", "dynamics/articulated.py", "dynamics/buffers.py",
                  "dynamics/closure.py", "dynamics/compiled.py", "dynamics/erk.py",
                  "dynamics/hinges.py", "dynamics/integration.py", "dynamics/kernels.py",
                  "dynamics/pack.py", "dynamics/panel_contact.py", "dynamics/rosenbrock.py",
                  "dynamics/spatial.py", "dynamics/stiff.py", "dynamics/switches.py")

NOTICE = "panel-deploy: compiling kernels for this machine, first run only (a few minutes)"


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


def kernel_sources_stamp(package_dir=PACKAGE_DIR) -> str:
    """The SHA-256 (hex) of the contents of :data:`KERNEL_SOURCES` under
    ``package_dir``: the source stamp of every kernel of the package, which
    changes with any of those files and not with their times (a build and the
    installation it makes hold the same bytes, not the same times)."""
    digest = hashlib.sha256()
    for name in KERNEL_SOURCES:
        digest.update(name.encode() + b"\0" + (Path(package_dir) / name).read_bytes() + b"\0")
    return digest.hexdigest()


def configure() -> None:
    """Point numba at the kernels compiled at install, and at a writable cache.

    Sets ``NUMBA_CACHE_LOCATOR_CLASSES`` to :data:`LOCATORS` (unless the user
    set locators), and ``NUMBA_CACHE_DIR`` to :func:`chosen_cache_dir` when
    that is not None.
    Through the environment, so that worker processes inherit them; numba's
    config is updated too when numba was imported first.
    """
    chosen = {}
    if not os.environ.get("NUMBA_CACHE_LOCATOR_CLASSES"):
        chosen["NUMBA_CACHE_LOCATOR_CLASSES"] = ("CACHE_LOCATOR_CLASSES", LOCATORS)
    path = chosen_cache_dir()
    if path is not None:
        chosen["NUMBA_CACHE_DIR"] = ("CACHE_DIR", path)
    config = sys.modules.get("numba.core.config")
    for variable, (attribute, value) in chosen.items():
        os.environ[variable] = value
        if config is not None:
            setattr(config, attribute, value)


_announced = False


def announce_compilation(stream=None) -> None:
    """Print :data:`NOTICE` once per process on stderr when numba starts compiling.

    A numba compile event fires only on a cache miss, so a warm run stays
    silent. Called by :mod:`panel_deploy.dynamics._jit` at import (importing numba here
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
