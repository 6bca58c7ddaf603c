"""`maglev-match cycles`: periodic orbits born at Hopf points, continued in one parameter
(paper Fig. 5): max/min gap deviation, period, Floquet stability, folds and limit contacts."""

from __future__ import annotations

import time
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import numpy as np
import typer

from maglev_match.cli import app
from maglev_match.cli.common import (
    DEFAULT_PRESET_NAME,
    PARAM_HELP,
    SCAN_MAX,
    ConfigOpt,
    JsonOpt,
    ModelOpt,
    OutOpt,
    PresetOpt,
    SetOpt,
    UserError,
    bounded,
    check_model,
    check_output_path,
    console,
    emit_json,
    finite,
    ncol_option,
    ntst_option,
    output_target,
    preload,
    progress_report,
    steps_option,
)
from maglev_match.cli.common import params_from_options as _params
from maglev_match.cli.cycle_tables import (  # noqa: F401 (apply_at: also used by tests)
    _branch_rows,
    _print_summary,
    _special_rows,
    _write_csv,
    apply_at,
)
from maglev_match.cli.models import MAGLEV_DELAYS, is_model_file, user_cycles
from maglev_match.core.params import ParameterError

if TYPE_CHECKING:  # the numerics (and JAX) are imported when the command runs
    from maglev_match.dynamics.cycles import CycleBranch
    from maglev_match.dynamics.hopf import HopfPoint

AtOpt = Annotated[
    list[str] | None,
    typer.Option("--at", help="Fix another parameter, NAME=VALUE (repeatable), e.g. "
                 "--at sigma=4e-4. Applied after --preset/--config/--set."),
]


def _hopf_json(h: HopfPoint, param: str) -> dict[str, Any]:
    return {param: h.value, "l1": h.l1, "kind": h.kind, "frequency": h.frequency,
            "period": 2 * np.pi / h.frequency, "crossing_speed": h.crossing_speed,
            "others_stable": h.others_stable, "converged": h.converged}


