"""Restart from saved branches: cycle branches, Hopf curves and equilibrium branches.

A saved branch is a netCDF file (``cycles --out``, ``hopf-curve --out``, or
:func:`save_equilibrium_branch`). Each carries, besides its data, what a restart needs and
what a reader needs to trust it: the kind of file (attribute ``maglev_match_file``), the
command that wrote it (``maglev_match_command``), the model (``model``), its state and
parameter names (coordinates ``state`` and ``parameter``) and the full parameter vector.
:func:`stamp` adds these on writing.

Loading is validation first (:func:`load_cycle_restart`, :func:`load_hopf_curve_restart`,
:func:`load_equilibrium_restart`): the file must be readable netCDF of the right kind, for a
model with the caller's states and parameter names, with the variables and shapes a
restart uses, finite states and a positive period at the chosen point, and attributes
that agree with the data (the continuation parameter's value at the Hopf point is the
saved parameter vector's entry). Every problem is one :class:`RestartFileError` naming the
file and what is wrong; nothing of a file that fails a check is used. Files written before
the kind attributes existed are recognised by their variables.

A restart continues the saved branch at the saved parameter values. A caller that also
gives parameter values (``--set``/``--at``) must give the saved ones (all but the
continuation parameter), else :func:`check_parameters` refuses with the differences: the
saved orbit belongs to those values, and continuing it under others would answer for
another system.

The library functions :func:`restart_cycle_branch`, :func:`restart_hopf_curve` and
:func:`restart_equilibrium_branch` load, check and continue in one call; their results name
the restart point and file. :func:`restart` is the one entry point for the Python API: it
reads the kind of file and, without a system, the model and values it was saved with.
"""

from __future__ import annotations

import json
import math
import stat
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path
from typing import Any

import numpy as np

from maglev_match.maglev.catalog import MODEL_NAMES

