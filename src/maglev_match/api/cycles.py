"""Cycles born at Hopf points and continued in one parameter (`maglev-match cycles`), for
the maglev models and user model files, and the restart of a saved branch.

The workflow is decided here, once: the Hopf points along the parameter are found by the
method the parameter needs (:func:`maglev_match.api.hopf.hopf_points`: ordinary, beam or
vehicle data, or a delay with the discretised delay system sized for the range), the branch
starts from the one nearest the design value (or from every one), and the maglev models stop
at their physical limits (the gap range and, unless ignored, a reversing coil current). A
restart continues a saved branch from one of its points, with no Hopf search.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from maglev_match.api.compat import deprecated
from maglev_match.api.inputs import StudiedModel, names_a_preset, resolve_model
from maglev_match.api.progress import reported
from maglev_match.core.params import ParameterError, Params
from maglev_match.core.results import Plottable

if TYPE_CHECKING:  # pragma: no cover
    from maglev_match.dynamics.cycles import CycleBranch
    from maglev_match.dynamics.system import System

__all__ = ["cycle_branch", "cycle_study", "CycleStudy", "restart_branch", "saved_model",
           "saved_part",
           "restart_point_extrema", "branch_label"]

#: (step, cycle point) after each accepted step of a branch
StepProgress = Callable[[int, Any], None]


def _hopf_json(h: Any, param: str) -> dict[str, Any]:
    import numpy as np

    return {param: h.value, "l1": h.l1, "kind": h.kind, "frequency": h.frequency,
            "period": 2 * np.pi / h.frequency, "crossing_speed": h.crossing_speed,
            "others_stable": h.others_stable, "converged": h.converged}


def branch_label(k: int) -> str:
    """The label of the k-th branch in tables and figures (b1, b2, ...)."""
    return f"b{k + 1}"


@dataclass(frozen=True)
class CycleStudy(Plottable):
    """Branches of cycles along one parameter, and where they came from.

    model : 'unit', 'vehicle' or a user model file's name; is_user : a user model file.
    param : the continued parameter; at : values fixed with it ({name: value}).
    hopfs : every Hopf point found along the parameter (nearest the design value first);
        chosen : those the branches start from; scan : the Hopf search (None for a
        restart).
    branches : the :class:`~maglev_match.dynamics.cycles.CycleBranch` of each chosen point.
    restart : the saved point a restart continued from (None otherwise).
    mesh : (ntst, ncol); elapsed : seconds of computation.
    """

    model: str
    is_user: bool
    param: str
    at: Mapping[str, float]
    hopfs: list
    chosen: list
    branches: list
    scan: Any = None
    restart: Any = None
    mesh: tuple[int, int] = (80, 4)
    elapsed: float = 0.0
    system: Any = field(default=None, repr=False, compare=False)
    params: Params | None = field(default=None, repr=False, compare=False)
    model_file: str | None = None

    @property
    def warnings(self) -> tuple[str, ...]:
        """What the Hopf search reported (each branch has its own warnings)."""
        return () if self.scan is None else tuple(self.scan.warnings)

    # ----- tables ------------------------------------------------------------------------
    def branch_rows(self, k: int = 0) -> list[dict[str, Any]]:
        """The points of branch ``k``: value, period, the extrema (maglev: gap deviation and
        current; a user model: every observable), stability and its multipliers."""
        import numpy as np

        br, param = self.branches[k], self.param
        rows = []
        for c in br.points:
            if self.is_user:
                r = {param: c.value, "period": c.period, "stable": c.stable,
                     "unstable_multipliers": c.n_unstable,
                     "trivial_multiplier_error": abs(c.trivial_multiplier - 1.0),
                     "max_abs_multiplier": float(np.max(np.abs(c.multipliers)))
                     if len(c.multipliers) else 0.0, "kind": c.kind}
                for name, (hi, lo) in c.extrema.items():
                    r[f"{name}_max"], r[f"{name}_min"] = hi, lo
                rows.append(r)
                continue
            gmax, gmin = c.extrema["gap_deviation"]
            imax, imin = c.extrema["current"]
            rows.append({
                param: c.value, "period": c.period, "gap_dev_max": gmax, "gap_dev_min": gmin,
                "current_min": imin, "current_max": imax, "stable": c.stable,
                "stability": c.stability or ("stable" if c.stable else "unstable"),
                "unstable_multipliers": c.n_unstable,
                "max_abs_multiplier": float(np.max(np.abs(c.multipliers))),
                "kind": c.kind,
                "trivial_multiplier_error": float(abs(c.trivial_multiplier - 1.0)),
                "stability_reliable": c.reliable,
            })
        return rows

    def special_rows(self, k: int = 0) -> list[dict[str, Any]]:
        """The special points of branch ``k`` (LPC, BP, PD, NS, contacts with a limit)."""
        import numpy as np

        from maglev_match.dynamics.continuation import SpecialPointKind

        br, param = self.branches[k], self.param
        if self.is_user:
            return [{"type": s.type, param: s.value, "period": s.period, "located": s.located,
                     "detail": s.detail, "label": s.label} for s in br.special_points]
        rows = []
        for s in br.special_points:
            gmax, gmin = s.extrema.get("gap_deviation", (float("nan"), float("nan")))
            rows.append({"type": s.type, param: s.value, "period": s.period,
                         "gap_dev_max": gmax, "gap_dev_min": gmin,
                         "current_min": s.extrema.get("current", (np.nan, np.nan))[1],
                         "limit": s.detail if s.type == SpecialPointKind.CONTACT else "",
                         "detail": s.detail, "located": s.located, "label": s.label})
        return rows

    def restart_json(self) -> dict[str, Any] | None:
        rs = self.restart
        if rs is None:
            return None
        return {"file": rs.path, "label": rs.label, "saved_param": rs.param,
                "param": self.param, "value": rs.value, "period": rs.period,
                "hopf_search": False, "hopf_value": rs.start.value}

    def as_json(self) -> dict[str, Any]:
        """The command's JSON answer (without the files)."""
        param = self.param
        if self.is_user:
            return {"model": self.model, "model_file": self.model_file, "param": param,
                    **({"values": dict(self.at)} if self.restart is None else
                       {"restart": self.restart_json()}),
                    "hopf_points": [{param: h.value, "frequency": h.frequency, "l1": h.l1,
                                     "kind": h.kind} for h in self.hopfs],
                    "branches": [{"hopf": h.value, "branch": self.branch_rows(k),
                                  "special_points": self.special_rows(k),
                                  "stopped_reason": br.stopped_reason,
                                  "warnings": list(br.warnings)}
                                 for k, (h, br) in enumerate(zip(self.chosen, self.branches,
                                                                 strict=True))],
                    "warnings": list(self.warnings)}
        main, h0 = self.branches[0], self.chosen[0]
        if self.restart is not None:
            import numpy as np

            rs = self.restart
            hopf = {rs.param: rs.start.value, "l1": rs.start.l1,
                    "kind": _kind(rs.start.l1), "frequency": rs.start.frequency,
                    "period": 2 * np.pi / rs.start.frequency, "from_file": True}
        else:
            hopf = _hopf_json(h0, param)
        result: dict[str, Any] = {
            "model": self.model, "param": param,
            **({"restart": self.restart_json()} if self.restart is not None else
               {"at": dict(self.at)}),
            "hopf": hopf,
            "label": "b1",  # the label of the branch in the figure and the CSV
            "branch": self.branch_rows(0),
            "special_points": self.special_rows(0),
            "stopped_reason": main.stopped_reason,
            **({} if self.restart is not None else {"end": main.message}),
            "steps": main.steps,
            "warnings": list(main.warnings) + list(self.warnings),
            "hopf_points": [_hopf_json(h, param) for h in self.hopfs],
            "mesh": {"ntst": self.mesh[0], "ncol": self.mesh[1]},
            "elapsed_s": self.elapsed,
        }
        if len(self.branches) > 1:
            result["other_branches"] = [
                {"label": branch_label(k + 1), "hopf": _hopf_json(h, param),
                 "branch": self.branch_rows(k + 1), "special_points": self.special_rows(k + 1),
                 "stopped_reason": br.stopped_reason, "warnings": list(br.warnings)}
                for k, (h, br) in enumerate(zip(self.chosen[1:], self.branches[1:],
                                                strict=True))]
        return result

    # ----- files -------------------------------------------------------------------------
    def branch_dataset(self, k: int = 0, command: str = "cycles") -> Any:
        """Branch ``k`` as an annotated netCDF dataset (profiles, multipliers, special
        points), stamped as a restartable cycle branch (:mod:`maglev_match.analyses.restart`)."""
        from maglev_match.analyses.restart import RestartKind, stamp
        from maglev_match.core.datasets import annotate
        from maglev_match.core.units import unit

        br, system = self.branches[k], self.system
        if self.is_user:
            ds = br.to_xarray(system)
        else:
            ds = annotate(br.to_xarray(system, param_unit=unit(self.param)), self.params)
        stamp(ds, RestartKind.CYCLE_BRANCH, system, self.model,
              command if self.restart is None else f"{command} --restart")
        if self.restart is not None:
            ds.attrs["restart_of"] = f"{self.restart.label} of {self.restart.path}"
        if self.model_file is not None:  # a user model: the API's restart loads it again
            ds.attrs["model_file"] = str(Path(self.model_file).resolve())
        return ds

    def to_xarray(self) -> Any:
        """The first branch's dataset (:meth:`branch_dataset`)."""
        return self.branch_dataset(0)