@app.command("cycles")
def cycles_command(
    param: Annotated[str, typer.Option("--param", help=PARAM_HELP)] = "omega1",
    at: AtOpt = None,
    start: Annotated[float | None, typer.Option(
        "--from", help="Search Hopf points from this value (default: design value / 4).",
        callback=finite)] = None,
    stop: Annotated[float | None, typer.Option(
        "--to", help="... up to this value (default: design value x 4).",
        callback=finite)] = None,
    all_hopf: Annotated[bool, typer.Option(
        "--all", help="Continue from every Hopf point in the range (default: the one "
        "nearest the design value).")] = False,
    n_scan: Annotated[int, typer.Option(
        "--scan", help="Sampling of the equilibrium branch searched for Hopf points (steps "
        "at most 1/scan of the range).", callback=bounded(3, SCAN_MAX, integer=True))] = 100,
    ntst: Annotated[int, typer.Option("--ntst", help="Mesh intervals.",
                                      callback=ntst_option)] = 80,
    ncol: Annotated[int, typer.Option("--ncol", help="Collocation points (2-7).",
                                      callback=ncol_option)] = 4,
    max_steps: Annotated[int, typer.Option("--max-steps", help="Continuation steps.",
                                           callback=steps_option)] = 300,
    ignore_current: Annotated[bool, typer.Option(
        "--ignore-current", help="Do not stop where the coil current reaches 0 (only the "
        "gap limits stop the branch).")] = False,
    preset: PresetOpt = DEFAULT_PRESET_NAME,
    config: ConfigOpt = None,
    set_: SetOpt = None,
    model: ModelOpt = "unit",
    json_out: JsonOpt = False,
    out: OutOpt = None,
    restart: Annotated[Path | None, typer.Option(
        "--restart", help="Continue from a point of a branch saved by --out (netCDF) instead "
        "of from a Hopf point: no Hopf search (--from/--to/--all/--scan are refused), the "
        "saved model, mesh and parameter values (give no --preset/--config/--set/--at, or the "
        "saved ones). With another --param the saved cycle is continued in that "
        "parameter.")] = None,
    label: Annotated[str | None, typer.Option(
        "--label", help="With --restart: the point to continue from, P<k> for the k-th "
        "branch point or a special point's label (LPC1, PD1, ...).")] = None,
) -> None:
    """Cycles born at Hopf points, continued in --param until a physical limit (Fig. 5)."""
    check_output_path(out)
    if not 2 <= ncol <= 7:
        raise ParameterError("--ncol", ncol, "must be between 2 and 7")
    if ntst < 4:
        raise ParameterError("--ntst", ntst, "must be at least 4")
    if is_model_file(model):  # a user model file: no maglev limits or read-outs
        return user_cycles(model, set_, at, param, start, stop, all_hopf, n_scan, ntst, ncol,
                           max_steps, json_out, out, restart=restart, label=label)
    if restart is not None or label is not None:  # continue a saved branch (cli/restart.py)
        from maglev_match.cli.restart import cycles_restart

        return cycles_restart(restart=restart, label=label, param=param, model=model,
                              preset=preset, config=config, set_=set_, at=at, ntst=ntst,
                              ncol=ncol, max_steps=max_steps, ignore_current=ignore_current,
                              json_out=json_out, out=out)
    check_model(model)
    params = apply_at(_params(preset, config, set_), at)
    # the numerics (and JAX) once the options are known to be good
    from maglev_match.analyses.engineering import engineering_system, is_engineering
    from maglev_match.dynamics.cycles import cycle_branch
    from maglev_match.dynamics.delay import delay_hopf_points, is_delay_parameter
    from maglev_match.dynamics.hopf import locate_hopf_points
    from maglev_match.maglev.limits import cycle_limit_margins
    from maglev_match.maglev.models import build_system

    if out is not None or not json_out:  # files at the end: load their writers meanwhile
        preload("maglev_match.plots.cycles", "maglev_match.core.datasets", "xarray", "h5netcdf")
    system = build_system(params, model)
    try:
        design = getattr(params, param) if is_engineering(param) else (
            params.tau if param in MAGLEV_DELAYS else system.param(param))
    except KeyError as exc:
        raise UserError(str(exc).strip("'\"")) from None
    a = design / 4 if start is None else start
    b = design * 4 if stop is None else stop
    if param in MAGLEV_DELAYS:  # a delay axis: the discretised delay system up to its end
        a = 0.0 if start is None else start
        if not b > 0:
            raise UserError(f"--param {param}: give the largest delay with --to (the design "
                            f"value is {design:g} s)")
        if min(a, b) < 0:
            raise ParameterError("--from", min(a, b), f"{param} is a delay: >= 0 s")
        system = build_system(params, model, tau_max=max(a, b))
    if is_engineering(param):  # beam/vehicle data: omega1, sigma (geometry) follow it
        if start is None or stop is None:
            raise UserError(f"--param {param}: give the range with --from and --to")
        system = engineering_system(params, model, param, min(a, b), max(a, b))
    if not (np.isfinite(a) and np.isfinite(b)) or a == b:
        raise UserError(f"--from/--to: empty search range [{a}, {b}]")
    t0 = time.perf_counter()
    if n_scan < 3:
        raise ParameterError("--scan", n_scan, "must be at least 3")
    with progress_report("cycles") as prog:
        prog.stage(f"searching Hopf points along {param} in [{a:.6g}, {b:.6g}] ...")
        if is_delay_parameter(system, param):  # crossings of the characteristic equation
            scan = delay_hopf_points(system, param, min(a, b), max(a, b), n_scan=n_scan)
        else:
            scan = locate_hopf_points(system, param, min(a, b), max(a, b), n_scan=n_scan)
        hopfs = [h for h in scan.points if h.converged]
        if not hopfs:
            raise UserError(f"no Hopf point of the equilibrium along {param} in "
                            f"[{a:.6g}, {b:.6g}]; widen --from/--to")
        hopfs.sort(key=lambda h: abs(h.value - design))
        chosen = hopfs if all_hopf else hopfs[:1]
        limits = cycle_limit_margins(params, include_current=not ignore_current)
        branches: list[CycleBranch] = []
        for h in chosen:
            prog.stage(f"continuing cycles from the Hopf point {param} = {h.value:.6g} ...")

            def report(step, pt, h=h):
                prog.update(f"cycles from Hopf at {param} = {h.value:.6g}: step {step}, "
                            f"{param} = {pt.value:.6g}, max gap dev "
                            f"{pt.extrema['gap_deviation'][0] * 1e3:.3f} mm")

            br = cycle_branch(system, h, param, ntst=ntst, ncol=ncol, max_steps=max_steps,
                              limits=limits, progress=report)
            branches.append(br)
            prog.stage(f"branch from {param} = {h.value:.6g}: {len(br.points)} cycles, "
                       f"ended: {br.stopped_reason}")
    elapsed = time.perf_counter() - t0

    main_branch, h0 = branches[0], chosen[0]
    result: dict[str, Any] = {
        "model": model,
        "param": param,
        "at": {k.split("=")[0]: float(k.split("=")[1]) for k in (at or [])},
        "hopf": _hopf_json(h0, param),
        "label": "b1",  # the label of the branch in the figure and the CSV
        "branch": _branch_rows(main_branch, param),
        "special_points": _special_rows(main_branch, param),
        "stopped_reason": main_branch.stopped_reason,
        "end": main_branch.message,
        "steps": main_branch.steps,
        "warnings": list(main_branch.warnings) + list(scan.warnings),
        "hopf_points": [_hopf_json(h, param) for h in hopfs],
        "mesh": {"ntst": ntst, "ncol": ncol},
        "elapsed_s": elapsed,
    }
    if all_hopf and len(branches) > 1:
        result["other_branches"] = [
            {"label": f"b{k + 2}", "hopf": _hopf_json(h, param),
             "branch": _branch_rows(br, param),
             "special_points": _special_rows(br, param), "stopped_reason": br.stopped_reason,
             "warnings": list(br.warnings)}
            for k, (h, br) in enumerate(zip(chosen[1:], branches[1:], strict=True))
        ]
    if json_out:
        if out is not None:
            files = _write_outputs(out, param, model, scan, branches, params, at, system)
            result["files"] = [str(f) for f in files]
        emit_json(result)
        return
    # The answer first, the files after: writing the netCDF and the figure costs about a
    # second (xarray, HDF5 and two renderings), which the reader need not wait for.
    _print_summary(result, branches, chosen, param, [])
    with progress_report("cycles") as prog:
        prog.stage("writing the branch files and the figure ...")
        files = _write_outputs(out, param, model, scan, branches, params, at, system)
    for f in files:
        console.print(f"wrote {f}")


