"""Atomic file output: every file the program writes appears complete or not at all.

A writer writes to a temporary file in the *same folder* as the target (same file system,
so the final :func:`os.replace` is an atomic rename, POSIX ``rename(2)``), the data are
flushed to disk with ``fsync``, and only then is the temporary file renamed over the
target. A crash, ``kill -9`` or a full disk during the write leaves the previous file
(if any) untouched and at worst a stray ``.<name>.*.tmp`` file, which is removed when the
failure is seen in-process.

A full disk (``ENOSPC``, or a quota, ``EDQUOT``) during a write is raised as
:class:`DiskFull`, one line naming the file, with the previous file untouched. netCDF files
are written through :func:`atomic_write_netcdf`, which builds the whole file in memory first:
HDF5 (through h5py) does not survive a write error inside its own file driver (a full disk
there ended in a segmentation fault), while a plain write of finished bytes fails cleanly.

Usage::

    atomic_write(path, lambda tmp: fig.savefig(tmp, format="png"))
    with atomic_open(path, "w", newline="") as fh:
        csv.writer(fh).writerow(...)
    atomic_write_text(path, text)
    atomic_write_netcdf(path, dataset)
"""

from __future__ import annotations

import contextlib
import errno
import os
import re
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import IO, Any, TypeVar

__all__ = ["atomic_write", "atomic_open", "atomic_write_text", "atomic_write_bytes",
           "atomic_write_netcdf", "temp_path_for", "DiskFull", "is_disk_full"]

T = TypeVar("T")

#: errno values that mean "no room left": the device is full or the user's quota is used up.
DISK_FULL_ERRNOS = frozenset(e for e in (errno.ENOSPC, getattr(errno, "EDQUOT", None))
                             if e is not None)


class DiskFull(Exception):
    """A file could not be written because the disk (or the user's quota) is full.

    Deliberately not an :class:`OSError`: callers that treat OSError as a lost connection
    or a missing file (a Dask client, a checkpoint reader) must not swallow it. The previous
    content of ``path`` is untouched (the write went to a temporary file, now removed).
    """

    def __init__(self, path: str | Path, detail: str = ""):
        self.path = Path(path)
        self.detail = detail or os.strerror(errno.ENOSPC)
        super().__init__(f"disk full: cannot write {self.path} ({self.detail})")


def is_disk_full(exc: BaseException) -> bool:
    """Whether ``exc`` (or an exception it was raised from) is a full disk or quota."""
    seen = 0
    while exc is not None and seen < 10:
        if isinstance(exc, DiskFull) or (isinstance(exc, OSError)
                                         and exc.errno in DISK_FULL_ERRNOS):
            return True
        exc = exc.__cause__ or exc.__context__
        seen += 1
    return False


def _disk_full_or_raise(path: Path, exc: BaseException) -> None:
    """Re-raise a full-disk error while writing ``path`` as :class:`DiskFull`."""
    if isinstance(exc, DiskFull):
        raise exc
    if is_disk_full(exc):
        detail = exc.strerror if isinstance(exc, OSError) and exc.strerror else ""
        raise DiskFull(path, detail) from exc


def temp_path_for(path: str | Path) -> Path:
    """A fresh, unused temporary path beside ``path`` that keeps its suffix (writers such
    as matplotlib and numpy choose the format from the suffix)."""
    path = Path(path)
    remove_orphans(path)
    fd, name = tempfile.mkstemp(prefix=f".{path.stem}.{os.getpid()}-",
                                suffix=f".tmp{path.suffix}", dir=path.parent)
    os.close(fd)
    return Path(name)


def remove_orphans(path: str | Path) -> list[Path]:
    """Remove the temporary files of ``path`` left by writers that no longer run (a run
    killed with kill -9 cannot remove its own): ``.STEM.PID-RANDOM.tmpSUFFIX`` whose PID
    is not a live process of this host. A live writer's file is left alone. Returns the
    removed files."""
    path = Path(path)
    removed = []
    pattern = re.compile(rf"^\.{re.escape(path.stem)}\.(\d+)-[^/]*\.tmp{re.escape(path.suffix)}$")
    try:
        names = os.listdir(path.parent)
    except OSError:
        return removed
    for name in names:
        m = pattern.match(name)
        if m is None or _alive(int(m.group(1))):
            continue
        with contextlib.suppress(OSError):
            (path.parent / name).unlink()
            removed.append(path.parent / name)
    return removed


