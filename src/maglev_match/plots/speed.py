"""Figures at speed: the read-outs of a speed sweep against speed, and the time histories of
a run over several spans with the periodic response overlaid."""

from __future__ import annotations

import numpy as np

from maglev_match.analyses.speed.spans import SpanRun
from maglev_match.analyses.speed.sweep import SpeedSweep
from maglev_match.core.results import figure
from maglev_match.plots.base import new_figure

__all__ = ["speed_figure", "span_run_figure"]

KMH = 3.6  # km/h per m/s


def _mark(ax, sweep, with_labels: bool) -> list:
    """Resonance speeds (dotted grey) and located stability changes (dashed red)."""
    handles = []
    for k, r in enumerate(sweep.resonances):
        h = ax.axvline(r.speed * KMH, color="0.55", ls=":", lw=0.9)
        if k == 0:
            handles.append((h, "resonance speed (excitation meets a natural frequency)"))
    for k, c in enumerate(sweep.stability_changes):
        if c.converged:
            h = ax.axvline(c.speed * KMH, color="r", ls="--", lw=1.2)
            if k == 0:
                handles.append((h, f"stability change ({c.kind})"))
    return handles if with_labels else []


def speed_figure(sweep):
    """Five panels against speed (km/h): DAF, largest |gap deviation| (mm), Sperling's Wz,
    the largest |multiplier| of the span map (1 dashed: the stability limit) and
    chi(v) = h(v) / w0; resonance speeds and located stability changes marked. Unstable
    speeds are drawn as crosses; open triangles mark chi(v) where every jump up to the gap
    range returned in the deciding direction (h(v) is that range); the standstill headline
    index, chi(v)'s limit as v -> 0, is a dashed line. With the critical delay computed a
    sixth panel shows tau_c(v) (ms) with its low-speed limit dashed and the delay set, if
    any, dotted. Returns the figure."""
    v = sweep.speeds * KMH
    stable = np.array([p.stable is not False for p in sweep.points])
    delay = bool(getattr(sweep.options, "critical_delay", False))
    fig, axes = new_figure(5 + delay, 1, figsize=(7.5, 11.0 + 2.2 * delay), sharex=True)
    panels = [
        ("daf", "DAF", 1.0),
        ("gap_dev_abs_max", "largest |gap deviation| (mm)", 1e3),
        ("wz", "Sperling Wz (vertical)", 1.0),
        ("largest_multiplier", "largest |multiplier|", 1.0),
        ("chi", "chi(v) = h(v) / w0", 1.0),
    ] + ([("tau_c", "critical delay tau_c(v) (ms)", 1e3)] if delay else [])
    for ax, (name, label, factor) in zip(axes, panels, strict=True):
        y = sweep.column(name) * factor
        ax.plot(v, y, "-", color="C0", lw=1.2)
        ax.plot(v[stable], y[stable], "o", color="C0", ms=3.5)
        if (~stable).any():
            ax.plot(v[~stable], y[~stable], "x", color="r", ms=6, label="unstable")
        ax.set_ylabel(label)
        if name == "largest_multiplier":
            ax.axhline(1.0, color="k", ls="--", lw=0.8)
        extra = []
        if name == "chi":
            every = np.array([p.every_size_returned for p in sweep.points])
            if every.any():
                extra = [(ax.plot(v[every], y[every], "^", mfc="none", color="C1", ms=7)[0],
                          "every jump up to the gap range returned (h(v) = gap range)")]
            st = getattr(sweep, "standstill", None)
            if st:
                extra.append((ax.axhline(st["chi"], color="C2", ls="--", lw=1.0),
                              f"standstill index {st['chi']:.3f} (the limit v -> 0)"))
        if name == "tau_c":
            fr = sweep.column("tau_c_frozen") * 1e3
            if np.isfinite(fr).any():
                extra = [(ax.axhline(float(np.nanmax(fr)), color="C2", ls="--", lw=1.0),
                          f"low-speed limit {np.nanmax(fr):.4g} ms (position-averaged "
                          "frozen spectrum)")]
            if sweep.params.tau > 0:
                extra.append((ax.axhline(sweep.params.tau * 1e3, color="k", ls=":", lw=1.0),
                              f"the delay set, {sweep.params.tau * 1e3:g} ms"))
        handles = _mark(ax, sweep, ax is axes[0]) + extra
        if handles:
            ax.legend([h for h, _ in handles], [t for _, t in handles], fontsize=7,
                      loc="best")
    axes[-1].set_xlabel("speed (km/h)")
    model = {"unit": "levitation unit", "vehicle": "full vehicle",
             "force": "moving force"}.get(sweep.model, sweep.model)
    axes[0].set_title(f"At speed over identical spans (L = {sweep.params.L:g} m): {model}"
                      + (f", delay tau = {sweep.params.tau * 1e3:g} ms" if sweep.params.tau > 0
                         else ""))
    fig.tight_layout()
    return fig


