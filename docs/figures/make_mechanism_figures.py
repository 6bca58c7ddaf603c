"""Regenerate the two figures of docs/matching-index.md: what decides the critical disturbance.

* ``docs/img/mechanism_grazing.png``: the soft turnout beam pushed down (x5(0) > 0). Runs just
  below and above the solved critical size: the gap of the critical run touches gap 0
  tangentially at t*, the run below turns back, the run above collides.
* ``docs/img/mechanism_basin.png``: the soft turnout beam with omega1 = 118 rad/s, beam up
  (x5(0) < 0). Runs just below and above the solved critical size follow the saddle cycle
  of the clamped system for a time that grows as the size approaches the critical one, then
  leave on opposite sides; right: the same runs as gap against gap rate, with the saddle
  cycle (collocation per segment; its held-current segments thick).

Usage (from the repository root): python docs/figures/make_mechanism_figures.py
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from maglev_match.analyses.critical import Mechanism, critical_from_bisection  # noqa: E402
from maglev_match.analyses.simulation import (  # noqa: E402
    critical_disturbance,
    initial_state,
    simulate_maglev,
)
from maglev_match.core.params import load_preset  # noqa: E402

OUT = Path(__file__).resolve().parents[1] / "img"


def _run(P, direction, size, t_end, n_save=6001):
    sim = simulate_maglev(P, "unit", initial_state(P, "unit", x5=direction * size), t_end,
                          n_save=n_save)
    ds = sim.to_xarray()
    return (ds["time"].values, ds["gap_deviation"].values[:, 0] * 1e3,
            ds["gap_rate"].values[:, 0], sim)


def grazing() -> None:
    P = load_preset("turnout-soft")
    r = critical_from_bisection(P, critical_disturbance(P, direction=1))
    assert r.mechanism == Mechanism.GRAZING, r.reason
    fig, (ax, zoom) = plt.subplots(1, 2, figsize=(10, 4), gridspec_kw={"width_ratios": [3, 2]})
    lower = (P.gap_min - P.c0) * 1e3
    for rel, colour, label in ((-1e-2, "tab:blue", "1 % below: returns"),
                               (0.0, "k", "critical size (solved)"),
                               (1e-2, "tab:red", "1 % above: collides")):
        t, g, _, sim = _run(P, 1, r.size * (1 + rel), 0.3)
        for a in (ax, zoom):
            a.plot(t, g, color=colour, lw=1.2, label=f"{label}")
    for a in (ax, zoom):
        a.axhline(lower, color="0.3", ls="--", lw=1)
        a.axvline(r.t_star, color="0.6", ls=":", lw=1)
    zoom.set_xlim(r.t_star - 0.006, r.t_star + 0.006)
    zoom.set_ylim(lower - 0.15, lower + 0.6)
    ax.set_title(f"grazing: beam down, x5(0) = {r.size * 1e3:.5g} mm, tangency at "
                 f"t* = {r.t_star:.4g} s", fontsize=10)
    zoom.set_title("near t*: the gap touches its lower limit (gap 0)", fontsize=10)
    for a in (ax, zoom):
        a.set_xlabel("time (s)")
    ax.set_ylabel("gap deviation c - c0 (mm)")
    ax.legend(fontsize=8, loc="upper right")
    fig.tight_layout()
    fig.savefig(OUT / "mechanism_grazing.png", dpi=130)
    plt.close(fig)


def basin() -> None:
    P = load_preset("turnout-soft").replace(omega1=118.0)
    r = critical_from_bisection(P, critical_disturbance(P, direction=-1))
    assert r.mechanism == Mechanism.BASIN_BOUNDARY, r.reason
    fig, (ax, ph) = plt.subplots(1, 2, figsize=(11, 4), gridspec_kw={"width_ratios": [3, 2]})
    runs = ((-1e-3, "tab:cyan"), (-1e-6, "tab:blue"), (1e-3, "tab:orange"), (1e-6, "tab:red"))
    for rel, colour in runs:
        t, g, rate, sim = _run(P, -1, r.size * (1 + rel), 6.0, n_save=12001)
        word = (f"collides at {sim.collision_time:.2f} s" if sim.outcome == "collision"
                else "returns" if abs(g[np.isfinite(g)][-1]) < 0.05 else sim.outcome)
        ax.plot(t, g, color=colour, lw=0.5, alpha=0.8,
                label=f"size {rel:+.0e} relative to the critical one: {word}")
        ph.plot(g, rate, color=colour, lw=0.3, alpha=0.8)
    orbit = r.orbit
    _, X, seg = orbit.profile(200)
    gap = (X[:, 0] - X[:, 4]) * 1e3  # c - c0 = x1 - x5
    rate = X[:, 1] - X[:, 5]  # dc/dt = x2 - x6
    held = np.array([orbit.segments[k].mode[0] == 1 for k in seg])
    ph.plot(gap, rate, "k", lw=1.2, label="saddle cycle of the clamped system")
    ph.plot(np.where(held, gap, np.nan), np.where(held, rate, np.nan), "k", lw=3.0,
            label="current held at zero")
    for a in (ax,):
        a.axhline((P.gap_min - P.c0) * 1e3, color="0.3", ls="--", lw=1)
        a.axhline((P.gap_max - P.c0) * 1e3, color="0.3", ls="--", lw=1)
    ax.set_title(f"basin boundary: omega1 = 118 rad/s, beam up, |x5(0)| = {r.size * 1e3:.5g} "
                 f"mm;\nsaddle cycle period {r.cycle_period * 1e3:.1f} ms, unstable multiplier "
                 f"{r.multiplier:.3f}", fontsize=10)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("gap deviation c - c0 (mm)")
    ax.legend(fontsize=7, loc="lower right")
    ph.set_xlabel("gap deviation (mm)")
    ph.set_ylabel("gap rate (m/s)")
    ph.set_xlim((P.gap_min - P.c0) * 1e3 - 0.5, (P.gap_max - P.c0) * 1e3 + 0.5)
    ph.set_ylim(-1.4 * np.max(np.abs(rate)), 1.4 * np.max(np.abs(rate)))
    ph.legend(fontsize=7, loc="upper left")
    ph.set_title("runs near the critical size and the cycle", fontsize=10)
    fig.tight_layout()
    fig.savefig(OUT / "mechanism_basin.png", dpi=130)
    plt.close(fig)


if __name__ == "__main__":
    OUT.mkdir(parents=True, exist_ok=True)
    grazing()
    basin()
    print(f"wrote {OUT / 'mechanism_grazing.png'} and {OUT / 'mechanism_basin.png'}")