def _kind(l1: float | None) -> str:
    """Criticality of a saved Hopf point (as `hopf` and `cycles` print it)."""
    import math

    if l1 is None or not math.isfinite(l1):
        return "unknown"
    return "subcritical" if l1 > 0 else "supercritical" if l1 < 0 else "degenerate"


def _search_range(studied: StudiedModel, system: Any, param: str, start: float | None,
                  stop: float | None) -> tuple[float, float, Any]:
    """Where Hopf points are searched: (a, b, system): by default the design value / 4 to
    x 4; a delay from 0 (the discretised delay system sized for the range); beam or vehicle
    data need both ends."""
    import numpy as np

    from maglev_match.analyses.engineering import engineering_system, is_engineering

    design = studied.design_value(param)
    if studied.is_user:
        a = (design / 4 if design > 0 else design - 1.0) if start is None else start
        b = (design * 4 if design > 0 else design + 1.0) if stop is None else stop
    else:
        a = design / 4 if start is None else start
        b = design * 4 if stop is None else stop
    if param in studied.delays:  # a delay axis: the discretised delay system up to its end
        a = 0.0 if start is None else start
        unit = "" if studied.is_user else " s"
        for field_, value in (("start", a), ("stop", b)):
            if value < 0:
                raise ParameterError(field_, value, f"{param} is a delay: the search range "
                                     f"must lie at or above 0 (>= 0{unit})")
        if not studied.is_user and not b > 0:
            raise ParameterError("stop", b, f"give the largest delay {param} to search, > 0 "
                                 f"s (the design value is {design:g} s)")
        system = studied.system(tau_max=max(a, b))
    if studied.params is not None and is_engineering(param):  # omega1, sigma follow it
        if start is None or stop is None:
            raise ParameterError("start/stop", None, f"give the range of {param} (beam or "
                                 "vehicle data have no default range)")
        system = engineering_system(studied.params, studied.label, param, min(a, b), max(a, b))
    if not (np.isfinite(a) and np.isfinite(b)) or a == b:
        raise ParameterError("start/stop", f"[{a}, {b}]", "the search range is empty")
    return a, b, system


