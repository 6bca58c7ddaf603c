"""Floquet multipliers of a hybrid periodic orbit.

**Floquet multipliers of a hybrid orbit** (:func:`hybrid_floquet`): of the monodromy matrix
M = S_{S-1} Phi_{S-1} ... S_0 Phi_0, with Phi_i the fundamental matrix of segment i (from
its collocation blocks: the condensed end-point relations of
:func:`~maglev_match.dynamics.floquet.condensed_pairs`) and S_i the saltation matrix at
the end of segment i (:func:`~maglev_match.dynamics.hybrid.saltation.saltation_matrix`);
the eigenvalues of the formal product by the periodic Schur algorithm of
:func:`~maglev_match.dynamics.floquet.periodic_eigenvalues` (Bojanczyk, Golub & Van Dooren
1992; Kressner 2006, ch. 3). A sliding segment entered through a projection makes one
multiplier exactly 0.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import jax.numpy as jnp
import numpy as np

from maglev_match.core import jax_setup  # noqa: F401  (float64)
from maglev_match.core.reprs import compact_repr
from maglev_match.dynamics.hybrid.saltation import saltation_matrix
from maglev_match.dynamics.hybrid.system import HybridSystem

if TYPE_CHECKING:  # annotation only: the orbits module calls this one
    from maglev_match.dynamics.hybrid.orbits import HybridOrbit

__all__ = ["HybridFloquet", "hybrid_floquet"]


@dataclass(frozen=True)
class HybridFloquet:
    """Floquet data of a hybrid orbit.

    multipliers : the eigenvalues of the monodromy matrix by the periodic Schur algorithm
    (largest modulus first); transfers : per segment, the fundamental matrix over the
    segment (n, n); saltations : per segment, the saltation matrix at its end;
    intervals : per segment, the transfer matrices of its mesh intervals (NTST_i, n, n).
    """

    __repr__ = compact_repr

    multipliers: np.ndarray
    transfers: tuple[np.ndarray, ...]
    saltations: tuple[np.ndarray, ...]
    intervals: tuple[np.ndarray, ...] = ()

    def monodromy(self, start: int = 0, interval: int = 0) -> np.ndarray:
        """The monodromy matrix at mesh point ``interval`` of segment ``start`` (0: the
        segment's start, right after the previous segment's switch): the product of every
        interval transfer matrix and saltation matrix once around the orbit from there
        (explicit product; for eigenvectors of moderately unstable orbits)."""
        S = len(self.transfers)
        n = self.transfers[0].shape[0]
        M = np.eye(n)
        P0 = self.intervals[start] if self.intervals else None
        if P0 is not None:
            for Pj in P0[interval:]:
                M = Pj @ M
        else:
            M = self.transfers[start] @ M
        M = self.saltations[start] @ M
        for q in range(1, S):
            i = (start + q) % S
            M = self.saltations[i] @ self.transfers[i] @ M
        if P0 is not None:
            for Pj in P0[:interval]:
                M = Pj @ M
        return M


def hybrid_floquet(hs: HybridSystem, orbit: HybridOrbit) -> HybridFloquet:
    """Floquet multipliers of a hybrid orbit: the formal product of the segments' condensed
    collocation pairs (:func:`~maglev_match.dynamics.floquet.condensed_pairs`) and the
    saltation matrices at the switches, by the periodic Schur algorithm
    (:func:`~maglev_match.dynamics.floquet.periodic_eigenvalues`)."""
    from maglev_match.dynamics.collocation import collocation_kernel, interval_nodes
    from maglev_match.dynamics.floquet import (
        condensed_pairs,
        periodic_eigenvalues,
        transfer_matrices,
    )

    n, m = hs.dim, orbit.ncol
    pj = jnp.asarray(orbit.p)
    Fs, Es, transfers, salts, intervals = [], [], [], [], []
    S = len(orbit.segments)
    for i, sg in enumerate(orbit.segments):
        mesh = np.asarray(sg.mesh)
        ntst = mesh.size - 1
        h = np.diff(mesh)
        idx = interval_nodes(ntst, m)
        _, _, J, _ = collocation_kernel(hs.mode_rhs(sg.mode), m)(
            jnp.asarray(sg.states[idx]), jnp.asarray(h), sg.duration, pj, jnp.zeros_like(pj))
        J = np.asarray(J)
        F, E = condensed_pairs(J, sg.duration, h, m)
        P = transfer_matrices(J, sg.duration, h, m)
        Phi = np.eye(n)
        for Pj in P:
            Phi = Pj @ Phi
        Sal = (saltation_matrix(hs, sg.states[-1], np.asarray(sg.mode, float), sg.switch,
                                orbit.p) if sg.switch >= 0 else np.eye(n))
        intervals.append(P)
        Fs.extend(F)
        Es.extend(E)
        Fs.append(Sal)
        Es.append(np.eye(n))
        transfers.append(Phi)
        salts.append(Sal)
        del i
    pe = periodic_eigenvalues(np.array(Fs), np.array(Es))
    with np.errstate(over="ignore"):
        mu = np.exp(pe.log_abs) * np.exp(1j * pe.phase)
    mu = np.where(np.isneginf(pe.log_abs), 0.0, mu)
    order = np.argsort(-np.abs(mu))
    mu = mu[order]
    if np.all(np.abs(mu.imag) <= 1e-12 * np.maximum(np.abs(mu), 1e-300)):
        mu = mu.real
    del S
    return HybridFloquet(multipliers=mu, transfers=tuple(transfers), saltations=tuple(salts),
                         intervals=tuple(intervals))

