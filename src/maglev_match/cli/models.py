"""``--model``: the built-in maglev models (``unit``, ``vehicle``) or a user model file.

A value ending in ``.py`` is a user model (see :mod:`maglev_match.maglev.user`): ``--set
NAME=VALUE`` then applies to the file's PARAMS and ``--preset``/``--config`` (maglev parameter
sets) do not apply. Commands whose physics only make sense for the maglev models refuse a
file with one clear line (:func:`refuse_model_file`). The user-model versions of ``cycles``
and ``simulate`` live here too, so the maglev command modules only gain a branch.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from maglev_match.cli.common import (
    UserError,
    check_model,
    console,
    console_err,
    emit_json,
    given,
    is_file_name,
    output_target,
    params_from_options,
    print_warnings,
    progress_report,
    refuse_given,
)
from maglev_match.cli.cycle_tables import _cycle_rows, _special_rows_user, shown_rows
from maglev_match.cli.restart import (
    HOPF_SEARCH_OPTIONS,
    _fail_if_nothing_continued,
    _mesh,
    _need_label,
    _refuse_continued_value,
    _restart_json,
    restart_errors,
)
from maglev_match.core.params import ParameterError, Params
from maglev_match.maglev.catalog import model_info

if TYPE_CHECKING:  # the user-model loader and System import JAX: loaded when used
    import numpy as np

    from maglev_match.dynamics.system import System
    from maglev_match.maglev.user import UserModel


def is_model_file(model: str) -> bool:
    """True when a ``--model`` value names a Python file rather than a built-in model
    (the same rule as :func:`maglev_match.maglev.user.is_model_file`, without importing
    that module: a usage error must not wait for JAX)."""
    return str(model).endswith(".py")

__all__ = ["ResolvedModel", "delay_names", "is_model_file", "refuse_model_file",
           "resolve_model"]


@dataclass(frozen=True)
class ResolvedModel:
    """What a command needs from ``--model``.

    system : the ODE system at the chosen parameter values.
    description : one line naming the model and its key values, for text output.
    label : 'unit', 'vehicle' or the model file's stem (used in output names and JSON).
    params : the maglev parameter set, or None for a user model.
    user : the loaded user model, or None for a built-in one.
    """

    system: System
    description: str
    label: str
    params: Params | None = None
    user: UserModel | None = None

    @property
    def is_user(self) -> bool:
        return self.user is not None


def parse_sets(user: UserModel, sets: list[str] | None, option: str = "--set"
               ) -> dict[str, float]:
    """NAME=VALUE items for a user model's PARAMS (unknown names list the valid ones)."""
    values: dict[str, float] = {}
    for item in sets or []:
        if "=" not in item:
            raise UserError(f"{option} '{item}': expected NAME=VALUE, e.g. "
                            f"{next(iter(user.params), 'a')}=1.5")
        name, text = (t.strip() for t in item.split("=", 1))
        if name not in user.params:
            raise ParameterError(option, name, f"model file {user.path} has no such parameter; "
                                 f"valid names: {', '.join(user.params) or '(none)'}")
        try:
            v = float(text)
        except ValueError:
            raise ParameterError(name, text, "must be a number") from None
        if not math.isfinite(v):
            raise ParameterError(name, text, "must be finite")
        values[name] = v
    return values


def load_user_model(path: str) -> UserModel:
    """:func:`load_model` with its error turned into a command-line error (exit code 2)."""
    from maglev_match.maglev.user import ModelFileError, load_model

    try:
        return load_model(path)
    except ModelFileError as exc:
        raise UserError(str(exc)) from None


def user_system(user: UserModel, values: dict[str, float], option: str = "--set", *,
                tau_max: float | None = None) -> System:
    """The user model's system at ``values``, refused (exit code 2, before any work) when its
    right-hand side or Jacobian is not finite at X0 there: an overflow such as
    ``--set rho=1e308`` is a numerical failure to name, not a verdict to print."""
    problem = user.numerical_problem(values)
    if problem is not None:
        given = " ".join(f"{k}={v:g}" for k, v in values.items())
        raise UserError(f"{option} {given}: numerical failure: {problem}; choose values that "
                        "keep it finite" if given else f"model file {user.path}: numerical "
                        f"failure at the defaults: {problem}")
    return user.system(values, tau_max=tau_max)


