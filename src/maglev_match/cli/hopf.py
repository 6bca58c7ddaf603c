"""`maglev-match hopf` (Hopf points along one parameter) and `hopf-curve` (the Hopf curve in
two parameters with l1 and codimension-two points, paper Fig. 4): options parsed here, the
computation in :mod:`maglev_match.api.hopf`, the answer printed and saved here."""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Annotated

import typer
from rich.table import Table

from maglev_match.cli import app
from maglev_match.cli.common import (
    DEFAULT_PRESET_NAME,
    PARAM_HELP,
    ConfigOpt,
    JsonOpt,
    ModelOpt,
    OutOpt,
    PresetOpt,
    SetOpt,
    UserError,
    api_options,
    check_output_path,
    console,
    emit_json,
    finite,
    fraction_option,
    grid_option,
    model_inputs,
    output_target,
    parse_range,
    print_warnings,
    progress_report,
    refuse_given,
    scan_option,
    unit_of,
)
from maglev_match.core.io import atomic_open
from maglev_match.core.params import ParameterError
from maglev_match.core.units import header

#: API keyword -> option, for `hopf`
HOPF_OPTIONS = {"param": "--param", "start": "--from", "stop": "--to", "n_scan": "--steps",
                "model": "--model", "config": "--config"}
#: API keyword -> option, for `hopf-curve`
HOPF_CURVE_OPTIONS = {"x": "--params", "y": "--params", "names": "--params",
                      "bounds": "--range", "n_scan": "--scan-steps", "grid": "--grid",
                      "max_step": "--max-step", "model": "--model", "config": "--config",
                      "restart": "--restart", "label": "--label", "x/y": "--params",
                      "restart/label": "--restart"}


@app.command("hopf")
def hopf_command(
    param: Annotated[str, typer.Option("--param", help=PARAM_HELP)] = "omega1",
    start: Annotated[float, typer.Option("--from", help="First value.", callback=finite)] = 30.0,
    stop: Annotated[float, typer.Option("--to", help="Last value.", callback=finite)] = 300.0,
    steps: Annotated[int, typer.Option("--steps", help="Sampling of the equilibrium branch: "
                                       "its steps are at most 1/steps of the range.",
                                       callback=scan_option)] = 200,
    preset: PresetOpt = DEFAULT_PRESET_NAME,
    config: ConfigOpt = None,
    set_: SetOpt = None,
    model: ModelOpt = "unit",
    out: OutOpt = None,
    json_out: JsonOpt = False,
) -> None:
    """Hopf points of the equilibrium along one parameter: value, frequency, crossing speed
    d Re(lambda)/d param and the first Lyapunov coefficient l1 (> 0 subcritical).

    Writes the points (CSV) and a figure of max Re(lambda) along the parameter with the
    Hopf points marked (PNG/SVG) into --out (default maglev-match-out/hopf/)."""
    check_output_path(out)
    if steps < 2:
        raise ParameterError("--steps", steps, "must be at least 2")
    if not start < stop:
        raise UserError(f"--from {start:g} --to {stop:g}: the range must be increasing")
    params, overrides = model_inputs(model, preset, config, set_)
    from maglev_match import api

    with progress_report("hopf") as prog, api_options(HOPF_OPTIONS):
        scan = api.hopf_points(params, param, start, stop, model=model, n_scan=steps,
                               stage=prog.stage, **overrides)
    user = str(model).endswith(".py")
    model = Path(model).stem if user else model  # (a model file is named by its stem)
    names = scan.columns
    records = scan.records()
    specials = [{"type": str(sp.type), param: sp.value, "located": sp.located,
                 "label": sp.label, "frequency": sp.frequency}
                for sp in scan.special_points]
    delay_note = scan.delay
    unit = "" if user else unit_of(param)
    files = ([] if json_out and out is None else  # --json alone: the JSON is the result
             _write_hopf_points(out, model, param, unit, names, records, scan))
    if json_out:
        emit_json({"param": param, "model": model, "from": start, "to": stop,
                   "points": records, "special_points": specials,
                   "files": [str(f) for f in files], "warnings": list(scan.warnings),
                   **({"delay": delay_note} if delay_note else {})})
        return
    console.print(f"Hopf points along {param} in [{start:g}, {stop:g}] {unit}, "
                  f"model {model}: {len(records)} found")
    if delay_note:
        console.print(delay_note["text"], highlight=False)
    if records:
        table = Table("label", *names, "omega (rad/s)", "dRe/dp", "l1", "type",
                      "others stable", "converged")
        for hp, r in zip(scan.points, records, strict=True):
            table.add_row(r["label"], *[f"{r[n]:.8g}" for n in names], f"{hp.frequency:.6g}",
                          f"{hp.crossing_speed:.4g}", f"{hp.l1:.4g}", hp.kind,
                          str(hp.others_stable), str(hp.converged))
        console.print(table)
        console.print("l1 with <q,q> = 1, <p,q> = 1 (paper eq. 24): > 0 subcritical "
                      "(unstable cycle), < 0 supercritical (stable cycle)")
    folds = [sp for sp in specials if sp["type"] != "H"]
    for sp in folds:
        console.print(f"  {sp['label']}: {sp['type']} of the equilibrium at {param} = "
                      f"{sp[param]:.8g} ({sp['located']})")
    console.print(f"wrote {', '.join(str(f) for f in files)}", highlight=False)
    print_warnings(list(scan.warnings) + [w for hp in scan.points for w in hp.warnings])


