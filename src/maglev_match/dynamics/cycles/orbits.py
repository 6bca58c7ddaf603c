"""Periodic orbits as collocation profiles and their read-outs: the data a cycle branch
starts from at a Hopf point (:class:`HopfStart`, :func:`hopf_start`), the orbit itself
(:class:`PeriodicOrbit`: a piecewise polynomial of degree NCOL on a mesh in normalised
time, as in AUTO-07p / MATCONT), the extreme values of observables over an orbit
(:func:`orbit_extrema`: a coarse and a fine pass over the collocation polynomial, then the
vertex of a parabola, in one compiled call) and its first Fourier coefficient and mean
state (:func:`first_harmonic`, :func:`first_harmonic_mean`, Gauss quadrature on the mesh;
near a Hopf point the first harmonic is eps q / 2 + O(eps^2), which watches where a family
meets an equilibrium).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import cache
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from maglev_match.core.aot import cached_kernel
from maglev_match.core.jax_setup import to_device
from maglev_match.core.reprs import compact_repr
from maglev_match.dynamics.collocation import (
    collocation_tables,
    evaluate_profile,
    interval_nodes,
    lagrange_basis,
    node_times,
)
from maglev_match.dynamics.system import System

__all__ = [
    "HopfStart",
    "PeriodicOrbit",
    "as_hopf_start",
    "first_harmonic",
    "first_harmonic_mean",
    "hopf_start",
    "orbit_extrema",
]


Array = Any


@dataclass(frozen=True)
class HopfStart:
    """What a cycle branch needs from a Hopf point.

    Parameters
    ----------
    param : name of the continuation parameter.
    value : its value at the Hopf point.
    x : equilibrium state at the Hopf point.
    p : full parameter vector at the Hopf point.
    frequency : omega (rad/s) of the critical pair +-i omega.
    q : complex right eigenvector, J q = i omega q.
    l1 : first Lyapunov coefficient if known (sign: < 0 supercritical, > 0 subcritical).
    """

    param: str
    value: float
    x: np.ndarray
    p: np.ndarray
    frequency: float
    q: np.ndarray
    l1: float | None = None


@dataclass(frozen=True)
class PeriodicOrbit:
    """A periodic orbit as a piecewise-polynomial collocation profile.

    ``mesh`` (NTST + 1,) in [0, 1]; ``states`` (NTST NCOL + 1, dim) at the nodes
    t_j + k/NCOL (t_{j+1} - t_j); time t = T s for the normalised time s.
    """

    __repr__ = compact_repr

    mesh: np.ndarray
    ncol: int
    states: np.ndarray
    period: float  # s
    p: np.ndarray

    @property
    def ntst(self) -> int:
        return self.mesh.size - 1

    @property
    def node_times(self) -> np.ndarray:
        """Normalised times of all nodes (NTST NCOL + 1,)."""
        return node_times(self.mesh, self.ncol)

    @property
    def times(self) -> np.ndarray:
        """Times of the nodes (s)."""
        return self.node_times * self.period

    def evaluate(self, s: Array) -> np.ndarray:
        """States at normalised times s in [0, 1] (periodic extension), shape (len(s), dim)."""
        return evaluate_profile(self.mesh, self.ncol, self.states, np.asarray(s, float) % 1.0)


def hopf_start(
    system: System,
    x_eq: Array,
    p: Array,
    param: str,
    omega: float,
    q: Array,
    l1: float | None = None,
) -> HopfStart:
    """The data a cycle branch starts from: the equilibrium x_eq at parameters p (the Hopf
    point along ``param``), the critical frequency omega (rad/s) and eigenvector q."""
    p = np.asarray(p, float)
    return HopfStart(param=param, value=float(p[system.param_index(param)]),
                     x=np.asarray(x_eq, float), p=p, frequency=float(omega),
                     q=np.asarray(q, complex), l1=None if l1 is None else float(l1))


def as_hopf_start(system: System, hopf: Any, param: str) -> HopfStart:
    if isinstance(hopf, HopfStart):
        return hopf
    # duck-typed HopfPoint from dynamics.hopf
    p = np.asarray(hopf.p, float)
    l1 = getattr(hopf, "l1", None)
    l1 = None if l1 is None or not np.isfinite(l1) else float(l1)
    return hopf_start(system, hopf.x, p, param, float(hopf.frequency), hopf.q, l1)


@cache
def _local_basis(m: int, npts: int) -> np.ndarray:
    """Lagrange basis of degree m at npts equally spaced local points: (npts, m+1)."""
    return lagrange_basis(np.linspace(0.0, 1.0, m + 1), np.linspace(0.0, 1.0, npts))[0]


def _lagrange_jnp(m: int) -> Callable:
    """tau -> the m + 1 Lagrange basis values at local time tau in [0, 1] (nodes k / m), as
    a JAX function (differentiable in tau)."""
    c = np.linspace(0.0, 1.0, m + 1)
    others = np.array([[i for i in range(m + 1) if i != k] for k in range(m + 1)])
    denom = np.array([np.prod(c[k] - c[others[k]]) for k in range(m + 1)])
    co, de = to_device(c[others]), to_device(denom)

    def basis(tau):
        return jnp.prod(tau - co, axis=1) / de

    return basis


@cache
def _extrema_kernel(gs: tuple[Callable, ...], m: int, refine: int) -> Callable:
    """One jitted call giving (max, min) of each observable in ``gs`` over an orbit: the
    coarse pass over 4 NCOL + 1 points per interval, the intervals around each extreme, the
    fine pass (``refine`` + 1 points per interval) over those, and the vertex of the
    parabola through the best fine sample and its two neighbours, where the observable is
    evaluated once more (cached per observables, NCOL, refine; see :func:`orbit_extrema`).
    The fine samples alone carry a sampling error up to g'' (dt / 2)^2 / 2 (~4e-8 relative
    on model A's gap), and a margin built on them would be rough at that level; the vertex
    is within O(dt^2) of the polynomial's own extremum, so its value is within O(dt^4)
    (~1e-13 relative there): a smooth function of the orbit to the branch tolerance."""
    Lc = to_device(_local_basis(m, 4 * m + 1))
    Lf = to_device(_local_basis(m, refine + 1))
    npts = Lf.shape[0]
    dtau = 1.0 / (npts - 1.0)
    basis = _lagrange_jnp(m)
    batches = [jax.vmap(g, (0, None)) for g in gs]

    def vertex(g, nodes_j, v3, i, comp, p, sign):
        """sign * g at the vertex of the parabola through local samples i-1, i, i+1."""
        fm, f0, fp = sign * v3[0], sign * v3[1], sign * v3[2]
        den = fm - 2.0 * f0 + fp
        off = jnp.where(den < 0, 0.5 * (fm - fp) / jnp.where(den < 0, den, -1.0), 0.0)
        tau = (i + jnp.clip(off, -1.0, 1.0)) * dtau
        val = sign * jnp.ravel(g(basis(tau) @ nodes_j, p))[comp]
        return sign * jnp.maximum(val, f0)

    def kernel(nodes, p):
        ntst, n = nodes.shape[0], nodes.shape[2]
        X = jnp.einsum("sk,jkn->jsn", Lc, nodes).reshape(-1, n)
        out = []
        for g, gb in zip(gs, batches, strict=True):
            vals = gb(X, p).reshape(ntst, Lc.shape[0], -1)
            jmax = jnp.argmax(vals.reshape(-1)) // (vals.shape[1] * vals.shape[2])
            jmin = jnp.argmax(-vals.reshape(-1)) // (vals.shape[1] * vals.shape[2])
            js = jnp.stack([(jmax - 1) % ntst, jmax, (jmax + 1) % ntst,
                            (jmin - 1) % ntst, jmin, (jmin + 1) % ntst])
            Xf = jnp.einsum("sk,jkn->jsn", Lf, nodes[js]).reshape(-1, n)
            vf = gb(Xf, p).reshape(6, npts, -1)
            ncomp = vf.shape[2]
            res = []
            for sign, first in ((1.0, 0), (-1.0, 3)):
                part = vf[first:first + 3]
                k = jnp.argmax(sign * part.reshape(-1))
                blk, rest = k // (npts * ncomp), k % (npts * ncomp)
                i, comp = rest // ncomp, rest % ncomp
                i = jnp.clip(i, 1, npts - 2)  # three samples of the same interval
                v3 = jax.lax.dynamic_slice(part[blk][:, comp], (i - 1,), (3,))
                res.append(vertex(g, nodes[js[first + blk]], v3, i, comp, p, sign))
            out.append(jnp.stack([jnp.maximum(res[0], jnp.max(vals)),
                                  jnp.minimum(res[1], jnp.min(vals))]))
        return jnp.stack(out)

    return cached_kernel(kernel, gs, m, refine)


# the last few orbits' extrema: a branch point's read-out and its limit margins ask for
# the same orbit (entries hold the orbit itself, so an id is never reused while cached)
_EXTREMA_MEMO: list[tuple[System, PeriodicOrbit, int, dict[str, tuple[float, float]]]] = []


def orbit_extrema(
    system: System, orbit: PeriodicOrbit, names: Sequence[str], refine: int = 200
) -> dict[str, tuple[float, float]]:
    """Max and min of each named observable over the orbit (over all components of a
    vector observable), from the collocation polynomial: a coarse pass over 4 NCOL + 1
    points per interval, then a fine pass (``refine`` + 1 points per interval) over the
    intervals around the extreme values. All observables in one compiled call
    (:func:`_extrema_kernel`); the values of an orbit asked again are remembered."""
    names = list(names)
    if not names:
        return {}
    for sys_, orb, ref, ext in _EXTREMA_MEMO:
        if sys_ is system and orb is orbit and ref == refine and all(k in ext for k in names):
            return {k: ext[k] for k in names}
    nodes = orbit.states[interval_nodes(orbit.ntst, orbit.ncol)]  # (ntst, m+1, n)
    gs = tuple(system.observables[name] for name in names)
    v = np.asarray(_extrema_kernel(gs, orbit.ncol, refine)(nodes, np.asarray(orbit.p, float)))
    out = {name: (float(v[k, 0]), float(v[k, 1])) for k, name in enumerate(names)}
    _EXTREMA_MEMO.insert(0, (system, orbit, refine, out))
    del _EXTREMA_MEMO[4:]
    return dict(out)


@cache
def _first_harmonic_weights(m: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss weights and the Lagrange basis at the Gauss points (for the quadrature of
    the first Fourier coefficient of a profile)."""
    _, z, w, L, _ = collocation_tables(m)
    return z, w, L


def first_harmonic(mesh: np.ndarray, m: int, U: np.ndarray) -> np.ndarray:
    """c1 = int_0^1 u(t) exp(-2 pi i t) dt (complex, one per state) of a collocation
    profile, by Gauss quadrature on its mesh (exact for the polynomial up to the
    exponential's quadrature error, and independent of the mesh to that accuracy). Near a
    Hopf point u(t) = x* + eps Re(q exp(2 pi i t)) + O(eps^2), so c1 = eps q / 2 + O(eps^2):
    a smooth function of the branch that passes through zero where the family meets the
    equilibrium."""
    z, w, L = _first_harmonic_weights(m)
    ntst = mesh.size - 1
    h = np.diff(mesh)
    Ui = U[interval_nodes(ntst, m)]  # (ntst, m+1, n)
    Uz = np.einsum("lk,jkn->jln", L, Ui)  # (ntst, m, n) at the Gauss points
    t = mesh[:-1, None] + h[:, None] * z[None, :]
    ph = np.exp(-2j * np.pi * t) * (h[:, None] * w[None, :])
    return np.einsum("jl,jln->n", ph, Uz)


def first_harmonic_mean(orbit: PeriodicOrbit) -> np.ndarray:
    """The mean state int_0^1 u(t) dt of a collocation orbit (Gauss quadrature)."""
    z, w, L = _first_harmonic_weights(orbit.ncol)
    h = np.diff(orbit.mesh)
    Ui = orbit.states[interval_nodes(orbit.ntst, orbit.ncol)]
    Uz = np.einsum("lk,jkn->jln", L, Ui)
    return np.einsum("jl,jln->n", h[:, None] * w[None, :], Uz)