#: Options of the maglev models that a user model file refuses (parameter name -> option).
MAGLEV_PARAMETER_SETS = {"preset": "--preset"}


def resolve_model(model: str, sets: list[str] | None, preset: str | None = None,
                  config: Path | None = None, *, limited: bool = False,
                  delay_axis: tuple[str, float] | None = None) -> ResolvedModel:
    """The system ``--model`` names, with ``--set`` (and, for the maglev models,
    ``--preset``/``--config``) applied.

    Parameters
    ----------
    model : 'unit', 'vehicle' or a path ending in .py.
    sets : the ``--set NAME=VALUE`` items.
    preset, config : the maglev parameter set options (a user model refuses ``--config``).
    limited : the maglev model with its physical limits (built-in models only).
    delay_axis : (parameter, largest value) of a parameter axis: when the parameter is a
        delay of the model, the system is the discretised delay system sized for delays up
        to that value, even where the delay is 0 (see :mod:`maglev_match.dynamics.delay`).
    """
    if is_model_file(model):
        if config is not None:
            raise UserError(f"--config {config}: maglev parameter files do not apply to a "
                            f"user model ({model}); use --set NAME=VALUE")
        refuse_given(MAGLEV_PARAMETER_SETS, f"maglev parameter presets do not apply to a user "
                     f"model ({model}); use --set NAME=VALUE")
        user = load_user_model(model)
        values = parse_sets(user, sets)
        vals = user.values_with(values)
        desc = (f"Model {user.name} ({model}, {len(user.states)} states), "
                + ", ".join(f"{k} = {v:.6g}" for k, v in vals.items()))
        tau_max = (delay_axis[1] if delay_axis is not None and delay_axis[0] in user.delays
                   else None)
        return ResolvedModel(system=user_system(user, values, tau_max=tau_max),
                             description=desc,
                             label=user.name, user=user)
    check_model(model)
    from maglev_match.cli.common import DEFAULT_PRESET_NAME

    params = params_from_options(preset or DEFAULT_PRESET_NAME, config, sets)
    from maglev_match.maglev.models import build_system  # (after the checks: JAX loads here)

    info = model_info(model)
    desc = (f"Model {info.letter} ({info.title}), "
            f"omega1 = {params.omega1:.4g} rad/s, sigma = {params.sigma:.4g} 1/kg")
    tau_max = (delay_axis[1] if delay_axis is not None and delay_axis[0] in MAGLEV_DELAYS
               else None)
    return ResolvedModel(system=build_system(params, model, limited=limited, tau_max=tau_max),
                         description=desc, label=model, params=params)


#: the delay parameters of the maglev models
MAGLEV_DELAYS = ("tau",)


def delay_names(rm: ResolvedModel) -> tuple[str, ...]:
    """The delay parameters of a resolved model (the maglev models: tau; a user model: its
    DELAYS)."""
    return rm.user.delays if rm.user is not None else MAGLEV_DELAYS


#: ``--model`` on the commands that analyse the maglev models themselves (index, map,
#: report, reproduce): accepted only to refuse a model file with a clear message.
MaglevOnlyModelOpt = Annotated[
    str | None, typer.Option("--model", hidden=True,
                             help="Not an option of this command (maglev models only).")
]


def refuse_model_file(model: str | None, command: str) -> None:
    """Commands built on the maglev physics (index, map, report, reproduce) refuse a file
    (and any other --model value: they choose the maglev models themselves)."""
    if model is None:
        return
    if is_model_file(model):
        raise UserError(f"--model {model}: '{command}' works on the maglev models only; "
                        "user model files are accepted by stability, root-locus, hopf, "
                        "hopf-curve, cycles and simulate")
    raise UserError(f"--model {model}: '{command}' has no --model option (it analyses the "
                    "maglev models itself)")


# ---------------------------------------------------------------------------------------
# cycles and simulate for a user model
# ---------------------------------------------------------------------------------------
def _at_values(user: UserModel, at: list[str] | None) -> dict[str, float]:
    return parse_sets(user, at, option="--at")


