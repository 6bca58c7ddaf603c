"""Saved branch files: their kinds and errors, the marks a restart needs (:func:`stamp`),
opening a file and telling its kind (:func:`open_saved`, :func:`file_kind`,
:func:`expect_kind`), the checks every kind shares, and the saved parameter values of a
restart point (:func:`saved_values`, :func:`saved_params`).

A saved branch is a netCDF file (``cycles --out``, ``hopf-curve --out``, or
:func:`save_equilibrium_branch`). Each carries, besides its data, what a restart needs and
what a reader needs to trust it: the kind of file (attribute ``maglev_match_file``), the
command that wrote it (``maglev_match_command``), the model (``model``), its state and
parameter names (coordinates ``state`` and ``parameter``) and the full parameter vector.
:func:`stamp` adds these on writing.

Loading is validation first: the file must be readable netCDF of the right kind, for a
model with the caller's states and parameter names, with the variables and shapes a
restart uses, finite states and a positive period at the chosen point, and attributes
that agree with the data (the continuation parameter's value at the Hopf point is the
saved parameter vector's entry). Every problem is one :class:`RestartFileError` naming the
file and what is wrong; nothing of a file that fails a check is used. Files written before
the kind attributes existed are recognised by their variables (:func:`file_kind`). Each
kind's loader (:mod:`~maglev_match.analyses.restart.cycles`,
:mod:`~maglev_match.analyses.restart.hopf_curve`,
:mod:`~maglev_match.analyses.restart.equilibria`) is built from the checks here: a variable
with its dimensions (:func:`variable`), the state and parameter names
(:func:`saved_names`), attributes (:func:`attr_text`, :func:`attr_number`,
:func:`attr_int`), the saved model against the caller's (:func:`check_saved_model`),
finite values (:func:`require_finite`) and the labels on offer (:func:`label_error`).
"""

from __future__ import annotations

import json
import math
import stat
import warnings
from collections.abc import Sequence
from enum import StrEnum
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "FILE_ATTR", "COMMAND_ATTR", "MODEL_ATTR", "SAME",
    "RestartKind", "RestartFileError", "RestartLabelError", "RestartMismatch", "stamp",
    "open_saved", "file_kind", "expect_kind", "variable", "saved_names", "attr_text",
    "attr_number", "attr_int", "check_saved_model", "require_finite", "label_error",
    "saved_values", "saved_params",
]

FILE_ATTR = "maglev_match_file"
COMMAND_ATTR = "maglev_match_command"
MODEL_ATTR = "model"
#: relative agreement asked of two stored copies of the same number (a float64 written
#: and read back is exact; this only allows for values recomputed through a sum)
SAME = 1e-12


class RestartKind(StrEnum):
    """What a saved file holds."""

    CYCLE_BRANCH = "cycle-branch"
    HOPF_CURVE = "hopf-curve"
    EQUILIBRIUM_BRANCH = "equilibrium-branch"


_WRITER = {RestartKind.CYCLE_BRANCH: "'maglev-match cycles --out'",
           RestartKind.HOPF_CURVE: "'maglev-match hopf-curve --out'",
           RestartKind.EQUILIBRIUM_BRANCH: "save_equilibrium_branch"}
_NOUN = {RestartKind.CYCLE_BRANCH: "saved cycle branch",
         RestartKind.HOPF_CURVE: "saved Hopf curve",
         RestartKind.EQUILIBRIUM_BRANCH: "saved equilibrium branch"}


class RestartFileError(ValueError):
    """A restart file that cannot be used; the message is one line naming the file and
    what is wrong with it."""

    def __init__(self, path: str | Path, problem: str):
        self.path = str(path)
        self.problem = problem
        super().__init__(f"restart file {self.path}: {problem}")


class RestartLabelError(RestartFileError):
    """The asked point is not in the saved file (the message lists the labels on offer)."""

    def __init__(self, path: str | Path, label: str, problem: str):
        self.label = label
        super().__init__(path, problem)


class RestartMismatch(ValueError):
    """Parameter values given for a restart that differ from the saved branch's."""

    def __init__(self, path: str | Path, differences: Sequence[tuple[str, float, float]]):
        self.path = str(path)
        self.differences = tuple(differences)
        shown = ", ".join(f"{n} = {given:.10g} given, {saved:.10g} saved"
                          for n, given, saved in self.differences[:4])
        more = f" and {len(self.differences) - 4} more" if len(self.differences) > 4 else ""
        super().__init__(
            f"the restart continues the branch saved in {self.path} at its own parameter "
            f"values, and these differ: {shown}{more}; give the values it was saved with "
            "(or no parameter options: the saved ones are used), or start a new branch "
            "without --restart")


