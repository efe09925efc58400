"""The numba cache locator for the kernels compiled when the package was installed.

numba imports this module by name (``NUMBA_CACHE_LOCATOR_CLASSES``, set by
:func:`panel_deploy._numba_cache.configure`) when it decorates the first
cached kernel, so numba is already loaded and importing it costs nothing.
"""

from __future__ import annotations

from pathlib import Path

from numba.core.caching import InTreeCacheLocator

from ._numba_cache import COMPILED_MARKER, PACKAGE_DIR

_COMPILED = COMPILED_MARKER.exists()


class CompiledKernelsLocator(InTreeCacheLocator):
    """numba's in-tree locator (``__pycache__`` next to the source), for this
    package's kernels only, and only in a package whose build compiled them.

    Declines (numba then asks its own locators) for other packages' functions,
    in a package built without its kernels, and where ``__pycache__`` is not
    writable, since numba writes new specialisations where it reads.
    """

    @classmethod
    def from_function(cls, py_func, py_file):
        if not _COMPILED or PACKAGE_DIR not in Path(py_file).resolve().parents:
            return None
        return super().from_function(py_func, py_file)
