"""`maglev-match hopf` (Hopf points along one parameter) and `hopf-curve` (the Hopf curve in
two parameters with l1 and codimension-two points, paper Fig. 4)."""

from __future__ import annotations

import csv
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import numpy as np
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
    check_output_path,
    check_param,
    console,
    emit_json,
    finite,
    fraction_option,
    grid_option,
    output_target,
    parse_range,
    print_warnings,
    progress_report,
    scan_option,
    unit_of,
    validate_value,
)
from maglev_match.core.io import atomic_open
from maglev_match.core.params import ParameterError
from maglev_match.core.units import header
from maglev_match.maglev.catalog import model_info

if TYPE_CHECKING:  # the numerics (and JAX) are imported when a command runs
    from maglev_match.dynamics.hopf import HopfPoint

# The plane of the paper's Fig. 4 for model A; model B has no sigma (that is model A's force
# gain), so its default plane is the beam frequency against the velocity gain.
DEFAULT_PLANE = {"unit": ("omega1", "sigma"), "vehicle": ("omega1", "kD")}
DEFAULT_RANGES = {"omega1": (30.0, 400.0), "sigma": (1e-4, 8e-4)}
# a delay axis without a design value: 0 .. 5 ms (the maglev models lose stability near
# 1.2-1.5 ms); its first value is DELAY_FLOOR times the last (the discretisation is singular
# at 0, where the model is the delay-free one)
DEFAULT_DELAY_RANGE = 0.005
DELAY_FLOOR = 1e-3


def _point_record(hp: HopfPoint, system, names: tuple[str, ...]) -> dict:
    rec = {n: system.param(n, hp.p) for n in names}
    rec.update({
        "frequency": hp.frequency,
        "crossing_speed": hp.crossing_speed,
        "l1": hp.l1,
        "kind": hp.kind,
        "others_stable": hp.others_stable,
        "converged": hp.converged,
        "residual": hp.residual,
        "warnings": list(hp.warnings),
    })
    return rec


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
    from maglev_match.cli.models import resolve_model

    check_output_path(out)
    if steps < 2:
        raise ParameterError("--steps", steps, "must be at least 2")
    if not start < stop:
        raise UserError(f"--from {start:g} --to {stop:g}: the range must be increasing")
    # --model unit|vehicle|FILE.py; along a delay: the discretised delay system (tau <= --to)
    rm = resolve_model(model, set_, preset, config, delay_axis=(param, stop))
    from maglev_match.analyses.engineering import engineering_hopf_points, is_engineering
    from maglev_match.dynamics.delay import delay_hopf_points, is_delay_parameter
    from maglev_match.dynamics.hopf import locate_hopf_points

    params, system, model = rm.params, rm.system, rm.label
    engineering = params is not None and is_engineering(param)
    if not engineering:
        check_param(system, model, param, "--param")
    for v in (start, stop):
        if params is not None:
            validate_value(params, param, v)
    with progress_report("hopf") as prog:
        prog.stage(f"searching Hopf points along {param} in [{start:g}, {stop:g}] ...")
        if engineering:  # a beam/vehicle quantity: omega1, sigma (model B: geometry) follow it
            scan, system = engineering_hopf_points(params, model, param, start, stop, steps)
            names = tuple(dict.fromkeys(DEFAULT_PLANE.get(model, ()) + ("sigma",)))
            names = tuple(n for n in names if n in system.param_names)
            records = [{param: hp.value, **_point_record(hp, system, names)}
                       for hp in scan.points]
            names = (param, *names)
        elif is_delay_parameter(system, param):  # crossings of the characteristic equation
            if start < 0:
                raise ParameterError("--from", start, f"{param} is a delay: the range must "
                                     "start at or above 0")
            scan = delay_hopf_points(system, param, start, stop, n_scan=steps)
            names = tuple(dict.fromkeys((param,) + DEFAULT_PLANE.get(model, ())))
            records = [_point_record(hp, system, names) for hp in scan.points]
        else:
            scan = locate_hopf_points(system, param, start, stop, n_scan=steps)
            names = tuple(dict.fromkeys((param,) + DEFAULT_PLANE.get(model, ())))
            records = [_point_record(hp, system, names) for hp in scan.points]
        for k, rec in enumerate(records):  # AUTO's and MatCont's label of a Hopf point
            rec["label"] = f"H{k + 1}"
    specials = [{"type": str(sp.type), param: sp.value, "located": sp.located,
                 "label": sp.label, "frequency": sp.frequency}
                for sp in scan.special_points]
    delay_note = _delay_note(system, param)
    unit = "" if rm.is_user else unit_of(param)
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


