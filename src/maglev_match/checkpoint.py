"""Checkpoint folders of design maps: one writer at a time, tiles that cannot mix.

A map's checkpoint folder holds ``spec.json`` (the map's spec), one ``tile_AAAAA_BBBBB.npz``
per finished block of rows and a ``.lock`` file. Three guards make a folder safe to reuse:

* **Lock.** A run holds an exclusive ``flock(2)`` on ``.lock`` for its whole duration; a
  second run on the same folder is refused with a message naming the holder's pid. The
  kernel drops the lock when its process dies (even by ``kill -9``), so a stale lock file
  of a dead process never blocks anything: the file is simply locked again.
* **Fingerprint.** Every tile stores the SHA-256 of its map's spec (:func:`fingerprint`)
  and its row range. A tile whose fingerprint, rows, variables or shapes do not match the
  current map (a tile of another grid, left after ``spec.json`` was deleted or written by
  an older run) is rejected.
* **Validation.** A tile that cannot be read (truncated, not a zip file, corrupt) is named
  in a :class:`CheckpointWarning`, moved aside and recomputed, never a traceback.

Tiles and ``spec.json`` are written atomically (:mod:`maglev_match.io`).
"""

from __future__ import annotations

import contextlib
import errno
import hashlib
import json
import os
import socket
import time
import warnings
import zipfile
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path

import numpy as np

from maglev_match.io import atomic_write, atomic_write_text

__all__ = ["CheckpointWarning", "CheckpointLocked", "MapStopped", "TileStatus", "TileCheck",
           "fingerprint", "lock_folder", "tile_path", "save_tile", "check_tile",
           "load_tile", "prepare_folder", "FINGERPRINT_KEY", "ROWS_KEY"]

FINGERPRINT_KEY = "__fingerprint__"
ROWS_KEY = "__rows__"
LOCK_NAME = ".lock"
SPEC_NAME = "spec.json"


class CheckpointWarning(UserWarning):
    """A checkpoint tile that was rejected (and will be recomputed)."""


class CheckpointLocked(RuntimeError):
    """Another process holds the checkpoint folder's lock."""

    def __init__(self, folder: Path, holder: str):
        self.folder = folder
        self.holder = holder
        super().__init__(
            f"the checkpoint folder {folder} is in use by another map ({holder}); wait for it "
            "to finish or choose another --out"
        )


class MapStopped(RuntimeError):
    """A map stopped before all tiles were computed (interrupt, lost scheduler). Carries the
    exit code the command line should use (130 for an interrupt) and the resume hint."""

    def __init__(self, message: str, exit_code: int = 1):
        self.exit_code = exit_code
        super().__init__(message)


class TileStatus(StrEnum):
    """Outcome of checking one checkpoint tile."""

    OK = "ok"
    MISSING = "missing"
    UNREADABLE = "unreadable"
    FOREIGN = "foreign"  # another map's tile (fingerprint differs)
    MALFORMED = "malformed"  # readable but wrong rows, variables or shapes


@dataclass(frozen=True)
class TileCheck:
    """Result of :func:`check_tile`: status and a reason for the warning."""

    path: Path
    status: TileStatus
    reason: str = ""

    @property
    def ok(self) -> bool:
        return self.status is TileStatus.OK


def fingerprint(spec_key: str) -> str:
    """SHA-256 hex digest of a map spec's canonical JSON (``MapSpec.key()``)."""
    return hashlib.sha256(spec_key.encode("utf-8")).hexdigest()


def tile_path(folder: Path, rows: tuple[int, int]) -> Path:
    """The file of the tile holding rows [rows[0], rows[1])."""
    return Path(folder) / f"tile_{rows[0]:05d}_{rows[1]:05d}.npz"


# ----- lock ------------------------------------------------------------------------------
def _holder_text(lock_file: Path) -> str:
    try:
        info = json.loads(lock_file.read_text())
        started = time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(info["time"]))
        return f"pid {info['pid']} on {info['host']}, started {started}"
    except (OSError, ValueError, KeyError, TypeError):
        return "a process that did not record its pid"


