"""``cycles --restart FILE --label L`` and ``hopf-curve --restart FILE --label L``: continue
a saved branch, saying what was done.

A restart searches no Hopf point (the branch's Hopf start is in the file), names the restart
point and file in its first line, draws the saved part of the branch and the restart point
in its figure, and refuses every option that would not apply: the Hopf search's range and
sampling, a mesh other than the saved one, and parameter values other than the saved ones
(give none, and the saved values are used; give them, and they must be the saved ones:
the restart continues the saved orbit, which belongs to those values). The library side
is :mod:`maglev_match.analyses.restart`.
"""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import typer

from maglev_match.cli.common import (
    UserError,
    check_model,
    emit_json,
    given,
    output_target,
    params_from_options,
    print_error,
    progress_report,
    refuse_given,
)
from maglev_match.maglev.catalog import MODEL_NAMES

__all__ = ["cycles_restart", "hopf_curve_restart", "restart_errors"]

#: Options of `cycles` that only steer the Hopf search a restart does not do.
HOPF_SEARCH_OPTIONS = {"start": "--from", "stop": "--to", "all_hopf": "--all", "n_scan": "--scan"}
#: Options that choose parameter values.
PARAMETER_OPTIONS = ("preset", "config", "set_", "at")

if TYPE_CHECKING:  # NumPy is imported when a restart runs (fast usage errors)
    import numpy as np


def restart_errors(fn):
    """Turn the restart module's errors into command-line errors (exit code 2)."""
    import functools

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        from maglev_match.analyses.restart import (
            RestartFileError,
            RestartLabelError,
            RestartMismatch,
        )

        try:
            return fn(*args, **kwargs)
        except RestartLabelError as exc:
            raise UserError(f"--label {exc.label}: {exc}") from None
        except (RestartFileError, RestartMismatch) as exc:
            raise UserError(f"--restart: {exc}") from None

    return wrapper


def _need_label(restart: Path | None, label: str | None) -> None:
    if restart is None or label is None:
        raise UserError("--restart FILE and --label LABEL go together (e.g. --restart "
                        "branch.nc --label P12)")


def _named(items: list[str] | None) -> set[str]:
    return {t.split("=", 1)[0].strip() for t in items or [] if "=" in t}


def _refuse_continued_value(rs, set_: list[str] | None, at: list[str] | None) -> None:
    """A --set/--at of the parameter the saved branch is continued in would be dropped (its
    value comes from the restart point): refused."""
    if rs.param in _named(set_) | _named(at):
        raise UserError(f"--set/--at {rs.param}: {rs.param} is the parameter the saved branch "
                        f"is continued in; a restart takes its value from the restart point "
                        f"{rs.label} ({rs.param} = {rs.value:.8g}); leave it out")


def _mesh(rs, ntst: int, ncol: int) -> tuple[int, int]:
    """The saved mesh; a --ntst/--ncol that differs from it is refused."""
    saved_ntst, saved_ncol = rs.state.mesh.size - 1, rs.ncol
    for name, option, value, saved in (("ntst", "--ntst", ntst, saved_ntst),
                                       ("ncol", "--ncol", ncol, saved_ncol)):
        if given(name) and value != saved:
            raise UserError(f"{option} {value}: a restart goes on with the saved mesh "
                            f"({option} {saved}); leave {option} out")
    return saved_ntst, saved_ncol


def _saved_part(rs, system, observable: str) -> tuple[np.ndarray, ...]:
    """Values, max, min and stability of ``observable`` over the saved branch points."""
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


def _restart_point_extrema(rs, system, observable: str) -> tuple[float, float]:
    from maglev_match.dynamics.cycles import PeriodicOrbit, orbit_extrema

    orbit = PeriodicOrbit(mesh=rs.state.mesh, ncol=rs.ncol, states=rs.state.states,
                          period=rs.state.period, p=rs.p)
    return orbit_extrema(system, orbit, [observable])[observable]


def _fail_if_nothing_continued(br, rs) -> None:
    """A restart whose first point does not converge continued nothing: a numerical
    failure, exit code 1 (after the result was printed), never a silent exit 0."""
    if br.points:
        return
    why = "; ".join(br.warnings) or str(br.stopped_reason)
    print_error(f"the restart from {rs.label} of {rs.path} continued nothing: {why} "
                f"(stopped: {br.stopped_reason}); the saved point does not solve the "
                "periodic problem of this model with these values")
    raise typer.Exit(1)


def _kind(l1: float | None) -> str:
    """Criticality of the saved Hopf point (as `hopf` and `cycles` print it)."""
    if l1 is None or not math.isfinite(l1):
        return "unknown"
    return "subcritical" if l1 > 0 else "supercritical" if l1 < 0 else "degenerate"