def _print_user_points(br, param: str) -> None:
    """The rows :func:`shown_rows` picks of a user model's cycle branch, one line each."""
    for k in shown_rows(len(br.points)):
        c = br.points[k]
        console.print(f"  {param} = {c.value:.8g}  T = {c.period:.6g}  "
                      f"{'stable' if c.stable else 'unstable'} ({c.n_unstable} unstable "
                      f"multipliers, |trivial - 1| = {abs(c.trivial_multiplier - 1):.1e})",
                      highlight=False)


def user_cycles(model: str, sets: list[str] | None, at: list[str] | None, param: str,
                start: float | None, stop: float | None, all_hopf: bool, n_scan: int,
                ntst: int, ncol: int, max_steps: int, json_out: bool, out: Path | None,
                *, restart: Path | None = None, label: str | None = None) -> None:
    """``cycles`` on a user model: Hopf points along ``param``, then the cycle branch from
    the one nearest the current value (or from all with ``--all``), continued without
    physical limits; extrema of every state and observable along the branch. With
    ``--out`` the branches are also saved as netCDF (restartable); ``--restart FILE
    --label L`` continues a saved one (:func:`user_cycles_restart`)."""
    import numpy as np

    from maglev_match.dynamics.cycles import cycle_branch
    from maglev_match.dynamics.delay import delay_hopf_points, is_delay_parameter
    from maglev_match.dynamics.hopf import locate_hopf_points

    refuse_given({"ignore_current": "--ignore-current", "config": "--config",
                  "preset": "--preset"},
                 f"applies to the maglev models only; a user model ({model}) has no coil "
                 "current limit and takes its values from --set/--at")
    user = load_user_model(model)
    if restart is not None or label is not None:
        return user_cycles_restart(user=user, model=model, restart=restart, label=label,
                                   param=param, sets=sets, at=at, ntst=ntst, ncol=ncol,
                                   max_steps=max_steps, json_out=json_out, out=out)
    values = {**parse_sets(user, sets), **_at_values(user, at)}
    system = user_system(user, values, "--set/--at")
    if param not in system.param_names:
        raise ParameterError("--param", param, f"model file {model} has no such parameter; "
                             f"valid names: {', '.join(system.param_names)}")
    design = system.param(param)
    a = (design / 4 if design > 0 else design - 1.0) if start is None else start
    b = (design * 4 if design > 0 else design + 1.0) if stop is None else stop
    if param in user.delays:  # a delay axis from 0: the discretised delay system
        a = 0.0 if start is None else start
        if min(a, b) < 0:
            raise ParameterError("--from", min(a, b), f"{param} is a delay: >= 0")
        system = user.system(values, tau_max=max(a, b))
    if not (np.isfinite(a) and np.isfinite(b)) or a == b:
        raise UserError(f"--from/--to: empty search range [{a}, {b}]")
    if is_delay_parameter(system, param):
        scan = delay_hopf_points(system, param, min(a, b), max(a, b), n_scan=n_scan)
    else:
        scan = locate_hopf_points(system, param, min(a, b), max(a, b), n_scan=n_scan)
    hopfs = sorted((h for h in scan.points if h.converged), key=lambda h: abs(h.value - design))
    if not hopfs:
        raise UserError(f"no Hopf point of the equilibrium along {param} in "
                        f"[{min(a, b):.6g}, {max(a, b):.6g}]; widen --from/--to")
    chosen = hopfs if all_hopf else hopfs[:1]
    names = tuple(system.observables)
    branches = []
    for h in chosen:
        console_err.print(f"cycles from Hopf at {param} = {h.value:.6g} ...", highlight=False)
        branches.append(cycle_branch(system, h, param, ntst=ntst, ncol=ncol,
                                     max_steps=max_steps, observables=names))

    result = {
        "model": user.name, "model_file": str(model), "param": param, "values": values,
        "hopf_points": [{param: h.value, "frequency": h.frequency, "l1": h.l1,
                         "kind": h.kind} for h in hopfs],
        "branches": [{"hopf": h.value, "branch": _cycle_rows(br, param),
                      "special_points": _special_rows_user(br, param),
                      "stopped_reason": br.stopped_reason, "warnings": list(br.warnings)}
                     for h, br in zip(chosen, branches, strict=True)],
        "warnings": list(scan.warnings),
    }
    if out is not None:
        import csv

        from maglev_match.analyses.restart import RestartKind, stamp
        from maglev_match.core.io import atomic_open, atomic_write_netcdf

        folder, stem = output_target(out, "cycles", f"cycles_{user.name}_{param}")
        path = folder / f"{stem}.csv"
        allrows = [{"branch": k, **r} for k, br in enumerate(branches)
                   for r in _cycle_rows(br, param)]
        with atomic_open(path, "w", newline="") as fh:
            if allrows:
                w = csv.DictWriter(fh, fieldnames=list(allrows[0]))
                w.writeheader()
                w.writerows(allrows)
        result["files"] = [str(path)]
        for k, br in enumerate(branches):  # the full branches, restartable (--restart)
            if not br.points:
                continue
            nc = folder / (f"{stem}.nc" if k == 0 else f"{stem}_{k}.nc")
            ds = stamp(br.to_xarray(system), RestartKind.CYCLE_BRANCH, system, user.name,
                       "cycles")
            ds.attrs["model_file"] = str(Path(model).resolve())  # (for the API's restart)
            atomic_write_netcdf(nc, ds)
            result["files"].append(str(nc))
    if json_out:
        emit_json(result)
        return
    for h, br in zip(chosen, branches, strict=True):
        console.print(f"Hopf point {param} = {h.value:.8g}, frequency {h.frequency:.6g} rad/s, "
                      f"l1 = {h.l1:.4g} ({h.kind}); branch stopped: {br.stopped_reason} after "
                      f"{br.steps} steps", highlight=False)
        _print_user_points(br, param)
        for s in br.special_points:
            console.print(f"  {s.type} at {param} = {s.value:.8g} ({s.located})"
                          f"{': ' + s.detail if s.detail else ''}", highlight=False)
        print_warnings(br.warnings)
    for f in result.get("files", []):
        console.print(f"wrote {f}", highlight=False)
    print_warnings(scan.warnings)


