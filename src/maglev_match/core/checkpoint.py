"""Checkpoint folders of long computations: one writer at a time, pieces that cannot mix.

A design map saves its rows block by block ("tiles"), a Monte Carlo study its samples block
by block ("chunks"); both go through this module, so both have the same guarantees. A
checkpoint folder holds a spec file (the computation's canonical description: ``spec.json``
for a map, ``study.json`` for a Monte Carlo study), one ``<prefix>_AAAAA_BBBBB.npz`` per
finished piece [A, B) and a ``.lock`` file. Three guards make a folder safe to reuse:

* **Lock.** A run holds an exclusive ``flock(2)`` on ``.lock`` for its whole duration; a
  second run on the same folder is refused with a message naming the holder's pid. The
  kernel drops the lock when its process dies (even by ``kill -9``), so a stale lock file
  of a dead process never blocks anything: the file is simply locked again.
* **Fingerprint.** Every piece stores the SHA-256 of its computation's spec
  (:func:`fingerprint`) and its range. A piece whose fingerprint, range, variables or
  shapes do not match the current computation (a piece of another grid or study, left after
  the spec file was deleted or written by an older run) is rejected.
* **Validation.** A piece that cannot be read (truncated, not a zip file, corrupt) is named
  in a :class:`CheckpointWarning`, moved aside and recomputed, never a traceback.

Pieces and the spec file are written atomically (:mod:`maglev_match.core.io`): a run killed or
stopped by a full disk while writing leaves the pieces already written intact.

:class:`Checkpoint` bundles a folder with its spec, prefix and variable shapes; the
``*_tile`` functions are the map's view of it (rows of ``nx`` columns).
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
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path

import numpy as np

from maglev_match.core.errors import CheckpointLocked, MapStopped  # noqa: F401 (defined JAX- and NumPy-free)
from maglev_match.core.io import atomic_write, atomic_write_text

__all__ = ["CheckpointWarning", "CheckpointLocked", "MapStopped", "TileStatus", "TileCheck",
           "Checkpoint", "fingerprint", "lock_folder", "piece_path", "save_piece",
           "check_piece", "load_piece", "usable_pieces", "tile_path", "save_tile",
           "check_tile", "load_tile", "usable_tiles", "prepare_folder", "tile_shapes",
           "tile_checkpoint", "FINGERPRINT_KEY", "ROWS_KEY"]

FINGERPRINT_KEY = "__fingerprint__"
ROWS_KEY = "__rows__"
LOCK_NAME = ".lock"
SPEC_NAME = "spec.json"
TILE_PREFIX = "tile"
TILE_DIGITS = 5

#: Shapes of a piece's variables, given its range [a, b): name -> shape.
ShapesFn = Callable[[tuple[int, int]], Mapping[str, tuple[int, ...]]]


class CheckpointWarning(UserWarning):
    """A checkpoint piece that was rejected (and will be recomputed)."""


class TileStatus(StrEnum):
    """Outcome of checking one checkpoint piece (a map tile or a Monte Carlo chunk)."""

    OK = "ok"
    MISSING = "missing"
    UNREADABLE = "unreadable"
    FOREIGN = "foreign"  # another computation's piece (fingerprint differs)
    MALFORMED = "malformed"  # readable but wrong range, variables or shapes


@dataclass(frozen=True)
class TileCheck:
    """Result of :func:`check_piece`: status and a reason for the warning."""

    path: Path
    status: TileStatus
    reason: str = ""

    @property
    def ok(self) -> bool:
        return self.status is TileStatus.OK


def fingerprint(spec_key: str) -> str:
    """SHA-256 hex digest of a computation's canonical JSON spec (e.g. ``MapSpec.key()``)."""
    return hashlib.sha256(spec_key.encode("utf-8")).hexdigest()


def piece_path(folder: Path, rows: tuple[int, int], prefix: str = TILE_PREFIX,
               digits: int = TILE_DIGITS) -> Path:
    """The file of the piece holding the range [rows[0], rows[1])."""
    return Path(folder) / f"{prefix}_{rows[0]:0{digits}d}_{rows[1]:0{digits}d}.npz"


def tile_path(folder: Path, rows: tuple[int, int]) -> Path:
    """The file of the map tile holding rows [rows[0], rows[1])."""
    return piece_path(folder, rows)


# ----- lock ------------------------------------------------------------------------------
def _holder_text(lock_file: Path) -> str:
    try:
        info = json.loads(lock_file.read_text())
        started = time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(info["time"]))
        return f"pid {info['pid']} on {info['host']}, started {started}"
    except (OSError, ValueError, KeyError, TypeError):
        return "a process that did not record its pid"


