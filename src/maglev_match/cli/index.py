"""`maglev-match index` (the main job) and `maglev-match map`."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from maglev_match.cli import app
from maglev_match.cli.common import (
    DEFAULT_PRESET_NAME,
    ConfigOpt,
    JsonOpt,
    PresetOpt,
    SetOpt,
    check_index_params,
    check_output_path,
    console,
    console_err,
    emit_json,
    ntst_option,
    output_target,
    params_from_options,
    print_warnings,
    progress_report,
    rows_per_tile_option,
    scheduler_option,
    workers_option,
)
from maglev_match.cli.models import MaglevOnlyModelOpt, refuse_model_file

CASE_TEXT = {
    "unstable_equilibrium": "the equilibrium is unstable (h = 0)",
    "unstable_cycle": "an unstable limit cycle surrounds the stable equilibrium (h = its max gap "
    "deviation)",
    "no_cycle_within_limits": "no unstable cycle surrounds the equilibrium within the gap range "
    "(h = gap_max - c0)",
}


@app.command("index")
def index_command(
    preset: PresetOpt = DEFAULT_PRESET_NAME,
    config: ConfigOpt = None,
    set_: SetOpt = None,
    no_simulation: Annotated[
        bool, typer.Option("--no-simulation", help="Skip the simulation-based h_simulation.")
    ] = False,
    json_out: JsonOpt = False,
    model: MaglevOnlyModelOpt = None,
) -> None:
    """The matching index chi = h / w0 of model A, with the case that decided h."""
    refuse_model_file(model, "index")
    from maglev_match.matching import matching_index

    params = params_from_options(preset, config, set_)
    check_index_params(params)
    with progress_report("index") as prog:
        prog.stage("computing the matching index ...")
        res = matching_index(params, simulate=not no_simulation)
    if json_out:
        emit_json(res.as_json())
        return
    mm = 1e3
    verdict = "[bold green]stable[/]" if res.stable else "[bold red]unstable[/]"
    console.print(f"[bold]maglev-match index[/] — preset {preset}"
                  + (f", config {config}" if config else "")
                  + (f", set {' '.join(set_)}" if set_ else ""))
    console.print(f"  beam: omega1 = {res.omega1:.5g} rad/s, sigma = {res.sigma:.4g} 1/kg")
    console.print(f"  equilibrium: {verdict}, max Re(lambda) = {res.max_real_part:.4g} 1/s")
    if res.hopf_param is not None:
        dist = f" ({res.hopf_distance:.1%} away)" if res.hopf_distance is not None else ""
        kind = ("subcritical" if (res.l1 or 0) > 0 else "supercritical") if res.l1 else ""
        console.print(f"  nearest Hopf point: {res.hopf_param} = {res.hopf_value:.6g}{dist}"
                      + (f", {kind}, l1 = {res.l1:.3g}" if kind else ""))
    console.print(f"  h  = {res.h * mm:.4g} mm: {CASE_TEXT.get(res.case, res.case)}")
    console.print(f"  w0 = {res.w0 * mm:.4g} mm (static beam deflection)")
    console.print(f"  [bold]chi = {res.chi:.4g}[/]: {res.reading}")
    if res.h_simulation is not None:
        console.print(f"  by simulation: the largest beam-deflection disturbance x5(0) that "
                      f"returns is {res.h_simulation * mm:.4g} mm, chi_simulation = "
                      f"{res.chi_simulation:.4g}")
    if res.current_reverses:
        console.print("  [yellow]note:[/] the coil current on the cycle would reverse (min "
                      f"{res.cycle_current_min:.3g} A); the clamped system differs there")
    if not res.converged:
        console_err.print(f"[red]continuation failed:[/] {res.message}")
    print_warnings(res.warnings)


@app.command("map")
def map_command(
    x: Annotated[str, typer.Option("--x", help="NAME=START:STOP:COUNT, e.g. omega1=40:190:100")],
    y: Annotated[str, typer.Option("--y", help="NAME=START:STOP:COUNT, e.g. sigma=2e-4:6e-4:100")],
    preset: PresetOpt = DEFAULT_PRESET_NAME,
    config: ConfigOpt = None,
    set_: SetOpt = None,
    out: Annotated[Path | None, typer.Option(
        "--out", help="netCDF file to write, or a folder for map_X_Y.nc (default: "
        "maglev-match-out/map/).")] = None,
    resume: Annotated[bool, typer.Option("--resume", help="Reuse finished tiles.")] = False,
    scheduler: Annotated[
        str | None, typer.Option("--scheduler", help="Existing Dask scheduler, tcp://host:port.",
                                 callback=scheduler_option)
    ] = None,
    workers: Annotated[
        int | None, typer.Option("--workers", help="Local workers (default: all cores; 0: none).",
                                 callback=workers_option)
    ] = None,
    rows_per_tile: Annotated[int, typer.Option("--rows-per-tile",
                                               callback=rows_per_tile_option)] = 2,
    ntst: Annotated[int, typer.Option("--ntst", help="Collocation intervals for cycles.",
                                      callback=ntst_option)] = 30,
    json_out: JsonOpt = False,
    model: MaglevOnlyModelOpt = None,
) -> None:
    """Stability, h, w0 and chi over a grid of two parameters (netCDF + figure)."""
    refuse_model_file(model, "map")
    from maglev_match.io import atomic_write
    from maglev_match.maps import MapSpec, map_dataset, parse_axis, run_map
    from maglev_match.params import ParameterError
    from maglev_match.plots import save_figure
    from maglev_match.plots.maps import map_figure

    check_output_path(out)
    base = params_from_options(preset, config, set_)
    ax, ay = parse_axis(x, "--x"), parse_axis(y, "--y")
    folder, stem = output_target(out, "map", f"map_{ax.name}_{ay.name}")
    if rows_per_tile < 1:
        raise ParameterError("--rows-per-tile", rows_per_tile, "must be at least 1")
    spec = MapSpec(base=base.as_input_dict(), x=ax, y=ay, rows_per_tile=rows_per_tile,
                   ntst=ntst)
    spec.validate()  # every grid point, before any work starts
    out = folder / f"{stem}.nc"
    checkpoint = out.with_name(out.name + ".tiles")
    with progress_report("map") as prog:
        prog.stage(f"map {ax.name} x {ay.name}: {len(spec.tiles)} tiles ...")
        data = run_map(spec, checkpoint, resume=resume, scheduler=scheduler, workers=workers,
                       progress=prog.tiles)
    from maglev_match.datasets import annotate_map

    ds = annotate_map(map_dataset(spec, data), base)
    out.parent.mkdir(parents=True, exist_ok=True)
    atomic_write(out, lambda tmp: ds.to_netcdf(tmp, engine="h5netcdf"))
    figs = save_figure(map_figure(ds, design_point=(float(getattr(base, ax.name)),
                                                    float(getattr(base, ay.name)))),
                       out.with_suffix(""))
    summary = {
        "netcdf": str(out), "figures": [str(f) for f in figs], "x": ax.name, "y": ay.name,
        "shape": [ay.count, ax.count], "stable_fraction": float(ds["stable"].mean()),
        "chi_max": float(ds["chi"].max()), "unresolved": int((ds["resolved"] == 0).sum()),
    }
    if json_out:
        emit_json(summary)
        return
    console.print(f"wrote {out} and {', '.join(str(f) for f in figs)}")
    console.print(f"stable at {summary['stable_fraction']:.0%} of the points; chi up to "
                  f"{summary['chi_max']:.3g}; {summary['unresolved']} unresolved points")