def _delay_note(system, param: str, crossings: bool = True) -> dict | None:
    """How a delay model was analysed (the delay axis, or a model with a delay)."""
    from maglev_match.dynamics.delay import DiscretisedSystem

    if not isinstance(system, DiscretisedSystem):
        return None
    axis = param in system.delays and crossings
    text = (f"  delay system: Chebyshev discretisation of the past with N = {system.nodes} "
            f"nodes per delay (dimension {system.dim} = {system.n_state} states + "
            f"{system.dim - system.n_state} history values); l1 with <q,q> = 1 over the "
            f"{system.n_state} states"
            + ("; Hopf points in the delay are the crossings of the characteristic equation "
               "(exact; delay 0 is the delay-free model)" if axis else ""))
    return {"nodes": system.nodes, "dimension": system.dim, "states": system.n_state,
            "delays": list(system.delays), "axis": axis, "text": text}


def _parse_ranges(items: list[str] | None) -> dict[str, tuple[float, float]]:
    out: dict[str, tuple[float, float]] = {}
    for item in items or []:
        if "=" not in item:
            raise UserError(f"--range '{item}': expected NAME=FROM:TO, e.g. sigma=1e-4:8e-4")
        name, text = item.split("=", 1)
        a, b = parse_range(text, f"--range {name}")
        if not a < b:
            raise UserError(f"--range {item}: the range must be increasing")
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
    from maglev_match.cli.models import delay_names, resolve_model

    check_output_path(out)
    model_arg = model
    rm = resolve_model(model, set_, preset, config)  # --model unit|vehicle|FILE.py
    params, system, model = rm.params, rm.system, rm.label
    from maglev_match.dynamics.hopf_curve import hopf_curves_from_scans, stability_grid
    restarted = None
    if restart is not None or label is not None:  # continue a saved curve (cli/restart.py)
        from maglev_match.cli.common import refuse_given
        from maglev_match.cli.restart import hopf_curve_restart

        refuse_given({"scan_steps": "--scan-steps"}, "a restart searches no Hopf point: it "
                     "continues the saved curve from --label; leave this option out")
        names_given = None
        if params_opt is not None:
            parts = [t.strip() for t in params_opt.split(",") if t.strip()]
            names_given = tuple(parts) if len(parts) == 2 else None
            if names_given is None:
                raise UserError(f"--params '{params_opt}': expected two names P1,P2")
        restarted = hopf_curve_restart(rm=rm, restart=restart, label=label,
                                       given_names=names_given,
                                       given_bounds=_parse_ranges(ranges), max_step=max_step,
                                       sets=set_)
        params_opt = ",".join(restarted[2])
        system, params = restarted[4], restarted[5]  # the saved values unless given
    if params_opt is None and rm.is_user:
        raise UserError(f"--params: give the two parameters of model {model}, e.g. "
                        f"--params {','.join(system.param_names[:2])}")
    if params_opt is None:
        names = DEFAULT_PLANE[model]
    else:
        parts = [t.strip() for t in params_opt.split(",") if t.strip()]
        if len(parts) != 2 or parts[0] == parts[1]:
            raise UserError(f"--params '{params_opt}': expected two different names P1,P2")
        names = (parts[0], parts[1])
    delays = delay_names(rm)
    for n in names:
        if n not in delays:  # a delay is a parameter of the discretised system (below)
            check_param(system, model, n, "--params")
    given = _parse_ranges(ranges)
    for n in given:
        if n not in names:
            raise UserError(f"--range {n}: not one of --params {','.join(names)}")
    bounds = {}
    for n in names:
        if n in given:
            bounds[n] = given[n]
        elif n in DEFAULT_RANGES and not rm.is_user:
            bounds[n] = DEFAULT_RANGES[n]
        elif n in delays:  # a delay: from 0 (its design value may be 0)
            v = system.param(n) if n in system.param_names else 0.0
            bounds[n] = (0.0, 2.0 * v if v > 0 else DEFAULT_DELAY_RANGE)
        else:
            v = system.param(n)
            bounds[n] = (0.5 * v, 2.0 * v) if v > 0 else (v - 1.0, v + 1.0)
        for v in bounds[n]:
            if params is not None:
                validate_value(params, n, v)
    delay_notes = []
    for n in names:
        if n in delays:  # the discretised delay system, sized for the largest delay
            lo, hi = bounds[n]
            if lo < 0:
                raise ParameterError("--range", f"{n}={lo:g}:{hi:g}", f"{n} is a delay: the "
                                     "range must start at or above 0")
            if lo < DELAY_FLOOR * hi:
                bounds[n] = (DELAY_FLOOR * hi, hi)
                delay_notes.append(f"{n} from {DELAY_FLOOR * hi:g} (the discretised delay "
                                   f"system is singular at {n} = 0, the delay-free model)")
            rm = resolve_model(model_arg, set_, preset, config, delay_axis=(n, hi))
            system = rm.system
    a, b = bounds[names[1]]
    scan_values = [a + f * (b - a) for f in (0.5, 0.1, 0.9)]
    if restarted is not None:  # the saved bounds, widened by --range
        bounds = restarted[3]

    with progress_report("hopf-curve") as prog:
        if restarted is not None:
            curves, warnings = [restarted[0]], []
            prog.stage(restarted[1].describe())
        else:
            prog.stage(f"scanning {names[0]} at {len(scan_values)} values of {names[1]} ...")
            curves, warnings = hopf_curves_from_scans(system, names, bounds, scan_values,
                                                   n_scan=scan_steps, max_step=max_step,
                                                   progress=prog.stage)
        grid_data = None
        if grid > 0:
            prog.stage(f"stability grid {grid} x {grid} ...")
            g1 = np.linspace(*bounds[names[0]], grid)
            g2 = np.linspace(*bounds[names[1]], grid)
            mr, ok = stability_grid(system, names, g1, g2)
            if not ok.all():
                warnings.append(f"equilibrium not found at {int((~ok).sum())} grid points")
            grid_data = (g1, g2, mr)
    folder, stem = output_target(out, "hopf-curve",
                                 f"hopf_curve_{model}_{names[0]}_{names[1]}")
    csv_path = folder / f"{stem}.csv"
    points, special = [], []
    span0 = bounds[names[0]][1] - bounds[names[0]][0]
    span1 = bounds[names[1]][1] - bounds[names[1]][0]
    for k, c in enumerate(curves):
        for pt in c.points:
            points.append({names[0]: pt.values[0], names[1]: pt.values[1],
                           "frequency": pt.frequency, "l1": pt.l1, "branch": k,
                           "others_stable": pt.others_stable})
        for sp in c.special_points:
            if sp.type == "HH" and any(
                    r["type"] == "HH" and abs(r[names[0]] - sp.values[0]) <= 1e-6 * span0
                    and abs(r[names[1]] - sp.values[1]) <= 1e-6 * span1 for r in special):
                continue  # the same double-Hopf point seen from the crossing branch
            rec = {"type": sp.type, names[0]: sp.values[0], names[1]: sp.values[1],
                   "frequency": sp.frequency, "branch": k, "converged": sp.converged,
                   "located": sp.located, "label": f"{sp.label}" + (f"/{k}" if k else "")}
            if sp.type == "GH":
                rec["l2"] = sp.l2
            if sp.type == "HH":
                rec["other_frequency"] = sp.other_frequency
            special.append(rec)
    with atomic_open(csv_path, "w", newline="") as fh:
        w = csv.writer(fh)
        nh = [f"{n} ({unit_of(n)})" if not rm.is_user and unit_of(n) else n for n in names]
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
    from maglev_match.plots import save_figure
    from maglev_match.plots.hopf import hopf_curve_figure

    which = f"model {model}" if rm.is_user else model_info(model).short
    title = f"Hopf curve, {which}" + ("" if rm.is_user else f" ({preset})")
    if restarted is not None:  # the saved values, not the preset's
        title = (f"Hopf curve, {which}, restarted from {restarted[1].label} of "
                 f"{Path(restarted[1].path).name}")
    units = ("", "") if rm.is_user else (unit_of(names[0]), unit_of(names[1]))
    fig = hopf_curve_figure(curves, names, units, grid_data, title=title,
                            design_point=(system.param(names[0]), system.param(names[1])))
    if restarted is not None:  # where the restarted curve was continued from
        from maglev_match.plots.restart import mark_restart_point

        rs = restarted[1]
        mark_restart_point(fig.axes[0], *rs.values, label=rs.label, source=Path(rs.path).name)
    figs = save_figure(fig, folder / stem)
    from maglev_match.core.datasets import annotate
    from maglev_match.core.io import atomic_write_netcdf

    nc_files = []
    for k, c in enumerate(curves):
        nc = folder / (f"{stem}.nc" if k == 0 else f"{stem}_{k}.nc")
        ds = annotate(c.to_xarray(units, system.state_names), params)
        _restartable_curve(ds, system, model, names, bounds,
                           rm.user.path if rm.is_user else None)
        atomic_write_netcdf(nc, ds)
        nc_files.append(str(nc))
    branches = [{"converged": c.converged, "message": c.message, "n_points": len(c.points),
                 "closed": c.closed, "warnings": list(c.warnings)} for c in curves]
    if json_out:
        emit_json({"params": list(names), "model": model, "delay_notes": delay_notes,
                   "restart": None if restarted is None else {
                       "file": restarted[1].path, "label": restarted[1].label,
                       "values": list(restarted[1].values), "hopf_search": False},
                   "bounds": {n: list(bounds[n]) for n in names}, "points": points,
                   "special_points": special, "branches": branches, "csv": str(csv_path),
                   "special_csv": str(sp_path), "figures": [str(f) for f in figs],
                   "netcdf": nc_files, "warnings": warnings})
        return
    if restarted is not None:
        console.print(f"hopf-curve: {restarted[1].describe()}; no Hopf search",
                      highlight=False, markup=False)
    console.print(f"Hopf curve in ({names[0]}, {names[1]}), model {model}: "
                  f"{len(curves)} branch(es), {len(points)} points")
    note = _delay_note(system, names[0], crossings=False)
    if note:
        console.print(note["text"], highlight=False)
    for text in delay_notes:
        console.print(f"  {text}", highlight=False)
    for k, c in enumerate(curves):
        l1 = c.l1()
        signs = "".join("+" if s > 0 else "-" for s in _runs(np.sign(l1)))
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
    print_warnings(warnings + [w for c in curves for w in c.warnings])


def _restartable_curve(ds, system, model: str, names: tuple[str, str],
                       bounds: dict[str, tuple[float, float]],
                       model_file: str | None = None) -> None:
    """What a restart of the saved curve needs (:mod:`maglev_match.analyses.restart`): the curve's
    two parameters, their bounds, the full parameter vector and the kind attributes."""
    from maglev_match.analyses.restart import RestartKind, stamp

    stamp(ds, RestartKind.HOPF_CURVE, system, model, "hopf-curve")
    if model_file is not None:  # a user model: the API's restart loads it again
        ds.attrs["model_file"] = str(Path(model_file).resolve())
    ds.attrs["curve_params"] = f"{names[0]},{names[1]}"
    for n in names:
        ds.attrs[f"bounds_{n}"] = np.array(bounds[n], float)
    ds["base_p"] = (("parameter",), np.asarray(system.p, float),
                    {"units": "parameter units", "long_name": "parameter vector of the curve "
                     "(the two curve parameters vary along it)"})


def _runs(signs: np.ndarray) -> list[float]:
    out: list[float] = []
    for s in signs:
        if not out or s != out[-1]:
            out.append(float(s))
    return out
