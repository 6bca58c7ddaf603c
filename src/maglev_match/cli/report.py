"""`maglev-match report` (self-contained HTML study report) and `maglev-match reproduce`
(the paper's figures and claims table recomputed with the printed defaults)."""

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
    UserError,
    check_output_path,
    console,
    console_err,
    emit_json,
    horizon_option,
    is_file_name,
    output_target,
    params_from_options,
    progress_report,
)
from maglev_match.cli.models import MaglevOnlyModelOpt, refuse_model_file

QuickOpt = Annotated[
    bool, typer.Option("--quick", help="Coarse, fast settings (previews and tests).")
]


def _progress(prog, total: int | None = None):
    """A section callback for :func:`~maglev_match.present.report.study_report`: one stage line per
    section, numbered ``[k/n]`` when the number of sections is known."""
    count = [0]

    def show(title: str) -> None:
        prog.stage(f"{title} ...", done=count[0] if total else None, total=total)
        count[0] += 1

    return show


@app.command("report")
def report_command(
    preset: PresetOpt = DEFAULT_PRESET_NAME,
    config: ConfigOpt = None,
    set_: SetOpt = None,
    out: Annotated[Path | None, typer.Option(
        "--out", help="The HTML file to write, or a folder for report.html (default: "
        "maglev-match-out/report/).")] = None,
    quick: QuickOpt = False,
    model_b: Annotated[bool, typer.Option(
        "--vehicle/--no-vehicle", help="Also analyse model B (full vehicle).")] = True,
    t_end: Annotated[float, typer.Option("--t-end", help="Simulation horizon (s).",
                                         callback=horizon_option)] = 3.0,
    json_out: JsonOpt = False,
    model: MaglevOnlyModelOpt = None,
) -> None:
    """Self-contained HTML study report of one vehicle-beam pair (figures embedded; the
    PNG/SVG files are written to <out stem>_figures/ beside it)."""
    refuse_model_file(model, "report")
    from maglev_match.present.documents import report_sections, study_report

    if out is not None and is_file_name(out) and out.suffix.lower() not in (".html", ".htm"):
        raise UserError(f"--out {out}: the report is an HTML file; give a name ending in .html "
                        "or a folder")
    if not t_end > 0:
        raise UserError(f"--t-end {t_end:g}: must be > 0")
    check_output_path(out)
    folder, stem = output_target(out, "report", "report")
    named = out is not None and is_file_name(out)
    out = folder / (f"{stem}{out.suffix}" if named else f"{stem}.html")
    params = params_from_options(preset, config, set_)
    label = preset + (f" + {config}" if config else "") + (
        " + " + ", ".join(set_) if set_ else "")
    with progress_report("report") as prog:
        res = study_report(params, out, quick=quick, vehicle=model_b, t_end=t_end, label=label,
                           progress=_progress(prog, report_sections()))
    summary = {
        "report": str(res.path),
        "figures": [str(f) for f in res.figures],
        "seconds": res.seconds,
        "headline": res.headline,
        "sections": {s.key: {"available": s.available, "reason": s.reason,
                             "seconds": s.seconds} for s in res.sections},
    }
    if json_out:
        emit_json(summary)
        return
    console.print(f"wrote {res.path} ({len(res.figures)} figure files) in {res.seconds:.1f} s")
    if res.headline is not None:
        h = res.headline
        what = "the paper's chi: --quick skips the simulation" if quick else \
            f"headline, from the {h['reading_basis']}"
        console.print(f"  chi = {h['chi']:.4g} ({what}): {h['reading']}")
    for key, reason in res.unavailable:
        console_err.print(f"[yellow]section '{key}' not available:[/] {reason}")


@app.command("reproduce")
def reproduce_command(
    out: Annotated[Path | None, typer.Option(
        "--out", help="Output folder, or the HTML file (its folder gets the rest; default: "
        "maglev-match-out/reproduce/).")] = None,
    quick: QuickOpt = False,
    only: Annotated[list[str] | None, typer.Option(
        "--only", help="Figure sections to include (repeatable): fig4, fig5, fig6-8, "
        "fig11-13, fig12, variants. Default: all.")] = None,
    json_out: JsonOpt = False,
    model: MaglevOnlyModelOpt = None,
) -> None:
    """Recompute the paper's figures (Figs. 4-8, 11-13) and its claims with the printed
    defaults; writes reproduce.html, claims.csv, claims.json and figures/ into --out."""
    refuse_model_file(model, "reproduce")
    from maglev_match.present.documents import REPRODUCE_SECTIONS as keys
    from maglev_match.present.documents import reproduce

    for k in only or []:
        if k not in keys:
            raise UserError(f"--only {k}: no such section; choose from {', '.join(keys)}")
    if out is not None and is_file_name(out) and out.suffix.lower() not in (".html", ".htm"):
        raise UserError(f"--out {out}: give a folder or an HTML file name (reproduce writes "
                        "several files)")
    check_output_path(out)
    html_name = out.name if out is not None and is_file_name(out) else None
    out, _ = output_target(out, "reproduce", "reproduce")
    n_sections = len(only) if only else len(keys)
    with progress_report("reproduce") as prog:
        report, claims = reproduce(out, quick=quick, only=only or None,
                                   progress=_progress(prog, n_sections + 1))  # + claims
    if html_name is not None and html_name != report.path.name:
        import dataclasses
        import os

        os.replace(report.path, out / html_name)
        report = dataclasses.replace(report, path=out / html_name)
    if json_out:
        from dataclasses import asdict

        emit_json({"report": str(report.path), "seconds": report.seconds,
                   "claims": [asdict(c) for c in claims],
                   "figures": [str(f) for f in report.figures],
                   "unavailable": dict(report.unavailable)})
        return
    from rich.table import Table

    table = Table("claim", "paper", "ours", "verdict", "difference", show_lines=False)
    colour = {"agree": "green", "close": "yellow", "differ": "red"}
    for c in claims:
        table.add_row(c.claim, c.paper, c.ours,
                      f"[{colour.get(c.verdict, 'magenta')}]{c.verdict}[/]", c.difference)
    console.print(table)
    console.print(f"wrote {report.path}, {out / 'claims.csv'} and {len(report.figures)} "
                  f"figure files in {report.seconds:.1f} s")
    for key, reason in report.unavailable:
        console_err.print(f"[yellow]section '{key}' not available:[/] {reason}")
