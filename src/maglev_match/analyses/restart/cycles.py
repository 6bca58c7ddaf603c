"""Restart of a saved cycle branch (``cycles --out``): the validated restart point
(:func:`load_cycle_restart`, :class:`CycleRestart`), the check of the caller's parameter
values (:func:`check_parameters`) and the continuation from the point
(:func:`restart_cycle_branch`, :class:`RestartedCycleBranch`).

A restart continues the saved branch at the saved parameter values. A caller that also
gives parameter values (``--set``/``--at``) must give the saved ones (all but the
continuation parameter), else :func:`check_parameters` refuses with the differences: the
saved orbit belongs to those values, and continuing it under others would answer for
another system.

The file checks are those of :mod:`maglev_match.analyses.restart.files`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from maglev_match.analyses.restart.files import (
    MODEL_ATTR,
    SAME,
    RestartFileError,
    RestartKind,
    RestartMismatch,
    attr_int,
    attr_number,
    attr_text,
    check_saved_model,
    expect_kind,
    label_error,
    open_saved,
    require_finite,
    saved_names,
    variable,
)

__all__ = ["CycleRestart", "load_cycle_restart", "check_parameters", "RestartedCycleBranch",
           "restart_cycle_branch"]


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
    expect_kind(ds, where, RestartKind.CYCLE_BRANCH)
    states = saved_names(ds, where, "state")
    params = saved_names(ds, where, "parameter")
    n = len(states)
    if n == 0:
        raise RestartFileError(where, "has no states")
    n_attr = attr_int(ds, where, "n_states")
    if n_attr is not None and n_attr != n:
        raise RestartFileError(where, f"attribute n_states = {n_attr} but {n} state names")
    check_saved_model(ds, where, system, states, params)
    param = attr_text(ds, where, "param")
    if param not in params:
        raise RestartFileError(where, f"attribute param = '{param}' names no parameter of the "
                               f"saved model (it has {', '.join(params[:8])}"
                               f"{', ...' if len(params) > 8 else ''})")
    hopf_value = attr_number(ds, where, "hopf_value")
    freq = attr_number(ds, where, "hopf_frequency")
    if not freq > 0:
        raise RestartFileError(where, f"attribute hopf_frequency = {freq:g} must be > 0 rad/s")
    l1 = attr_number(ds, where, "hopf_l1", allow_nan=True)
    hx = require_finite(where, "hopf_x (the equilibrium at the Hopf point)",
                        variable(ds, where, "hopf_x", ("state",)))
    q = (variable(ds, where, "hopf_q_re", ("state",))
         + 1j * variable(ds, where, "hopf_q_im", ("state",)))
    require_finite(where, "the Hopf eigenvector (hopf_q_re, hopf_q_im)", np.abs(q))
    if not np.linalg.norm(q) > 0:
        raise RestartFileError(where, "the Hopf eigenvector (hopf_q_re, hopf_q_im) is zero")
    hp = require_finite(where, "hopf_p (the parameters at the Hopf point)",
                        variable(ds, where, "hopf_p", ("parameter",)))
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
        raise label_error(where, label, labels, specials, "saved branch")
    mesh_all = variable(ds, where, pre + "r_mesh", (dim, "mesh_node"))
    st_all = variable(ds, where, pre + "r_states", (dim, "node", "state"))
    tst_all = variable(ds, where, pre + "r_t_states", (dim, "node", "state"))
    scalars = {name: variable(ds, where, pre + name, (dim,))
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
        v = attr_int(ds, where, name)
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
    mesh = require_finite(where, f"the mesh at '{label}'", mesh_all[k])
    if not (abs(mesh[0]) <= 1e-12 and abs(mesh[-1] - 1.0) <= 1e-12
            and np.all(np.diff(mesh) > 0)):
        raise RestartFileError(where, f"the mesh at '{label}' does not increase from 0 to 1")
    states_k = require_finite(where, f"the cycle states at '{label}'", st_all[k])
    t_states = require_finite(where, f"the tangent at '{label}'", tst_all[k])
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
