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
import numpy as np
from numba.core import caching, config

__all__ = ["njit", "prange", "source_key", "compiled_sources", "entry_point"]

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


class _LoadingCache(caching.FunctionCache):
    """Numba's function cache, loading without a refresh of the compiler's registries.

    Numba's ``load_overload`` refreshes the target context before it reads the cache: that
    installs every typing and lowering registry, which imports Numba's whole NumPy support
    and, through it, ``scipy.linalg`` (about 0.4 s at the first load of a process).  A
    function rebuilt from the cache is machine code that needs none of them, only the
    runtime's symbols (:meth:`numba.core.runtime.nrt.rtsys.initialize`, done here).  A cache
    miss compiles as before, and Numba's compiler refreshes the registries itself.
    """

    def load_overload(self, sig, target_context):
        from numba.core.runtime import nrt
        nrt.rtsys.initialize(target_context)
        with self._guard_against_spurious_io_errors():
            return self._load_overload(sig, target_context)


def _with_loading_cache(dispatcher):
    if not hasattr(dispatcher, "py_func"):          # NUMBA_DISABLE_JIT=1: the plain Python function
        return dispatcher
    dispatcher._cache = _LoadingCache(dispatcher.py_func)
    return dispatcher


def njit(*args, **kwargs):
    """``numba.njit`` with ``cache=True`` by default, cached under the package key.

    A cached function is loaded by :class:`_LoadingCache` (for the lazily compiled form:
    a function, or keyword options only; an explicit signature keeps Numba's cache; a Numba
    without the internals it relies on keeps its own cache).  ``_nrt=False`` (compile
    without reference counting, for functions that allocate nothing) is a Numba option
    without a public promise; where the installed Numba does not know it, it is dropped and
    the function compiles with reference counting, the same results.
    """
    kwargs.setdefault("cache", True)
    if "_nrt" in kwargs and not _KNOWS_NRT:
        kwargs.pop("_nrt")
    if not kwargs["cache"] or not _LOADING_CACHE_OK or any(not callable(a) for a in args):
        return numba.njit(*args, **kwargs)
    kwargs["cache"] = False
    if args:
        return _with_loading_cache(numba.njit(**kwargs)(args[0]))
    return lambda func: _with_loading_cache(numba.njit(**kwargs)(func))


_ENTRY_POINTS: dict = {}


def _type_key(a):
    """What Numba's type of the argument ``a`` depends on: an array's class, dtype, dimensions,
    layout flags, writability and alignment, a tuple's items', any other value's class."""
    if isinstance(a, np.ndarray):
        fl = a.flags
        return type(a), a.dtype, a.ndim, fl.c_contiguous, fl.f_contiguous, fl.writeable, fl.aligned
    if type(a) is tuple:
        return tuple([_type_key(x) for x in a])
    return type(a)


def entry_point(dispatcher, *args):
    """The machine code of ``dispatcher`` for the types of ``args`` (compiled or loaded from
    the cache if need be), callable from Python without the dispatcher's check of every
    argument's type on each call (about 0.1 us per argument); ``dispatcher`` itself where the
    installed Numba cannot give it (or the JIT is disabled).

    ``args`` are examples and are not run.  The entry point converts its arguments to exactly
    these types without checking them: every call must pass arguments of the same types
    (arrays of the same dtype, dimensions and layout, Python ints and floats where the
    examples have them).  Entry points are kept per dispatcher and argument types
    (:func:`_type_key`, Python scalars by their class), so that asking again costs a few
    microseconds instead of Numba's typing of every argument.
    """
    key = (dispatcher, _type_key(args))
    fn = _ENTRY_POINTS.get(key)
    if fn is not None:
        return fn
    try:
        fn = dispatcher.compile(tuple(numba.typeof(a) for a in args))
    except Exception:                                   # no such Numba API, or the JIT disabled
        return dispatcher
    _ENTRY_POINTS[key] = fn
    return fn


def _knows_nrt() -> bool:
    try:
        from numba.core.cpu import CPUTargetOptions
    except ImportError:
        return False
    return hasattr(CPUTargetOptions, "_nrt")


def _loading_cache_ok() -> bool:
    """Whether this Numba has the internals :class:`_LoadingCache` overrides and calls."""
    try:
        from numba.core.runtime import nrt
        from numba.core.dispatcher import Dispatcher
    except ImportError:
        return False
    return (hasattr(caching.FunctionCache, "_load_overload")
            and hasattr(caching.FunctionCache, "_guard_against_spurious_io_errors")
            and hasattr(getattr(nrt, "rtsys", None), "initialize")
            and "_cache" in getattr(Dispatcher, "__init__").__code__.co_names)


_KNOWS_NRT = _knows_nrt()
_LOADING_CACHE_OK = _loading_cache_ok()
