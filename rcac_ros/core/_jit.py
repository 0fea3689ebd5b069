"""How the package's numba kernels are compiled and cached.

Every compiled function of the package is declared with :func:`njit` (numba's, with the
package's cache) and every entry kernel of a control law with :func:`kernel` (one signature,
compiled when first needed, never at import). Two rules follow:

- **Compile only what runs.** Importing a module or building a controller compiles
  nothing; a controller compiles (or loads from the cache) the kernels of its own law at
  its ``compile()`` or first step (:func:`ready`), and nothing else.
- **Never stale.** numba keys its cache on the one source file that defines a function,
  so a change in an inlined helper of another file, or an upgrade in place, could load an
  old kernel. Here every kernel's cache entry is keyed on :data:`SOURCE_KEY`, a digest of
  every source file that holds compiled code (:data:`KERNEL_SOURCES`) and numba's version,
  and lives in its own directory of the user's cache (:func:`cache_dir`): a change to any
  of them starts a fresh directory, and a read-only install (a system package) keeps its
  cache where the user can write.

The cache directory is ``$NUMBA_CACHE_DIR/rcac_ros/<key>`` when ``NUMBA_CACHE_DIR`` is set,
else ``$RCAC_CACHE_DIR/<key>``, else ``$XDG_CACHE_HOME/rcac_ros/numba/<key>`` (default
``~/.cache``). Where it cannot be written, a keyed directory under the system's temporary
directory is used; where neither can, the kernels compile without a cache. numba's own
locations (keyed on one file) are never used.

The module also holds the two intrinsics that reach into numba's array structure
(:func:`unmanaged`, :func:`address_of`): the kernels' views without reference counts.
"""

import hashlib
import os
import tempfile
import threading

import numba
from numba.core import caching, cgutils, types
from numba.extending import intrinsic

_PACKAGE = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

#: the files whose compiled code a kernel may inline or call: the core's modules and the
#: command guards' kernel (relative to the package)
KERNEL_SOURCES = tuple(sorted(
    [os.path.join("core", f) for f in os.listdir(os.path.join(_PACKAGE, "core"))
     if f.endswith(".py")] + [os.path.join("nodes", "safety", "guards.py")]))


def _source_key():
    digest = hashlib.sha256(numba.__version__.encode())
    for rel in KERNEL_SOURCES:
        digest.update(rel.encode())
        with open(os.path.join(_PACKAGE, rel), "rb") as f:
            digest.update(f.read())
    return digest.hexdigest()[:20]


#: digest of numba's version and of every file of :data:`KERNEL_SOURCES`
SOURCE_KEY = _source_key()


def cache_dir():
    """The directory of this source's compiled kernels (see the module docstring)."""
    if os.environ.get("NUMBA_CACHE_DIR"):
        root = os.path.join(os.environ["NUMBA_CACHE_DIR"], "rcac_ros")
    elif os.environ.get("RCAC_CACHE_DIR"):
        root = os.environ["RCAC_CACHE_DIR"]
    else:
        base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
        root = os.path.join(base, "rcac_ros", "numba")
    return os.path.join(root, SOURCE_KEY)


class _KeyedLocator(caching._CacheLocator):
    """numba cache locator: :func:`cache_dir`, one folder per module, stamped with
    :data:`SOURCE_KEY` instead of the defining file alone."""

    def __init__(self, py_func, py_file):
        self._lineno = py_func.__code__.co_firstlineno
        rel = os.path.relpath(os.path.abspath(py_file), _PACKAGE)
        self._cache_path = os.path.join(cache_dir(), os.path.splitext(rel)[0].replace(os.sep, "."))

    def get_cache_path(self):
        return self._cache_path

    def get_source_stamp(self):
        return SOURCE_KEY

    def get_disambiguator(self):
        return str(self._lineno)

    @classmethod
    def from_function(cls, py_func, py_file):
        if not os.path.abspath(py_file).startswith(_PACKAGE + os.sep):
            return None
        self = cls(py_func, py_file)
        try:
            self.ensure_cache_path()
        except OSError:
            self._cache_path = os.path.join(_fallback_dir(), os.path.basename(self._cache_path))
            try:
                self.ensure_cache_path()
            except OSError:
                return None                 # no cache at all (see njit)
        return self