@reported("cycles", units=False)
def cycle_study(params: Params | str | None = None, param: str = "omega1", *,
                model: str = "unit", at: Mapping[str, Any] | None = None,
                start: float | None = None, stop: float | None = None,
                all_hopf: bool = False, n_scan: int = 100, ntst: int | None = None,
                ncol: int | None = None, max_steps: int = 300, ignore_current: bool = False,
                config: str | Path | None = None, restart: str | Path | None = None,
                label: str | None = None, stage: Callable[[str], None] | None = None,
                progress: StepProgress | None = None, **overrides: Any) -> CycleStudy:
    """Cycles born at Hopf points, continued in `param` until a physical limit (`maglev-match
    cycles`; paper Fig. 5).

    The orbits are solved by orthogonal collocation at Gauss points on an adaptive mesh (de
    Boor & Swartz 1973; Doedel's AUTO notes) and continued by pseudo-arclength until a
    physical limit, a failure or `max_steps`; Floquet multipliers come from the monodromy
    matrix of the condensed collocation blocks (Doedel, Keller & Kernevez 1991).

    Parameters
    ----------
    params : Params | str | None
        The parameter set (see [`resolve_params`][maglev_match.api.inputs.resolve_params]);
        with `restart`, None takes the saved values.
    param : str
        The continuation parameter (a model parameter, a delay, or beam/vehicle data).
    model : str
        `"unit"`, `"vehicle"` or a user model file `FILE.py` (continued without physical
        limits, with the extrema of every observable).
    at : mapping, optional
        Values fixed with the others, applied after `params` and `overrides` (`--at`).
    start, stop : float, optional
        Where Hopf points are searched (default: the design value / 4 to x 4; a delay from
        0, its largest value required; beam or vehicle data: both required).
    all_hopf : bool
        Continue from every Hopf point in the range (default: the one nearest the design
        value).
    n_scan : int
        Values of the bracketing scan.
    ntst, ncol : int
        Mesh intervals (default 80) and collocation points per interval (2 to 7, default 4);
        a restart keeps the saved mesh (another one is refused).
    max_steps : int
        Continuation steps.
    ignore_current : bool
        Do not stop where the coil current reaches zero (only the gap limits stop).
    config : str or Path, optional
        A TOML file applied on top of the preset.
    restart, label : optional
        A branch file written by `cycles --out` and the point to continue from (`P<k>` or a
        special point's label); no Hopf search.
    stage : callable, optional
        Called with a line of text when a stage starts.
    progress : callable, optional
        Called as `progress(step, cycle)` after each accepted step.
    **overrides : float
        Parameter values applied on top.

    Returns
    -------
    CycleStudy
        The branches, the Hopf points, the tables (`branch_rows`, `special_rows`,
        `as_json`), the restartable datasets (`branch_dataset`) and the figure (`.plot()`).
    """
    say = stage or (lambda text: None)
    if ncol is not None and not 2 <= ncol <= 7:
        raise ParameterError("ncol", ncol, "must be between 2 and 7")
    if ntst is not None and ntst < 4:
        raise ParameterError("ntst", ntst, "must be at least 4")
    if n_scan < 3:
        raise ParameterError("n_scan", n_scan, "must be at least 3")
    own_values = params is not None or config is not None or bool(overrides) or bool(at)
    studied = resolve_model(params, model, config=config, **overrides)
    if restart is not None or label is not None:
        return _restart_study(studied, param, restart, label, own_values, at, ntst, ncol,
                              max_steps, ignore_current, dict(overrides), say, progress)
    if ignore_current and studied.is_user:
        raise ParameterError("ignore_current", True, "applies to the maglev models only; a "
                             "user model has no coil current limit")
    ntst, ncol = (80 if ntst is None else ntst), (4 if ncol is None else ncol)
    studied = studied.with_values(**dict(at or {}))
    from maglev_match.dynamics.cycles import cycle_branch as _cycle_branch
    from maglev_match.dynamics.delay import delay_hopf_points, is_delay_parameter
    from maglev_match.dynamics.hopf import locate_hopf_points

    system = studied.system()
    studied.check_param(param, "param", engineering=True)
    a, b, system = _search_range(studied, system, param, start, stop)
    design = studied.design_value(param)
    t0 = time.perf_counter()
    say(f"searching Hopf points along {param} in [{min(a, b):.6g}, {max(a, b):.6g}] ...")
    if is_delay_parameter(system, param):  # crossings of the characteristic equation
        scan = delay_hopf_points(system, param, min(a, b), max(a, b), n_scan=n_scan)
    else:
        scan = locate_hopf_points(system, param, min(a, b), max(a, b), n_scan=n_scan)
    hopfs = sorted((h for h in scan.points if h.converged),
                   key=lambda h: abs(h.value - design))
    if not hopfs:
        raise ParameterError("start/stop", f"[{min(a, b):.6g}, {max(a, b):.6g}]",
                             f"no Hopf point of the equilibrium along {param} there; widen "
                             "the range")
    chosen = hopfs if all_hopf else hopfs[:1]
    if studied.is_user:
        limits, observables = None, tuple(system.observables)
    else:
        limits, observables = studied.maglev.cycle_limits(not ignore_current), None
    branches = []
    for h in chosen:
        say(f"continuing cycles from the Hopf point {param} = {h.value:.6g} ...")
        kw = {"limits": limits} if limits is not None else {"observables": observables}
        br = _cycle_branch(system, h, param, ntst=ntst, ncol=ncol, max_steps=max_steps,
                           progress=progress, **kw)
        branches.append(br)
        say(f"branch from {param} = {h.value:.6g}: {len(br.points)} cycles, ended: "
            f"{br.stopped_reason}")
    return CycleStudy(model=studied.label, is_user=studied.is_user, param=param,
                      at=dict(at or {}), hopfs=hopfs, chosen=chosen, branches=branches,
                      scan=scan, mesh=(ntst, ncol), elapsed=time.perf_counter() - t0,
                      system=system, params=studied.params, model_file=studied.file)


