"""Root-locus figure: eigenvalues of the equilibrium as one parameter varies; and the
eigenvalues of one equilibrium (a stability verdict) in the complex plane."""

from __future__ import annotations

import numpy as np

from maglev_match.core.results import figure
from maglev_match.dynamics.equilibria import RootLocusResult, StabilityResult
from maglev_match.plots.base import new_figure

__all__ = ["root_locus_figure", "stability_figure", "axis_crossings", "zoom_window",
           "NEAR_TRACKS"]

# The window shows the eigenvalue tracks nearest the imaginary axis: this many of them
# (conjugate pairs count twice), i.e. the slowest three modes.
NEAR_TRACKS = 6


def zoom_window(eigenvalues: np.ndarray, n_tracks: int = NEAR_TRACKS
                ) -> tuple[tuple[float, float], tuple[float, float]]:
    """Axis limits ((re_lo, re_hi), (im_lo, im_hi)) that frame the ``n_tracks`` eigenvalues
    of largest real part at every parameter value, with a margin, and always the
    imaginary axis. ``eigenvalues`` (n_values, dim)."""
    ev = np.asarray(eigenvalues)
    order = np.argsort(-ev.real, axis=1)
    near = np.take_along_axis(ev, order[:, : min(n_tracks, ev.shape[1])], axis=1)
    re_lo, re_hi = float(near.real.min()), float(max(near.real.max(), 0.0))
    span = max(re_hi - re_lo, 1e-3)
    im = float(np.abs(near.imag).max())
    im = max(im, 0.1 * span)
    return (re_lo - 0.08 * span, re_hi + 0.08 * span), (-1.08 * im, 1.08 * im)


def axis_crossings(values: np.ndarray, eigenvalues: np.ndarray
                   ) -> list[tuple[float, float, bool]]:
    """Where the rightmost eigenvalue crosses the imaginary axis between two samples:
    ``(parameter value, |Im| there (rad/s), Hopf)`` by linear interpolation of max
    Re(lambda) and of the crossing eigenvalue's |Im|; ``Hopf`` is True for a complex pair
    (|Im| > 0 on both sides), False for a real eigenvalue (a fold or branch point)."""
    values = np.asarray(values, float)
    ev = np.asarray(eigenvalues)
    k_max = np.argmax(ev.real, axis=1)
    lead = ev[np.arange(len(values)), k_max]
    mr = lead.real
    out = []
    for k in range(len(values) - 1):
        if (mr[k] < 0) != (mr[k + 1] < 0):  # (a sample exactly on the axis counts once)
            # follow the eigenvalue that crossed: the rightmost one on the unstable side
            # and, on the other side, the eigenvalue of the same track (the nearest one)
            u, o = (k, k + 1) if mr[k] >= 0 else (k + 1, k)
            zu = lead[u]
            zo = ev[o][np.argmin(np.abs(ev[o].real - zu.real)
                                 + np.abs(np.abs(ev[o].imag) - abs(zu.imag)))]
            a, b = (zo, zu) if o == k else (zu, zo)  # in parameter order
            t = a.real / (a.real - b.real) if a.real != b.real else 0.0
            t = min(max(t, 0.0), 1.0)
            scale = max(abs(a), abs(b), 1.0)
            hopf = min(abs(a.imag), abs(b.imag)) > 1e-9 * scale
            out.append((float(values[k] + t * (values[k + 1] - values[k])),
                        float(abs(a.imag) + t * (abs(b.imag) - abs(a.imag))), bool(hopf)))
    return out


