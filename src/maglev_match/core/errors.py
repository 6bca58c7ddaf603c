"""Exceptions and warnings that the command line must recognise without importing JAX.

The command line catches these by class; the modules that raise them (the user-model loader)
import JAX, so the classes live here, in a module that imports nothing heavy.

* :class:`ModelFileError` — a user model file that cannot be used (exit code 2).
* :class:`CheckpointLocked` — a checkpoint folder in use by another run (exit code 2).
* :class:`MapStopped` — a map stopped before all tiles were computed (its own exit code).
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["CheckpointLocked", "MapStopped", "ModelFileError"]


class ModelFileError(ValueError):
    """A user model file that cannot be used; the message is one line naming the file."""

    def __init__(self, path: str | Path, problem: str):
        self.path = str(path)
        self.problem = problem
        super().__init__(f"model file {self.path}: {problem}")


class CheckpointLocked(RuntimeError):
    """Another process holds the checkpoint folder's lock."""

    def __init__(self, folder: Path, holder: str, what: str = "map"):
        self.folder = folder
        self.holder = holder
        super().__init__(
            f"the checkpoint folder {folder} is in use by another {what} ({holder}); wait "
            "for it to finish or choose another --out"
        )


class MapStopped(RuntimeError):
    """A map stopped before all tiles were computed (interrupt, lost scheduler). Carries the
    exit code the command line should use (130 for an interrupt) and the resume hint."""

    def __init__(self, message: str, exit_code: int = 1):
        self.exit_code = exit_code
        super().__init__(message)
