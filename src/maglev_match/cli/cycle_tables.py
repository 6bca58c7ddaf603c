"""The tables of a cycle branch, shared by `cycles`, its restarts and user models: the rows
of the CSV files and the JSON, their writer (SI values, units in the headers), the printed
summary, and `--at`."""

from __future__ import annotations

import csv
from pathlib import Path
from typing import TYPE_CHECKING, Any

from rich import box
from rich.table import Table

from maglev_match.cli.common import UserError, console
from maglev_match.core.io import atomic_open, atomic_write_text
from maglev_match.core.params import ParameterError, Params, warn_overridden

if TYPE_CHECKING:  # the numerics (and JAX) are imported when a command runs
    from maglev_match.dynamics.cycles import CycleBranch

__all__ = ["apply_at", "branch_rows", "special_rows", "write_csv", "print_summary", "shown_rows",
           "user_cycle_rows", "user_special_rows"]


def apply_at(params: Params, at: list[str] | None) -> Params:
    """Apply NAME=VALUE settings to a parameter set (validated)."""
    values: dict[str, float] = {}
    for item in at or []:
        if "=" not in item:
            raise UserError(f"--at '{item}': expected NAME=VALUE, e.g. sigma=4e-4")
        name, text = item.split("=", 1)
        try:
            values[name.strip()] = float(text)
        except ValueError:
            raise ParameterError(name.strip(), text, "must be a number") from None
    try:
        new = params.replace(**values) if values else params
    except TypeError as exc:
        raise UserError(f"--at: unknown parameter ({exc})") from None
    warn_overridden(new, set(values))  # e.g. --at L=20 while omega1 is set explicitly
    return new


def _branch_rows(br: CycleBranch, param: str) -> list[dict[str, Any]]:
    import numpy as np

    rows = []
    for c in br.points:
        gmax, gmin = c.extrema["gap_deviation"]
        imax, imin = c.extrema["current"]
        rows.append({
            param: c.value, "period": c.period, "gap_dev_max": gmax, "gap_dev_min": gmin,
            "current_min": imin, "current_max": imax, "stable": c.stable,
            "stability": c.stability or ("stable" if c.stable else "unstable"),
            "unstable_multipliers": c.n_unstable,
            "max_abs_multiplier": float(np.max(np.abs(c.multipliers))),
            "kind": c.kind,
            "trivial_multiplier_error": float(abs(c.trivial_multiplier - 1.0)),
            "stability_reliable": c.reliable,
        })
    return rows


def _special_rows(br: CycleBranch, param: str) -> list[dict[str, Any]]:
    import numpy as np

    from maglev_match.dynamics.continuation import SpecialPointKind

    rows = []
    for s in br.special_points:
        gmax, gmin = s.extrema.get("gap_deviation", (float("nan"), float("nan")))
        rows.append({"type": s.type, param: s.value, "period": s.period, "gap_dev_max": gmax,
                     "gap_dev_min": gmin,
                     "current_min": s.extrema.get("current", (np.nan, np.nan))[1],
                     "limit": s.detail if s.type == SpecialPointKind.CONTACT else "",
                     "detail": s.detail, "located": s.located, "label": s.label})
    return rows


def _write_csv(path: Path, rows: list[dict[str, Any]], param: str | None = None) -> None:
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


def _print_summary(result, branches, chosen, param, files, first_line: str | None = None
                   ) -> None:
    from maglev_match.dynamics.continuation import SpecialPointKind

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
                    if s.type == SpecialPointKind.CONTACT else
                    f"{s.type}{': ' + s.detail if s.detail else ''}")
            gap = s.extrema.get("gap_deviation")
            tail = (f", gap dev max {gap[0] * 1e3:.4f} mm, min {gap[1] * 1e3:.4f} mm"
                    if gap is not None and s.type != SpecialPointKind.HOPF else "")
            console.print(f"  {s.label or s.type}: {what} at {param} = {s.value:.10g} "
                          f"({s.located}){tail}")
        for w in br.warnings:
            console.print(f"  [yellow]warning:[/] {w}")
    for f in files:
        console.print(f"wrote {f}")


def _cycle_rows(br, param: str) -> list[dict[str, Any]]:
    """The rows of a user-model cycle branch (CSV and JSON)."""
    import numpy as np

    out_rows = []
    for c in br.points:
        r = {param: c.value, "period": c.period, "stable": c.stable,
             "unstable_multipliers": c.n_unstable,
             "trivial_multiplier_error": abs(c.trivial_multiplier - 1.0),
             "max_abs_multiplier": float(np.max(np.abs(c.multipliers)))
             if len(c.multipliers) else 0.0, "kind": c.kind}
        for k, (hi, lo) in c.extrema.items():
            r[f"{k}_max"], r[f"{k}_min"] = hi, lo
        out_rows.append(r)
    return out_rows


def _special_rows_user(br, param: str) -> list[dict[str, Any]]:
    return [{"type": s.type, param: s.value, "period": s.period, "located": s.located,
             "detail": s.detail, "label": s.label} for s in br.special_points]


def shown_rows(n: int) -> list[int]:
    """The rows of a branch of ``n`` points that the text tables show: about a dozen,
    evenly spaced, and the last."""
    return sorted(set(range(0, n, max(1, n // 12))) | {n - 1}) if n else []


# the names the command modules have used
branch_rows, special_rows, write_csv, print_summary = (_branch_rows, _special_rows, _write_csv,
                                                       _print_summary)
user_cycle_rows, user_special_rows = _cycle_rows, _special_rows_user
