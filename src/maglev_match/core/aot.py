"""Ahead-of-time kernels: jitted functions whose traced program is kept on disk, so a new
process skips Python tracing and lowering and goes straight to the (persistently cached)
XLA executable.

Why. With the XLA compilation cache warm, a command-line process still traced every kernel
again: JAX's persistent cache stores executables keyed by the lowered program, so finding
an entry needs the program first. Tracing the package's kernels (nested forward-mode
derivatives, vmapped multilinear forms, the collocation blocks, the integrator's loop) took
about 3 s of a 5.6 s ``maglev-match index`` (measured 2026-11-25 with ``JAX_LOG_COMPILES=1``).

How. :func:`cached_kernel` wraps a kernel built by a factory (``@cache``-d on its static
ingredients: the right-hand side, NCOL, an order, a solver name, ...). On the first call
with a given argument signature it looks for a serialized :class:`jax.export.Exported` in
``<MAGLEV_MATCH_CACHE>/aot/``; if there is none (or it cannot be read) it exports the kernel
(``jax.export.export(jax.jit(fn))(*args)``), serializes it and writes it atomically. Either
way the call goes through ``jax.jit(exported.call)``, whose compilation is a hit of the
persistent XLA cache from the second process on. The StableHLO program is the one plain
``jax.jit`` compiles, so the results are bitwise the same (tested).

The file's key (SHA-256) is made of

* the kernel's name (its module and qualified name, or an explicit ``name``);
* the identity of every static ingredient (:func:`identity`): plain values by ``repr``,
  small NumPy arrays by content, functions of this package by module, qualified name, code
  and the identities of their closure cells and defaults;
* the argument signature: the pytree structure and each leaf's shape, dtype and weak type;
* the package version, a hash of the package's source files, the jax and jaxlib versions,
  the x64 flag and the backend.

Parameter values are arguments of the kernels, never part of the key, so a new parameter
value reuses the same file. A static ingredient without a stable identity (a user's model
loaded with ``--model file.py``, a closure over an object) makes the kernel a plain
``jax.jit`` (nothing written). A corrupt, truncated or mismatching file is ignored and
rewritten; files of another environment unused for 7 days are deleted (:func:`prune`,
once per process, before its first export). The mechanism is off (plain ``jax.jit``) when
the cache is switched off (``MAGLEV_MATCH_CACHE=""``), when ``MAGLEV_MATCH_AOT=0``, or when
``jax.export`` cannot serialize (the ``flatbuffers`` package is missing). Calls with tracers
(a kernel used inside another kernel's trace) always go to the plain ``jax.jit``, which
inlines.

Reference: JAX documentation, "Exporting and serializing staged-out computations"
(``jax.export``), and "Persistent compilation cache".
"""

from __future__ import annotations

import gc
import hashlib
import os
import tempfile
import types
import weakref
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any

import jax
import numpy as np

from maglev_match.core import jax_setup

__all__ = ["AotStats", "Kernel", "STATS", "aot_dir", "cached_kernel", "enabled", "identity",
           "prune", "release_compiled_code"]

_PACKAGE_ROOT = Path(__file__).resolve().parents[1]  # src/maglev_match
_MAX_ARRAY = 4096  # arrays up to this many elements can be static ingredients


@dataclass
class AotStats:
    """Counters of this process (for benchmarks and tests)."""

    loaded: int = 0  # kernels read from disk
    exported: int = 0  # kernels exported and written
    plain: int = 0  # kernels that run as plain jax.jit (no identity, AOT off, failures)
    rejected: int = 0  # unreadable or mismatching files that were replaced
    released: int = 0  # times the compiled code in memory was released (mapping limit)
    names: list[str] = field(default_factory=list)  # names of the exported kernels

    def reset(self) -> None:
        self.loaded = self.exported = self.plain = self.rejected = self.released = 0
        self.names.clear()


STATS = AotStats()


