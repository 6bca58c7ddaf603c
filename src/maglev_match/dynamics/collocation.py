"""Orthogonal collocation on a mesh: the Gauss-Legendre points and the Lagrange basis of
each mesh interval (de Boor & Swartz 1973; Ascher, Mattheij & Russell 1995, ch. 5).

A profile on [0, 1] is a piecewise polynomial of degree NCOL, given on each mesh interval by
its values at NCOL + 1 equally spaced nodes; the equations are imposed at the NCOL
Gauss-Legendre points of every interval.
"""

from __future__ import annotations

from functools import cache

import numpy as np


@cache
def _tables(m: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Nodes c_k = k/m, Gauss points z_l, weights w_l on [0, 1]; L[l,k] = ell_k(z_l),
    D[l,k] = ell_k'(z_l) for the Lagrange basis on the nodes."""
    c = np.linspace(0.0, 1.0, m + 1)
    g, w = np.polynomial.legendre.leggauss(m)
    z, w = 0.5 * (g + 1.0), 0.5 * w
    L, D = _lagrange(c, z)
    return c, z, w, L, D


def _lagrange(c: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Values and derivatives of the Lagrange basis on nodes c at points s: (len(s), len(c))."""
    s = np.asarray(s, float)
    n = c.size
    L = np.ones((s.size, n))
    D = np.zeros((s.size, n))
    for k in range(n):
        others = [i for i in range(n) if i != k]
        denom = np.prod([c[k] - c[i] for i in others])
        for i in others:
            L[:, k] *= s - c[i]
        for i in others:
            term = np.ones(s.size)
            for r in others:
                if r != i:
                    term *= s - c[r]
            D[:, k] += term
        L[:, k] /= denom
        D[:, k] /= denom
    return L, D
