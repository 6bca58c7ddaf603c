"""Figures of simulated runs in the style of the paper's Figs. 6-8, 11 and 13: the gap
deviation's time history beside its phase portrait (gap deviation vs. gap rate) with the
physical limits drawn; for model B, the gaps of the three levitation frames."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from maglev_match.plots import new_figure, save_figure
from maglev_match.simulation import MaglevSimulation, history_dataset

__all__ = ["plot_simulation", "simulation_figure"]

_COLOURS = ("tab:blue", "tab:red", "tab:green", "tab:purple", "tab:orange", "tab:brown")


def _limits(ax, sim: MaglevSimulation, axis: str = "y") -> None:
    p = sim.params
    for v in ((p.gap_min - p.c0) * 1e3, (p.gap_max - p.c0) * 1e3):
        if axis == "y":
            ax.axhline(v, color="k", ls=":", lw=1.0)
        else:
            ax.axvline(v, color="k", ls=":", lw=1.0)


def _label(sim: MaglevSimulation, name: str | None) -> str:
    base = name or ""
    if sim.outcome == "collision":
        return f"{base} collision at {sim.collision_time:.3f} s ({sim.limit}, point {sim.point})"
    return f"{base} {sim.outcome}".strip()


def simulation_figure(sims: Sequence[MaglevSimulation], labels: Sequence[str] | None = None,
                      title: str | None = None):
    """A figure of one or more runs of the same model. Model A: time history of the gap
    deviation (mm) and the phase portrait (gap deviation vs. gap rate), limits dotted.
    Model B: the six gaps in three panels (one per frame) and the phase portrait of the
    first run's points. Returns (fig, axes)."""
    if not sims:
        raise ValueError("nothing to plot")
    labels = list(labels) if labels is not None else [None] * len(sims)
    model = sims[0].model
    if model == "unit":
        fig, axes = new_figure(1, 2, figsize=(11.0, 4.2))
        ax_t, ax_p = axes
        for k, (sim, lab) in enumerate(zip(sims, labels, strict=True)):
            ds = history_dataset(sim)
            colour = _COLOURS[k % len(_COLOURS)]
            ls = "-" if k % 2 == 0 else "--"
            gd = ds.gap_deviation.values[:, 0] * 1e3
            ax_t.plot(ds.time.values, gd, color=colour, ls=ls, lw=1.0, label=_label(sim, lab))
            ax_p.plot(gd, ds.gap_rate.values[:, 0], color=colour, ls=ls, lw=0.8)
        _limits(ax_t, sims[0], "y")
        _limits(ax_p, sims[0], "x")
        ax_t.set_xlabel("time t (s)")
        ax_t.set_ylabel("gap deviation c - c0 (mm)")
        ax_t.legend(fontsize=8, loc="best")
        ax_p.set_xlabel("gap deviation c - c0 (mm)")
        ax_p.set_ylabel("gap rate dc/dt (m/s)")
        ax_t.set_title("time history")
        ax_p.set_title("phase portrait (gap vs. gap rate)")
    else:
        fig, axes = new_figure(2, 2, figsize=(11.0, 7.0))
        panels = [axes[0, 0], axes[0, 1], axes[1, 0]]
        ax_p = axes[1, 1]
        for k, (sim, lab) in enumerate(zip(sims, labels, strict=True)):
            ds = history_dataset(sim)
            ls = "-" if k == 0 else "--"
            gd = ds.gap_deviation.values * 1e3
            for frame in range(3):
                for side in range(2):
                    j = 2 * frame + side
                    panels[frame].plot(
                        ds.time.values, gd[:, j], color=_COLOURS[side + 2 * (k % 2)], ls=ls,
                        lw=1.0, label=f"point {j + 1}" + (f" ({lab})" if lab else ""))
            if k == 0:
                for j in range(6):
                    ax_p.plot(gd[:, j], ds.gap_rate.values[:, j], color=_COLOURS[j], lw=0.7,
                              label=f"point {j + 1}")
        for frame, ax in enumerate(panels):
            _limits(ax, sims[0], "y")
            ax.set_title(f"frame {frame + 1}")
            ax.set_xlabel("time t (s)")
            ax.set_ylabel("gap deviation (mm)")
            ax.legend(fontsize=7, loc="best")
        _limits(ax_p, sims[0], "x")
        ax_p.set_xlabel("gap deviation (mm)")
        ax_p.set_ylabel("gap rate (m/s)")
        ax_p.set_title("phase portrait")
        ax_p.legend(fontsize=7, loc="best")
    outcome = "; ".join(_label(s, lab) for s, lab in zip(sims, labels, strict=True))
    fig.suptitle(title or outcome, fontsize=10)
    fig.tight_layout()
    return fig, axes


def plot_simulation(sims: MaglevSimulation | Sequence[MaglevSimulation], path: str | Path,
                    labels: Sequence[str] | None = None, title: str | None = None
                    ) -> list[Path]:
    """Save :func:`simulation_figure` as PNG and SVG at ``path`` (suffix replaced)."""
    runs = [sims] if isinstance(sims, MaglevSimulation) else list(sims)
    fig, _ = simulation_figure(runs, labels, title)
    return save_figure(fig, path)

