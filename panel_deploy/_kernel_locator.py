"""numba cache locators for this package's kernels (:mod:`panel_deploy._numba_cache`).

numba imports this module by name (``NUMBA_CACHE_LOCATOR_CLASSES``, set by
:func:`panel_deploy._numba_cache.configure`) when it decorates the first
cached kernel, so numba is already loaded and importing it costs nothing.

Each locator serves this package's functions only (numba's own locators,
after them, serve every other package) and stamps them with the hash of all
kernel sources (:func:`~panel_deploy._numba_cache.kernel_sources_stamp`)
instead of numba's stamp of the function's own file.
"""

from __future__ import annotations

from functools import cache
from pathlib import Path

from numba.core.caching import InTreeCacheLocator, UserProvidedCacheLocator

from ._numba_cache import COMPILED_MARKER, PACKAGE_DIR, kernel_sources_stamp

_COMPILED = COMPILED_MARKER.exists()


def _ours(py_file) -> bool:
    return PACKAGE_DIR in Path(py_file).resolve().parents


@cache
def _stamp() -> str:
    return kernel_sources_stamp()


class _KernelSourcesStamp:
    """Serves this package's functions only, and stamps a kernel with every
    kernel source, not its own file alone: a kernel compiled before a change
    to any of them, in its file or in one it calls into, is stale."""

    @classmethod
    def from_function(cls, py_func, py_file):
        return super().from_function(py_func, py_file) if _ours(py_file) else None

    def get_source_stamp(self):
        return _stamp()


class CompiledKernelsLocator(_KernelSourcesStamp, InTreeCacheLocator):
    """numba's in-tree locator (``__pycache__`` next to the source), in a
    package whose build compiled the kernels, even when ``NUMBA_CACHE_DIR`` is
    set: they are part of the installation.

    Declines in a package built without its kernels, and where ``__pycache__``
    is not writable, since numba writes new specialisations where it reads.
    """

    @classmethod
    def from_function(cls, py_func, py_file):
        return super().from_function(py_func, py_file) if _COMPILED else None


class UserDirKernelsLocator(_KernelSourcesStamp, UserProvidedCacheLocator):
    """numba's locator of ``NUMBA_CACHE_DIR`` (the user's, or the per-user
    folder of a read-only package), when it is set."""


class InTreeKernelsLocator(_KernelSourcesStamp, InTreeCacheLocator):
    """numba's in-tree locator, numba's default for a checkout."""
