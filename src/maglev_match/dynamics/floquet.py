"""Floquet multipliers of a periodic orbit from its collocation blocks.

The variational equation v' = T A(t) v along a collocation orbit is discretised by the same
collocation as the orbit; condensing each mesh interval onto its end points gives a transfer
matrix P_j with v(t_{j+1}) = P_j v(t_j), and the multipliers are the eigenvalues of the
monodromy matrix P_{NTST-1} ... P_0 (Doedel, Keller & Kernevez 1991; Fairgrieve & Jepson 1991).
"""

from __future__ import annotations

import numpy as np

from maglev_match.dynamics.collocation import _tables


def floquet_multipliers_from_blocks(J: np.ndarray, T: float, h: np.ndarray, m: int) -> np.ndarray:
    """Monodromy matrix from the collocation blocks of the variational equation
    v' = T A(t) v: each interval's block is condensed onto its end points, giving the
    transfer matrix v(t_{j+1}) = P_j v(t_j); the monodromy is P_{NTST-1} ... P_0.
    Returns its eigenvalues (all of them, unsorted)."""
    ntst, _, n, _ = J.shape
    _, _, _, L, D = _tables(m)
    blk = (D[None, :, :, None, None] * np.eye(n)[None, None, None]
           - (T * h)[:, None, None, None, None] * L[None, :, :, None, None]
           * J[:, :, None, :, :])  # (ntst, m, m+1, n, n)
    blk = blk.transpose(0, 1, 3, 2, 4).reshape(ntst, m * n, (m + 1) * n)
    A0 = blk[:, :, :n]
    A1 = blk[:, :, n:]
    P = np.linalg.solve(A1, -A0)[:, -n:, :]  # (ntst, n, n)
    M = np.eye(n)
    for j in range(ntst):
        M = P[j] @ M
        # keep the product's size moderate; eigenvalues scale back exactly
    return np.linalg.eigvals(M)