def _fallback_dir():
    """:func:`cache_dir`'s stand-in where it cannot be written: still keyed, per user."""
    user = str(os.getuid()) if hasattr(os, "getuid") else "user"
    return os.path.join(tempfile.gettempdir(), f"rcac_ros-{user}", SOURCE_KEY)


class _KeyedImpl(caching.CompileResultCacheImpl):
    _locator_classes = [_KeyedLocator]      # never numba's own, keyed on one file


class _KeyedCache(caching.FunctionCache):
    _impl_class = _KeyedImpl


def njit(*args, **kwargs):
    """numba's ``njit`` (never with a signature: nothing compiles at import); with
    ``cache=True`` the cache is :func:`cache_dir`'s."""
    cache = kwargs.pop("cache", False)

    def decorate(func):
        dispatcher = numba.njit(**kwargs)(func)
        if cache and _compilable(dispatcher):      # (not under NUMBA_DISABLE_JIT)
            try:
                dispatcher._cache = _KeyedCache(dispatcher.py_func)
            except RuntimeError:                  # no writable keyed directory:
                pass                              # compiled each process, never stale
        return dispatcher
    if args and callable(args[0]):
        return decorate(args[0])
    if args:
        raise TypeError("rcac_ros.core._jit.njit takes no signature: use kernel(signature)")
    return decorate


#: dispatcher -> (the one signature :func:`ready` compiles it for, the kernels it calls)
_SIGNATURES = {}
#: one :func:`ready` at a time (a node compiles in a thread while its executor may build a law)
_READY = threading.RLock()


def kernel(signature, calls=()):
    """Declare an entry kernel: compiled for ``signature`` alone, by :func:`ready`, and
    cached; any other argument types are then a TypeError at dispatch (never a silent
    recompilation). ``calls``: the kernels (declared so) that its body calls, readied first
    so that it links their one compiled version."""
    def decorate(func):
        dispatcher = njit(func, cache=True)
        _SIGNATURES[dispatcher] = (signature, tuple(calls))
        return dispatcher
    return decorate


def ready(dispatcher):
    """Compile ``dispatcher`` for its signature (or load it from the cache), once, and refuse
    any other signature from then on; returns it. The first call in a process with an empty
    cache takes seconds to a minute, later ones nothing."""
    with _READY:
        if _compilable(dispatcher):
            signature, calls = _SIGNATURES[dispatcher]
            for callee in calls:
                ready(callee)
            dispatcher.compile(signature)
            dispatcher.disable_compile()
    return dispatcher


def is_ready(dispatcher):
    """True once :func:`ready` ran for ``dispatcher`` in this process (always, for a plain
    Python function: numba's ``NUMBA_DISABLE_JIT``, or a wrapper)."""
    return not _compilable(dispatcher)


def _compilable(dispatcher):
    return getattr(dispatcher, "_can_compile", False)


@intrinsic
def unmanaged(typingctx, arr):
    """``arr`` itself (the same data, shape, strides and type) without its reference count.

    An array or a view of one carries a pointer to its owner's reference count, and numba
    counts it up and down (an atomic operation each way, and a barrier to the compiler)
    wherever the kernel binds it to a name: every inlined helper taking an array, at every
    link, channel and step. A view of the array this returns carries none, so none of that
    runs: the compiled arithmetic is the same, in the same order.

    It must not outlive ``arr``: the kernel takes it of an array its caller holds (an
    argument) and uses it, and the views of it, only while that call runs. It is never
    returned, stored or given to Python.
    """
    if not isinstance(arr, types.Array):
        return None

    def codegen(context, builder, signature, args):
        ary = context.make_array(arr)(context, builder, value=args[0])
        ary.meminfo = cgutils.get_null_value(ary.meminfo.type)
        ary.parent = cgutils.get_null_value(ary.parent.type)
        return ary._getvalue()
    return arr(arr), codegen


@intrinsic
def address_of(typingctx, arr, start):
    """The address of ``arr``'s element ``start`` (counted in its data, C order)."""
    if not (isinstance(arr, types.Array) and arr.layout == "C"
            and isinstance(start, types.Integer)):
        return None

    def codegen(context, builder, signature, args):
        ary = context.make_array(arr)(context, builder, value=args[0])
        return builder.gep(ary.data, [args[1]])
    return types.CPointer(arr.dtype)(arr, start), codegen