# ---------------------------------------------------------------------------------------
# the memory-mapping limit
# ---------------------------------------------------------------------------------------
# Every XLA executable keeps ~3 memory mappings of its machine code, and Linux caps a
# process at vm.max_map_count mappings (65530 by default). A long process that compiles
# thousands of distinct kernels (a study over many structural parameters, a test session)
# would reach the cap, and the next compilation dies with a segmentation fault inside LLVM.
# So every MAP_CHECK_EVERY new kernel signatures the process counts its mappings, and past
# MAP_SHARE of the cap it releases the compiled code it holds; later calls reload kernels
# from the persistent caches (or compile them again).
MAP_SHARE = 0.6
MAP_CHECK_EVERY = 32
_LIVE: weakref.WeakSet = weakref.WeakSet()  # every Kernel of this process
_prepared = 0


def _map_limit() -> int:
    try:
        return int(Path("/proc/sys/vm/max_map_count").read_text())
    except (OSError, ValueError):  # not Linux
        return 0


def _map_count() -> int:
    try:
        with open("/proc/self/maps", "rb") as fh:
            return sum(1 for _ in fh)
    except OSError:
        return 0


def release_compiled_code() -> None:
    """Drop the compiled kernels this process holds in memory: JAX's caches and every
    :class:`Kernel`'s loaded signatures. Results do not change; the next call of a kernel
    loads or compiles it again."""
    for k in list(_LIVE):
        k._calls.clear()
    jax.clear_caches()
    gc.collect()
    STATS.released += 1


def _guard_mappings() -> None:
    """Release the compiled code when the process nears the mapping limit (see above)."""
    global _prepared
    _prepared += 1
    if _prepared % MAP_CHECK_EVERY:
        return
    limit = _map_limit()
    if limit and _map_count() > MAP_SHARE * limit:
        release_compiled_code()


def enabled() -> bool:
    """True when kernels are exported to / loaded from disk (see the module docstring)."""
    if os.environ.get("MAGLEV_MATCH_AOT", "1").strip().lower() in ("0", "off", "false", "no"):
        return False
    return jax_setup.CACHE_DIR is not None


def aot_dir() -> Path | None:
    """The folder of the exported kernels, or None when the mechanism is off."""
    if not enabled():
        return None
    return jax_setup.CACHE_DIR / "aot"  # type: ignore[operator]


# ---------------------------------------------------------------------------------------
# identities
# ---------------------------------------------------------------------------------------
def _ours(module: str | None) -> bool:
    return bool(module) and (module == "maglev_match" or module.startswith("maglev_match."))


def identity(obj: Any, _depth: int = 0) -> str | None:
    """A text that names ``obj`` the same way in every process, or None if there is none.

    Plain values (None, bool, int, float, complex, str, bytes) by type and ``repr``; tuples,
    lists and frozensets element-wise; NumPy arrays up to 4096 elements by dtype, shape and
    content; ``functools.partial`` by its function, arguments and keywords; functions
    defined in this package by module, qualified name, first line, a hash of their byte
    code and constants, and the identities of their defaults and closure cells. Anything
    else (objects, functions of other modules such as a user's model file) has none.
    """
    if _depth > 12:
        return None
    if obj is None or isinstance(obj, (bool, int, float, complex, str, bytes)):
        return f"{type(obj).__name__}:{obj!r}"
    if isinstance(obj, np.generic):
        return f"np.{obj.dtype.str}:{obj.item()!r}"
    if isinstance(obj, (tuple, list, frozenset)):
        items = sorted(obj, key=repr) if isinstance(obj, frozenset) else obj
        parts = [identity(o, _depth + 1) for o in items]
        if any(p is None for p in parts):
            return None
        return f"{type(obj).__name__}({','.join(parts)})"  # type: ignore[arg-type]
    if isinstance(obj, np.ndarray):
        if obj.size > _MAX_ARRAY or obj.dtype == object:
            return None
        digest = hashlib.sha256(np.ascontiguousarray(obj).tobytes()).hexdigest()[:24]
        return f"ndarray:{obj.dtype.str}:{obj.shape}:{digest}"
    if isinstance(obj, partial):
        kw = tuple(sorted(obj.keywords.items()))
        inner = [identity(x, _depth + 1) for x in (obj.func, obj.args, kw)]
        return None if None in inner else f"partial({','.join(inner)})"  # type: ignore[arg-type]
    if isinstance(obj, types.FunctionType):
        if not _ours(obj.__module__):
            return None
        code = obj.__code__
        h = hashlib.sha256(code.co_code)
        h.update(repr(tuple(c for c in code.co_consts if not isinstance(c, types.CodeType)))
                 .encode())
        parts = [f"fn:{obj.__module__}:{obj.__qualname__}:{code.co_firstlineno}:"
                 f"{h.hexdigest()[:16]}"]
        extra: list[Any] = [obj.__defaults__, tuple(sorted((obj.__kwdefaults__ or {}).items()))]
        for cell in obj.__closure__ or ():
            try:
                extra.append(cell.cell_contents)
            except ValueError:  # an empty cell
                extra.append(None)
        for x in extra:
            ident = identity(x, _depth + 1)
            if ident is None:
                return None
            parts.append(ident)
        return "|".join(parts)
    return None


