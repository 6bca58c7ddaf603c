"""`maglev-match iso-curve`: where in two parameters the headline index chi equals a target,
continued as a curve. Options parsed here, the computation in :mod:`maglev_match.api.iso`,
the answer printed and saved here (table with a status per point, CSV, netCDF, figure)."""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Annotated

import typer

from maglev_match.cli import app
from maglev_match.cli.common import (
    DEFAULT_PRESET_NAME,
    ConfigOpt,
    JsonOpt,
    OutOpt,
    PresetOpt,
    SetOpt,
    UserError,
    api_options,
    check_output_path,
    console,
    emit_json,
    model_inputs,
    output_target,
    parse_range,
    print_error,
    print_warnings,
    progress_report,
)
from maglev_match.core.params import ParameterError

#: API keyword -> option, for `iso-curve`
ISO_CURVE_OPTIONS = {"target": "TARGET", "names": "--params", "ranges": "--range",
                     "at": "--at", "model": "--model", "simulate": "--no-simulation",
                     "points": "--points", "step": "--step", "tol": "--tol",
                     "config": "--config", "source": "--restart"}

#: what a restart takes from its saved curve (python name -> option as typed)
SAVED_BY_THE_CURVE = {"params_": "--params", "at": "--at", "no_simulation": "--no-simulation",
                      "preset": "--preset", "config": "--config", "set_": "--set",
                      "model": "--model"}


def parse_target(text: str) -> float:
    """'chi=5' or '5' -> 5.0 (the rule on the value is the API's)."""
    name, _, value = text.partition("=") if "=" in text else ("chi", "", text)
    if name.strip() != "chi":
        raise UserError(f"TARGET '{text}': expected chi=VALUE, e.g. chi=5 (the headline "
                        "index is the only quantity followed)")
    try:
        return float(value)
    except ValueError:
        raise UserError(f"TARGET '{text}': the value must be a number, e.g. chi=5") from None


def _ranges(items: list[str] | None) -> dict[str, tuple[float, float]]:
    out: dict[str, tuple[float, float]] = {}
    for item in items or []:
        if "=" not in item:
            raise UserError(f"--range '{item}': expected NAME=LOW:HIGH, e.g. kD=100:200")
        name, text = (s.strip() for s in item.split("=", 1))
        if name in out:
            raise UserError(f"--range {name}: given twice")
        out[name] = parse_range(text, f"--range {name}")
    return out


def iso_overlay(iso: float | None, iso_curve: Path | None, names: list[str],
                what: str = "map") -> dict:
    """The figure options of ``map --iso VALUE`` / ``--iso-curve FILE``, checked before the
    map is computed: a level (finite, > 0), or an iso-chi curve file of the map's two
    parameters (its level must equal ``--iso`` when both are given). ``what`` names the
    figure in the messages (``design`` uses it for its varied parameters)."""
    import math

    if iso is not None and not (math.isfinite(iso) and iso > 0):
        raise ParameterError("--iso", iso, "must be a finite number > 0 (a level of chi)")
    if iso_curve is None:
        return {} if iso is None else {"iso": iso}
    import xarray as xr

    try:
        curve = xr.load_dataset(iso_curve)
    except (OSError, ValueError) as exc:
        raise UserError(f"--iso-curve {iso_curve}: not a readable netCDF file ({exc})") \
            from None
    if not str(curve.attrs.get("title", "")).startswith("maglev-match iso-chi curve"):
        raise UserError(f"--iso-curve {iso_curve}: not an iso-chi curve file (written by "
                        "`maglev-match iso-curve`)")
    pair = str(curve.attrs.get("curve_params", "")).split(",")
    if sorted(pair) != sorted(names):
        raise UserError(f"--iso-curve {iso_curve}: a curve in ({', '.join(pair)}), the "
                        f"{what} is in ({', '.join(names)})")
    target = float(curve.attrs["target"])
    if iso is not None and iso != target:
        raise UserError(f"--iso {iso:g} and --iso-curve {iso_curve} (chi = {target:g}) "
                        "name different levels")
    return {"iso_curve": curve, "iso_source": Path(iso_curve).name}


