"""Exceptions and warnings that the command line must recognise without importing JAX.

The command line catches these by class; the modules that raise them (the user-model loader,
the JAX set-up) import JAX, so the classes live here, in a module that imports nothing heavy.

* :class:`ModelFileError` — a user model file that cannot be used (exit code 2);
* :class:`EnvironmentProblem` — the process environment makes the computation impossible,
  e.g. ``JAX_PLATFORMS`` names a platform this machine does not have (exit code 2);
* :class:`EnvironmentWarning` — the environment costs something but the command goes on,
  e.g. a compilation cache folder that cannot be written.
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["ModelFileError", "EnvironmentProblem", "EnvironmentWarning"]


class ModelFileError(ValueError):
    """A user model file that cannot be used; the message is one line naming the file."""

    def __init__(self, path: str | Path, problem: str):
        self.path = str(path)
        self.problem = problem
        super().__init__(f"model file {self.path}: {problem}")


class EnvironmentProblem(RuntimeError):
    """An environment variable (or the terminal) makes the run impossible; the message
    names the variable, its value and what to do."""

    def __init__(self, variable: str, value: str, problem: str, remedy: str):
        self.variable = variable
        self.value = value
        super().__init__(f"{variable}={value}: {problem}; {remedy}")


class EnvironmentWarning(UserWarning):
    """Something in the environment costs speed or convenience; the run goes on."""