def user_simulate(model: str, sets: list[str] | None, t: float, state: np.ndarray | None,
                  n_save: int, rtol: float, atol: float, json_out: bool, out: Path | None
                  ) -> None:
    """``simulate`` on a user model: from ``--x0`` (default X0, the file's equilibrium
    guess), without physical limits; reports the outcome and the final state."""
    import numpy as np

    from maglev_match.dynamics.integrate.simulate import SimulationOptions, simulate

    user = load_user_model(model)
    system = user_system(user, parse_sets(user, sets))
    x0 = user.x0 if state is None else np.asarray(state, float)
    if x0.shape != (system.dim,):
        raise UserError(f"--x0: {x0.size} values given, model {user.name} has "
                        f"{system.dim} states ({', '.join(system.state_names)})")
    console_err.print(f"simulating model {user.name} for {t:g} s ...", highlight=False)
    res = simulate(system, x0, t, options=SimulationOptions(rtol=rtol, atol=atol),
                   n_save=n_save)
    written = []
    if out is not None:
        if is_file_name(out) and out.suffix != ".csv":
            raise UserError(f"--out {out}: for a user model the history file must end in .csv "
                            "(or give a folder)")
        folder, stem = output_target(out, "simulate", f"simulation_{user.name}")
        path = folder / f"{stem}.csv"
        header = ",".join(["t", *system.state_names])
        np.savetxt(path, np.column_stack([res.t, res.x]), delimiter=",", header=header,
                   comments="")
        written.append(str(path))
    summary = {"model": user.name, "model_file": str(model), "outcome": res.outcome,
               "final_time": res.final_time,
               "final_state": dict(zip(system.state_names, res.final_state.tolist(),
                                       strict=True)),
               "converged_time": res.converged_time, "accepted": res.accepted,
               "rejected": res.rejected, "warnings": list(res.warnings), "files": written}
    if json_out:
        emit_json(summary)
        print_warnings(res.warnings)
        return
    console.print(f"Model {user.name} ({model}): {res.outcome} at t = {res.final_time:.6g} s",
                  highlight=False)
    console.print("final state: " + ", ".join(
        f"{n} = {v:.6g}" for n, v in zip(system.state_names, res.final_state, strict=True)),
        highlight=False)
    console.print(f"steps: {res.accepted} accepted, {res.rejected} rejected", highlight=False)
    for w in written:
        console.print(f"wrote {w}", highlight=False)
    print_warnings(res.warnings)