@app.command("iso-curve")
def iso_curve_command(
    target: Annotated[str | None, typer.Argument(
        help="The level followed, chi=VALUE (e.g. chi=5): the headline chi, or with "
        "--no-simulation the paper's chi (with --restart: the saved curve's).",
        metavar="chi=VALUE", show_default=False)] = None,
    params_: Annotated[str, typer.Option(
        "--params", help="The curve's two parameters P1,P2, e.g. EI,kD (beam data L, EI, "
        "mbar derive omega1 and sigma).")] = "EI,kD",
    range_: Annotated[list[str] | None, typer.Option(
        "--range", help="NAME=LOW:HIGH for P1 or P2 (repeatable): the curve ends on it "
        "(default: half to twice the base value).")] = None,
    at: Annotated[str | None, typer.Option(
        "--at", help="The start, NAME=VALUE: that parameter fixed, the other solved over "
        "its range (default: P2 at the middle of its range).")] = None,
    no_simulation: Annotated[bool, typer.Option(
        "--no-simulation", help="Follow the paper's chi alone (no critical disturbance "
        "simulated).")] = False,
    points: Annotated[int, typer.Option(
        "--points", help="At most this many points, both directions together (1: the "
        "start alone).")] = 30,
    step: Annotated[float, typer.Option(
        "--step", help="The first step as a fraction of the ranges.")] = 0.05,
    tol: Annotated[float, typer.Option(
        "--tol", help="|chi - target| <= tol * target at every solved point (with "
        "--restart: default the saved curve's).")] = 1e-7,
    restart: Annotated[Path | None, typer.Option(
        "--restart", help="Continue the curve saved in this netCDF file (written by "
        "iso-curve --out) beyond both of its ends, at its parameter set, model, target and "
        "part; --points new points, --range may widen its ranges.")] = None,
    preset: PresetOpt = DEFAULT_PRESET_NAME,
    config: ConfigOpt = None,
    set_: SetOpt = None,
    model: Annotated[str, typer.Option(
        "--model", help="'unit' (model A) or 'vehicle' (model B).")] = "unit",
    json_out: JsonOpt = False,
    out: OutOpt = None,
) -> None:
    """The iso-chi curve: where the headline chi(P1, P2) equals the target, continued in
    two parameters, with the deciding part and the status of each point; writes CSV,
    netCDF and a figure."""
    check_output_path(out)
    ranges = _ranges(range_)
    from maglev_match import api

    if restart is not None:
        from maglev_match.cli.common import given, refuse_given
        from maglev_match.cli.restart import restart_error_context

        refuse_given(SAVED_BY_THE_CURVE, "a restart continues the saved curve at its own "
                     "parameter set, model, parameters and part; leave this out")
        if target is not None:
            raise UserError(f"TARGET {target}: a restart follows the saved curve's level; "
                            "leave TARGET out with --restart")
        with progress_report("iso-curve") as prog, api_options(ISO_CURVE_OPTIONS), \
                restart_error_context():
            curve = api.restart_iso_curve(restart, ranges=ranges, points=points, step=step,
                                          tol=tol if given("tol") else None,
                                          stage=prog.stage)
    else:
        if target is None:
            raise UserError("TARGET: give the level to follow, chi=VALUE (e.g. chi=5), or "
                            "--restart FILE to continue a saved curve")
        value = parse_target(target)
        if str(model).endswith(".py"):
            raise UserError(f"--model {model}: iso-chi curves are computed for the maglev "
                            "models unit and vehicle (a user model has no index)")
        names = [p.strip() for p in params_.split(",")]
        params, overrides = model_inputs(model, preset, config, set_)
        with progress_report("iso-curve") as prog, api_options(ISO_CURVE_OPTIONS):
            curve = api.iso_curve(params, value, names=names, ranges=ranges, at=at,
                                  model=model, simulate=not no_simulation, points=points,
                                  step=step, tol=tol, stage=prog.stage, **overrides)
    files: list[Path] = []
    if out is not None or not json_out:
        files = write_outputs(curve, out)
    if json_out:
        result = curve.as_json()
        result["files"] = [str(f) for f in files]
        emit_json(result)
    else:
        print_text(curve)
        for f in files:
            console.print(f"wrote {f}", highlight=False)
    if not curve.points:
        print_error("the iso-chi curve could not start: " + "; ".join(curve.warnings))
        raise typer.Exit(1)


