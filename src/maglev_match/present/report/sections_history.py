"""The study report's time histories, shared with the reproduction of the paper's
Figs. 6-8, 11 and 13: one simulation with the physical limits on
(:func:`run_time_history`), its outcome in words (:func:`outcome_text`, :func:`converges`,
:func:`late_amplitude`), the figure of gap deviation and phase portrait
(:func:`time_history_figure`, its time axis fitted by :func:`fitted_window`) and the
section after the typical disturbance (:func:`section_time_history`)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from maglev_match.core.params import Params
from maglev_match.core.units import label as unit_label
from maglev_match.maglev.catalog import model_info
from maglev_match.present.report.html import formatted_rows, render, save_and_embed

if TYPE_CHECKING:
    from maglev_match.present.report.base import ReportContext

__all__ = [
    "run_time_history",
    "late_amplitude",
    "converges",
    "outcome_text",
    "SETTLED_FRACTION",
    "fitted_window",
    "time_history_figure",
    "section_time_history",
]


def run_time_history(params: Params, model: str, t_end: float, *, x5: float | None = None,
                     initial: str = "equilibrium", q1: float | None = None):
    """One simulation with the physical limits on, and its history as an xarray Dataset."""
    from maglev_match.analyses.simulation import history_dataset, simulate_maglev
    from maglev_match.maglev.models import maglev_model

    m = maglev_model(params, model)
    x0 = m.initial_state(initial, x5=x5, q1=q1)
    # 10001 saved points (0.3-0.5 ms apart): smooth phase portraits of 20 Hz oscillations
    sim = simulate_maglev(m, x0=x0, t_end=t_end, n_save=10001)
    return sim, history_dataset(sim)


def late_amplitude(sim: Any, window: float = 1.0) -> tuple[float, float]:
    """Largest |gap deviation| (m, over all levitation points) in the first and in the last
    ``window`` seconds of a run."""
    from maglev_match.analyses.simulation import history_dataset

    ds = history_dataset(sim)
    t = ds["time"].values
    g = np.abs(ds["gap_deviation"].values).max(axis=1)
    if len(t) == 0:
        return float("nan"), float("nan")
    early = g[t <= t[0] + window].max()
    late = g[t >= t[-1] - window].max()
    return float(early), float(late)


def converges(sim: Any) -> bool:
    """The run returned to the equilibrium, or had not collided by the horizon with the
    gap oscillation in its last second below half of that in its first second."""
    if sim.outcome == "converged":
        return True
    if sim.outcome != "running":
        return False
    early, late = late_amplitude(sim)
    return bool(late < 0.5 * early)


def outcome_text(sim: Any) -> str:
    """The outcome of a run in words."""
    if sim.outcome == "collision":
        where = f" at levitation point {sim.point}" if model_info(sim.model).points > 1 else ""
        return f"collision with the {sim.limit} gap limit{where} at t = {sim.collision_time:.4g} s"
    if sim.outcome == "running":
        early, late = late_amplitude(sim)
        trend = "decaying" if late < 0.5 * early else "not decaying"
        return (f"no collision by t = {sim.t_end:g} s; max |c - c0| {early * 1e3:.3g} mm in "
                f"the first second, {late * 1e3:.3g} mm in the last ({trend})")
    return {"converged": "returns to the equilibrium", "running": "still moving at the horizon",
            "failed": "integration failed"}.get(sim.outcome, sim.outcome)


#: A gap oscillation below this fraction of its peak counts as died out (the same rule as
#: the simulation figure, :data:`maglev_match.plots.simulate.SETTLED_FRACTION`).
SETTLED_FRACTION = 0.02


def fitted_window(histories: Sequence[Any]) -> tuple[float, float]:
    """(end of the fitted time axis, horizon) in s for history datasets: 25 % past the
    latest time any gap deviation exceeds 2 % of its run's peak (a collision ends its run
    there), at least 0.1 s, at most the horizon."""
    horizon, latest = 0.0, 0.0
    for ds in histories:
        t = ds["time"].values
        if len(t) == 0:
            continue
        horizon = max(horizon, float(t[-1]))
        g = np.abs(ds["gap_deviation"].values).reshape(len(t), -1).max(axis=1)
        if not np.any(g > 0):
            continue
        above = np.nonzero(g > SETTLED_FRACTION * g.max())[0]
        latest = max(latest, float(t[min(above[-1] + 1, len(t) - 1)]))
    horizon = horizon or 1.0
    return float(min(horizon, max(0.1, 1.25 * latest))), horizon


def time_history_figure(runs: Sequence[tuple[str, Any]], params: Params, title: str,
                        points: Sequence[int] | None = None):
    """Left: gap deviation (mm) against time, the axis fitted to the motion
    (:func:`fitted_window`) with the whole run in an inset when the motion ends early;
    right: phase portrait gap deviation against gap rate (mm/s). ``runs`` = (label, history
    Dataset) pairs; model B histories show the given levitation points."""
    from maglev_match.plots import new_figure

    fig, (ax1, ax2) = new_figure(1, 2, figsize=(11, 4.2))
    styles = ["-", "--", "-.", ":"]
    t_fit, horizon = fitted_window([ds for _, ds in runs])
    inset = None
    if t_fit < 0.8 * horizon:  # the motion is over early: the whole run in an inset
        inset = ax1.inset_axes([0.58, 0.62, 0.4, 0.34])
    for k, (label, ds) in enumerate(runs):
        t = ds["time"].values
        gd = ds["gap_deviation"].values
        rate = ds["gap_rate"].values
        pts = list(points) if points is not None else list(range(gd.shape[1]))
        for j, pidx in enumerate(pts):
            lab = label if len(pts) == 1 else f"{label}, point {pidx + 1}"
            color = f"C{(k * len(pts) + j) % 10}"
            ax1.plot(t, gd[:, pidx] * 1e3, color=color, ls=styles[k % 4], lw=1.2, label=lab)
            if inset is not None:
                inset.plot(t, gd[:, pidx] * 1e3, color=color, ls=styles[k % 4], lw=0.8)
            ax2.plot(gd[:, pidx] * 1e3, rate[:, pidx] * 1e3, color=color, ls=styles[k % 4],
                     lw=0.9)
    for g in (params.gap_min - params.c0, params.gap_max - params.c0):
        ax1.axhline(g * 1e3, color="k", ls=":", lw=1)
        ax2.axvline(g * 1e3, color="k", ls=":", lw=1)
    ax1.set_xlim(0.0, t_fit)
    ax1.set_xlabel("time (s)" if inset is None else
                   f"time (s); shown: 0 to {t_fit:.3g} s, the whole {horizon:g} s run inset")
    ax1.set_ylabel("gap deviation c - c0 (mm)")
    ax1.set_title(title)
    ax1.legend(fontsize=7, loc="lower right" if inset is not None else "best")
    if inset is not None:
        inset.set_xlim(0.0, horizon)
        inset.axvspan(0.0, t_fit, color="0.85", lw=0)
        inset.set_title(f"whole run, 0 to {horizon:g} s", fontsize=7)
        inset.tick_params(labelsize=6)
        inset.grid(alpha=0.3)
    ax2.set_xlabel("gap deviation c - c0 (mm)")
    ax2.set_ylabel(unit_label("gap_rate", "gap rate dc/dt"))
    ax2.set_title("phase portrait")
    return fig


def section_time_history(params: Params, ctx: ReportContext) -> tuple[str, list[Path], Any]:
    """The typical disturbance: model A with the beam at its undeflected position,
    x5(0) = -w0 (and model B pressed onto the free beam), limits on."""
    t_end = ctx.settings.t_end
    sim, ds = run_time_history(params, "unit", t_end, x5=-params.w0)
    runs = [(f"model A, x5(0) = -w0 = {-params.w0 * 1e3:.3g} mm", ds)]
    figure, files = save_and_embed(
        time_history_figure(runs, params, "Model A after the typical disturbance"), ctx,
        "time_history_unit", "Model A with the physical limits on, from x5(0) = -w0; the "
        "dotted lines are the gap limits.")
    figures = [figure]
    rows = [("model A", f"x5(0) = {-params.w0 * 1e3:.4g} mm", outcome_text(sim))]
    data = {"unit": sim.summary()}
    if ctx.settings.include_vehicle:
        simb, dsb = run_time_history(params, "vehicle", t_end, initial="pressed")
        fb, filesb = save_and_embed(
            time_history_figure([("model B pressed", dsb)], params,
                                "Model B pressed onto the free beam", points=[0, 2, 4]),
            ctx, "time_history_vehicle",
            "Model B: the vehicle pressed onto the free beam (all q_n = 0), gaps at the "
            "first point of each levitation frame.")
        figures.append(fb)
        files += filesb
        rows.append(("model B", "pressed onto the free beam", outcome_text(simb)))
        data["vehicle"] = simb.summary()
    return (render("time_history.html.j2", figures=figures, rows=formatted_rows(rows)), files,
            data)