def _alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError, ValueError):
        return True  # (another user's process, or not a pid: leave it)
    return True


def _fsync_file(path: Path) -> None:
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def _fsync_dir(folder: Path) -> None:
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass  # some file systems do not support fsync on directories
    finally:
        os.close(fd)


def _set_normal_mode(path: Path) -> None:
    """mkstemp creates files with mode 0600; give the file the usual 0666 minus umask."""
    umask = os.umask(0)
    os.umask(umask)
    with contextlib.suppress(OSError):
        os.chmod(path, 0o666 & ~umask)


def atomic_write(path: str | Path, writer: Callable[[Path], T], *, fsync: bool = True) -> T:
    """Run ``writer(tmp)`` on a temporary path beside ``path``, then rename it to ``path``.

    Parameters
    ----------
    path : the target file; its folder must exist.
    writer : called with the temporary path (same folder and suffix as ``path``); it must
        create the file there. Its return value is returned.
    fsync : flush the data to disk before the rename (so that a power cut cannot leave a
        renamed but empty file).

    On any exception (including KeyboardInterrupt) the temporary file is removed and the
    exception propagates; the target is unchanged.
    """
    path = Path(path)
    try:
        tmp = temp_path_for(path)
    except OSError as exc:
        _disk_full_or_raise(path, exc)
        raise
    try:
        result = writer(tmp)
        if fsync:
            _fsync_file(tmp)
        _set_normal_mode(tmp)
        os.replace(tmp, path)
    except BaseException as exc:
        with contextlib.suppress(OSError):
            tmp.unlink()
        _disk_full_or_raise(path, exc)
        raise
    if fsync:
        _fsync_dir(path.parent)
    return result


@contextlib.contextmanager
def atomic_open(path: str | Path, mode: str = "w", **kwargs: Any) -> Iterator[IO[Any]]:
    """``open(path, mode)`` whose content replaces ``path`` only when the block ends without
    an exception. ``mode`` must be a write mode ('w', 'wb', 'wt')."""
    if "w" not in mode or any(c in mode for c in "ra+x"):
        raise ValueError(f"atomic_open supports only write modes, not {mode!r}")
    if "b" not in mode:
        kwargs.setdefault("encoding", "utf-8")

    path = Path(path)
    try:
        tmp = temp_path_for(path)
    except OSError as exc:
        _disk_full_or_raise(path, exc)
        raise
    fh: IO[Any] | None = None
    try:
        fh = open(tmp, mode, **kwargs)  # noqa: SIM115  (closed below)
        with fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        _set_normal_mode(tmp)
        os.replace(tmp, path)
    except BaseException as exc:
        if fh is not None:
            with contextlib.suppress(Exception):
                fh.close()
        with contextlib.suppress(OSError):
            tmp.unlink()
        _disk_full_or_raise(path, exc)
        raise
    _fsync_dir(path.parent)


def atomic_write_text(path: str | Path, text: str, encoding: str = "utf-8") -> Path:
    """Write ``text`` to ``path`` atomically; returns ``path``."""
    with atomic_open(path, "w", encoding=encoding) as fh:
        fh.write(text)
    return Path(path)


def atomic_write_bytes(path: str | Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically; returns ``path``."""
    with atomic_open(path, "wb") as fh:
        fh.write(data)
    return Path(path)


def atomic_write_netcdf(path: str | Path, dataset: Any, engine: str = "h5netcdf") -> Path:
    """Write an :class:`xarray.Dataset` to ``path`` as netCDF-4, atomically.

    The file is built in memory first (``Dataset.to_netcdf()`` without a path returns its
    bytes) and then written and renamed like any other file, so a full disk is a clean
    :class:`DiskFull` with the previous file intact instead of an error inside HDF5's file
    driver (which crashed the process). Gridded results of this package are at most a few
    megabytes, so the copy in memory costs nothing worth keeping a second path for.
    """
    return atomic_write_bytes(path, netcdf_bytes(dataset, engine))


def netcdf_bytes(dataset: Any, engine: str = "h5netcdf") -> bytes:
    """An :class:`xarray.Dataset` as netCDF-4 bytes (what `atomic_write_netcdf` writes, and
    what the design explorer hands to the browser as a download)."""
    return bytes(dataset.to_netcdf(engine=engine))