def _num(v: float, fmt: str = ".6g") -> str:
    return "-" if v is None or (isinstance(v, float) and math.isnan(v)) else format(v, fmt)


def print_text(curve) -> None:
    """The curve as text: a line per point with its status, the special points, the ends
    and the warnings."""
    a, b = curve.names
    what = "headline chi" if curve.simulate else "the paper's chi (no simulation)"
    console.print(f"iso-chi curve {what} = {curve.target:g} in ({a}, {b}), model "
                  f"{curve.model}: {len(curve.points)} points, {curve.evaluations} index "
                  f"evaluations, {curve.cpu_seconds:.1f} s CPU", highlight=False,
                  markup=False)
    console.print(f"  {a:>13}  {b:>13}  {'chi':>10}  {'chi_paper':>10}  {'chi_sim':>10}  "
                  f"{'deciding':>10}  {'mechanism':>15}  {'dir':>4}  status", highlight=False,
                  markup=False)
    for r in curve.rows():
        mark = " (start)" if r["start"] else ""
        console.print(f"  {r[a]:>13.7g}  {r[b]:>13.7g}  {_num(r['chi'], '.8g'):>10}  "
                      f"{_num(r['chi_paper'], '.5g'):>10}  "
                      f"{_num(r['chi_simulation'], '.5g'):>10}  {r['basis']:>10}  "
                      f"{r['mechanism'] or '-':>15}  {r['direction'] or '-':>4}  "
                      f"{r['status']}{mark}", highlight=False, markup=False)
    for s in curve.special_rows():
        console.print(f"  {s['kind']}: {s['before']} -> {s['after']} at {a} = {s[a]:.8g}, "
                      f"{b} = {s[b]:.8g} (chi_paper {_num(s['chi_paper'], '.7g')}, "
                      f"chi_simulation {_num(s['chi_simulation'], '.7g')}"
                      f"{'' if s['located'] else '; NOT located: ' + s['message']})",
                      highlight=False, markup=False)
    console.print(f"  ends: backwards: {curve.ends[0]}; forwards: {curve.ends[1]}",
                  highlight=False, markup=False)
    print_warnings(curve.warnings)


def write_outputs(curve, out: Path | None) -> list[Path]:
    """CSV of the points and of the special points, netCDF and the figure."""
    from maglev_match.core.io import atomic_open, atomic_write_netcdf

    a, b = curve.names
    folder, stem = output_target(out, "iso-curve", f"iso_chi_{curve.model}_{a}_{b}")
    folder.mkdir(parents=True, exist_ok=True)
    units = dict(zip(curve.names, curve.units, strict=True))
    files = []
    for path, rows in ((folder / f"{stem}.csv", curve.rows()),
                       (folder / f"{stem}_special_points.csv", curve.special_rows())):
        with atomic_open(path, "w", newline="") as fh:
            w = csv.writer(fh)
            if rows:
                keys = list(rows[0])
                w.writerow([f"{k} ({units[k]})" if k in units else k for k in keys])
                w.writerows([[r[k] for k in keys] for r in rows])
        files.append(path)
    if curve.points:
        nc = folder / f"{stem}.nc"
        atomic_write_netcdf(nc, curve.to_xarray())
        files.append(nc)
    files += curve.plot(folder / f"{stem}.png")
    return files