def _restart_study(studied: StudiedModel, param: str | None, restart, label, own_values: bool,
                   at, ntst, ncol, max_steps, ignore_current, overrides: dict, say,
                   progress) -> CycleStudy:
    """A saved branch continued from its point ``label``: the saved model and mesh, the
    saved parameter values unless values are given (then they must be the saved ones)."""
    from maglev_match.analyses.engineering import is_engineering
    from maglev_match.analyses.restart import (
        check_parameters,
        load_cycle_restart,
        saved_params,
        saved_values,
    )
    from maglev_match.dynamics.cycles import cycle_branch as _cycle_branch

    if restart is None or label is None:
        raise ParameterError("restart/label", restart or label, "a restart needs the file "
                             "and the label of the point together (e.g. P12)")
    if param is not None and studied.params is not None and is_engineering(param):
        raise ParameterError("param", param, "a restart continues in a model parameter "
                             "(omega1, sigma, kD, ...), not along beam or vehicle data")
    at = dict(at or {})
    if studied.is_user and ignore_current:
        raise ParameterError("ignore_current", True, "applies to the maglev models only")
    studied = studied.with_values(**at)
    system = studied.system()
    rs = load_cycle_restart(restart, label, system)
    if rs.param in set(overrides) | set(at):
        raise ParameterError(rs.param, "given", f"{rs.param} is the parameter the saved "
                             f"branch is continued in; a restart takes its value from the "
                             f"restart point {rs.label} ({rs.param} = {rs.value:.8g}); leave "
                             "it out")
    param = rs.param if param is None else param
    if param not in system.param_names:
        raise ParameterError("param", param, f"model '{studied.label}' has no such parameter")
    params = studied.params
    if studied.is_user:
        if not own_values:
            from dataclasses import replace

            vals = saved_values(rs)
            studied = replace(studied, values={n: vals[n] for n in studied.user.params
                                               if n in vals})
            system = studied.system()
    elif not own_values:  # the saved values (the parameter set the branch was computed with)
        saved = saved_params(rs)
        if saved is not None:
            from maglev_match.maglev.models import maglev_model

            params = saved
            system = maglev_model(saved, studied.label).system()
    check_parameters(rs, system, param)
    saved_ntst, saved_ncol = rs.state.mesh.size - 1, rs.ncol
    for name, value, saved in (("ntst", ntst, saved_ntst), ("ncol", ncol, saved_ncol)):
        if value is not None and value != saved:
            raise ParameterError(name, value, f"a restart goes on with the saved mesh "
                                 f"({name} = {saved}); leave it out")
    if studied.is_user:
        kw: dict[str, Any] = {"observables": tuple(system.observables)}
    else:
        from maglev_match.maglev.limits import cycle_limit_margins

        kw = {"limits": cycle_limit_margins(params, include_current=not ignore_current)}
    t0 = time.perf_counter()
    say(f"{rs.describe()}; no Hopf search ...")
    br = _cycle_branch(system, rs.start, param, ntst=saved_ntst, ncol=saved_ncol,
                       max_steps=max_steps, progress=progress, restart=rs.state,
                       restart_param=rs.param, **kw)
    say(f"restarted branch: {len(br.points)} cycles, stopped: {br.stopped_reason}")
    return CycleStudy(model=studied.label, is_user=studied.is_user, param=param,
                      at=at, hopfs=[], chosen=[rs.start], branches=[br], restart=rs,
                      mesh=(saved_ntst, saved_ncol), elapsed=time.perf_counter() - t0,
                      system=system, params=params, model_file=studied.file)