def _write_hopf_points(out, model: str, param: str, unit: str, names: tuple[str, ...],
                       records: list[dict], scan) -> list:
    """The Hopf points as CSV (units in the headers, SI values) and the figure of the
    scanned margin max Re(lambda) with the points marked; returns the written files."""
    folder, stem = output_target(out, "hopf", f"hopf_{model}_{param}")
    csv_path = folder / f"{stem}.csv"
    cols = [*names, "frequency", "crossing_speed", "l1", "kind", "others_stable", "converged",
            "residual"]
    with atomic_open(csv_path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow([header(c) if c != param or unit == "" else f"{c} ({unit})"
                     for c in cols])
        for r in records:
            w.writerow([f"{r[c]:.12g}" if isinstance(r[c], float) else r[c] for c in cols])
    from maglev_match.plots import save_figure
    from maglev_match.plots.hopf import hopf_scan_figure

    fig = hopf_scan_figure(scan, param, unit)
    return [csv_path, *save_figure(fig, folder / stem)]


def _parse_ranges(items: list[str] | None) -> dict[str, tuple[float, float]]:
    out: dict[str, tuple[float, float]] = {}
    for item in items or []:
        if "=" not in item:
            raise UserError(f"--range '{item}': expected NAME=FROM:TO, e.g. sigma=1e-4:8e-4")
        name, text = item.split("=", 1)
        a, b = parse_range(text, f"--range {name}")
        if not (math.isfinite(a) and math.isfinite(b)):
            raise UserError(f"--range {item}: FROM and TO must be finite numbers")
        if not a < b:
            raise UserError(f"--range {item}: the range must be increasing (FROM < TO)")
        out[name.strip()] = (a, b)
    return out


@app.command("hopf-curve")
def hopf_curve_command(
    params_opt: Annotated[
        str | None,
        typer.Option("--params", help="Two parameters P1,P2 (default omega1,sigma for "
                     "model unit, omega1,kD for model vehicle)."),
    ] = None,
    ranges: Annotated[
        list[str] | None,
        typer.Option("--range", help="NAME=FROM:TO bounds of a parameter (repeatable); "
                     "defaults omega1=30:400, sigma=1e-4:8e-4, others 0.5x..2x the value."),
    ] = None,
    scan_steps: Annotated[int, typer.Option("--scan-steps", callback=scan_option,
                                            help="Sampling of each equilibrium branch "
                                            "searched for Hopf points.")] = 100,
    grid: Annotated[int, typer.Option("--grid", callback=grid_option, help="Stability grid "
                                      "points per axis for shading S/U (0: no grid).")] = 60,
    max_step: Annotated[float, typer.Option("--max-step", callback=fraction_option,
                                            help="Largest continuation step, "
                                            "as a fraction of the ranges.")] = 1e-2,
    preset: PresetOpt = DEFAULT_PRESET_NAME,
    config: ConfigOpt = None,
    set_: SetOpt = None,
    model: ModelOpt = "unit",
    out: OutOpt = None,
    json_out: JsonOpt = False,
    restart: Annotated[Path | None, typer.Option(
        "--restart", help="Continue a curve saved by --out (netCDF) from the point --label, "
        "in both directions, instead of searching Hopf points (--scan-steps is refused); "
        "the saved parameters and bounds (--range widens them).")] = None,
    label: Annotated[str | None, typer.Option(
        "--label", help="With --restart: P<k> for the k-th curve point or a "
        "codimension-two point's label (GH1, ...).")] = None,
) -> None:
    """The Hopf curve in two parameters by continuation, with l1 along it and the
    codimension-two points (GH with l2, BT, ZH, HH); writes CSV and a Fig. 4-style figure."""
    check_output_path(out)
    user = str(model).endswith(".py")
    restarting = restart is not None or label is not None
    if restarting:
        refuse_given({"scan_steps": "--scan-steps"}, "a restart searches no Hopf point: it "
                     "continues the saved curve from --label; leave this option out")
        if restart is None or label is None:
            raise UserError("--restart FILE and --label LABEL go together (e.g. --restart "
                            "curve.nc --label P3)")
    names = None
    if params_opt is not None:
        parts = [t.strip() for t in params_opt.split(",") if t.strip()]
        if len(parts) != 2 or parts[0] == parts[1]:
            raise UserError(f"--params '{params_opt}': expected two different names P1,P2")
        names = (parts[0], parts[1])
    elif user and not restarting:
        raise UserError(f"--params: give the two parameters of model {Path(model).stem}")
    bounds = _parse_ranges(ranges)
    if names is not None:
        for n in bounds:
            if n not in names:
                raise UserError(f"--range {n}: not one of --params {','.join(names)}")
    # a restart takes the saved values unless --preset/--config/--set are given
    params, overrides = model_inputs(model, preset, config, set_,
                                     default_params=not restarting)
    if params is not None and config is None and not set_:
        params = preset  # the preset by name: the figure's title names it
    from maglev_match import api

    with progress_report("hopf-curve") as prog, api_options(HOPF_CURVE_OPTIONS), \
            _restart_errors():
        x, y = ((None, None) if names is None else
                (tuple((n, *bounds.pop(n)) if n in bounds else n for n in names)))
        st = api.hopf_curve(params, x, y, model=model, bounds=bounds or None,
                            n_scan=scan_steps, max_step=max_step, grid=grid,
                            stage=prog.stage, restart=restart, label=label, study=True,
                            **overrides)
    names = st.names
    folder, stem = output_target(out, "hopf-curve",
                                 f"hopf_curve_{st.model}_{names[0]}_{names[1]}")
    csv_path = folder / f"{stem}.csv"
    points, special = st.point_rows(), st.special_rows()
    nh = [f"{n} ({unit_of(n)})" if not user and unit_of(n) else n for n in names]
    with atomic_open(csv_path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["branch", *nh, header("frequency"), "l1", "others_stable"])
        for r in points:
            w.writerow([r["branch"], f"{r[names[0]]:.12g}", f"{r[names[1]]:.12g}",
                        f"{r['frequency']:.12g}", f"{r['l1']:.8g}", r["others_stable"]])
    sp_path = folder / f"{stem}_special.csv"
    with atomic_open(sp_path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["type", *nh, header("frequency"), "l2", "branch"])
        for r in special:
            w.writerow([r["type"], f"{r[names[0]]:.12g}", f"{r[names[1]]:.12g}",
                        f"{r['frequency']:.10g}", "" if r.get("l2") is None else
                        f"{r['l2']:.8g}", r["branch"]])
    figs = st.plot(folder / stem)
    from maglev_match.core.io import atomic_write_netcdf

    nc_files = []
    for k in range(len(st.curves)):
        nc = folder / (f"{stem}.nc" if k == 0 else f"{stem}_{k}.nc")
        atomic_write_netcdf(nc, st.curve_dataset(k))
        nc_files.append(str(nc))
    if json_out:
        emit_json({**st.as_json(), "csv": str(csv_path), "special_csv": str(sp_path),
                   "figures": [str(f) for f in figs], "netcdf": nc_files})
        return
    if st.restart is not None:
        console.print(f"hopf-curve: {st.restart.text}; no Hopf search", highlight=False,
                      markup=False)
    console.print(f"Hopf curve in ({names[0]}, {names[1]}), model {st.model}: "
                  f"{len(st.curves)} branch(es), {len(points)} points")
    if st.delay:
        console.print(st.delay["text"], highlight=False)
    for text in st.delay_notes:
        console.print(f"  {text}", highlight=False)
    for k, c in enumerate(st.curves):
        signs = "".join("+" if v > 0 else "-" for v in _runs(c.l1()))
        console.print(f"  branch {k}: {len(c.points)} points, l1 sign pattern along it: "
                      f"{signs}; {c.message}")
    if special:
        table = Table("type", names[0], names[1], "omega (rad/s)", "l2")
        for r in special:
            table.add_row(r["type"], f"{r[names[0]]:.8g}", f"{r[names[1]]:.8g}",
                          f"{r['frequency']:.6g}",
                          "" if r.get("l2") is None else f"{r['l2']:.4g}")
        console.print(table)
    else:
        console.print("  no codimension-two points inside the bounds")
    console.print(f"wrote {csv_path}, {sp_path}, {', '.join(nc_files)} and "
                  f"{', '.join(str(f) for f in figs)}")
    print_warnings(list(st.warnings) + [w for c in st.curves for w in c.warnings])


def _restart_errors():
    """A restart's file and label errors as command-line errors (exit code 2)."""
    from maglev_match.cli.restart import restart_error_context

    return restart_error_context()


def _runs(l1) -> list[float]:
    """The signs of l1 along a branch, one per run of equal signs."""
    out: list[float] = []
    for v in l1:
        s = int(v > 0) - int(v < 0)
        if not out or s != out[-1]:
            out.append(float(s))
    return out
