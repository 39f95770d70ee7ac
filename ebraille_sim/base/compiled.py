"""Numba compilation with a disk cache keyed on every compiled source of the package.

Numba keys a cached function on its own source file only.  The kernel inlines the laws of
the physics modules and bakes in the slot indices of the state layout, so a change in any
of those files must also invalidate the kernel's cache.  Every compiled function of this
package is therefore decorated with :func:`njit` from this module, whose cache locator
stamps the cache index with :func:`source_key`: a SHA-256 digest of every package source
that compiles with Numba (and of the layout).  A changed source gives a new key; Numba then
finds the index stale and recompiles.  Nothing is deleted and nothing is scanned at import
beyond reading those sources once per process.

``NUMBA_CACHE_DIR``, when set, is honoured (the cache goes below it); where neither that
nor the source tree's ``__pycache__`` is writable, Numba's own user-wide cache is used.
"""
from __future__ import annotations

import functools
import hashlib
import os
import pathlib

import numba
from numba.core import caching, config

__all__ = ["njit", "prange", "source_key", "compiled_sources"]

prange = numba.prange

_PACKAGE_ROOT = pathlib.Path(__file__).resolve().parent.parent
_CONTROLLERS_ROOT = _PACKAGE_ROOT.parent / "controllers"
_MARKER = b"base.compiled import"


def compiled_sources(roots=None) -> list[pathlib.Path]:
    """The sources below ``roots`` (default: the package and ``controllers``) that compile
    with Numba, and the state layout they index."""
    if roots is None:
        roots = [_PACKAGE_ROOT] + ([_CONTROLLERS_ROOT] if _CONTROLLERS_ROOT.is_dir() else [])
    out = []
    for root in roots:
        for f in sorted(root.rglob("*.py")):
            try:
                data = f.read_bytes()
            except OSError:
                continue
            if _MARKER in data or f.name == "layout.py":
                out.append(f)
    return out


@functools.lru_cache(maxsize=4)
def source_key(roots: tuple | None = None) -> bytes:
    """SHA-256 over the names and contents of :func:`compiled_sources` (computed once per process)."""
    h = hashlib.sha256()
    for f in compiled_sources(None if roots is None else list(roots)):
        h.update(f.name.encode())
        h.update(f.read_bytes())
    return h.digest()


@functools.lru_cache(maxsize=None)
def _uses_package_njit(path: str) -> bool:
    """Whether the source at ``path`` compiles with this module's :func:`njit` (read once)."""
    try:
        return _MARKER in pathlib.Path(path).read_bytes()
    except OSError:
        return False


def _inside_package(path: pathlib.Path) -> bool:
    return path.is_relative_to(_PACKAGE_ROOT) or path.is_relative_to(_CONTROLLERS_ROOT)


class _PackageCacheLocator(caching.InTreeCacheLocator):
    """Cache beside the source (or below ``NUMBA_CACHE_DIR``), stamped with the package key.

    Code outside the package that compiles with this module's :func:`njit` (tests,
    benchmarks, a user's own compiled controller) inlines the package's functions too: its
    stamp is the package key together with its own file's modification time and size, so a
    changed law or supervisor recompiles it as well.
    """

    def __init__(self, py_func, py_file):
        super().__init__(py_func, py_file)
        path = pathlib.Path(py_file).resolve()
        self._outside = not _inside_package(path)
        if config.CACHE_DIR:
            if self._outside:
                rel = pathlib.Path("external", hashlib.sha256(str(path.parent).encode()).hexdigest()[:16])
            else:
                rel = path.parent.relative_to(_PACKAGE_ROOT.parent)
            self._cache_path = os.path.join(config.CACHE_DIR, "ebraille_sim_cache", str(rel))

    def get_source_stamp(self):
        if self._outside:
            st = os.stat(self._py_file)
            return source_key(), st.st_mtime, st.st_size
        return source_key()

    @classmethod
    def from_function(cls, py_func, py_file):
        try:
            path = pathlib.Path(py_file).resolve()
        except (OSError, TypeError):
            return None
        if not (_inside_package(path) or _uses_package_njit(str(path))):
            return None
        return super().from_function(py_func, py_file)


if _PackageCacheLocator not in caching.CacheImpl._locator_classes:
    caching.CacheImpl._locator_classes.insert(0, _PackageCacheLocator)


def njit(*args, **kwargs):
    """``numba.njit`` with ``cache=True`` by default, cached under the package key.

    ``_nrt=False`` (compile without reference counting, for functions that allocate nothing)
    is a Numba option without a public promise; where the installed Numba does not know it,
    it is dropped and the function compiles with reference counting, the same results.
    """
    kwargs.setdefault("cache", True)
    if "_nrt" in kwargs and not _KNOWS_NRT:
        kwargs.pop("_nrt")
    return numba.njit(*args, **kwargs)


def _knows_nrt() -> bool:
    try:
        from numba.core.cpu import CPUTargetOptions
    except ImportError:
        return False
    return hasattr(CPUTargetOptions, "_nrt")


_KNOWS_NRT = _knows_nrt()