__all__ = [
    "RestartKind", "RestartFileError", "RestartLabelError", "RestartMismatch", "stamp",
    "open_saved",
    "file_kind", "CycleRestart", "load_cycle_restart", "check_parameters",
    "RestartedCycleBranch", "restart_cycle_branch", "saved_values", "saved_params",
    "HopfCurveRestart", "load_hopf_curve_restart", "restart_hopf_curve",
    "equilibrium_branch_dataset", "save_equilibrium_branch", "EquilibriumRestart",
    "load_equilibrium_restart", "restart_equilibrium_branch", "saved_system", "restart",
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
        ds = xr.load_dataset(path, engine="h5netcdf")
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


def _expect_kind(ds: Any, where: str, kind: RestartKind) -> None:
    found, what = file_kind(ds)
    if found is not kind:
        raise RestartFileError(where, f"not a {_NOUN[kind]} (it is {what}); give the .nc "
                               f"file written by {_WRITER[kind]}")


# ---------------------------------------------------------------------------------------
# reading: checks shared by every kind
# ---------------------------------------------------------------------------------------
def _var(ds: Any, where: str, name: str, dims: tuple[str, ...]) -> np.ndarray:
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


def _names(ds: Any, where: str, coord: str) -> list[str]:
    if coord not in ds.coords or ds[coord].ndim != 1:
        raise RestartFileError(where, f"lacks the coordinate '{coord}' (the model's "
                               f"{coord} names)")
    return [str(v) for v in ds[coord].values]


def _attr_text(ds: Any, where: str, name: str) -> str:
    v = ds.attrs.get(name)
    if not isinstance(v, str) or not v:
        raise RestartFileError(where, f"attribute '{name}' is missing or not a name "
                               f"(got {v!r})"[:200])
    return v


def _attr_number(ds: Any, where: str, name: str, *, allow_nan: bool = False) -> float:
    v = ds.attrs.get(name)
    try:
        x = float(np.asarray(v).item()) if v is not None else None
    except (TypeError, ValueError):
        x = None
    if x is None or (not math.isfinite(x) and not (allow_nan and math.isnan(x))):
        raise RestartFileError(where, f"attribute '{name}' is missing or not a finite number "
                               f"(got {v!r})"[:200])
    return x


def _attr_int(ds: Any, where: str, name: str) -> int | None:
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


def _check_model(ds: Any, where: str, system: Any, states: list[str],
                 params: list[str]) -> None:
    """The saved model's state and parameter names must be the caller's."""
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


def _finite(where: str, what: str, arr: np.ndarray) -> np.ndarray:
    if not np.all(np.isfinite(arr)):
        raise RestartFileError(where, f"{what}: {int(np.sum(~np.isfinite(arr)))} of "
                               f"{arr.size} values are NaN or infinite (they must be finite)")
    return arr


def _label_error(where: str, label: str, labels: list[str], specials: list[str],
                 what: str) -> RestartFileError:
    shown = labels[:3] + (["..."] if len(labels) > 4 else []) + labels[3:][-1:]
    offer = ", ".join(shown + specials) or "none"
    return RestartLabelError(where, label, f"no point '{label}' in the {what}; it has: "
                             f"{offer}")


# ---------------------------------------------------------------------------------------
# cycle branches
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class CycleRestart:
    """A validated restart point of a saved cycle branch.

    path, label : the file and the point (P<k> or a special point's label).
    param : the parameter the saved branch was continued in.
    start : the branch's Hopf start (:class:`~maglev_match.dynamics.cycles.HopfStart`).
    state : the continuation state at the point
        (:class:`~maglev_match.dynamics.cycles.RestartState`).
    parameter_names : the saved model's parameter names; ``p`` the full parameter vector at
        the restart point (the Hopf point's with ``param`` = the point's value).
    model : the saved model label ('' for files from before it was stored).
    branch_values, branch_periods, branch_stable : the saved branch points (NaN where a
        point has no value), for drawing the saved part.
    branch_mesh, branch_profiles, ncol : the saved points' orbits (mesh, nodes x states).
    params_json : the saved maglev parameter set (attribute ``params``), or None.
    """

    path: str
    label: str
    param: str
    start: Any
    state: Any
    parameter_names: tuple[str, ...]
    p: np.ndarray
    model: str
    branch_values: np.ndarray
    branch_periods: np.ndarray
    branch_stable: np.ndarray
    branch_mesh: np.ndarray
    branch_profiles: np.ndarray
    ncol: int
    params_json: str | None = None

    @property
    def value(self) -> float:
        """The continuation parameter at the restart point."""
        return float(self.state.value)

    @property
    def period(self) -> float:
        return float(self.state.period)

    def describe(self) -> str:
        """One line for headers: point, file, where it is and where its branch began."""
        return (f"restart from {self.label} of {self.path}: {self.param} = {self.value:.8g}, "
                f"period {self.period:.6g} s (branch born at the Hopf point {self.param} = "
                f"{self.start.value:.8g})")

    def saved_orbits(self) -> list[tuple[int, Any]]:
        """The saved branch points with a usable orbit, as (index, PeriodicOrbit)."""
        from maglev_match.dynamics.cycles import PeriodicOrbit

        out = []
        ip = list(self.parameter_names).index(self.param)
        for k, v in enumerate(self.branch_values):
            mesh, prof, T = self.branch_mesh[k], self.branch_profiles[k], self.branch_periods[k]
            if not (np.isfinite(v) and np.isfinite(T) and T > 0 and np.all(np.isfinite(mesh))
                    and np.all(np.isfinite(prof))):
                continue
            p = np.array(self.p, float)
            p[ip] = v
            out.append((k, PeriodicOrbit(mesh=mesh, ncol=self.ncol, states=prof, period=T,
                                         p=p)))
        return out


def load_cycle_restart(source: Any, label: str, system: Any = None) -> CycleRestart:
    """Validate a saved cycle branch and read the restart point ``label``.

    Parameters
    ----------
    source : the .nc file (path) or its Dataset.
    label : 'P<k>' (the k-th branch point) or a special point's label (LPC1, PD1, ...).
    system : the model to restart with (its state and parameter names must be the saved
        ones); None skips that check.

    Raises
    ------
    RestartFileError : one line naming the file and the problem.
    """
    from maglev_match.dynamics.cycles import HopfStart, RestartState

    ds, where = open_saved(source)
    _expect_kind(ds, where, RestartKind.CYCLE_BRANCH)
    states = _names(ds, where, "state")
    params = _names(ds, where, "parameter")
    n = len(states)
    if n == 0:
        raise RestartFileError(where, "has no states")
    n_attr = _attr_int(ds, where, "n_states")
    if n_attr is not None and n_attr != n:
        raise RestartFileError(where, f"attribute n_states = {n_attr} but {n} state names")
    _check_model(ds, where, system, states, params)
    param = _attr_text(ds, where, "param")
    if param not in params:
        raise RestartFileError(where, f"attribute param = '{param}' names no parameter of the "
                               f"saved model (it has {', '.join(params[:8])}"
                               f"{', ...' if len(params) > 8 else ''})")
    hopf_value = _attr_number(ds, where, "hopf_value")
    freq = _attr_number(ds, where, "hopf_frequency")
    if not freq > 0:
        raise RestartFileError(where, f"attribute hopf_frequency = {freq:g} must be > 0 rad/s")
    l1 = _attr_number(ds, where, "hopf_l1", allow_nan=True)
    hx = _finite(where, "hopf_x (the equilibrium at the Hopf point)",
                 _var(ds, where, "hopf_x", ("state",)))
    q = (_var(ds, where, "hopf_q_re", ("state",))
         + 1j * _var(ds, where, "hopf_q_im", ("state",)))
    _finite(where, "the Hopf eigenvector (hopf_q_re, hopf_q_im)", np.abs(q))
    if not np.linalg.norm(q) > 0:
        raise RestartFileError(where, "the Hopf eigenvector (hopf_q_re, hopf_q_im) is zero")
    hp = _finite(where, "hopf_p (the parameters at the Hopf point)",
                 _var(ds, where, "hopf_p", ("parameter",)))
    ip = params.index(param)
    if abs(hp[ip] - hopf_value) > SAME * max(1.0, abs(hopf_value)):
        raise RestartFileError(where, f"inconsistent: attribute param = '{param}' with "
                               f"hopf_value = {hopf_value:.10g}, but the saved parameters have "
                               f"{param} = {hp[ip]:.10g} at the Hopf point")
    labels = [str(v) for v in ds["label"].values] if "label" in ds.coords else []
    specials = ([str(v) for v in ds["special_label"].values]
                if "special_label" in ds.coords else [])
    if label in labels:
        k, pre, dim = labels.index(label), "", "point"
    elif label in specials:
        k, pre, dim = specials.index(label), "special_", "special"
    else:
        raise _label_error(where, label, labels, specials, "saved branch")
    mesh_all = _var(ds, where, pre + "r_mesh", (dim, "mesh_node"))
    st_all = _var(ds, where, pre + "r_states", (dim, "node", "state"))
    tst_all = _var(ds, where, pre + "r_t_states", (dim, "node", "state"))
    scalars = {name: _var(ds, where, pre + name, (dim,))
               for name in ("r_period", "r_value", "r_t_period", "r_t_value", "r_ds",
                            "r_accepted")}
    npts = mesh_all.shape[0]
    if any(a.shape[0] != npts for a in (st_all, tst_all, *scalars.values())):
        raise RestartFileError(where, "the restart variables have different numbers of points")
    ntst = mesh_all.shape[1] - 1
    if ntst < 1:
        raise RestartFileError(where, "the restart mesh has no interval")
    nodes = st_all.shape[1]
    if (nodes - 1) % ntst or not 2 <= (nodes - 1) // ntst <= 7:
        raise RestartFileError(where, f"{nodes} profile nodes do not fit a mesh of {ntst} "
                               "intervals with 2 to 7 collocation points each")
    ncol = (nodes - 1) // ntst
    for name, attr in (("ntst", ntst), ("ncol", ncol)):
        v = _attr_int(ds, where, name)
        if v is not None and v != attr:
            raise RestartFileError(where, f"attribute {name} = {v} but the restart data "
                                   f"have {name} = {attr}")
    if st_all.shape[2] != n or tst_all.shape[1:] != st_all.shape[1:]:
        raise RestartFileError(where, f"the saved profiles have {st_all.shape[2]} states, "
                               f"the file names {n}")
    T = float(scalars["r_period"][k])
    if math.isnan(T) and np.all(np.isnan(st_all[k])):
        raise RestartFileError(where, f"point '{label}' has no restart data (a located end "
                               "point of the branch); choose a P<k> point before it")
    if not (math.isfinite(T) and T > 0):
        raise RestartFileError(where, f"the period at '{label}' is {T:g} s: it must be a "
                               "finite number > 0")
    mesh = _finite(where, f"the mesh at '{label}'", mesh_all[k])
    if not (abs(mesh[0]) <= 1e-12 and abs(mesh[-1] - 1.0) <= 1e-12
            and np.all(np.diff(mesh) > 0)):
        raise RestartFileError(where, f"the mesh at '{label}' does not increase from 0 to 1")
    states_k = _finite(where, f"the cycle states at '{label}'", st_all[k])
    t_states = _finite(where, f"the tangent at '{label}'", tst_all[k])
    vals = {name: float(a[k]) for name, a in scalars.items()}
    for name, v in vals.items():
        if not math.isfinite(v):
            raise RestartFileError(where, f"{pre}{name} at '{label}' is not finite")
    if not vals["r_ds"] > 0:
        raise RestartFileError(where, f"the step r_ds at '{label}' is {vals['r_ds']:g}: it "
                               "must be > 0")
    acc = vals["r_accepted"]
    if acc < 0 or not float(acc).is_integer():
        raise RestartFileError(where, f"r_accepted at '{label}' is {acc:g}: it must be a "
                               "whole number >= 0")
    state = RestartState(mesh=mesh, states=states_k, period=T, value=vals["r_value"],
                         t_states=t_states, t_period=vals["r_t_period"],
                         t_value=vals["r_t_value"], ds=vals["r_ds"], accepted=int(acc))
    start = HopfStart(param=param, value=hopf_value, x=hx, p=hp, frequency=freq, q=q,
                      l1=None if math.isnan(l1) else l1)
    p_here = np.array(hp, float)
    p_here[ip] = vals["r_value"]
    # the saved branch points (for drawing), tolerant: a display never blocks a restart
    bv = np.full(0, np.nan)
    bT, bs, bmesh, bprof = bv, np.zeros(0, bool), np.zeros((0, ntst + 1)), np.zeros((0, 1, n))
    try:
        bv = np.asarray(ds["value"].values, float).reshape(-1)
        bT = np.asarray(ds["period"].values, float).reshape(-1)
        bs = np.asarray(ds["stable"].values).astype(bool).reshape(-1)
        bmesh = np.asarray(ds["mesh"].values, float)
        bprof = np.asarray(ds["profile"].values, float)
        if not (bv.shape == bT.shape == bs.shape and bmesh.shape[0] == bv.size
                and bprof.shape[0] == bv.size and bprof.ndim == 3 and bprof.shape[2] == n):
            raise ValueError("shapes")
    except (KeyError, ValueError, TypeError):
        bv = np.full(0, np.nan)
        bT, bs, bmesh, bprof = bv, np.zeros(0, bool), np.zeros((0, ntst + 1)), \
            np.zeros((0, 1, n))
    pj = ds.attrs.get("params")
    model = ds.attrs.get(MODEL_ATTR)
    return CycleRestart(path=where, label=label, param=param, start=start, state=state,
                        parameter_names=tuple(params), p=p_here,
                        model=model if isinstance(model, str) else "",
                        branch_values=bv, branch_periods=bT, branch_stable=bs,
                        branch_mesh=bmesh, branch_profiles=bprof,
                        ncol=ncol,
                        params_json=pj if isinstance(pj, str) and pj.startswith("{") else None)


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


def check_parameters(restart: CycleRestart, system: Any, param: str | None = None) -> None:
    """Refuse (:class:`RestartMismatch`) a ``system`` whose parameters differ from the saved
    ones anywhere but in the saved continuation parameter (which varies along the branch).
    ``param``: the parameter the restart continues in (when it is another one, the saved
    point's value of it is where the new branch starts, so it must agree too)."""
    diffs = []
    for k, name in enumerate(restart.parameter_names):
        if name == restart.param:
            continue
        given, saved = float(system.p[k]), float(restart.p[k])
        if abs(given - saved) > SAME * max(abs(saved), abs(given), 1e-300):
            diffs.append((name, given, saved))
    if diffs:
        raise RestartMismatch(restart.path, diffs)


@dataclass(frozen=True)
class RestartedCycleBranch:
    """A cycle branch continued from a saved point: the new points (after the restart
    point) and the validated restart they came from."""

    branch: Any
    restart: CycleRestart
    param: str

    def describe(self) -> str:
        base = self.restart.describe()
        if self.param != self.restart.param:
            base += f", continued in {self.param} from {self.param} = " \
                    f"{self.restart.p[list(self.restart.parameter_names).index(self.param)]:.8g}"
        return base


def restart_cycle_branch(source: Any, label: str, system: Any, param: str | None = None,
                         **options: Any) -> RestartedCycleBranch:
    """Continue a saved cycle branch from its point ``label``.

    Parameters
    ----------
    source : the .nc file written by ``cycles --out`` (or its Dataset).
    label : P<k> or a special point's label.
    system : the model; its state and parameter names must be the saved ones and its
        parameter values the saved ones (all but the continuation parameter), see
        :func:`check_parameters`.
    param : the parameter to continue in (default: the saved one; another one continues
        the saved cycle in that parameter, the others fixed at the point).
    options : passed to :func:`~maglev_match.dynamics.cycles.cycle_branch` (ntst and ncol
        are those of the saved mesh unless given).

    Returns
    -------
    :class:`RestartedCycleBranch`. No Hopf point is searched: the branch's Hopf start comes
    from the file.
    """
    from maglev_match.dynamics.cycles import cycle_branch

    rs = load_cycle_restart(source, label, system)
    param = rs.param if param is None else param
    if param not in rs.parameter_names:
        raise RestartFileError(rs.path, f"the model has no parameter '{param}' to continue in")
    check_parameters(rs, system, param)
    options.setdefault("ntst", rs.state.mesh.size - 1)
    options.setdefault("ncol", rs.ncol)
    br = cycle_branch(system, rs.start, param, restart=rs.state, restart_param=rs.param,
                      **options)
    return RestartedCycleBranch(branch=br, restart=rs, param=param)


# ---------------------------------------------------------------------------------------
# Hopf curves
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class HopfCurveRestart:
    """A validated point of a saved Hopf curve: the two curve parameters, their values, the
    equilibrium and frequency there, the full parameter vector and the saved bounds."""

    path: str
    label: str
    names: tuple[str, str]
    values: tuple[float, float]
    x: np.ndarray
    frequency: float
    p: np.ndarray
    parameter_names: tuple[str, ...]
    bounds: dict[str, tuple[float, float]]
    model: str
    params_json: str | None = None

    def describe(self) -> str:
        return (f"restart from {self.label} of {self.path}: {self.names[0]} = "
                f"{self.values[0]:.8g}, {self.names[1]} = {self.values[1]:.8g}, frequency "
                f"{self.frequency:.6g} rad/s")


def load_hopf_curve_restart(source: Any, label: str, system: Any = None) -> HopfCurveRestart:
    """Validate a saved Hopf curve and read the point ``label`` (P<k>, the k-th curve point,
    or a codimension-two point's label such as GH1: its equilibrium is taken from the
    nearest curve point and refined on restarting)."""
    ds, where = open_saved(source)
    _expect_kind(ds, where, RestartKind.HOPF_CURVE)
    states = _names(ds, where, "state")
    params = _names(ds, where, "parameter")
    _check_model(ds, where, system, states, params)
    text = ds.attrs.get("curve_params")
    if not isinstance(text, str):
        raise RestartFileError(where, "lacks the attribute curve_params (the two parameters "
                               "of the curve); it was written before restarts of Hopf curves "
                               "existed: compute the curve again with --out")
    names = tuple(t.strip() for t in text.split(","))
    if len(names) != 2 or names[0] == names[1] or not set(names) <= set(params):
        raise RestartFileError(where, f"attribute curve_params = '{text}' does not name two "
                               "parameters of the saved model")
    v1 = _var(ds, where, names[0], ("point",))
    v2 = _var(ds, where, names[1], ("point",))
    om = _var(ds, where, "frequency", ("point",))
    eq = _var(ds, where, "equilibrium", ("point", "state"))
    base = _finite(where, "base_p (the parameters of the curve)",
                   _var(ds, where, "base_p", ("parameter",)))
    if eq.shape[1] != len(states):
        raise RestartFileError(where, f"the saved equilibria have {eq.shape[1]} states, the "
                               f"file names {len(states)}")
    labels = [f"P{k}" for k in range(v1.size)]
    specials = ([str(v) for v in ds["special_label"].values]
                if "special_label" in ds.coords else [])
    if label in labels:
        k = labels.index(label)
        vals = (float(v1[k]), float(v2[k]))
        freq = float(om[k])
        x = eq[k]
    elif label in specials:
        j = specials.index(label)
        vals = (float(_var(ds, where, f"special_{names[0]}", ("special",))[j]),
                float(_var(ds, where, f"special_{names[1]}", ("special",))[j]))
        freq = float(_var(ds, where, "special_frequency", ("special",))[j])
        ok = np.isfinite(v1) & np.isfinite(v2) & np.all(np.isfinite(eq), axis=1)
        if not ok.any():
            raise RestartFileError(where, "has no finite curve point to take the equilibrium "
                                   "from")
        spans = np.array([np.ptp(v1[ok]) or 1.0, np.ptp(v2[ok]) or 1.0])
        d = np.hypot((v1 - vals[0]) / spans[0], (v2 - vals[1]) / spans[1])
        x = eq[int(np.nanargmin(np.where(ok, d, np.inf)))]
    else:
        raise _label_error(where, label, labels, specials, "saved Hopf curve")
    _finite(where, f"the curve point '{label}'", np.array(vals))
    _finite(where, f"the equilibrium at '{label}'", x)
    if not (math.isfinite(freq) and freq > 0):
        raise RestartFileError(where, f"the frequency at '{label}' is {freq:g}: a Hopf point "
                               "needs a finite frequency > 0 rad/s (a Bogdanov-Takens end "
                               "point cannot be restarted)")
    bounds = {}
    for nm in names:
        b = ds.attrs.get(f"bounds_{nm}")
        try:
            lo, hi = (float(t) for t in np.asarray(b, float).ravel())
        except (TypeError, ValueError):
            raise RestartFileError(where, f"attribute bounds_{nm} is missing or not two "
                                   "numbers") from None
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
            raise RestartFileError(where, f"attribute bounds_{nm} = [{lo:g}, {hi:g}] is not an "
                                   "increasing finite range")
        bounds[nm] = (lo, hi)
    p = np.array(base, float)
    p[params.index(names[0])], p[params.index(names[1])] = vals
    model = ds.attrs.get(MODEL_ATTR)
    pj = ds.attrs.get("params")
    return HopfCurveRestart(path=where, label=label, names=(names[0], names[1]), values=vals,
                            x=np.array(x, float), frequency=freq, p=p,
                            parameter_names=tuple(params), bounds=bounds,
                            model=model if isinstance(model, str) else "",
                            params_json=pj if isinstance(pj, str) and pj.startswith("{")
                            else None)


def restart_hopf_curve(source: Any, label: str, system: Any,
                       bounds: Mapping[str, tuple[float, float]] | None = None,
                       **options: Any) -> tuple[Any, HopfCurveRestart]:
    """Continue a saved Hopf curve from its point ``label`` (in both directions) inside
    ``bounds`` (default: the saved ones; wider bounds extend the curve). The saved point is
    refined on the Hopf defining system first (it must converge there); ``system``'s
    parameters other than the two curve parameters must be the saved ones.

    Returns (the :class:`~maglev_match.dynamics.hopf_curve.HopfCurve`, the restart)."""
    from maglev_match.dynamics.hopf import refine_hopf_point
    from maglev_match.dynamics.hopf_curve import hopf_curve

    rs = load_hopf_curve_restart(source, label, system)
    diffs = [(n, float(system.p[k]), float(rs.p[k]))
             for k, n in enumerate(rs.parameter_names) if n not in rs.names
             and abs(system.p[k] - rs.p[k]) > SAME * max(abs(rs.p[k]), abs(system.p[k]), 1e-300)]
    if diffs:
        raise RestartMismatch(rs.path, diffs)
    bnds = dict(rs.bounds if bounds is None else bounds)
    hp = refine_hopf_point(system, rs.names[0], rs.values[0], rs.x, rs.frequency, p=rs.p,
                           bounds=bnds.get(rs.names[0]))
    if not hp.converged:
        raise RestartFileError(rs.path, f"the saved point '{label}' does not converge to a "
                               f"Hopf point of this model ({hp.message or 'Newton failed'})")
    return hopf_curve(system, rs.names, hp, bnds, **options), rs


# ---------------------------------------------------------------------------------------
# equilibrium branches
# ---------------------------------------------------------------------------------------
def equilibrium_branch_dataset(branch: Any, system: Any, model: str = "",
                               param_unit: str = "", command: str = "api") -> Any:
    """An :class:`~maglev_match.dynamics.equilibria.EquilibriumBranch` as a restartable
    xarray Dataset: parameter values, equilibria, eigenvalues and stability per point
    (labels P0, P1, ...), the special points (LP, BP, H) with their labels, the parameter
    vector and the kind attributes (:func:`stamp`)."""
    import xarray as xr

    n = system.dim
    eig = np.asarray(branch.eigenvalues, complex).reshape(-1, n)
    sps = list(branch.special_points)
    data = {
        "value": (("point",), np.asarray(branch.values, float),
                  {"units": param_unit or "1", "long_name": f"{branch.param} on the branch"}),
        "equilibrium": (("point", "state"), np.asarray(branch.states, float).reshape(-1, n),
                        {"units": "state units", "long_name": "equilibrium state"}),
        "eigenvalue_real": (("point", "index"), eig.real,
                            {"units": "1/s", "long_name": "real part of the eigenvalue"}),
        "eigenvalue_imag": (("point", "index"), eig.imag,
                            {"units": "rad/s", "long_name": "imaginary part of the eigenvalue"}),
        "stable": (("point",), np.asarray(branch.stable, np.int8),
                   {"units": "1", "long_name": "1 if every eigenvalue has Re < 0"}),
        "p": (("parameter",), np.asarray(branch.p, float),
              {"units": "parameter units", "long_name": "parameter vector (the continued "
               "entry varies along the branch)"}),
        "special_value": (("special",), np.array([sp.value for sp in sps], float),
                          {"units": param_unit or "1", "long_name": f"{branch.param} there"}),
        "special_equilibrium": (("special", "state"),
                                np.array([sp.x for sp in sps], float).reshape(-1, n),
                                {"units": "state units", "long_name": "equilibrium there"}),
        "special_type": (("special",), np.array([str(sp.type) for sp in sps], object),
                         {"units": "1", "long_name": "LP, BP or H"}),
        "special_located": (("special",), np.array([sp.located for sp in sps], object),
                            {"units": "1", "long_name": "how it was located"}),
    }
    coords = {"label": ("point", [f"P{k}" for k in range(len(branch.values))],
                        {"units": "1", "long_name": "point label"}),
              "special_label": ("special", [sp.label for sp in sps],
                                {"units": "1", "long_name": "special point label"}),
              "index": ("index", np.arange(n), {"units": "1", "long_name": "eigenvalue "
                                                "number, largest real part first"})}
    ds = xr.Dataset(data, coords=coords, attrs={
        "param": branch.param, "stop_reason": str(branch.stop_reason),
        "title": f"branch of equilibria in {branch.param}"})
    return stamp(ds, RestartKind.EQUILIBRIUM_BRANCH, system, model, command)


def save_equilibrium_branch(branch: Any, system: Any, path: str | Path, model: str = "",
                            param_unit: str = "") -> Path:
    """Write :func:`equilibrium_branch_dataset` to ``path`` (netCDF, atomically)."""
    from maglev_match.core.io import atomic_write_netcdf

    return atomic_write_netcdf(path, equilibrium_branch_dataset(branch, system, model,
                                                                param_unit))


@dataclass(frozen=True)
class EquilibriumRestart:
    """A validated point of a saved equilibrium branch."""

    path: str
    label: str
    param: str
    value: float
    x: np.ndarray
    p: np.ndarray
    parameter_names: tuple[str, ...]
    model: str

    def describe(self) -> str:
        return (f"restart from {self.label} of {self.path}: {self.param} = "
                f"{self.value:.8g}")


def load_equilibrium_restart(source: Any, label: str, system: Any = None
                             ) -> EquilibriumRestart:
    """Validate a saved equilibrium branch and read the point ``label`` (P<k> or a special
    point's label such as H1 or LP1)."""
    ds, where = open_saved(source)
    _expect_kind(ds, where, RestartKind.EQUILIBRIUM_BRANCH)
    states = _names(ds, where, "state")
    params = _names(ds, where, "parameter")
    _check_model(ds, where, system, states, params)
    param = _attr_text(ds, where, "param")
    if param not in params:
        raise RestartFileError(where, f"attribute param = '{param}' names no parameter of the "
                               "saved model")
    p = _finite(where, "p (the parameter vector)", _var(ds, where, "p", ("parameter",)))
    labels = [str(v) for v in ds["label"].values] if "label" in ds.coords else []
    specials = ([str(v) for v in ds["special_label"].values]
                if "special_label" in ds.coords else [])
    if label in labels:
        k = labels.index(label)
        value = float(_var(ds, where, "value", ("point",))[k])
        x = _var(ds, where, "equilibrium", ("point", "state"))[k]
    elif label in specials:
        k = specials.index(label)
        value = float(_var(ds, where, "special_value", ("special",))[k])
        x = _var(ds, where, "special_equilibrium", ("special", "state"))[k]
    else:
        raise _label_error(where, label, labels, specials, "saved equilibrium branch")
    if x.shape != (len(states),):
        raise RestartFileError(where, f"the equilibrium at '{label}' has {x.size} states, the "
                               f"file names {len(states)}")
    _finite(where, f"the equilibrium at '{label}'", x)
    if not math.isfinite(value):
        raise RestartFileError(where, f"{param} at '{label}' is not finite")
    p = np.array(p, float)
    p[params.index(param)] = value
    model = ds.attrs.get(MODEL_ATTR)
    return EquilibriumRestart(path=where, label=label, param=param, value=value,
                              x=np.array(x, float), p=p, parameter_names=tuple(params),
                              model=model if isinstance(model, str) else "")


def restart_equilibrium_branch(source: Any, label: str, system: Any, stop: float,
                               **options: Any) -> tuple[Any, EquilibriumRestart]:
    """Continue a saved equilibrium branch from its point ``label`` towards ``stop`` (the
    parameter's value where to end), with LP, BP and Hopf points located on the way.
    ``system``'s other parameters must be the saved ones.

    Returns (the :class:`~maglev_match.dynamics.equilibria.EquilibriumBranch`, the
    restart)."""
    from maglev_match.dynamics.equilibria import equilibrium_branch

    rs = load_equilibrium_restart(source, label, system)
    if not math.isfinite(float(stop)) or float(stop) == rs.value:
        raise ValueError(f"stop = {stop!r}: must be a finite value other than the restart "
                         f"point's {rs.param} = {rs.value:g}")
    diffs = [(n, float(system.p[k]), float(rs.p[k]))
             for k, n in enumerate(rs.parameter_names) if n != rs.param
             and abs(system.p[k] - rs.p[k]) > SAME * max(abs(rs.p[k]), abs(system.p[k]), 1e-300)]
    if diffs:
        raise RestartMismatch(rs.path, diffs)
    return equilibrium_branch(system, rs.param, rs.value, float(stop), p=rs.p, x0=rs.x,
                              **options), rs


# ---------------------------------------------------------------------------------------
# one entry point (the Python API's restart)
# ---------------------------------------------------------------------------------------
_SAVED_P = {RestartKind.CYCLE_BRANCH: "hopf_p", RestartKind.HOPF_CURVE: "base_p",
            RestartKind.EQUILIBRIUM_BRANCH: "p"}


def saved_system(source: Any) -> tuple[Any, Any]:
    """The model a saved file was computed with, at its saved parameter values:
    (System, Params or None). Model A or B from the file's ``model`` and ``params``
    attributes; a user model from its ``model_file`` attribute (the file is loaded again).
    A file that names neither is a :class:`RestartFileError` (give the system yourself)."""
    import dataclasses

    ds, where = open_saved(source)
    kind, what = file_kind(ds)
    if kind is None:
        raise RestartFileError(where, f"not a saved branch (it is {what})")
    model = ds.attrs.get(MODEL_ATTR)
    pj = ds.attrs.get("params")
    if model in MODEL_NAMES and isinstance(pj, str):
        from maglev_match.core.params import FIELD_NAMES, ParameterError, make_params
        from maglev_match.maglev.models import build_system

        try:
            params = make_params({k: v for k, v in json.loads(pj).items()
                                  if k in FIELD_NAMES})
        except (ValueError, TypeError, AttributeError, ParameterError) as exc:
            raise RestartFileError(where, "its parameter set (attribute params) is not valid: "
                                   f"{' '.join(str(exc).split())[:160]}") from None
        return build_system(params, model), params
    mfile = ds.attrs.get("model_file")
    if isinstance(mfile, str) and mfile.endswith(".py"):
        from maglev_match.maglev.user import load_model

        system = load_model(mfile).system()
        names = _names(ds, where, "parameter")
        p = _finite(where, _SAVED_P[kind], _var(ds, where, _SAVED_P[kind], ("parameter",)))
        if list(names) != list(system.param_names):
            raise RestartFileError(where, f"the model file {mfile} has other parameters than "
                                   "the saved branch")
        return dataclasses.replace(system, p=np.array(p, float)), None
    raise RestartFileError(where, "does not say which model computed it (no model/params or "
                           "model_file attribute): pass the system to restart with")


def restart(source: Any, label: str, system: Any = None, *, param: str | None = None,
            stop: float | None = None, bounds: Mapping[str, tuple[float, float]] | None = None,
            **options: Any) -> Any:
    """Continue any saved branch from its point ``label`` — the Python API's restart.

    The kind of file decides what is continued: a cycle branch (``cycles --out``;
    ``param`` may name another parameter to continue in), a Hopf curve (``hopf-curve
    --out``; ``bounds`` default the saved ones) or an equilibrium branch
    (:func:`save_equilibrium_branch`; ``stop`` is required). Without ``system`` the saved
    model at its saved parameter values is used (:func:`saved_system`); a cycle branch of
    model A or B then gets the physical limits the ``cycles`` command uses (the coil
    current and the gap range), unless ``limits`` is given. ``options`` go to the
    continuation.

    Returns
    -------
    :class:`RestartedCycleBranch`, or (HopfCurve, :class:`HopfCurveRestart`), or
    (EquilibriumBranch, :class:`EquilibriumRestart`).
    """
    ds, where = open_saved(source)
    kind, what = file_kind(ds)
    if kind is None:
        raise RestartFileError(where, f"not a saved branch (it is {what})")
    params = None
    if system is None:
        system, params = saved_system(source)
    if kind is RestartKind.CYCLE_BRANCH:
        if params is not None and "limits" not in options:
            from maglev_match.maglev.limits import cycle_limit_margins

            options["limits"] = cycle_limit_margins(params)
        return restart_cycle_branch(source, label, system, param=param, **options)
    if kind is RestartKind.HOPF_CURVE:
        return restart_hopf_curve(source, label, system, bounds, **options)
    if stop is None:
        raise ValueError("restart of an equilibrium branch: give stop, the value of the "
                         "continued parameter where the branch should end")
    return restart_equilibrium_branch(source, label, system, stop, **options)
