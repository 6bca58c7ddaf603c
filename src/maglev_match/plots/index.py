"""Figures of the headline index (``maglev-match index``): what chi is made of (the paper's
chi, chi_simulation and the headline among the reading bands, and the lengths h and w0
behind them), and the spread of chi under parameter scatter (``index --scatter``,
``--monte-carlo``). The drawers only draw what the results carry: nothing is computed."""

from __future__ import annotations

import math

import numpy as np

from maglev_match.analyses.matching import READING_LEVELS, MatchingIndex
from maglev_match.api.index import IndexSpread
from maglev_match.core.results import figure
from maglev_match.plots.base import new_figure

__all__ = ["index_figure", "spread_figure"]

_BAND_COLOURS = ("#f4cccc", "#fff2cc", "#d9ead3", "#cfe2f3")


def _finite(*values) -> list[float]:
    return [float(v) for v in values if v is not None and math.isfinite(float(v))]


def index_figure(res: MatchingIndex, title: str | None = None):
    """The headline index and its parts. Left: bars of the paper's chi, chi_simulation
    (when it was computed) and the headline chi (hatched), over the reading bands of
    :data:`~maglev_match.analyses.matching.READING_LEVELS` (0-1 poor, 1-5 good, 5-10 very
    good, above 10 best). Right: the lengths behind them in mm: w0, h and the simulated
    critical disturbances (those computed). A part that was not computed is not drawn.

    Returns the figure."""
    fig, (ax1, ax2) = new_figure(1, 2, figsize=(10.5, 4.4),
                                 gridspec_kw={"width_ratios": [3, 2]})
    names, heights = ["chi_paper"], [res.chi_paper]
    if res.chi_simulation is not None:
        names.append("chi_simulation")
        heights.append(res.chi_simulation)
    names.append(f"chi (headline,\n{res.reading_basis})")
    heights.append(res.chi)
    shown = [h if math.isfinite(h) else 0.0 for h in map(float, heights)]
    top = max([12.0] + [1.15 * v for v in _finite(*heights)])
    lower = 0.0
    for k, (upper, words) in enumerate(READING_LEVELS):
        hi = min(upper, top)
        if hi > lower:
            ax1.axhspan(lower, hi, color=_BAND_COLOURS[k % len(_BAND_COLOURS)], alpha=0.6,
                        zorder=0, lw=0)
            ax1.text(0.99, 0.5 * (lower + hi), words.split(":")[0], ha="right",
                     va="center", fontsize=8, color="0.25", zorder=5,
                     transform=ax1.get_yaxis_transform(),
                     bbox={"boxstyle": "round", "fc": "white", "ec": "none", "alpha": 0.8})
        lower = upper
    x = np.arange(len(names))
    bars = ax1.bar(x, shown, width=0.5, color=["C0"] * (len(names) - 1) + ["C2"],
                   edgecolor="k", zorder=3)
    bars[-1].set_hatch("//")
    for xi, h in zip(x, heights, strict=True):
        text = f"{h:.4g}" if math.isfinite(h) else "not computed"
        ax1.annotate(text, (xi, shown[xi]), textcoords="offset points", xytext=(0, 3),
                     ha="center", fontsize=9, zorder=4)
    ax1.set_xticks(x, names)
    ax1.set_ylim(0.0, top)
    ax1.set_ylabel("chi = h / w0")
    ax1.set_title("the index and its reading bands")
    lengths = [("w0", res.w0), ("h", res.h), ("h_sim up", res.h_simulation_up),
               ("h_sim down", res.h_simulation_down)]
    lengths = [(n, v) for n, v in lengths if v is not None and math.isfinite(float(v))]
    xl = np.arange(len(lengths))
    ax2.bar(xl, [1e3 * float(v) for _, v in lengths], width=0.6,
            color=["0.5"] + ["C1"] * (len(lengths) - 1), edgecolor="k", zorder=3)
    ax2.set_xticks(xl, [n for n, _ in lengths])
    ax2.set_ylabel("length (mm)")
    ax2.set_title("static deflection w0 and basin sizes h")
    if title is None:
        title = (f"Matching index chi = {res.chi:.4g} ({res.case}; model {res.model})\n"
                 f"{res.reading}")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return fig