def cycle_branch(params: Params | str | None = None, param: str = "omega1", *,
                 model: str = "unit", start: float | None = None, stop: float | None = None,
                 n_scan: int = 100, ntst: int = 80, ncol: int = 4, max_steps: int = 300,
                 ignore_current: bool = False,
                 progress: StepProgress | None = None,
                 **overrides: Any) -> CycleBranch:
    """The branch of periodic orbits born at the Hopf point nearest the design value of
    `param` (:func:`cycle_study`'s first branch).

    Parameters
    ----------
    params : Params | str | None
        The parameter set (see [`resolve_params`][maglev_match.api.inputs.resolve_params]).
    param : str
        The continuation parameter.
    model : str
        `"unit"`, `"vehicle"` or a user model file `FILE.py`.
    start, stop : float, optional
        Where Hopf points are searched (default: the design value / 4 to x 4).
    n_scan : int
        Values of the bracketing scan.
    ntst, ncol : int
        Mesh intervals and collocation points per interval (2 to 7).
    max_steps : int
        Continuation steps.
    ignore_current : bool
        Do not stop where the coil current reaches zero (only the gap limits stop).
    progress : callable, optional
        Called as `progress(step, cycle)` after each accepted step.
    **overrides : float
        Parameter values applied on top, validated like `--set NAME=VALUE`.

    Returns
    -------
    CycleBranch
        See [`CycleBranch`][maglev_match.dynamics.cycles.CycleBranch].
    """
    if isinstance(params, str) and not names_a_preset(params):  # cycle_branch(param, p)
        deprecated("cycle_branch(param, params)", "cycle_branch(params, param)")
        old_params = param if isinstance(param, Params) or names_a_preset(param) else None
        params, param = old_params, params
    return cycle_study(params, param, model=model, start=start, stop=stop, n_scan=n_scan,
                       ntst=ntst, ncol=ncol, max_steps=max_steps,
                       ignore_current=ignore_current, progress=progress,
                       **overrides).branches[0]