def span_run_figure(run):
    """Time histories of a run over spans (:class:`maglev_match.analyses.speed.sweep.SpanRun`): gap
    deviation and coil current per levitation point (the current's clamp at zero drawn), the
    car body's acceleration and the mid-span deflection of every span, with the periodic
    response repeated span after span (dashed) and the span boundaries (the front of the
    vehicle reaching a support) marked. Returns the figure."""
    fig, axes = new_figure(4, 1, figsize=(8.0, 10.5), sharex=True)
    t = run.t
    ax = axes[0]
    for j in range(run.gap_deviation.shape[1]):
        ax.plot(t, run.gap_deviation[:, j] * 1e3, lw=0.9, label=f"point {j + 1}")
    if run.periodic_gap is not None:
        for j in range(run.periodic_gap.shape[1]):
            ax.plot(t, run.periodic_gap[:, j] * 1e3, "k--", lw=0.7,
                    label="periodic response" if j == 0 else None)
    ax.set_ylabel("gap deviation (mm)")
    ax.legend(fontsize=7, ncol=4)
    ax = axes[1]
    for j in range(run.current.shape[1]):
        ax.plot(t, run.current[:, j], lw=0.9, label=f"point {j + 1}")
    lo, hi = float(np.nanmin(run.current)), float(np.nanmax(run.current))
    if run.limited and lo < 0.25 * hi:  # the clamp near the currents drawn: show it
        ax.axhline(0.0, color="r", lw=0.8, ls=":", label="clamp: current >= 0")
    elif run.limited:
        ax.text(0.01, 0.04, f"clamp at 0 A not approached (smallest {lo:.3g} A)",
                transform=ax.transAxes, fontsize=7, color="0.35")
    ax.set_ylabel("coil current (A)")
    ax.legend(fontsize=7, ncol=4)
    ax = axes[2]
    ax.plot(t, run.body_acceleration, lw=0.9, label="run")
    if run.periodic_acceleration is not None:
        ax.plot(t, run.periodic_acceleration, "k--", lw=0.7, label="periodic response")
    ax.set_ylabel("car-body acceleration (m/s^2)")
    ax.legend(fontsize=7)
    ax = axes[3]
    for s in range(run.midspan.shape[1]):
        ax.plot(t, run.midspan[:, s] * 1e3, lw=0.9, label=f"span {s + 1}")
    ax.set_ylabel("mid-span deflection (mm, down)")
    ax.set_xlabel("time (s)")
    if run.midspan.shape[1] <= 8:
        ax.legend(fontsize=7, ncol=4)
    for a in axes:
        for tb in run.span_starts:
            a.axvline(tb, color="0.7", lw=0.6, ls=":")
        if run.collision_time is not None:
            a.axvline(run.collision_time, color="r", lw=1.2)
    axes[0].set_title(f"{run.spans} spans at {run.speed * KMH:.4g} km/h "
                      f"({run.outcome})")
    fig.tight_layout()
    return fig


def speed_map_figure(ds):
    """A map at speed (:func:`maglev_match.analyses.speed.sweep.run_speed_map`): chi(v) as colour at
    stable
    points, unstable points crossed, points where every jump up to the gap range returned
    (h(v) = the gap range) marked by open
    triangles, the speed axis in km/h. Returns the figure."""
    yname, xname = ds["chi"].dims
    x, y = ds[xname].values.astype(float), ds[yname].values.astype(float)
    xl, yl = xname, yname
    if xname == "v":
        x, xl = x * KMH, "speed v (km/h)"
    if yname == "v":
        y, yl = y * KMH, "speed v (km/h)"
    chi = np.ma.masked_invalid(ds["chi"].values)
    fig, ax = new_figure(figsize=(8.0, 5.5))
    X, Y = np.meshgrid(x, y)
    if "tau_c" in ds:  # a map over the delay: the leading multiplier and tau_c(v)
        _delay_map(fig, ax, ds, xname, x, y, X, Y)
    elif chi.count():
        mesh = ax.pcolormesh(x, y, chi, shading="nearest", cmap="viridis")
        fig.colorbar(mesh, ax=ax, label="chi(v) = h(v) / w0")
    unstable = ds["stable"].values == 0
    if unstable.any():
        ax.plot(X[unstable], Y[unstable], "rx", ms=7, label="periodic response unstable")
    ceiling = ((ds["every_size_returned"].values == 1) if "every_size_returned" in ds
               else np.zeros_like(unstable))
    if ceiling.any():
        ax.plot(X[ceiling], Y[ceiling], "^", mfc="none", color="w", ms=6,
                label="every jump up to the gap range returned (h(v) = gap range)")
    if unstable.any() or ceiling.any() or "tau_c" in ds:
        ax.legend(fontsize=8)
    ax.set_xlabel(xl)
    ax.set_ylabel(yl)
    what = "max|multiplier| and tau_c(v)" if "tau_c" in ds else "chi(v)"
    ax.set_title(f"At speed ({ds.attrs.get('model', '')}): {what} over {xname} and {yname}")
    fig.tight_layout()
    return fig


def _delay_map(fig, ax, ds, xname, x, y, X, Y) -> None:
    """The largest |multiplier| (log colour scale) over (v, tau), its unit-circle contour
    on the grid and the solved tau_c(v) (a line over the speeds)."""
    from matplotlib.colors import LogNorm

    mu = np.ma.masked_invalid(ds["largest_multiplier"].values)
    if mu.count():
        mesh = ax.pcolormesh(x, y, mu, shading="nearest", cmap="coolwarm",
                             norm=LogNorm(vmin=max(float(mu.min()), 1e-6),
                                          vmax=max(float(mu.max()), 1.0 + 1e-9)))
        fig.colorbar(mesh, ax=ax, label="largest |multiplier| of the span map")
    v = ds["v"].values.astype(float) * KMH
    tc = ds["tau_c"].values.astype(float)
    ok = np.isfinite(tc)
    if ok.any():
        if xname == "v":
            ax.plot(v[ok], tc[ok], "k.-", lw=1.5, label="critical delay tau_c(v) (solved)")
        else:
            ax.plot(tc[ok], v[ok], "k.-", lw=1.5, label="critical delay tau_c(v) (solved)")


@figure.register(SpeedSweep)
def _speed_sweep(sweep: SpeedSweep, **kw):
    return speed_figure(sweep, **kw)


@figure.register(SpanRun)
def _span_run(run: SpanRun, **kw):
    return span_run_figure(run, **kw)