@restart_errors
def user_cycles_restart(*, user, model: str, restart: Path | None, label: str | None,
                        param: str, sets: list[str] | None, at: list[str] | None, ntst: int,
                        ncol: int, max_steps: int, json_out: bool, out: Path | None) -> None:
    """`cycles --restart` on a user model file (its own cycles file)."""
    from maglev_match.analyses.restart import (
        RestartKind,
        check_parameters,
        load_cycle_restart,
        saved_values,
        stamp,
    )

    _need_label(restart, label)
    refuse_given(HOPF_SEARCH_OPTIONS, "a restart searches no Hopf point: it continues the "
                 "saved branch from --label; leave this option out")
    values = {**parse_sets(user, sets), **parse_sets(user, at, option="--at")}
    system = user.system()
    rs = load_cycle_restart(restart, label, system)
    _refuse_continued_value(rs, sets, at)
    if not given("param"):
        param = rs.param
    if param not in system.param_names:
        raise UserError(f"--param {param}: model file {model} has no such parameter; valid "
                        f"names: {', '.join(system.param_names)}")
    if values:
        system = user_system(user, values, "--set/--at")
    else:
        system = user_system(user, saved_values(rs), "the saved parameters")
    check_parameters(rs, system, param)
    ntst, ncol = _mesh(rs, ntst, ncol)
    from maglev_match.dynamics.cycles import cycle_branch

    with progress_report("cycles") as prog:
        prog.stage(f"{rs.describe()}; no Hopf search ...")
        br = cycle_branch(system, rs.start, param, ntst=ntst, ncol=ncol, max_steps=max_steps,
                          restart=rs.state, restart_param=rs.param,
                          observables=tuple(system.observables))
    header = rs.describe() + (f", continued in {param}" if param != rs.param else "")
    result = {"model": user.name, "model_file": str(model), "param": param,
              "restart": _restart_json(rs, param),
              "branches": [{"hopf": rs.start.value, "branch": _cycle_rows(br, param),
                            "special_points": _special_rows_user(br, param),
                            "stopped_reason": br.stopped_reason,
                            "warnings": list(br.warnings)}],
              "hopf_points": [], "warnings": []}
    if out is not None:
        import csv

        from maglev_match.core.io import atomic_open, atomic_write_netcdf

        folder, stem = output_target(out, "cycles", f"cycles_{user.name}_{param}_restart")
        rows = _cycle_rows(br, param)
        path = folder / f"{stem}.csv"
        with atomic_open(path, "w", newline="") as fh:
            if rows:
                w = csv.DictWriter(fh, fieldnames=list(rows[0]))
                w.writeheader()
                w.writerows(rows)
        result["files"] = [str(path)]
        if br.points:
            ds = stamp(br.to_xarray(system), RestartKind.CYCLE_BRANCH, system, user.name,
                       "cycles --restart")
            ds.attrs["restart_of"] = f"{label} of {restart}"
            ds.attrs["model_file"] = str(Path(model).resolve())
            atomic_write_netcdf(folder / f"{stem}.nc", ds)
            result["files"].append(str(folder / f"{stem}.nc"))
    if json_out:
        emit_json(result)
        return _fail_if_nothing_continued(br, rs)
    console.print(f"cycles: {header}; no Hopf search", highlight=False, markup=False)
    console.print(f"branch stopped: {br.stopped_reason} after {br.steps} steps",
                  highlight=False)
    _print_user_points(br, param)
    for s in br.special_points:
        console.print(f"  {s.label or s.type}: {s.type} at {param} = {s.value:.8g} "
                      f"({s.located})", highlight=False)
    for f in result.get("files", []):
        console.print(f"wrote {f}", highlight=False)
    print_warnings(br.warnings)
    _fail_if_nothing_continued(br, rs)