# ---------------------------------------------------------------------------------------
# writing
# ---------------------------------------------------------------------------------------
def stamp(ds: Any, kind: RestartKind | str, system: Any, model: str, command: str) -> Any:
    """Mark a dataset as a restartable file of ``kind``: its kind, the writing command,
    the model label ('unit', 'vehicle' or a model file's stem), the number of states and
    the state and parameter names (as coordinates when absent). Returns ``ds``."""
    kind = RestartKind(kind)
    ds.attrs[FILE_ATTR] = str(kind)
    ds.attrs[COMMAND_ATTR] = command
    ds.attrs[MODEL_ATTR] = model
    ds.attrs["n_states"] = int(system.dim)
    if "state" not in ds.coords:
        ds.coords["state"] = ("state", list(system.state_names),
                              {"units": "1", "long_name": "state name"})
    if "parameter" not in ds.coords:
        ds.coords["parameter"] = ("parameter", list(system.param_names),
                                  {"units": "1", "long_name": "parameter name"})
    return ds


# ---------------------------------------------------------------------------------------
# reading: the file, its kind
# ---------------------------------------------------------------------------------------
def open_saved(source: Any) -> tuple[Any, str]:
    """The dataset of ``source`` (a path or an xarray Dataset) and the name messages use.
    A path that is missing, not a regular file or not netCDF is a :class:`RestartFileError`."""
    import xarray as xr

    if isinstance(source, xr.Dataset):
        return source, "(dataset)"
    path = Path(source)
    try:
        mode = path.stat().st_mode
    except FileNotFoundError:
        raise RestartFileError(path, "no such file") from None
    except OSError as exc:
        raise RestartFileError(path, f"cannot be read ({exc.strerror or exc})") from None
    if stat.S_ISDIR(mode):
        raise RestartFileError(path, "is a directory, not a saved branch file")
    if not stat.S_ISREG(mode):
        raise RestartFileError(path, "is not a regular file (a FIFO or a device?); give the "
                               "netCDF file itself")
    try:
        with open(path, "rb") as fh:
            head = fh.read(8)
    except OSError as exc:
        raise RestartFileError(path, f"cannot be read ({exc.strerror or exc})") from None
    if not head.startswith(b"\x89HDF\r\n\x1a\n") and not head.startswith(b"CDF"):
        raise RestartFileError(path, "is not a netCDF file (a saved branch is the .nc file "
                               "written by --out)")
    try:
        with warnings.catch_warnings():  # (h5netcdf's note on an HDF5 file that is not
            warnings.simplefilter("ignore", UserWarning)  # netCDF: judged below instead)
            ds = xr.load_dataset(path, engine="h5netcdf", phony_dims="sort")
    except Exception as exc:  # h5py/h5netcdf/xarray raise many types for damaged files
        detail = " ".join(str(exc).split())[:120]
        raise RestartFileError(path, f"cannot be read as netCDF ({type(exc).__name__}: "
                               f"{detail})") from None
    return ds, str(path)


def file_kind(ds: Any) -> tuple[RestartKind | None, str]:
    """The kind of a saved file and a description of what it is (for messages): from the
    ``maglev_match_file`` attribute, or, for older files, from its variables."""
    attr = ds.attrs.get(FILE_ATTR)
    if isinstance(attr, str) and attr in tuple(RestartKind):
        return RestartKind(attr), _NOUN[RestartKind(attr)]
    names = set(ds.variables)
    if {"r_period", "r_states", "hopf_x"} & names and "label" in ds.coords:
        return RestartKind.CYCLE_BRANCH, _NOUN[RestartKind.CYCLE_BRANCH]
    if {"frequency", "l1", "equilibrium"} <= names and "others_stable" in names:
        return RestartKind.HOPF_CURVE, _NOUN[RestartKind.HOPF_CURVE]
    if "chi" in names and "stable" in names:
        return None, "a design map (written by 'maglev-match map')"
    if "eigenvalue_real" in names:
        return None, "a root locus"
    if "time" in ds.dims or "gap_deviation" in names:
        return None, "a simulation history (written by 'maglev-match simulate')"
    return None, "a netCDF file that maglev-match did not write as a branch"


def expect_kind(ds: Any, where: str, kind: RestartKind) -> None:
    found, what = file_kind(ds)
    if found is not kind:
        raise RestartFileError(where, f"not a {_NOUN[kind]} (it is {what}); give the .nc "
                               f"file written by {_WRITER[kind]}")


# ---------------------------------------------------------------------------------------
# reading: checks shared by every kind
# ---------------------------------------------------------------------------------------
def variable(ds: Any, where: str, name: str, dims: tuple[str, ...]) -> np.ndarray:
    """The values of variable ``name`` with exactly ``dims``, as a float array."""
    if name not in ds.variables:
        raise RestartFileError(where, f"lacks the variable '{name}' (damaged or not written "
                               "by maglev-match)")
    v = ds[name]
    if tuple(v.dims) != tuple(dims):
        raise RestartFileError(where, f"variable '{name}' has dimensions {tuple(v.dims)}, "
                               f"expected {dims}")
    try:
        return np.asarray(v.values, dtype=float)
    except (TypeError, ValueError):
        raise RestartFileError(where, f"variable '{name}' does not hold numbers") from None


