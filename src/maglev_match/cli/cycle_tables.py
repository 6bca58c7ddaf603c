"""The tables of a cycle branch, shared by `cycles`, its restarts and user models: the rows
of the CSV files and the JSON, their writer (SI values, units in the headers), the printed
summary, and `--at`."""

from __future__ import annotations

import csv
from pathlib import Path
from typing import Any

from rich import box
from rich.table import Table

from maglev_match.cli.common import UserError, console
from maglev_match.core.io import atomic_open, atomic_write_text
from maglev_match.core.params import ParameterError

__all__ = ["at_values", "write_csv", "print_summary", "print_user_branch", "shown_rows"]


def at_values(at: list[str] | None) -> dict[str, float]:
    """``--at NAME=VALUE`` items as numbers (the API checks the names)."""
    values: dict[str, float] = {}
    for item in at or []:
        if "=" not in item:
            raise UserError(f"--at '{item}': expected NAME=VALUE, e.g. sigma=4e-4")
        name, text = item.split("=", 1)
        try:
            values[name.strip()] = float(text)
        except ValueError:
            raise ParameterError(name.strip(), text, "must be a number") from None
    return values


def write_csv(path: Path, rows: list[dict[str, Any]], param: str | None = None) -> None:
    """Rows as CSV, SI values, each header ``name (unit)`` (the continued parameter's unit
    from the parameter table, the others from :mod:`maglev_match.core.units`)."""
    from maglev_match.cli.common import unit_of
    from maglev_match.core.units import header

    if not rows:
        atomic_write_text(path, "")
        return
    keys = list(rows[0])
    unit = unit_of(param) if param else ""
    with atomic_open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow([f"{k} ({unit})" if k == param and unit else header(k) for k in keys])
        w.writerows([[r.get(k, "") for k in keys] for r in rows])


def print_summary(branches, chosen, param, files, first_line: str | None = None) -> None:
    """The branches as text: per branch its Hopf start (or a restart's first line), where it
    ended, a table of about a dozen cycles, the special points and the warnings."""

    for h, br in zip(chosen, branches, strict=True):
        if first_line is not None:  # a restart: its own header, no Hopf point found here
            console.print(first_line, highlight=False, markup=False)
        else:
            console.print(f"Hopf point {param} = {h.value:.8g}, frequency {h.frequency:.6g} "
                          f"rad/s, l1 = {h.l1:.4g} ({h.kind}); branch ended: "
                          f"{br.stopped_reason} after {br.steps} steps")
        if br.message:
            console.print(f"  {br.message}")
        table = Table(param, "T (s)", "gap dev max (mm)", "gap dev min (mm)", "i min (A)",
                      "stability", "n unst", box=box.SIMPLE)
        pts = br.points
        idx = shown_rows(len(pts))
        for k in idx:
            c = pts[k]
            table.add_row(f"{c.value:.7g}", f"{c.period:.5f}",
                          f"{c.extrema['gap_deviation'][0] * 1e3:.4f}",
                          f"{c.extrema['gap_deviation'][1] * 1e3:.4f}",
                          f"{c.extrema['current'][1]:.3f}",
                          (c.stability if c.reliable and c.stability else
                           ("stable" if c.stable else "unstable")) + ("" if c.reliable
                                                                     else "?"),
                          str(c.n_unstable) + ("" if c.reliable else "?"))
        console.print(table)
        unreliable = [c for c in pts if not c.reliable]
        if unreliable:
            console.print(f"  [yellow]{len(unreliable)} of {len(pts)} cycles have unreliable "
                          "multipliers (trivial multiplier away from 1, marked ?): their "
                          "stability is not trusted and no LPC/PD/NS/BP is declared "
                          "there[/]")
        for s in br.special_points:
            what = (f"contact with the physical limit '{s.detail}'"
                    if s.type == "contact" else
                    f"{s.type}{': ' + s.detail if s.detail else ''}")
            gap = s.extrema.get("gap_deviation")
            tail = (f", gap dev max {gap[0] * 1e3:.4f} mm, min {gap[1] * 1e3:.4f} mm"
                    if gap is not None and s.type != "H" else "")
            console.print(f"  {s.label or s.type}: {what} at {param} = {s.value:.10g} "
                          f"({s.located}){tail}")
        for w in br.warnings:
            console.print(f"  [yellow]warning:[/] {w}")
    for f in files:
        console.print(f"wrote {f}")


def print_user_branch(h, br, param: str, restarted: bool = False) -> None:
    """A user model's branch as text: its Hopf start and end, about a dozen cycles (value,
    period, stability) and the special points."""
    if not restarted:
        console.print(f"Hopf point {param} = {h.value:.8g}, frequency {h.frequency:.6g} rad/s, "
                      f"l1 = {h.l1:.4g} ({h.kind}); branch stopped: {br.stopped_reason} after "
                      f"{br.steps} steps", highlight=False)
    else:
        console.print(f"branch stopped: {br.stopped_reason} after {br.steps} steps",
                      highlight=False)
    for k in shown_rows(len(br.points)):
        c = br.points[k]
        console.print(f"  {param} = {c.value:.8g}  T = {c.period:.6g}  "
                      f"{'stable' if c.stable else 'unstable'} ({c.n_unstable} unstable "
                      f"multipliers, |trivial - 1| = {abs(c.trivial_multiplier - 1):.1e})",
                      highlight=False)
    for s in br.special_points:
        if restarted:
            console.print(f"  {s.label or s.type}: {s.type} at {param} = {s.value:.8g} "
                          f"({s.located})", highlight=False)
        else:
            console.print(f"  {s.type} at {param} = {s.value:.8g} ({s.located})"
                          f"{': ' + s.detail if s.detail else ''}", highlight=False)
    from maglev_match.cli.common import print_warnings

    print_warnings(br.warnings)


def shown_rows(n: int) -> list[int]:
    """The rows of a branch of ``n`` points that the text tables show: about a dozen,
    evenly spaced, and the last."""
    return sorted(set(range(0, n, max(1, n // 12))) | {n - 1}) if n else []