_ENV: str | None = None


def _environment() -> str:
    """Package version, source hash, jax/jaxlib versions, x64 flag and backend (cached)."""
    global _ENV
    if _ENV is None:
        import jaxlib

        from maglev_match import __version__

        h = hashlib.sha256()
        for path in sorted(_PACKAGE_ROOT.rglob("*.py")):
            h.update(str(path.relative_to(_PACKAGE_ROOT)).encode())
            h.update(path.read_bytes())
        _ENV = (f"maglev_match {__version__} src {h.hexdigest()} jax {jax.__version__} "
                f"jaxlib {jaxlib.__version__} x64 {bool(jax.config.jax_enable_x64)} "
                f"backend {jax.default_backend()}")
    return _ENV


def _environment_tag() -> str:
    """12 hex digits naming the environment (source, versions) in the file names."""
    return hashlib.sha256(_environment().encode()).hexdigest()[:12]


_PRUNED = False
STALE_AFTER_DAYS = 7.0


def prune(folder: Path, max_age_days: float = STALE_AFTER_DAYS) -> int:
    """Delete the exported kernels of other environments (another source or jax version)
    that were not written or read for ``max_age_days``; returns how many were deleted.

    Run once per process, before its first export, so the folder does not grow with every
    change of the package. Recent files of other environments are kept: two installations
    may share a cache folder."""
    import time

    tag = _environment_tag()
    cutoff = time.time() - max_age_days * 86400.0
    removed = 0
    for f in folder.glob("*.jaxexport"):
        parts = f.name.rsplit("-", 2)
        if len(parts) == 3 and parts[1] == tag:
            continue
        try:
            if f.stat().st_mtime < cutoff:
                f.unlink()
                removed += 1
        except OSError:  # another process removed it first, or no permission
            pass
    return removed


def _leaf_signature(x: Any) -> tuple | None:
    """(shape, dtype, weak) of one argument leaf, or None for what cannot be exported."""
    if isinstance(x, (np.ndarray, np.generic, jax.Array)):
        if isinstance(x, jax.core.Tracer):
            return None
        return (x.shape, x.dtype.str, bool(getattr(x, "weak_type", False)))
    if isinstance(x, (bool, int, float, complex)):
        return ((), type(x).__name__, True)
    return None