@contextlib.contextmanager
def lock_folder(folder: Path) -> Iterator[Path]:
    """Hold an exclusive lock on ``folder`` (created if needed) for the ``with`` block.

    Raises :class:`CheckpointLocked` at once (no waiting) when another process, or another
    open of the lock in this process, holds it. A lock file left by a dead process is not
    locked any more and is taken over.
    """
    import fcntl

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    lock_file = folder / LOCK_NAME
    fd = os.open(lock_file, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as exc:
            if exc.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                raise CheckpointLocked(folder, _holder_text(lock_file)) from None
            raise
        info = json.dumps({"pid": os.getpid(), "host": socket.gethostname(),
                           "time": time.time()})
        os.ftruncate(fd, 0)
        os.pwrite(fd, info.encode(), 0)
        try:
            yield folder
        finally:
            with contextlib.suppress(OSError):
                os.ftruncate(fd, 0)
            fcntl.flock(fd, fcntl.LOCK_UN)
    finally:
        os.close(fd)


# ----- spec and tiles --------------------------------------------------------------------
def prepare_folder(folder: Path, spec_key: str, resume: bool) -> None:
    """Make ``folder`` ready for the map with canonical spec ``spec_key`` (call it while
    holding the lock).

    Without ``resume`` every old tile is removed. With ``resume`` a folder whose
    ``spec.json`` names a different map is refused (ValueError); tiles are kept and checked
    one by one later (their fingerprints decide, so a deleted ``spec.json`` cannot make
    another grid's tiles look valid).
    """
    folder = Path(folder)
    keyfile = folder / SPEC_NAME
    if resume and keyfile.is_file():
        try:
            old = keyfile.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError):
            old = None
        if old is not None and old != spec_key:
            raise ValueError("the checkpoint belongs to a different map; remove it or drop "
                             "--resume")
    if not resume:
        for f in folder.glob("tile_*.npz"):
            f.unlink()
    for f in folder.glob(".tile_*.tmp.npz"):  # temporary files of an interrupted write
        with contextlib.suppress(OSError):
            f.unlink()
    atomic_write_text(keyfile, spec_key)


def save_tile(folder: Path, rows: tuple[int, int], data: dict[str, np.ndarray],
              spec_key: str) -> Path:
    """Write one tile atomically, with the spec's fingerprint and its row range."""
    target = tile_path(folder, rows)
    payload = dict(data)
    payload[FINGERPRINT_KEY] = np.array(fingerprint(spec_key))
    payload[ROWS_KEY] = np.array(rows, dtype=np.int64)
    atomic_write(target, lambda tmp: np.savez(tmp, **payload))
    return target


def _read(path: Path) -> dict[str, np.ndarray]:
    with np.load(path, allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


def check_tile(folder: Path, rows: tuple[int, int], spec_key: str,
               variables: Iterable[str], nx: int) -> TileCheck:
    """Whether the tile of ``rows`` exists, is readable and belongs to this map."""
    path = tile_path(folder, rows)
    if not path.exists():
        return TileCheck(path, TileStatus.MISSING)
    try:
        data = _read(path)
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, KeyError) as exc:
        detail = " ".join(str(exc).split())[:80]
        return TileCheck(path, TileStatus.UNREADABLE, "cannot be read: truncated or corrupt "
                         f"({type(exc).__name__}: {detail})")
    fp = data.get(FINGERPRINT_KEY)
    if fp is None:
        return TileCheck(path, TileStatus.FOREIGN, "has no map fingerprint (written by "
                         "another version or another program)")
    if str(fp) != fingerprint(spec_key):
        return TileCheck(path, TileStatus.FOREIGN, "belongs to a different map (fingerprint "
                         "differs)")
    stored_rows = data.get(ROWS_KEY)
    if stored_rows is None or tuple(int(r) for r in np.ravel(stored_rows)) != tuple(rows):
        return TileCheck(path, TileStatus.MALFORMED, "holds other rows than its name says")
    shape = (rows[1] - rows[0], nx)
    for v in variables:
        if v not in data:
            return TileCheck(path, TileStatus.MALFORMED, f"lacks the variable '{v}'")
        if data[v].shape != shape:
            return TileCheck(path, TileStatus.MALFORMED,
                             f"variable '{v}' has shape {data[v].shape}, expected {shape}")
    return TileCheck(path, TileStatus.OK)


def load_tile(folder: Path, rows: tuple[int, int]) -> dict[str, np.ndarray]:
    """The map variables of one tile (without the bookkeeping entries)."""
    data = _read(tile_path(folder, rows))
    return {k: v for k, v in data.items() if k not in (FINGERPRINT_KEY, ROWS_KEY)}


def usable_tiles(folder: Path, tiles: Iterable[tuple[int, int]], spec_key: str,
                 variables: Iterable[str], nx: int) -> tuple[list[tuple[int, int]],
                                                             list[TileCheck]]:
    """The tiles still to compute, and the rejected ones. A rejected tile (unreadable,
    foreign or malformed) is named in a :class:`CheckpointWarning` and moved aside to
    ``<name>.rejected`` so that it is recomputed."""
    variables = tuple(variables)
    todo: list[tuple[int, int]] = []
    rejected: list[TileCheck] = []
    for t in tiles:
        chk = check_tile(folder, t, spec_key, variables, nx)
        if chk.ok:
            continue
        todo.append(t)
        if chk.status is TileStatus.MISSING:
            continue
        rejected.append(chk)
        warnings.warn(f"checkpoint tile {chk.path} {chk.reason}; it is recomputed",
                      CheckpointWarning, stacklevel=2)
        with contextlib.suppress(OSError):
            os.replace(chk.path, chk.path.with_name(chk.path.name + ".rejected"))
    return todo, rejected
