"""Figures at speed over an irregular guideway: one panel per read-out against speed."""

from __future__ import annotations

import numpy as np

from maglev_match.analyses.speed.irregular import IrregularSweep
from maglev_match.core.results import figure
from maglev_match.plots.base import new_figure

__all__ = ["irregular_figure"]

KMH = 3.6  # km/h per m/s


def irregular_figure(sweep: IrregularSweep):
    """Six panels against speed (km/h): gap deviation (rms and largest, mm; the linear
    route's rms dashed where computed), current (rms of i - i0 and the largest, A; a red
    ring where it would reverse), car-body rms acceleration, Sperling's Wz, DAF, and the
    probability of contact over the run's distance with its 95 % Wilson interval."""
    v = np.asarray(sweep.speeds, float) * KMH
    c = sweep.column
    fig, axes = new_figure(6, 1, figsize=(7.5, 13.0), sharex=True)
    ax = axes[0]
    ax.plot(v, c("gap_rms") * 1e3, "o-", ms=3.5, label="rms")
    ax.plot(v, c("gap_max") * 1e3, "s-", ms=3.5, label="largest |.|")
    lin = c("gap_rms_linear")
    if np.isfinite(lin).any():
        ax.plot(v, c("gap_rms_profile") * 1e3, "^", ms=4, label="rms of the profile's part")
        ax.plot(v, lin * 1e3, "k--", lw=1.0, label="linear route (rigid guideway)")
    ax.set_ylabel("gap deviation (mm)")
    ax.legend(fontsize=8)
    ax = axes[1]
    ax.plot(v, c("current_rms"), "o-", ms=3.5, label="rms of i - i0")
    ax.plot(v, c("current_max"), "s-", ms=3.5, label="largest i")
    rev = c("reverses") > 0.5
    if rev.any():
        ax.plot(v[rev], c("current_max")[rev], "o", mfc="none", mec="r", ms=9,
                label="would reverse (clamp at 0)")
    ax.set_ylabel("current (A)")
    ax.legend(fontsize=8)
    axes[2].plot(v, c("acc_rms"), "o-", ms=3.5)
    axes[2].set_ylabel("car body rms acc. (m/s^2)")
    axes[3].plot(v, c("wz"), "o-", ms=3.5)
    axes[3].set_ylabel("Sperling Wz")
    axes[4].plot(v, c("daf"), "o-", ms=3.5)
    axes[4].set_ylabel("DAF")
    ax = axes[5]
    p, lo, hi = c("p_contact"), c("p_contact_low"), c("p_contact_high")
    ax.errorbar(v, p, yerr=[p - lo, hi - p], fmt="o", ms=4, capsize=3)
    ax.set_ylim(-0.02, 1.02)
    ax.set_ylabel(f"P(contact) over {sweep.distance:g} m")
    ax.set_xlabel("speed (km/h)")
    axes[0].set_title(f"{sweep.model} over an irregular guideway: "
                      f"{sweep.profile.describe()}", fontsize=9)
    fig.tight_layout()
    return fig


@figure.register(IrregularSweep)
def _irregular(sweep: IrregularSweep, **kw):
    return irregular_figure(sweep, **kw)
