"""`maglev-match stability`, `root-locus` and `presets`: options parsed here, the
computation in :mod:`maglev_match.api.linear`, the answer printed and saved here."""

from __future__ import annotations

import csv
from pathlib import Path
from typing import Annotated

import typer
from rich.table import Table
from rich.text import Text

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
    model_inputs,
    output_target,
    print_warnings,
    progress_report,
    scan_option,
    unit_of,
)
from maglev_match.core.params import ParameterError
from maglev_match.core.units import header, shown
from maglev_match.core.units import label as unit_label
from maglev_match.maglev.catalog import model_info

# The numerical modules (and JAX with them) are imported inside the commands, so that
# `presets`, `--help` and a usage error answer without loading them.

#: API keyword -> option, for `stability` and `root-locus`
STABILITY_OPTIONS = {"model": "--model", "config": "--config"}
ROOT_LOCUS_OPTIONS = {"param": "--param", "values": "--from/--to/--steps", "model": "--model",
                      "config": "--config"}


def _label(model: str) -> str:
    """'unit', 'vehicle' or a model file's name (its stem)."""
    return Path(model).stem if str(model).endswith(".py") else model


#: Relative size below which an imaginary part is rounding noise: eigenvalues of a real
#: matrix computed in float64 (LAPACK dgeev, backward error ~ 1e-16 ||J||) can split a real
#: double eigenvalue into a spurious pair +-i eps; |Im| <= IMAG_RTOL max(|lambda|, 1) is real.
IMAG_RTOL = 1e-9


def table_eigenvalues(eigenvalues) -> list[tuple[int, complex]]:
    """The eigenvalues to list in a stability table, as (index, lambda): each conjugate pair
    once (its member with Im > 0) and every real eigenvalue, where an imaginary part with
    |Im| <= IMAG_RTOL max(|lambda|, 1) is rounding noise and set to 0 (a real eigenvalue,
    kept with its multiplicity). The real matrix's spectrum is closed under conjugation
    (Golub & Van Loan, Matrix Computations, 7.4), so dropping Im < 0 loses nothing."""
    import numpy as np

    rows = []
    for k, z in enumerate(np.asarray(eigenvalues, complex)):
        if abs(z.imag) <= IMAG_RTOL * max(abs(z), 1.0):
            rows.append((k, complex(z.real, 0.0)))
        elif z.imag > 0:
            rows.append((k, complex(z)))
    return rows


@app.command("stability")
def stability_command(
    preset: PresetOpt = DEFAULT_PRESET_NAME,
    config: ConfigOpt = None,
    set_: SetOpt = None,
    model: ModelOpt = "unit",
    out: OutOpt = None,
    json_out: JsonOpt = False,
) -> None:
    """Equilibrium, eigenvalues and the stability verdict with its margin.

    Writes the eigenvalues (CSV) into --out (default maglev-match-out/stability/); with
    --json and no --out, nothing is written."""
    import numpy as np

    check_output_path(out)
    params, overrides = model_inputs(model, preset, config, set_)
    from maglev_match import api

    with api_options(STABILITY_OPTIONS):
        studied = api.resolve_model(params, model, **overrides)  # --model unit|vehicle|FILE.py
        res = api.stability(params, model=model, **overrides)
    system = res.system
    label = _label(model)
    files = [] if json_out and out is None else [_write_eigenvalues(out, label, res)]
    if json_out:
        out = {
            "model": label,
            "stable": res.stable,
            "max_real_part": res.max_real_part,
            "margin": res.margin,
            "eigenvalues": [[float(z.real), float(z.imag)] for z in res.eigenvalues],
            "omega1": float(params.omega1) if params else None,
            "sigma": float(params.sigma) if params else None,
            "equilibrium_converged": res.equilibrium.converged,
            "equilibrium_scaled_residual": res.equilibrium.scaled_residual,
            "warnings": list(res.warnings),
            "files": [str(f) for f in files],
        }
        if studied.is_user:
            out["parameters"] = dict(zip(system.param_names, system.p.tolist(), strict=True))
        if studied.is_user or model_info(model).points > 1:
            out["equilibrium"] = res.equilibrium.x.tolist()
            out["state_names"] = list(system.state_names)
        emit_json(out)
        return
    console.print(studied.description, highlight=False)
    verdict = "[bold green]STABLE[/]" if res.stable else "[bold red]UNSTABLE[/]"
    console.print(f"Equilibrium: {verdict}  max Re(lambda) = {res.max_real_part:.6g} 1/s "
                  f"(margin {res.margin:.6g} 1/s)")
    table = Table("#", "Re (1/s)", "Im (rad/s)", "f (Hz)", "damping ratio")
    for k, z in table_eigenvalues(res.eigenvalues):
        zeta = -z.real / abs(z) if abs(z) > 0 else float("nan")
        table.add_row(str(k + 1), f"{z.real:.6g}", f"{z.imag:.6g}",
                      f"{abs(z.imag) / (2 * np.pi):.4g}", f"{zeta:.4g}")
    console.print(table)
    console.print("(one row per conjugate pair, Im > 0; |Im| below "
                  f"{IMAG_RTOL:g} |lambda| is shown as a real eigenvalue)")
    for f in files:
        console.print(f"wrote {f}", highlight=False)
    print_warnings(res.warnings)


def _write_eigenvalues(out, model: str, res):
    """Every eigenvalue of the equilibrium as CSV (units in the headers)."""
    import numpy as np

    from maglev_match.core.io import atomic_open

    folder, stem = output_target(out, "stability", f"stability_{model}")
    path = folder / f"{stem}.csv"
    with atomic_open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["index", header("re"), header("im"), header("frequency_hz"),
                    header("damping_ratio")])
        for k, z in enumerate(np.asarray(res.eigenvalues, complex)):
            zeta = -z.real / abs(z) if abs(z) > 0 else float("nan")
            w.writerow([k + 1, f"{z.real:.12g}", f"{z.imag:.12g}",
                        f"{abs(z.imag) / (2 * np.pi):.12g}", f"{zeta:.12g}"])
    return path