# ---------------------------------------------------------------------------------------
# the kernel wrapper
# ---------------------------------------------------------------------------------------
class Kernel:
    """A jitted kernel that is exported to / loaded from disk per argument signature.

    Call it like the ``jax.jit`` of ``fn`` (positional arguments only). ``plain`` is that
    ``jax.jit``; ``key`` the static part of the file key (None: always plain)."""

    def __init__(self, fn: Callable, name: str, static_key: str | None) -> None:
        self.fn = fn
        self.name = name
        self.plain = jax.jit(fn)
        self.key = static_key
        self._calls: dict[tuple, Callable] = {}
        self.__wrapped__ = fn
        self.__doc__ = getattr(fn, "__doc__", None)
        _LIVE.add(self)

    def __repr__(self) -> str:
        mode = "plain jit" if self.key is None else f"{len(self._calls)} signature(s)"
        return f"Kernel({self.name}, {mode})"

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        if self.key is None or kwargs:
            return self.plain(*args, **kwargs)
        sig = self._signature(args)
        if sig is None:
            return self.plain(*args)
        call = self._calls.get(sig)
        if call is None:
            call = self._prepare(sig, args)
            self._calls[sig] = call
        return call(*args)

    @staticmethod
    def _signature(args: tuple) -> tuple | None:
        sig: list[Any] = []
        for a in args:
            s = _leaf_signature(a)
            if s is None:  # a pytree (tuple, dict) or a tracer: flatten
                leaves, tree = jax.tree_util.tree_flatten(a)
                parts = [_leaf_signature(x) for x in leaves]
                if not leaves or any(p is None for p in parts):
                    return None
                s = (str(tree), tuple(parts))  # type: ignore[assignment]
            sig.append(s)
        return tuple(sig)

    def _path(self, sig: tuple) -> Path | None:
        folder = aot_dir()
        if folder is None:
            return None
        text = f"{self.key}\n{sig!r}\n{_environment()}"
        digest = hashlib.sha256(text.encode()).hexdigest()[:32]
        short = "".join(c if c.isalnum() or c in "._-" else "_" for c in self.name)[-60:]
        return folder / f"{short}-{_environment_tag()}-{digest}.jaxexport"

    def _prepare(self, sig: tuple, args: tuple) -> Callable:
        """The callable for one signature: the loaded or freshly exported kernel, or the
        plain jit when exporting is not possible (then this process only)."""
        from jax import export

        _guard_mappings()
        path = self._path(sig)
        if path is None:
            STATS.plain += 1
            return self.plain
        exp = None
        try:
            blob = path.read_bytes()
        except OSError:
            blob = None
        if blob is not None:
            try:
                exp = export.deserialize(bytearray(blob))
                if not self._matches(exp, args):
                    raise ValueError("argument signature differs")
                STATS.loaded += 1
            except Exception:  # corrupt, truncated or stale: export again
                exp = None
                STATS.rejected += 1
            else:  # used: keep it from being pruned as stale
                try:
                    os.utime(path)
                except OSError:
                    pass
        if exp is None:
            global _PRUNED
            if not _PRUNED:
                _PRUNED = True
                prune(path.parent)
            try:
                exp = export.export(self.plain)(*args)
                data = exp.serialize()
            except Exception:  # not exportable here (e.g. no flatbuffers): plain jit
                STATS.plain += 1
                return self.plain
            _write_atomic(path, bytes(data))
            STATS.exported += 1
            STATS.names.append(self.name)
        return jax.jit(exp.call)

    @staticmethod
    def _matches(exp: Any, args: tuple) -> bool:
        leaves = jax.tree_util.tree_leaves(args)
        if len(leaves) != len(exp.in_avals):
            return False
        for x, a in zip(leaves, exp.in_avals, strict=True):
            t = jax.typeof(x)
            if tuple(t.shape) != tuple(a.shape) or t.dtype != a.dtype:
                return False
        return True


def _write_atomic(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file and a rename (readers never see
    a partial file); a failure (read-only or full disk) only loses the cache entry."""
    tmp = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".tmp-", suffix=".jaxexport")
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.replace(tmp, path)
        tmp = None
    except OSError:
        pass
    finally:
        if tmp is not None:
            try:
                os.unlink(tmp)
            except OSError:
                pass


def cached_kernel(fn: Callable, *static: Any, name: str | None = None) -> Callable:
    """``jax.jit(fn)``, exported ahead of time per argument signature (module docstring).

    Parameters
    ----------
    fn : the kernel, a pure JAX function of positional array arguments (pytrees allowed).
    static : everything the factory built ``fn`` from that is not an argument (the
        right-hand side, NCOL, an order, option values); together with ``name`` it must
        determine ``fn``.
    name : the kernel's name in the key (default: ``fn``'s module and qualified name); two
        kernels of one factory that share a qualified name (``G`` and ``jacfwd(G)``) need
        distinct names.

    Returns
    -------
    A :class:`Kernel` (a plain ``jax.jit`` when the mechanism is off or a static
    ingredient has no identity).
    """
    base = getattr(fn, "__wrapped__", fn)
    label = name or f"{getattr(base, '__module__', '?')}.{getattr(base, '__qualname__', '?')}"
    if not enabled():
        return jax.jit(fn)
    idents = [identity(s) for s in static]
    if any(i is None for i in idents):
        STATS.plain += 1
        return jax.jit(fn)
    return Kernel(fn, label, f"{label}\n" + "\n".join(idents))  # type: ignore[arg-type]