def saved_names(ds: Any, where: str, coord: str) -> list[str]:
    if coord not in ds.coords or ds[coord].ndim != 1:
        raise RestartFileError(where, f"lacks the coordinate '{coord}' (the model's "
                               f"{coord} names)")
    return [str(v) for v in ds[coord].values]


def attr_text(ds: Any, where: str, name: str) -> str:
    v = ds.attrs.get(name)
    if not isinstance(v, str) or not v:
        raise RestartFileError(where, f"attribute '{name}' is missing or not a name "
                               f"(got {v!r})"[:200])
    return v


def attr_number(ds: Any, where: str, name: str, *, allow_nan: bool = False) -> float:
    v = ds.attrs.get(name)
    try:
        x = float(np.asarray(v).item()) if v is not None else None
    except (TypeError, ValueError):
        x = None
    if x is None or (not math.isfinite(x) and not (allow_nan and math.isnan(x))):
        raise RestartFileError(where, f"attribute '{name}' is missing or not a finite number "
                               f"(got {v!r})"[:200])
    return x


def attr_int(ds: Any, where: str, name: str) -> int | None:
    """An optional whole-number attribute (None when absent)."""
    if name not in ds.attrs:
        return None
    v = ds.attrs[name]
    try:
        x = float(np.asarray(v).item())
    except (TypeError, ValueError):
        x = math.nan
    if not (math.isfinite(x) and x.is_integer()) or isinstance(v, str | bool):
        raise RestartFileError(where, f"attribute '{name}' = {v!r} is not a whole number"[:200])
    return int(x)


def check_saved_model(ds: Any, where: str, system: Any, states: list[str],
                      params: list[str]) -> None:
    """The saved model's state and parameter names must be the caller's."""
    n_attr = attr_int(ds, where, "n_states")
    if n_attr is not None and n_attr != len(states):
        raise RestartFileError(where, f"attribute n_states = {n_attr} but {len(states)} state "
                               "names: the file was edited or damaged")
    if system is None:
        return
    model = ds.attrs.get(MODEL_ATTR)
    saved = f"model '{model}'" if isinstance(model, str) else "a model"
    mine = f"model '{getattr(system, 'name', '') or '?'}'"
    if list(states) != list(system.state_names):
        raise RestartFileError(
            where, f"saved for {saved} with {len(states)} states "
                   f"({', '.join(states[:4])}{', ...' if len(states) > 4 else ''}), not for "
                   f"{mine} with {system.dim} states; restart with the model that saved it")
    if list(params) != list(system.param_names):
        extra = sorted(set(params) - set(system.param_names))
        missing = sorted(set(system.param_names) - set(params))
        raise RestartFileError(
            where, f"saved for {saved} whose parameters differ from {mine}'s"
                   + (f" (saved only: {', '.join(extra[:5])})" if extra else "")
                   + (f" (missing: {', '.join(missing[:5])})" if missing else "")
                   + "; restart with the model that saved it")


def require_finite(where: str, what: str, arr: np.ndarray) -> np.ndarray:
    if not np.all(np.isfinite(arr)):
        raise RestartFileError(where, f"{what}: {int(np.sum(~np.isfinite(arr)))} of "
                               f"{arr.size} values are NaN or infinite (they must be finite)")
    return arr


def label_error(where: str, label: str, labels: list[str], specials: list[str],
                what: str) -> RestartFileError:
    shown = labels[:3] + (["..."] if len(labels) > 4 else []) + labels[3:][-1:]
    offer = ", ".join(shown + specials) or "none"
    return RestartLabelError(where, label, f"no point '{label}' in the {what}; it has: "
                             f"{offer}")


# ---------------------------------------------------------------------------------------
# the saved values at a restart point (any kind)
# ---------------------------------------------------------------------------------------
def saved_values(restart: Any) -> dict[str, float]:
    """The saved parameter values at the restart point, name -> value (a
    :class:`CycleRestart`, :class:`HopfCurveRestart` or :class:`EquilibriumRestart`)."""
    return dict(zip(restart.parameter_names, (float(v) for v in restart.p), strict=True))


def saved_params(restart: Any) -> Any:
    """The saved maglev parameter set (:class:`~maglev_match.core.params.Params`) of a branch of
    model A or B, rebuilt from the file's ``params`` attribute, or None (a user model, or a
    file without it). A set that no longer validates is a :class:`RestartFileError`."""
    if getattr(restart, "params_json", None) is None:
        return None
    from maglev_match.core.params import FIELD_NAMES, ParameterError, make_params

    try:
        values = json.loads(restart.params_json)
        return make_params({k: v for k, v in values.items() if k in FIELD_NAMES})
    except (ValueError, TypeError, AttributeError, ParameterError) as exc:
        raise RestartFileError(restart.path, f"its parameter set (attribute params) is not "
                               f"valid: {' '.join(str(exc).split())[:160]}") from None