def restart_branch(source: str | Path | Any, label: str, system: System | None = None, *,
                   param: str | None = None, stop: float | None = None,
                   bounds: Mapping[str, tuple[float, float]] | None = None,
                   **options: Any) -> Any:
    """Continue a saved branch from one of its points (`cycles --restart FILE --label L`,
    `hopf-curve --restart FILE --label L`). The file says what it holds; no Hopf point is
    searched again.

    Parameters
    ----------
    source : str, Path or xarray.Dataset
        A branch file written by `cycles --out` or `hopf-curve --out` (or by
        `maglev_match.analyses.restart.save_equilibrium_branch`).
    label : str
        The point to continue from: `P<k>` for the k-th saved point, or a special point's
        label (`LPC1`, `PD1`, `GH1`, ...).
    system : System, optional
        The model; by default the saved model at its saved parameter values (model A or B,
        or the user model file the branch names). Its names and values must match the
        saved ones (all but the continued parameter), else a clear error names them.
    param : str, optional
        A cycle branch: continue in another parameter (default the saved one).
    stop : float, optional
        An equilibrium branch: where the continued parameter should end (required there).
    bounds : mapping, optional
        A Hopf curve: `{name: (low, high)}` for its two parameters (default the saved ones).
    **options
        Passed to the continuation (e.g. `max_steps`, `ntst`).

    Returns
    -------
    RestartedCycleBranch, or (HopfCurve, HopfCurveRestart), or (EquilibriumBranch,
    EquilibriumRestart); see `maglev_match.analyses.restart`. A damaged or mismatched file
    raises `maglev_match.analyses.restart.RestartFileError` naming the file and the problem.
    """
    from maglev_match.analyses.restart import restart as _restart

    return _restart(source, label, system, param=param, stop=stop, bounds=bounds, **options)



def saved_model(source: Any) -> str | None:
    """The maglev model a saved branch file was computed with ('unit', 'vehicle'), or None
    (a user model's file, or one that does not say)."""
    from maglev_match.analyses.restart import open_saved
    from maglev_match.maglev.catalog import MODEL_NAMES

    model = open_saved(source)[0].attrs.get("model")
    return model if model in MODEL_NAMES else None


def saved_part(rs: Any, system: Any, observable: str) -> tuple[Any, Any, Any, Any]:
    """Values, max, min and stability of ``observable`` over the points of a saved branch
    (``rs`` a :class:`~maglev_match.analyses.restart.CycleRestart`), for drawing it."""
    import numpy as np

    from maglev_match.dynamics.cycles import orbit_extrema

    vals, hi, lo, st = [], [], [], []
    for k, orbit in rs.saved_orbits():
        ext = orbit_extrema(system, orbit, [observable])[observable]
        vals.append(rs.branch_values[k])
        hi.append(ext[0])
        lo.append(ext[1])
        st.append(bool(rs.branch_stable[k]))
    return np.array(vals), np.array(hi), np.array(lo), np.array(st, bool)


def restart_point_extrema(rs: Any, system: Any, observable: str) -> tuple[float, float]:
    """(max, min) of ``observable`` over the orbit at the restart point."""
    from maglev_match.dynamics.cycles import PeriodicOrbit, orbit_extrema

    orbit = PeriodicOrbit(mesh=rs.state.mesh, ncol=rs.ncol, states=rs.state.states,
                          period=rs.state.period, p=rs.p)
    return orbit_extrema(system, orbit, [observable])[observable]