@contextlib.contextmanager
def lock_folder(folder: Path, what: str = "map") -> Iterator[Path]:
    """Hold an exclusive lock on ``folder`` (created if needed) for the ``with`` block.

    Raises :class:`CheckpointLocked` at once (no waiting) when another process, or another
    open of the lock in this process, holds it; ``what`` names the kind of run in the
    message ("map", "Monte Carlo run"). A lock file left by a dead process is not locked
    any more and is taken over.
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
                raise CheckpointLocked(folder, _holder_text(lock_file), what) from None
            raise
        info = json.dumps({"pid": os.getpid(), "host": socket.gethostname(),
                           "time": time.time()})
        os.ftruncate(fd, 0)
        with contextlib.suppress(OSError):  # a full disk: the lock holds without the note
            os.pwrite(fd, info.encode(), 0)
        try:
            yield folder
        finally:
            with contextlib.suppress(OSError):
                os.ftruncate(fd, 0)
            fcntl.flock(fd, fcntl.LOCK_UN)
    finally:
        os.close(fd)


# ----- spec and pieces -------------------------------------------------------------------
def prepare_folder(folder: Path, spec_key: str, resume: bool, *, prefix: str = TILE_PREFIX,
                   spec_name: str = SPEC_NAME, what: str = "map",
                   stale: Iterable[str] = ()) -> None:
    """Make ``folder`` ready for the computation with canonical spec ``spec_key`` (call it
    while holding the lock).

    Without ``resume`` every old piece (``<prefix>_*.npz``, and files matching the glob
    patterns in ``stale``, e.g. an older format's) is removed. With ``resume`` a folder whose
    spec file names a different computation is refused (ValueError); pieces are kept and
    checked one by one later (their fingerprints decide, so a deleted spec file cannot make
    another computation's pieces look valid).
    """
    folder = Path(folder)
    keyfile = folder / spec_name
    if resume and keyfile.is_file():
        try:
            old = keyfile.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError):
            old = None
        if old is not None and old != spec_key:
            raise ValueError(f"the checkpoint belongs to a different {what}; remove it or "
                             "drop --resume")
    if not resume:
        for pattern in (f"{prefix}_*.npz", *stale):
            for f in folder.glob(pattern):
                f.unlink()
    for f in folder.glob(f".{prefix}_*.tmp.npz"):  # temporary files of an interrupted write
        with contextlib.suppress(OSError):
            f.unlink()
    atomic_write_text(keyfile, spec_key)


def save_piece(path: Path, rows: tuple[int, int], data: Mapping[str, np.ndarray],
               spec_key: str) -> Path:
    """Write one piece to ``path`` atomically, with the spec's fingerprint and its range."""
    payload = dict(data)
    payload[FINGERPRINT_KEY] = np.array(fingerprint(spec_key))
    payload[ROWS_KEY] = np.array(rows, dtype=np.int64)
    atomic_write(path, lambda tmp: np.savez(tmp, **payload))
    return Path(path)


def save_tile(folder: Path, rows: tuple[int, int], data: dict[str, np.ndarray],
              spec_key: str) -> Path:
    """Write one map tile atomically, with the spec's fingerprint and its row range."""
    return save_piece(tile_path(folder, rows), rows, data, spec_key)


def _read(path: Path) -> dict[str, np.ndarray]:
    with np.load(path, allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


def check_piece(path: Path, rows: tuple[int, int], spec_key: str,
                shapes: Mapping[str, tuple[int, ...]], what: str = "map") -> TileCheck:
    """Whether the piece file ``path`` of the range ``rows`` exists, is readable and belongs
    to this computation: fingerprint, range and every variable of ``shapes`` with its shape.
    ``what`` names the computation in the reasons ("map", "Monte Carlo study")."""
    path = Path(path)
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
        return TileCheck(path, TileStatus.FOREIGN, f"has no {what} fingerprint (written by "
                         "another version or another program)")
    if str(fp) != fingerprint(spec_key):
        return TileCheck(path, TileStatus.FOREIGN, f"belongs to a different {what} "
                         "(fingerprint differs)")
    stored_rows = data.get(ROWS_KEY)
    if stored_rows is None or tuple(int(r) for r in np.ravel(stored_rows)) != tuple(rows):
        return TileCheck(path, TileStatus.MALFORMED, "holds other rows than its name says")
    for v, shape in shapes.items():
        if v not in data:
            return TileCheck(path, TileStatus.MALFORMED, f"lacks the variable '{v}'")
        if data[v].shape != tuple(shape):
            return TileCheck(path, TileStatus.MALFORMED,
                             f"variable '{v}' has shape {data[v].shape}, expected "
                             f"{tuple(shape)}")
    return TileCheck(path, TileStatus.OK)


def tile_shapes(variables: Iterable[str], nx: int) -> ShapesFn:
    """The shapes of a tile's variables: every one (rows, ``nx``)."""
    names = tuple(variables)
    return lambda rows: {v: (rows[1] - rows[0], nx) for v in names}


def check_tile(folder: Path, rows: tuple[int, int], spec_key: str,
               variables: Iterable[str], nx: int) -> TileCheck:
    """Whether the tile of ``rows`` exists, is readable and belongs to this map."""
    return check_piece(tile_path(folder, rows), rows, spec_key,
                       tile_shapes(variables, nx)(rows))


def load_piece(path: Path) -> dict[str, np.ndarray]:
    """The variables of one piece (without the bookkeeping entries)."""
    data = _read(Path(path))
    return {k: v for k, v in data.items() if k not in (FINGERPRINT_KEY, ROWS_KEY)}


def load_tile(folder: Path, rows: tuple[int, int]) -> dict[str, np.ndarray]:
    """The map variables of one tile (without the bookkeeping entries)."""
    return load_piece(tile_path(folder, rows))


def usable_pieces(pieces: Iterable[tuple[int, int]], path_of: Callable[[tuple[int, int]], Path],
                  spec_key: str, shapes_of: ShapesFn, what: str = "map", noun: str = "tile",
                  ) -> tuple[list[tuple[int, int]], list[TileCheck]]:
    """The pieces still to compute, and the rejected ones. A rejected piece (unreadable,
    foreign or malformed) is named in a :class:`CheckpointWarning` and moved aside to
    ``<name>.rejected`` so that it is recomputed."""
    todo: list[tuple[int, int]] = []
    rejected: list[TileCheck] = []
    for t in pieces:
        chk = check_piece(path_of(t), t, spec_key, shapes_of(t), what)
        if chk.ok:
            continue
        todo.append(t)
        if chk.status is TileStatus.MISSING:
            continue
        rejected.append(chk)
        warnings.warn(f"checkpoint {noun} {chk.path} {chk.reason}; it is recomputed",
                      CheckpointWarning, stacklevel=3)
        with contextlib.suppress(OSError):
            os.replace(chk.path, chk.path.with_name(chk.path.name + ".rejected"))
    return todo, rejected


def usable_tiles(folder: Path, tiles: Iterable[tuple[int, int]], spec_key: str,
                 variables: Iterable[str], nx: int) -> tuple[list[tuple[int, int]],
                                                             list[TileCheck]]:
    """The map tiles still to compute, and the rejected ones (see :func:`usable_pieces`)."""
    folder = Path(folder)
    return usable_pieces(tiles, lambda t: tile_path(folder, t), spec_key,
                         tile_shapes(variables, nx))


# ----- the bundle ------------------------------------------------------------------------
@dataclass(frozen=True)
class Checkpoint:
    """A checkpoint folder of one computation: where its pieces live, what they hold.

    folder : the folder (created when locked).
    spec_key : the computation's canonical spec (JSON text); its SHA-256 is every piece's
        fingerprint.
    shapes_of : the variables of the piece [a, b) and their shapes.
    prefix, digits : piece file names ``<prefix>_<a>_<b>.npz`` with ``digits`` digits.
    spec_name : the spec file in the folder.
    what, noun : the computation and its piece, as messages name them ("Monte Carlo
        study", "chunk").
    stale : glob patterns of an older format's pieces, removed on a fresh start.

    Use::

        with ck.locked(resume, run="Monte Carlo run"):
            todo = ck.todo(pieces)            # rejected pieces named and moved aside
            for piece in todo:
                ck.save(piece, compute(piece))
            parts = [ck.load(piece) for piece in pieces]
    """

    folder: Path
    spec_key: str
    shapes_of: ShapesFn
    prefix: str = TILE_PREFIX
    digits: int = TILE_DIGITS
    spec_name: str = SPEC_NAME
    what: str = "map"
    noun: str = "tile"
    stale: tuple[str, ...] = ()

    def path(self, rows: tuple[int, int]) -> Path:
        return piece_path(self.folder, rows, self.prefix, self.digits)

    @contextlib.contextmanager
    def locked(self, resume: bool, run: str | None = None) -> Iterator[Checkpoint]:
        """Lock the folder and prepare it (see :func:`prepare_folder`) for the block;
        ``run`` names the kind of run in the lock message (default ``what``)."""
        with lock_folder(self.folder, run or self.what):
            prepare_folder(self.folder, self.spec_key, resume, prefix=self.prefix,
                           spec_name=self.spec_name, what=self.what, stale=self.stale)
            yield self

    def check(self, rows: tuple[int, int]) -> TileCheck:
        return check_piece(self.path(rows), rows, self.spec_key, self.shapes_of(rows),
                           self.what)

    def todo(self, pieces: Iterable[tuple[int, int]]) -> list[tuple[int, int]]:
        """The pieces not yet (validly) computed; rejected ones are warned about and moved
        aside."""
        return usable_pieces(pieces, self.path, self.spec_key, self.shapes_of, self.what,
                             self.noun)[0]

    def save(self, rows: tuple[int, int], data: Mapping[str, np.ndarray]) -> Path:
        return save_piece(self.path(rows), rows, data, self.spec_key)

    def load(self, rows: tuple[int, int]) -> dict[str, np.ndarray]:
        return load_piece(self.path(rows))


def tile_checkpoint(folder: Path, spec_key: str, variables: Iterable[str], nx: int
                    ) -> Checkpoint:
    """The checkpoint of a tiled job in ``folder`` with the map's layout (``tile_*.npz``,
    ``spec.json``): every variable of ``variables`` of shape (rows, ``nx``)."""
    return Checkpoint(Path(folder), spec_key, tile_shapes(variables, nx))