def _restart_json(rs, param: str) -> dict[str, Any]:
    return {"file": rs.path, "label": rs.label, "saved_param": rs.param, "param": param,
            "value": rs.value, "period": rs.period, "hopf_search": False,
            "hopf_value": rs.start.value}


@restart_errors
def cycles_restart(*, restart: Path | None, label: str | None, param: str, model: str,
                   preset: str, config: Path | None, set_: list[str] | None,
                   at: list[str] | None, ntst: int, ncol: int, max_steps: int,
                   ignore_current: bool, json_out: bool, out: Path | None) -> None:
    """`cycles --restart` on model A or B."""
    import numpy as np

    from maglev_match.analyses.engineering import is_engineering
    from maglev_match.analyses.restart import (
        RestartKind,
        check_parameters,
        load_cycle_restart,
        saved_params,
        stamp,
    )
    from maglev_match.cli.cycle_tables import (
        _branch_rows,
        _special_rows,
        _write_csv,
        apply_at,
    )
    from maglev_match.maglev.limits import cycle_limit_margins
    from maglev_match.maglev.models import build_system

    _need_label(restart, label)
    refuse_given(HOPF_SEARCH_OPTIONS, "a restart searches no Hopf point: it continues the "
                 "saved branch from --label; leave this option out")
    if is_engineering(param):
        raise UserError(f"--param {param}: a restart continues in a model parameter "
                        "(omega1, sigma, kD, ...), not along beam or vehicle data")
    # the model: the one named, or the one the file was saved for
    from maglev_match.analyses.restart import open_saved

    saved_model = open_saved(restart)[0].attrs.get("model")
    if not given("model") and saved_model in MODEL_NAMES:
        model = saved_model
    check_model(model)
    own_values = any(given(n) for n in PARAMETER_OPTIONS)
    params = apply_at(params_from_options(preset, config, set_), at)
    system = build_system(params, model)
    rs = load_cycle_restart(restart, label, system)
    _refuse_continued_value(rs, set_, at)
    if not given("param"):
        param = rs.param
    if param not in system.param_names:
        raise UserError(f"--param {param}: model '{model}' has no such parameter")
    if own_values:
        check_parameters(rs, system, param)
    else:  # the saved values (the parameter set the branch was computed with)
        saved = saved_params(rs)
        if saved is not None:
            params = saved
            system = build_system(params, model)
        check_parameters(rs, system, param)
    ntst, ncol = _mesh(rs, ntst, ncol)
    limits = cycle_limit_margins(params, include_current=not ignore_current)
    from maglev_match.dynamics.cycles import cycle_branch

    t0 = time.perf_counter()
    with progress_report("cycles") as prog:
        prog.stage(f"{rs.describe()}; no Hopf search ...")

        def report(step, pt):
            prog.update(f"restart from {label}: step {step}, {param} = {pt.value:.6g}, max "
                        f"gap dev {pt.extrema['gap_deviation'][0] * 1e3:.3f} mm")

        br = cycle_branch(system, rs.start, param, ntst=ntst, ncol=ncol, max_steps=max_steps,
                          limits=limits, progress=report, restart=rs.state,
                          restart_param=rs.param)
        prog.stage(f"restarted branch: {len(br.points)} cycles, stopped: {br.stopped_reason}")
    elapsed = time.perf_counter() - t0
    header = rs.describe() + (f", continued in {param}" if param != rs.param else "")
    result: dict[str, Any] = {
        "model": model, "param": param,
        "restart": _restart_json(rs, param),
        "hopf": {rs.param: rs.start.value, "l1": rs.start.l1,
                 "kind": _kind(rs.start.l1), "frequency": rs.start.frequency,
                 "period": 2 * np.pi / rs.start.frequency, "from_file": True},
        "label": "b1", "branch": _branch_rows(br, param),
        "special_points": _special_rows(br, param), "stopped_reason": br.stopped_reason,
        "steps": br.steps, "warnings": list(br.warnings), "hopf_points": [],
        "mesh": {"ntst": ntst, "ncol": ncol}, "elapsed_s": elapsed,
    }
    files: list[Path] = []
    if out is not None or not json_out:
        folder, stem = output_target(out, "cycles", f"cycles_{model}_{param}_restart")
        rows = [{"branch": "b1", "restart_of": f"{label} of {restart}", **r}
                for r in _branch_rows(br, param)]
        _write_csv(folder / f"{stem}.csv", rows, param)
        _write_csv(folder / f"{stem}_special_points.csv",
                   [{"branch": "b1", **r} for r in _special_rows(br, param)], param)
        files += [folder / f"{stem}.csv", folder / f"{stem}_special_points.csv"]
        if br.points:
            from maglev_match.cli.common import unit_of
            from maglev_match.core.datasets import annotate
            from maglev_match.core.io import atomic_write_netcdf

            nc_ds = annotate(br.to_xarray(build_system(params, model),
                                          param_unit=unit_of(param)), params)
            stamp(nc_ds, RestartKind.CYCLE_BRANCH, system, model, "cycles --restart")
            nc_ds.attrs["restart_of"] = f"{label} of {restart}"
            atomic_write_netcdf(folder / f"{stem}.nc", nc_ds)
            files.append(folder / f"{stem}.nc")
        files += _restart_figure(br, rs, system, param, params, folder / stem, header, at)
        result["files"] = [str(f) for f in files]
    if json_out:
        emit_json(result)
        return _fail_if_nothing_continued(br, rs)
    from maglev_match.cli.cycle_tables import _print_summary

    _print_summary(result, [br], [rs.start], param, files,
                   first_line=f"cycles: {header}; no Hopf search; branch stopped: "
                   f"{br.stopped_reason} after {br.steps} steps")
    _fail_if_nothing_continued(br, rs)