def root_locus_figure(values: np.ndarray, eigenvalues: np.ndarray, param: str, unit: str = "",
                      design: tuple[float, np.ndarray] | None = None,
                      crossings: list[tuple[float, float, bool]] | None = None):
    """Root locus along ``param``.

    Left: the eigenvalues in the complex plane, coloured by the parameter value, zoomed on
    the tracks nearest the imaginary axis (:func:`zoom_window`); eigenvalues outside the
    window are counted and their range given in a note. Right: the largest real part
    against the parameter (the equilibrium is unstable above zero).

    Parameters
    ----------
    values : parameter values, shape (n,).
    eigenvalues : eigenvalues at each value, shape (n, dim) (1/s).
    param, unit : the parameter's name and unit (unit in parentheses or plain).
    design : optional (design value, its eigenvalues): marked with black crosses on the
        left and a vertical line on the right.
    crossings : where the equilibrium changes stability, as from :func:`axis_crossings`
        (the default): a Hopf crossing is marked at +-i omega on the imaginary axis (left)
        and at max Re = 0 (right), labelled with its value and frequency.

    Returns the figure.
    """
    values = np.asarray(values, float)
    eigenvalues = np.asarray(eigenvalues)
    unit = unit.strip().strip("()")
    label = f"{param} ({unit})" if unit else param
    fig, (ax1, ax2) = new_figure(1, 2, figsize=(11.5, 4.8))
    (x0, x1), (y0, y1) = zoom_window(eigenvalues)
    vv = np.repeat(values[:, None], eigenvalues.shape[1], axis=1)
    re, im = eigenvalues.real.ravel(), eigenvalues.imag.ravel()
    inside = (re >= x0) & (re <= x1) & (im >= y0) & (im <= y1)
    sc = ax1.scatter(re[inside], im[inside], c=vv.ravel()[inside], s=7, cmap="viridis",
                     vmin=values.min(), vmax=values.max())
    ax1.axvline(0.0, color="k", lw=0.8)
    ax1.axhline(0.0, color="0.6", lw=0.5)
    ax1.set_xlim(x0, x1)
    ax1.set_ylim(y0, y1)
    ax1.set_xlabel("Re(lambda) (1/s)")
    ax1.set_ylabel("Im(lambda) (rad/s)")
    ax1.set_title("Root locus near the imaginary axis")
    fig.colorbar(sc, ax=ax1, label=label)
    outside = ~inside
    if outside.any():
        # eigenvalues per parameter value outside the window (the same at every value
        # unless a track crosses the frame)
        per_value = outside.reshape(eigenvalues.shape).sum(axis=1)
        count = (f"{per_value.min()}" if per_value.min() == per_value.max()
                 else f"{per_value.min()}-{per_value.max()}")
        ax1.text(0.02, 0.02,
                 f"not shown: {count} eigenvalue(s) per value further out,\n"
                 f"Re from {re[outside].min():.4g} to {re[outside].max():.4g} 1/s, "
                 f"|Im| up to {np.abs(im[outside]).max():.4g} rad/s",
                 transform=ax1.transAxes, fontsize=7, va="bottom", ha="left",
                 bbox={"boxstyle": "round", "fc": "white", "ec": "0.7", "alpha": 0.9})
    ax2.plot(values, eigenvalues.real.max(axis=1), color="C0", label="max Re(lambda)")
    ax2.axhline(0.0, color="k", lw=0.8)
    ax2.set_xlabel(label)
    ax2.set_ylabel("max Re(lambda) (1/s)")
    ax2.set_title("Stability margin: unstable where max Re(lambda) > 0")
    if design is not None:
        dv, dev = float(design[0]), np.asarray(design[1])
        sel = (dev.real >= x0) & (dev.real <= x1) & (dev.imag >= y0) & (dev.imag <= y1)
        ax1.plot(dev.real[sel], dev.imag[sel], "kx", ms=8, mew=1.8)
        ax1.set_title(f"Root locus near the imaginary axis\n(x: eigenvalues at the design "
                      f"point {param} = {dv:.4g})", fontsize=10)
        ax2.axvline(dv, color="k", ls="--", lw=1.0, label=f"design point {param} = {dv:.4g}")
        ax2.plot([dv], [float(dev.real.max())], "kx", ms=8, mew=1.8)
    if crossings is None:
        crossings = axis_crossings(values, eigenvalues)
    hopf_label = real_label = True
    for value, omega, hopf in crossings:
        if hopf:
            ax1.plot([0.0, 0.0], [omega, -omega], "o", mfc="none", mec="C3", ms=11, mew=2,
                     zorder=6, label="Hopf crossing (+-i omega)" if hopf_label else None)
            ax2.plot([value], [0.0], "o", color="C3", ms=8, zorder=6,
                     label=(f"Hopf crossing {param} = {value:.5g}, omega = {omega:.4g} "
                            "rad/s (interpolated)"))
            hopf_label = False
        else:
            ax2.plot([value], [0.0], "s", color="C1", ms=7, zorder=6,
                     label=(f"real eigenvalue crosses 0 at {param} = {value:.5g}"
                            if real_label else None))
            real_label = False
    if not hopf_label:
        ax1.legend(loc="upper left", fontsize=8)
    ax2.legend(loc="upper left", fontsize=8)
    return fig


@figure.register(RootLocusResult)
def _root_locus(result: RootLocusResult, **kw):
    from maglev_match.plots.base import param_unit

    if result.design_value is not None and result.design_eigenvalues is not None:
        kw.setdefault("design", (result.design_value, result.design_eigenvalues))
    return root_locus_figure(result.values, result.eigenvalues, result.param,
                             result.param_unit or param_unit(result.param), **kw)


def stability_figure(result: StabilityResult, title: str | None = None):
    """The eigenvalues of one equilibrium in the complex plane (``maglev-match
    stability``): left, every eigenvalue; right, those nearest the imaginary axis
    (:func:`zoom_window`). Eigenvalues with Re < 0 are blue dots, those with Re >= 0 red
    crosses; the title gives the verdict and the margin -max Re(lambda).

    Returns the figure."""
    eig = np.asarray(result.eigenvalues)
    fig, (ax1, ax2) = new_figure(1, 2, figsize=(11.0, 4.6))
    left = eig.real < 0
    (x0, x1), (y0, y1) = zoom_window(eig[None, :])
    for ax in (ax1, ax2):
        ax.scatter(eig.real[left], eig.imag[left], s=28, color="C0", zorder=4,
                   label=f"Re < 0 ({int(left.sum())})")
        if (~left).any():
            ax.scatter(eig.real[~left], eig.imag[~left], s=50, marker="x", color="C3",
                       linewidths=2, zorder=5, label=f"Re >= 0 ({int((~left).sum())})")
        ax.axvline(0.0, color="k", lw=0.8)
        ax.axhline(0.0, color="0.6", lw=0.5)
        ax.set_xlabel("Re(lambda) (1/s)")
        ax.set_ylabel("Im(lambda) (rad/s)")
    ax1.set_title(f"All {eig.size} eigenvalues")
    ax1.legend(loc="best", fontsize=8)
    ax2.set_xlim(x0, x1)
    ax2.set_ylim(y0, y1)
    ax2.set_title("Near the imaginary axis")
    if title is None:
        name = getattr(result.system, "name", "") or "equilibrium"
        verdict = "stable" if result.stable else "unstable"
        if not result.equilibrium.converged:
            verdict = "not stable: the equilibrium did not converge"
        title = (f"{name}: {verdict}, margin -max Re(lambda) = {result.margin:.4g} 1/s")
    fig.suptitle(title, fontsize=10)
    return fig


@figure.register(StabilityResult)
def _stability(result: StabilityResult, **kw):
    return stability_figure(result, **kw)
