"""Root-locus figure: eigenvalues of the equilibrium as one parameter varies."""

from __future__ import annotations

import numpy as np

from maglev_match.plots import new_figure


def root_locus_figure(values: np.ndarray, eigenvalues: np.ndarray, param: str, unit: str = ""):
    """Left: eigenvalues in the complex plane coloured by the parameter value.
    Right: the largest real part against the parameter (stability boundary where it
    crosses zero)."""
    fig, (ax1, ax2) = new_figure(1, 2, figsize=(11, 4.5))
    vv = np.repeat(values[:, None], eigenvalues.shape[1], axis=1)
    sc = ax1.scatter(eigenvalues.real.ravel(), eigenvalues.imag.ravel(), c=vv.ravel(), s=6,
                     cmap="viridis")
    ax1.axvline(0.0, color="k", lw=0.8)
    ax1.set_xlabel("Re(lambda) (1/s)")
    ax1.set_ylabel("Im(lambda) (rad/s)")
    ax1.set_title("Root locus")
    # the interesting part is near the imaginary axis; clip far-left poles
    re = eigenvalues.real.ravel()
    left = np.percentile(re, 10)
    ax1.set_xlim(min(left, -1.0) * 1.1, max(re.max(), 1.0) * 1.3)
    fig.colorbar(sc, ax=ax1, label=f"{param} {unit}".strip())
    ax2.plot(values, eigenvalues.real.max(axis=1), color="C0")
    ax2.axhline(0.0, color="k", lw=0.8)
    ax2.set_xlabel(f"{param} {unit}".strip())
    ax2.set_ylabel("max Re(lambda) (1/s)")
    ax2.set_title("Stability margin (unstable above 0)")
    return fig
