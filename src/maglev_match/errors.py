"""Exceptions and warnings that the command line must recognise without importing JAX.

The command line catches these by class; the modules that raise them (the user-model loader)
import JAX, so the classes live here, in a module that imports nothing heavy.

* :class:`ModelFileError` — a user model file that cannot be used (exit code 2).
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["ModelFileError"]


class ModelFileError(ValueError):
    """A user model file that cannot be used; the message is one line naming the file."""

    def __init__(self, path: str | Path, problem: str):
        self.path = str(path)
        self.problem = problem
        super().__init__(f"model file {self.path}: {problem}")