@app.command("root-locus")
def root_locus_command(
    param: Annotated[str, typer.Option("--param", help=PARAM_HELP)] = "omega1",
    start: Annotated[float, typer.Option("--from", help="First value.", callback=finite)] = 40.0,
    stop: Annotated[float, typer.Option("--to", help="Last value.", callback=finite)] = 190.0,
    steps: Annotated[int, typer.Option("--steps", help="Number of values.",
                                       callback=scan_option)] = 151,
    preset: PresetOpt = DEFAULT_PRESET_NAME,
    config: ConfigOpt = None,
    set_: SetOpt = None,
    model: ModelOpt = "unit",
    out: OutOpt = None,
    json_out: JsonOpt = False,
) -> None:
    """Eigenvalues along one parameter: writes CSV and a PNG/SVG figure."""
    import numpy as np

    from maglev_match.core.io import atomic_open

    check_output_path(out)
    if steps < 2:
        raise ParameterError("--steps", steps, "must be at least 2")
    if not start < stop:
        raise UserError(f"--from {start:g} --to {stop:g}: the range must be increasing")
    params, overrides = model_inputs(model, preset, config, set_)
    model = str(model)
    from maglev_match import api

    values = np.linspace(start, stop, steps)
    with progress_report("root-locus") as prog, api_options(ROOT_LOCUS_OPTIONS):
        prog.stage(f"eigenvalues at {steps} values of {param} ...")
        res = api.root_locus(params, param, values, model=model, **overrides)
    model = _label(model)
    folder, stem = output_target(out, "root-locus", f"root_locus_{model}_{param}")
    csv_path = folder / f"{stem}.csv"
    with atomic_open(csv_path, "w", newline="") as fh:
        w = csv.writer(fh)
        pu = unit_of(param)
        w.writerow([f"{param} ({pu})" if pu else param, "index", header("re"), header("im"),
                    header("max_real_part"), "equilibrium_converged"])
        for v, eig, mr, ok in zip(values, res.eigenvalues, res.max_real_part, res.converged,
                                  strict=True):
            for k, z in enumerate(eig):
                w.writerow([f"{v:.10g}", k, f"{z.real:.12g}", f"{z.imag:.12g}", f"{mr:.12g}",
                            bool(ok)])
    unit = unit_of(param)
    figs = res.plot(folder / stem)
    crossings = res.stability_changes
    mr = res.max_real_part
    summary = {
        "param": param,
        "model": model,
        "values": values.tolist(),
        "max_real_part": mr.tolist(),
        "stability_changes": crossings,
        "csv": str(csv_path),
        "figures": [str(f) for f in figs],
        "warnings": list(res.warnings),
    }
    if json_out:
        emit_json(summary)
        return
    console.print(
        f"Root locus along {param} in [{start:g}, {stop:g}] ({steps} values), model {model}"
    )
    if crossings:
        console.print("max Re(lambda) changes sign near " + ", ".join(f"{c:.5g}" for c in crossings)
                      + f" {unit} (linear interpolation; `maglev-match hopf` refines)")
    else:
        state = "stable" if mr[0] < 0 else "unstable"
        console.print(f"no change of stability: {state} throughout")
    console.print(f"wrote {csv_path} and {', '.join(str(f) for f in figs)}")
    print_warnings(res.warnings)


@app.command("presets")
def presets_command(out: OutOpt = None, json_out: JsonOpt = False) -> None:
    """List the shipped parameter presets: beam values, a description, and what each
    changes relative to the preset it derives from.

    Writes the table (CSV, SI units) into --out (default maglev-match-out/presets/); with
    --json and no --out, nothing is written."""
    check_output_path(out)
    from maglev_match.api.linear import presets

    rows = [r.as_json() for r in presets()]
    files = [] if json_out and out is None else [_write_presets(out, rows)]
    if json_out:
        emit_json({"presets": rows, "files": [str(f) for f in files]})
        return
    table = Table("preset", *(unit_label(k) for k in ("omega1", "sigma", "w0", "L", "EI")))
    table.columns[0].no_wrap = True
    for r in rows:
        table.add_row(r["name"], f"{r['omega1']:.5g}", f"{r['sigma']:.4g}",
                      f"{shown('w0', r['w0']):.4g}", f"{r['L']:g}", f"{r['EI']:.4g}")
    console.print(table)
    for f in files:
        console.print(f"wrote {f}", highlight=False)
    for r in rows:
        if r["base"] is None:
            changed = "a base preset"
        elif r["changes"]:
            changed = f"changes vs {r['base']}: " + ", ".join(
                f"{k} {c['base']:.6g} -> {c['value']:.6g}" for k, c in r["changes"].items())
        else:
            changed = f"same values as {r['base']}"
        console.print(Text.assemble((r["name"], "bold"), f" ({changed})"), highlight=False)
        console.print(f"    {r['description']}", highlight=False, markup=False)


def _write_presets(out, rows: list[dict]):
    """The presets table as CSV: SI values, units in the headers."""
    from maglev_match.core.io import atomic_open

    folder, stem = output_target(out, "presets", "presets")
    path = folder / f"{stem}.csv"
    cols = ["omega1", "sigma", "w0", "L", "EI", "mbar"]
    with atomic_open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["name", *(header(c) for c in cols), "base", "description"])
        for r in rows:
            w.writerow([r["name"], *(f"{r[c]:.10g}" for c in cols), r["base"] or "",
                        r["description"]])
    return path
