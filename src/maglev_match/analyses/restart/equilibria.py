"""Saved equilibrium branches: writing a branch as a restartable file
(:func:`equilibrium_branch_dataset`, :func:`save_equilibrium_branch`), the validated restart
point (:func:`load_equilibrium_restart`, :class:`EquilibriumRestart`; P<k> or a special
point such as H1 or LP1) and the continuation from it (:func:`restart_equilibrium_branch`).
The stamp and the file checks are those of :mod:`maglev_match.analyses.restart.files`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from maglev_match.analyses.restart.files import (
    MODEL_ATTR,
    SAME,
    RestartFileError,
    RestartKind,
    RestartMismatch,
    attr_text,
    check_saved_model,
    expect_kind,
    label_error,
    open_saved,
    require_finite,
    saved_names,
    stamp,
    variable,
)

__all__ = ["equilibrium_branch_dataset", "save_equilibrium_branch", "EquilibriumRestart",
           "load_equilibrium_restart", "restart_equilibrium_branch"]


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
    expect_kind(ds, where, RestartKind.EQUILIBRIUM_BRANCH)
    states = saved_names(ds, where, "state")
    params = saved_names(ds, where, "parameter")
    check_saved_model(ds, where, system, states, params)
    param = attr_text(ds, where, "param")
    if param not in params:
        raise RestartFileError(where, f"attribute param = '{param}' names no parameter of the "
                               "saved model")
    p = require_finite(where, "p (the parameter vector)", variable(ds, where, "p", ("parameter",)))
    labels = [str(v) for v in ds["label"].values] if "label" in ds.coords else []
    specials = ([str(v) for v in ds["special_label"].values]
                if "special_label" in ds.coords else [])
    if label in labels:
        k = labels.index(label)
        value = float(variable(ds, where, "value", ("point",))[k])
        x = variable(ds, where, "equilibrium", ("point", "state"))[k]
    elif label in specials:
        k = specials.index(label)
        value = float(variable(ds, where, "special_value", ("special",))[k])
        x = variable(ds, where, "special_equilibrium", ("special", "state"))[k]
    else:
        raise label_error(where, label, labels, specials, "saved equilibrium branch")
    if x.shape != (len(states),):
        raise RestartFileError(where, f"the equilibrium at '{label}' has {x.size} states, the "
                               f"file names {len(states)}")
    require_finite(where, f"the equilibrium at '{label}'", x)
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
