"""Floquet-based stability of a cycle. The multipliers of a collocation orbit are those of
the product of the interval transfer matrices of the variational equation
(:func:`floquet_multipliers`; the Jacobian blocks at a solution by :func:`blocks_at`;
computed without forming the product by :mod:`~maglev_match.dynamics.floquet`); the
trivial multiplier (1 for an exact orbit, its distance to 1 an accuracy check) is split off
(:func:`split_trivial`), and the others give the stability (:class:`Stability`,
:func:`stability_of`) and the test functions of the cycle bifurcations PD, NS and BP
(:func:`multiplier_tests`, Kuznetsov 2004, sec. 10.3.2), with the checks that tell a
Neimark-Sacker point from a neutral saddle cycle (:func:`n_complex_outside`,
:func:`ns_pair_real`).
"""

from __future__ import annotations

from enum import StrEnum

import jax.numpy as jnp
import numpy as np

from maglev_match.dynamics.collocation import (
    CollocationBVP,
    collocation_kernel,
    interval_nodes,
)
from maglev_match.dynamics.continuation import SpecialPointKind, signed_geometric_mean
from maglev_match.dynamics.cycles.orbits import PeriodicOrbit
from maglev_match.dynamics.floquet import floquet_multipliers_from_blocks
from maglev_match.dynamics.system import System

__all__ = [
    "BIFURCATION_TESTS",
    "MULTIPLIER_TESTS",
    "Stability",
    "blocks_at",
    "floquet_multipliers",
    "multiplier_tests",
    "n_complex_outside",
    "ns_pair_real",
    "split_trivial",
    "stability_of",
]


class Stability(StrEnum):
    """Stability of a cycle from its nontrivial multipliers mu (tolerance ``neutral_tol``
    of :class:`CycleOptions`): unstable when some |mu| > 1 + tol; neutral when none is,
    but some |mu| >= 1 - tol (at a Hopf point, a fold, a PD, NS or BP the multipliers
    cannot decide; the first points of a branch next to its Hopf point are neutral);
    stable otherwise; unknown without (reliable) multipliers."""

    STABLE = "stable"
    UNSTABLE = "unstable"
    NEUTRAL = "neutral"
    UNKNOWN = "unknown"


def stability_of(mult: np.ndarray, tol: float) -> Stability:
    """The :class:`Stability` of a cycle from its nontrivial multipliers."""
    mult = np.asarray(mult)
    if mult.size == 0:
        return Stability.STABLE
    a = np.abs(mult)
    if np.any(a > 1.0 + tol):
        return Stability.UNSTABLE
    if np.any(a >= 1.0 - tol):
        return Stability.NEUTRAL
    return Stability.STABLE


def split_trivial(mult: np.ndarray) -> tuple[complex, np.ndarray]:
    k = int(np.argmin(np.abs(mult - 1.0)))
    return complex(mult[k]), np.delete(mult, k)


def floquet_multipliers(system: System, orbit: PeriodicOrbit) -> np.ndarray:
    """Floquet multipliers of a collocation orbit (all n, including the trivial one)."""
    m = orbit.ncol
    ntst = orbit.ntst
    h = np.diff(orbit.mesh)
    idx = interval_nodes(ntst, m)
    e = np.zeros_like(orbit.p)
    _, _, J, _ = collocation_kernel(system.rhs, m)(
        jnp.asarray(orbit.states[idx]), jnp.asarray(h), orbit.period, jnp.asarray(orbit.p),
        jnp.asarray(e),
    )
    return floquet_multipliers_from_blocks(np.asarray(J), orbit.period, h, m,
                                           method=getattr(system, "floquet_method", "auto"))


def blocks_at(prob: CollocationBVP, Y: np.ndarray, mesh: np.ndarray
               ) -> tuple[np.ndarray, float, np.ndarray]:
    """(J, T, h) at the solution Y on ``mesh`` (the problem's mesh may have moved on)."""
    m = prob.m
    U, T, lam = prob.unpack(Y)
    h = np.diff(mesh)
    p = prob.params(lam)
    _, _, J, _ = collocation_kernel(prob.system.rhs, m)(
        U[interval_nodes(mesh.size - 1, m)], h, T, p, np.zeros_like(p))
    return np.asarray(J), T, h


# multiplier test functions and the kinds they detect
MULTIPLIER_TESTS = {"PD": SpecialPointKind.PD, "NS": SpecialPointKind.NS}


# the test functions that are only evaluated where the Floquet data are reliable
BIFURCATION_TESTS = ("LPC", "PD", "NS", "BP")


def multiplier_tests(mult: np.ndarray) -> dict[str, float]:
    """Test functions of the nontrivial multipliers mu_i (Kuznetsov 2004, sec. 10.3.2):

    * PD: prod (mu_i + 1) / (1 + |mu_i|)          zero when a real mu passes -1;
    * NS: prod_{i<j} (mu_i mu_j - 1) / (1 + |mu_i mu_j|)   zero on a complex pair with
      |mu| = 1 (and on a real pair mu, 1/mu, which is no bifurcation: see the classifier);
    * BP: prod (mu_i - 1) / (1 + |mu_i|)          zero when a real mu passes +1 (at a
      branch point and at a fold alike; the branch uses the bordered test function of
      :meth:`CycleProblem.bp_test` instead, which a fold leaves alone).

    Each is returned as a signed geometric mean of its factors (same sign as the product)."""
    mult = np.asarray(mult, complex)
    i, j = np.triu_indices(mult.size, 1)
    prod = mult[i] * mult[j]
    return {
        "PD": signed_geometric_mean((mult + 1.0) / (1.0 + np.abs(mult))),
        "NS": signed_geometric_mean((prod - 1.0) / (1.0 + np.abs(prod))),
        "BP": signed_geometric_mean((mult - 1.0) / (1.0 + np.abs(mult))),
    }


def n_complex_outside(mult) -> int:
    """Number of non-real multipliers with |mu| > 1."""
    mult = np.asarray(mult, complex)
    return int(np.sum((np.abs(mult.imag) > 1e-6 * np.maximum(1.0, np.abs(mult)))
                      & (np.abs(mult) > 1.0)))


def ns_pair_real(mult) -> bool:
    """Whether the pair of multipliers with mu_i mu_j nearest 1 is real."""
    mult = np.asarray(mult, complex)
    if mult.size < 2:
        return True
    i, j = np.triu_indices(mult.size, 1)
    k = int(np.argmin(np.abs(mult[i] * mult[j] - 1.0)))
    return bool(abs(mult[i[k]].imag) <= 1e-6 * max(1.0, abs(mult[i[k]]))
                and abs(mult[j[k]].imag) <= 1e-6 * max(1.0, abs(mult[j[k]])))
