"""Atomic file output: every file the program writes appears complete or not at all.

A writer writes to a temporary file in the *same folder* as the target (same file system,
so the final :func:`os.replace` is an atomic rename, POSIX ``rename(2)``), the data are
flushed to disk with ``fsync``, and only then is the temporary file renamed over the
target. A crash, ``kill -9`` or a full disk during the write leaves the previous file
(if any) untouched and at worst a stray ``.<name>.*.tmp`` file, which is removed when the
failure is seen in-process.

Usage::

    atomic_write(path, lambda tmp: fig.savefig(tmp, format="png"))
    with atomic_open(path, "w", newline="") as fh:
        csv.writer(fh).writerow(...)
    atomic_write_text(path, text)
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import IO, Any, TypeVar

__all__ = ["atomic_write", "atomic_open", "atomic_write_text", "atomic_write_bytes",
           "temp_path_for"]

T = TypeVar("T")


def temp_path_for(path: str | Path) -> Path:
    """A fresh, unused temporary path beside ``path`` that keeps its suffix (writers such
    as matplotlib and numpy choose the format from the suffix)."""
    path = Path(path)
    fd, name = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=f".tmp{path.suffix}",
                                dir=path.parent)
    os.close(fd)
    return Path(name)


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
    tmp = temp_path_for(path)
    try:
        result = writer(tmp)
        if fsync:
            _fsync_file(tmp)
        _set_normal_mode(tmp)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
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
    tmp = temp_path_for(path)
    fh: IO[Any] | None = None
    try:
        fh = open(tmp, mode, **kwargs)  # noqa: SIM115  (closed below)
        with fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        _set_normal_mode(tmp)
        os.replace(tmp, path)
    except BaseException:
        if fh is not None:
            with contextlib.suppress(Exception):
                fh.close()
        with contextlib.suppress(OSError):
            tmp.unlink()
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
