"""Figures of simulated runs in the style of the paper's Figs. 6-8, 11 and 13.

Four panels against a time axis fitted to what happened (the collision, or the return to
equilibrium, with a margin): the gap deviation c - c0 with the physical gap limits, the
coil current with the zero-current limit, the beam deflection, and the phase portrait
(gap deviation against gap rate). The title says what was simulated (model, beam,
initial state, limits) and what happened (collision time, limit and levitation point;
return; neither by the horizon).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from maglev_match.analyses.simulation import MaglevSimulation, history_dataset
from maglev_match.api.simulation import UserSimulation
from maglev_match.core.results import figure, figure_of_many
from maglev_match.core.units import label as unit_label
from maglev_match.core.units import shown as shown_in
from maglev_match.maglev.catalog import model_info
from maglev_match.plots.base import new_figure, save_figure

__all__ = ["plot_simulation", "simulation_figure", "describe_initial", "describe_outcome",
           "fitted_time_window", "transient_end", "user_simulation_figure", "USER_PANELS"]

_COLOURS = ("tab:blue", "tab:red", "tab:green", "tab:purple", "tab:orange", "tab:brown")
_LIMIT_STYLE = {"color": "k", "ls": ":", "lw": 1.0}


def describe_initial(sim: MaglevSimulation) -> str:
    """The initial state in words: the states that differ from the equilibrium (at most
    three, SI units shown in mm, mm/s or A), or 'pressed onto the free beam' for model B
    (the run's :attr:`~maglev_match.analyses.simulation.MaglevSimulation.initial_text`)."""
    return sim.initial_text


def describe_outcome(sim: MaglevSimulation) -> str:
    """What happened, in words."""
    if sim.outcome == "collision":
        where = "magnet hits the rail (gap 0)" if sim.limit == "lower" else \
            f"gap opens to its upper limit ({sim.params.gap_max * 1e3:g} mm)"
        point = f" at levitation point {sim.point}" if model_info(sim.model).points > 1 \
            else ""
        return f"collision at t = {sim.collision_time:.3f} s: {where}{point}"
    if sim.outcome == "converged":
        t = sim.result.converged_time
        return ("returns to the equilibrium" + (f" (settled from t = {t:.2f} s)"
                                                if t is not None else ""))
    if sim.outcome == "running":
        end = transient_end(sim)
        tail = (f"; gap oscillation below {SETTLED_FRACTION:.0%} of its peak from "
                f"t = {end:.2f} s" if end < sim.t_end else "")
        return f"no collision by t = {sim.t_end:g} s, not yet settled{tail}"
    return "integration failed: " + "; ".join(sim.warnings)


SETTLED_FRACTION = 0.02  # a gap oscillation below 2 % of its peak counts as died out


def transient_end(sim: MaglevSimulation) -> float:
    """When the run's gap transient is over (s): the collision time; the start of the
    settled stretch of a converged run; otherwise the last time any gap deviation exceeds
    2 % of its peak over the run (the horizon if it never falls that low)."""
    if sim.outcome == "collision" and sim.collision_time is not None:
        return float(sim.collision_time)
    if sim.outcome == "converged" and sim.result.converged_time is not None:
        return float(sim.result.converged_time)
    ds = history_dataset(sim)
    t = ds.time.values
    g = np.abs(ds.gap_deviation.values).max(axis=1)
    if len(t) == 0 or not np.any(g > 0):
        return float(sim.t_end)
    above = np.nonzero(g > SETTLED_FRACTION * g.max())[0]
    return float(t[min(above[-1] + 1, len(t) - 1)])


def fitted_time_window(sims: Sequence[MaglevSimulation]) -> float:
    """The end of the time axis (s): 25 % past the latest end of a transient
    (:func:`transient_end`), at least 0.1 s, at most the horizon."""
    horizon = max(s.t_end for s in sims)
    latest = max(transient_end(s) for s in sims)
    return float(min(horizon, max(0.1, 1.25 * latest)))


def simulation_figure(sims: Sequence[MaglevSimulation], labels: Sequence[str] | None = None,
                      title: str | None = None):
    """A figure of one or more runs of the same model.

    Panels: gap deviation c - c0 (mm) with the gap limits dotted; coil current (A) with
    zero current dotted; beam deflection (mm: model A's w, model B's modal coordinates);
    phase portrait of the gap deviation against the gap rate (mm/s). Model B draws every
    levitation point of the first run (points 1-6) and, for further runs, point 1 dashed.
    Collisions are marked with a cross. The time axis ends 25 % after the latest deciding
    event (:func:`fitted_time_window`).

    Returns (fig, axes) with axes a 2 x 2 array: [[gap, current], [beam, phase]].
    """
    if not sims:
        raise ValueError("nothing to plot")
    labels = list(labels) if labels is not None else [describe_initial(s) for s in sims]
    model = sims[0].model
    if any(s.model != model for s in sims):
        raise ValueError("all runs of one figure must be of the same model")
    info = model_info(model)
    several = info.points > 1  # every levitation point of the first run
    p = sims[0].params
    fig, axes = new_figure(2, 2, figsize=(11.0, 7.2))
    ax_g, ax_i, ax_w, ax_p = axes[0, 0], axes[0, 1], axes[1, 0], axes[1, 1]
    t_max = fitted_time_window(sims)
    for k, (sim, lab) in enumerate(zip(sims, labels, strict=True)):
        ds = history_dataset(sim)
        t = ds.time.values
        gd = ds.gap_deviation.values * 1e3
        cur = ds.current.values
        rate = shown_in("gap_rate", ds.gap_rate.values)
        bw = ds.beam_deflection.values * 1e3
        ls = "-" if k == 0 else "--"
        if not several or k > 0:
            pts = [0]
        else:
            pts = list(range(gd.shape[1]))
        for j in pts:
            colour = _COLOURS[j % len(_COLOURS)] if (several and k == 0) else \
                _COLOURS[k % len(_COLOURS)]
            name = lab if not several else (f"point {j + 1}" if k == 0 else
                                            f"point 1 ({lab})")
            if several and k == 0 and j == 0:
                name = f"point 1 ({lab})"
            ax_g.plot(t, gd[:, j], color=colour, ls=ls, lw=1.0, label=name)
            ax_i.plot(t, cur[:, j], color=colour, ls=ls, lw=1.0)
            shown = t <= t_max
            ax_p.plot(gd[shown, j], rate[shown, j], color=colour, ls=ls, lw=0.8)
            if sim.outcome == "collision" and len(t) and (not several
                                                           or sim.point == j + 1):
                ax_g.plot(t[-1], gd[-1, j], "x", color=colour, ms=8, mew=2)
                ax_p.plot(gd[-1, j], rate[-1, j], "x", color=colour, ms=8, mew=2)
        if bw.ndim == 1:  # one deflection (model A's w), else modal coordinates
            ax_w.plot(t, bw, color=_COLOURS[k % len(_COLOURS)], ls=ls, lw=1.0)
        else:
            for n in range(bw.shape[1] if k == 0 else 1):
                ax_w.plot(t, bw[:, n], color=_COLOURS[n % len(_COLOURS)], ls=ls, lw=1.0,
                          label=f"q{n + 1}" if k == 0 else None)
    lo, hi = (p.gap_min - p.c0) * 1e3, (p.gap_max - p.c0) * 1e3
    for v in (lo, hi):
        ax_g.axhline(v, **_LIMIT_STYLE)
        ax_p.axvline(v, **_LIMIT_STYLE)
    ax_g.plot([], [], **_LIMIT_STYLE, label=f"gap limits: c - c0 = {lo:g} and {hi:g} mm "
              f"(gap {p.gap_min * 1e3:g} and {p.gap_max * 1e3:g} mm)")
    if any(s.outcome == "collision" for s in sims):
        ax_g.plot([], [], "kx", ms=7, mew=2, label="collision")
    ax_i.axhline(0.0, **_LIMIT_STYLE, label="zero current (never reverses)")
    i0 = sims[0].levitation_current
    ax_i.axhline(i0, color="0.6", lw=0.8, ls="-.", label=f"levitation current {i0:.3g} A")
    for ax in (ax_g, ax_i, ax_w):
        ax.set_xlim(0.0, t_max)
        ax.set_xlabel("time t (s)")
    ax_g.set_ylabel("gap deviation c - c0 (mm)")
    ax_g.set_title("gap (positive: wider)")
    ax_i.set_ylabel("coil current i (A)")
    ax_i.set_title("coil current" + (" (force-producing, max(i, 0))" if sims[0].limited
                                      else ""))
    if bw.ndim == 1:
        ax_w.set_ylabel("beam deflection w (mm, down positive)")
        ax_w.set_title("beam deflection under the unit")
    else:
        ax_w.set_ylabel("modal coordinate q_n (mm)")
        ax_w.set_title("beam modal coordinates (undeflected beam = 0)")
        ax_w.legend(fontsize=7, loc="best")
    ax_p.set_xlabel("gap deviation c - c0 (mm)")
    ax_p.set_ylabel(unit_label("gap_rate", "gap rate dc/dt"))
    horizon = max(s.t_end for s in sims)
    ax_p.set_title(f"phase portrait (0 to {t_max:.3g} s)")
    if t_max < horizon:
        ax_w.set_xlabel(f"time t (s); shown: 0 to {t_max:.3g} s of the {horizon:g} s "
                        "simulated")
    ax_g.legend(fontsize=7, loc="best")
    ax_i.legend(fontsize=7, loc="best")
    if title is None:
        what = (f"Model {info.letter} ({info.title}), "
                f"omega1 = {float(p.omega1):.4g} rad/s, sigma = {float(p.sigma):.3g} 1/kg, "
                f"limits {'on' if sims[0].limited else 'off'}")
        outcomes = [f"{lab}: {describe_outcome(s)}" for s, lab in zip(sims, labels,
                                                                          strict=True)]
        title = what + "\n" + "\n".join(outcomes)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return fig, axes


def plot_simulation(sims: MaglevSimulation | Sequence[MaglevSimulation], path: str | Path,
                    labels: Sequence[str] | None = None, title: str | None = None
                    ) -> list[Path]:
    """Save :func:`simulation_figure` as PNG and SVG at ``path`` (suffix replaced)."""
    runs = [sims] if isinstance(sims, MaglevSimulation) else list(sims)
    fig, _ = simulation_figure(runs, labels, title)
    return save_figure(fig, path)


@figure.register(MaglevSimulation)
def _simulation(sim: MaglevSimulation, **kw):
    return _simulations(sim, [sim], **kw)


@figure_of_many.register(MaglevSimulation)
def _simulations(first: MaglevSimulation, sims, **kw):
    return simulation_figure(list(sims), **kw)[0]


#: The most state panels of a user model's figure (a discretised delay system has many
#: states: its first ones, the model's own, are drawn)
USER_PANELS = 8


def user_simulation_figure(sim: UserSimulation, title: str | None = None):
    """A user model's run: one panel per state against time (the model's units), at most
    :data:`USER_PANELS` (the rest named in a note); the title gives the model and the
    outcome.

    Returns the figure."""
    t, x = sim.history()
    t, x = np.asarray(t, float), np.asarray(x, float).reshape(len(t), -1)
    names = list(sim.state_names)
    shown = min(len(names), USER_PANELS)
    fig, axes = new_figure(shown, 1, figsize=(8.0, 1.2 + 1.7 * shown), sharex=True,
                           squeeze=False)
    res = sim.result
    for k in range(shown):
        ax = axes[k, 0]
        ax.plot(t, x[:, k], color=_COLOURS[k % len(_COLOURS)], lw=1.1)
        ax.set_ylabel(names[k])
    axes[-1, 0].set_xlabel("time t (s, or the model's time unit)")
    if len(names) > shown:
        axes[-1, 0].text(0.99, 0.02, f"first {shown} of {len(names)} states shown",
                         transform=axes[-1, 0].transAxes, ha="right", fontsize=8)
    if title is None:
        title = (f"User model {sim.model}: {sim.outcome} at t = {res.final_time:.4g} s"
                 + (f" (settled from t = {res.converged_time:.4g} s)"
                    if res.converged_time is not None else ""))
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return fig


@figure.register(UserSimulation)
def _user_simulation(sim: UserSimulation, **kw):
    return user_simulation_figure(sim, **kw)