def _write_outputs(out, param, model, scan, branches, params, at, system=None) -> list[Path]:
    from maglev_match.plots import save_figure
    from maglev_match.plots.cycles import branch_label, cycle_diagram

    folder, stem = output_target(out, "cycles", f"cycles_{model}_{param}")
    files = []
    rows, specials = [], []
    for k, br in enumerate(branches):
        for r in _branch_rows(br, param):
            rows.append({"branch": branch_label(k), "hopf": br.hopf.value, **r})
        for r in _special_rows(br, param):
            specials.append({"branch": branch_label(k), **r})
    _write_csv(folder / f"{stem}.csv", rows, param)
    _write_csv(folder / f"{stem}_special_points.csv", specials, param)
    files += [folder / f"{stem}.csv", folder / f"{stem}_special_points.csv"]
    # the full branches (profiles, multipliers, special points, restart data) as netCDF
    from maglev_match.analyses.restart import RestartKind, stamp
    from maglev_match.cli.common import unit_of
    from maglev_match.core.datasets import annotate
    from maglev_match.core.io import atomic_write_netcdf
    from maglev_match.maglev.models import build_system

    system = build_system(params, model) if system is None else system
    for k, br in enumerate(branches):
        if not br.points:
            continue
        nc = folder / (f"{stem}.nc" if k == 0 else f"{stem}_{k}.nc")
        ds = annotate(br.to_xarray(system, param_unit=unit_of(param)), params)
        stamp(ds, RestartKind.CYCLE_BRANCH, system, model, "cycles")  # restartable
        atomic_write_netcdf(nc, ds)
        files.append(nc)
    lo = min([scan.scan_values[0]] + [float(np.min(b.values)) for b in branches if b.points])
    hi = max([scan.scan_values[-1]] + [float(np.max(b.values)) for b in branches if b.points])
    sel = (scan.scan_values >= lo) & (scan.scan_values <= hi)
    at_text = ", ".join(at or [])
    fig, _ = cycle_diagram(
        branches, param, scan.scan_values[sel], scan.max_real_part[sel] < 0,
        title=f"Cycles along {param}" + (f" ({at_text})" if at_text else ""),
        limits=(params.gap_min - params.c0, params.gap_max - params.c0),
        design_value=getattr(params, param, None),
    )
    files += save_figure(fig, folder / f"{stem}.png")
    return files