def spread_figure(spread: IndexSpread, title: str | None = None):
    """The spread of chi. With a Monte Carlo study: the histogram of the sampled chi with
    its mean and 5 % / 95 % quantiles, and the linearised chi +- sd shaded. Without: the
    linearised chi with +-1 and +-2 sd. Beside it (when the linearised spread was
    computed), each scattered parameter's part of the linearised standard deviation.

    Returns the figure."""
    lin, mc = spread.linearised, spread.sampled
    fig, axes = new_figure(1, 2 if lin is not None else 1, figsize=(10.0, 4.2),
                           squeeze=False)
    ax = axes[0, 0]
    if mc is None and lin is None:
        ax.text(0.5, 0.5, "no scatter given: no spread", ha="center", va="center",
                transform=ax.transAxes)
        ax.set_axis_off()
        fig.suptitle(title or "Spread of chi", fontsize=10)
        return fig
    if mc is not None:
        chi = np.asarray(mc.chi, float)
        ok = chi[np.isfinite(chi)]
        ax.hist(ok, bins=int(min(30, max(5, ok.size // 3))), color="C0", alpha=0.8,
                edgecolor="k", label=f"sampled chi ({ok.size} of {mc.n})")
        ax.axvline(mc.mean, color="k", lw=1.5, label=f"mean {mc.mean:.4g}")
        for key, ls in (("5%", "--"), ("95%", "--")):
            if key in mc.quantiles:
                ax.axvline(mc.quantiles[key], color="k", ls=ls, lw=1.0,
                           label=f"{key} quantile {mc.quantiles[key]:.4g}")
        if lin is not None:
            ax.axvspan(lin["chi"] - lin["sd"], lin["chi"] + lin["sd"], color="C1",
                       alpha=0.25, label=f"linearised chi +- sd ({lin['sd']:.3g})")
        ax.set_xlabel("chi")
        ax.set_ylabel("samples")
        ax.set_title("Monte Carlo: sampled chi")
        ax.legend(fontsize=8, loc="best")
        what = f"{mc.n} samples, sd {mc.sd:.3g}"
    else:
        c, sd = float(lin["chi"]), float(lin["sd"])
        ax.errorbar([0], [c], yerr=[[2 * sd], [2 * sd]], fmt="none", ecolor="0.6",
                    capsize=8, lw=1.2, label="+- 2 sd")
        ax.errorbar([0], [c], yerr=[[sd], [sd]], fmt="o", color="C0", ecolor="C0",
                    capsize=6, lw=2.0, label=f"chi = {c:.4g} +- {sd:.3g} (1 sd)")
        ax.set_xticks([0], ["chi"])
        ax.set_xlim(-1.0, 1.0)
        ax.set_ylabel("chi")
        ax.set_title("linearised spread")
        ax.legend(fontsize=8, loc="best")
        what = f"linearised sd {sd:.3g}"
    if lin is not None:
        parts = lin.get("contributions", {})
        axc = axes[0, -1]
        y = np.arange(len(parts))
        axc.barh(y, list(parts.values()), color="C1", edgecolor="k")
        axc.set_yticks(y, list(parts))
        axc.set_xlabel("part of the linearised sd of chi")
        axc.set_title("contributions")
    fig.suptitle(title or f"Spread of chi under parameter scatter ({what})", fontsize=10)
    fig.tight_layout()
    return fig


@figure.register(MatchingIndex)
def _index(res: MatchingIndex, **kw):
    return index_figure(res, **kw)


@figure.register(IndexSpread)
def _spread(spread: IndexSpread, **kw):
    return spread_figure(spread, **kw)