def _restart_figure(br, rs, system, param, params, target: Path, header: str, at) -> list:
    import numpy as np

    from maglev_match.plots import save_figure
    from maglev_match.plots.cycles import cycle_diagram
    from maglev_match.plots.restart import draw_saved_part

    at_text = ", ".join(at or [])
    fig, ax = cycle_diagram(
        [br], param, title=f"Cycles along {param}, restarted from {rs.label}"
        + (f" ({at_text})" if at_text else ""),
        limits=(params.gap_min - params.c0, params.gap_max - params.c0),
        design_value=getattr(params, param, None))
    if param == rs.param:
        vals, hi, lo, st = _saved_part(rs, system, "gap_deviation")
        rv = rs.value
    else:  # the saved branch lies along another parameter: only the restart point
        vals = hi = lo = np.zeros(0)
        st = np.zeros(0, bool)
        rv = float(rs.p[list(rs.parameter_names).index(param)])
    draw_saved_part(ax, vals, hi, lo, st, rv,
                    _restart_point_extrema(rs, system, "gap_deviation"), label=rs.label,
                    source=Path(rs.path).name, scale=1e3,
                    new_branch_text=f"b1: continued from {rs.label} of {Path(rs.path).name}")
    return save_figure(fig, target.with_suffix(".png"))


@restart_errors
def hopf_curve_restart(*, rm, restart: Path | None, label: str | None,
                       given_names: tuple[str, str] | None,
                       given_bounds: dict[str, tuple[float, float]],
                       max_step: float, sets: list[str] | None = None,
                       ) -> tuple[Any, Any, tuple[str, str], dict[str, tuple[float, float]],
                                  Any, Any]:
    """The Hopf curve continued from a saved point: (curve, restart, names, bounds, system,
    params). The curve parameters are the saved ones (a --params naming others is refused);
    --range widens or narrows the saved bounds; without --preset/--config/--set the saved
    parameter values are used (``system``, and ``params`` for the maglev models)."""
    import dataclasses

    import numpy as np

    from maglev_match.analyses.restart import (
        load_hopf_curve_restart,
        restart_hopf_curve,
        saved_params,
        saved_values,
    )

    _need_label(restart, label)
    rs = load_hopf_curve_restart(restart, label, rm.system)
    if given_names is not None and tuple(given_names) != rs.names:
        raise UserError(f"--params {','.join(given_names)}: the saved curve is in "
                        f"({', '.join(rs.names)}); a restart continues it there")
    fixed = sorted(set(rs.names) & _named(sets))
    if fixed:
        raise UserError(f"--set {fixed[0]}: {fixed[0]} varies along the saved Hopf curve; a "
                        f"restart starts from the point {rs.label} ({rs.names[0]} = "
                        f"{rs.values[0]:.8g}, {rs.names[1]} = {rs.values[1]:.8g}); leave it "
                        "out")
    system, params = rm.system, rm.params
    if not any(given(n) for n in PARAMETER_OPTIONS):  # the saved values
        saved = saved_params(rs) if not rm.is_user else None
        if saved is not None:
            from maglev_match.maglev.models import build_system

            params, system = saved, build_system(saved, rm.label)
        else:
            vals = saved_values(rs)
            system = dataclasses.replace(system, p=np.array([vals[n]
                                                             for n in system.param_names]))
    bounds = {**rs.bounds, **given_bounds}
    curve, rs = restart_hopf_curve(restart, label, system, bounds, max_step=max_step)
    return curve, rs, rs.names, bounds, system, params
