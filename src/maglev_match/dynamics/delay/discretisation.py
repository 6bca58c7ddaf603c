"""The pseudospectral discretisation of a delay system: Chebyshev nodes and differentiation on
the delay interval, the number of nodes a delay needs, and the discretised system, an ODE
the rest of the engine analyses unchanged.

**Pseudospectral discretisation** (Breda, Maset & Vermiglio 2005, SIAM J. Sci. Comput.
27:482; Breda, Diekmann, Gyllenberg, Scarabel & Vermiglio 2016, SIAM J. Appl. Dyn. Syst.
15:1). The past of y_k on [-tau_k, 0] is represented by its values at the Chebyshev
extremal nodes theta_j = tau_k (cos(j pi / N) - 1) / 2, j = 0..N (theta_0 = 0,
theta_N = -tau_k); the value at theta_0 is g_k(x(t)) itself, the N others are new states
Y_kj(t) ~ y_k(t + theta_j). The transport equation d/dt y(t + theta) = d/dtheta y(t + theta)
becomes, with the Chebyshev differentiation matrix D of the nodes (Trefethen 2000,
*Spectral Methods in MATLAB*, ch. 6),

    x'    = f(x, Y_1N, ..., Y_KN, p)
    Y_kj' = (2 / tau_k) sum_{i=0..N} D_ji Y_ki ,   j = 1..N,   Y_k0 = g_k(x, p)

an ODE of dimension n + N (m_1 + ... + m_K) whose first n states are the current state, so
every observable of the model reads the discretised state unchanged, and the equilibrium,
Hopf, l1, Hopf-curve, collocation, Floquet and simulation code of this package applies to
it as to any :class:`~maglev_match.dynamics.system.System` (:func:`discretise`). A delay
enters only through 1 / tau_k, so it is a smooth continuation parameter for tau_k > 0; at
tau_k = 0 the discretisation is singular (the history's time scale goes to zero) and the
delay-free ODE x' = f(x, g_1(x), ..., g_K(x)) is the system there
(:meth:`~maglev_match.dynamics.delay.system.DelayDifferentialSystem.ode_system`). The
equilibria do not depend on the delays: X* = (x*, g(x*) at every node).

The number N of intervals a delay needs (:func:`nodes_for`) resolves the eigenfunction
exp(lambda theta) of every root of interest to round-off (Breda et al. 2005); beyond
:data:`NODES_MAX` a delay is refused (:class:`DelayNodesError`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import cache
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from maglev_match.core import jax_setup  # noqa: F401  (float64 on)
from maglev_match.dynamics.delay.system import DelayDifferentialSystem
from maglev_match.dynamics.system import System

__all__ = [
    "NODES_MIN",
    "NODES_MAX",
    "NODES_PER_RATE",
    "DiscretisedSystem",
    "DelayNodesError",
    "chebyshev_nodes",
    "nodes_for",
    "max_delay_for",
    "discretise",
    "is_delay_parameter",
]

#: fewest Chebyshev intervals on a delay interval
NODES_MIN = 12
#: most Chebyshev intervals accepted (the discretised dimension is n + NODES_MAX * m)
NODES_MAX = 64
#: N = NODES_MIN + ceil(NODES_PER_RATE * rho * tau): the eigenfunction exp(lambda theta) of a
#: root with |lambda| <= rho is resolved to round-off (its Chebyshev coefficients on the
#: interval fall like (|lambda| tau / 4)^j / j!; 1e-16 is reached for j ~ 1.2 |lambda| tau + 12)
NODES_PER_RATE = 1.5


class DelayNodesError(ValueError):
    """A delay too long for the largest discretisation (names the delay, value and rule)."""

    def __init__(self, name: str, value: float, rule: str):
        self.field = name
        self.value = value
        self.rule = rule
        super().__init__(f"parameter '{name}' = {value!r}: {rule}")


# ---------------------------------------------------------------------------------------
# Chebyshev nodes and differentiation
# ---------------------------------------------------------------------------------------
@cache
def chebyshev_nodes(n_intervals: int) -> tuple[np.ndarray, np.ndarray]:
    """Chebyshev extremal nodes s_j = (cos(j pi / N) - 1) / 2 on [-1, 0] (s_0 = 0,
    s_N = -1) and the differentiation matrix D on them: (D y)_j = p'(s_j) for the
    polynomial p of degree N through (s_i, y_i). Trefethen 2000, program cheb.m, with the
    diagonal from the negative row sums (exact for constants) and the factor 2 of the map
    from [-1, 1] to [-1, 0]. Node theta_j of a delay tau is tau s_j, and d/dtheta = D / tau.
    """
    N = int(n_intervals)
    if N < 1:
        raise ValueError(f"n_intervals = {N}: must be at least 1")
    j = np.arange(N + 1)
    x = np.cos(np.pi * j / N)
    c = np.where((j == 0) | (j == N), 2.0, 1.0) * (-1.0) ** j
    dX = x[:, None] - x[None, :]
    D = np.outer(c, 1.0 / c) / (dX + np.eye(N + 1))
    D = D - np.diag(D.sum(axis=1))
    D.setflags(write=False)
    s = (x - 1.0) / 2.0
    s.setflags(write=False)
    return s, 2.0 * D


def nodes_for(tau: float, rate: float) -> int:
    """Chebyshev intervals N for a delay ``tau`` (s) of a system whose roots of interest have
    |lambda| <= ``rate`` (rad/s): NODES_MIN + ceil(NODES_PER_RATE rate tau)."""
    return NODES_MIN + int(math.ceil(NODES_PER_RATE * max(rate, 0.0) * max(tau, 0.0)))


def max_delay_for(rate: float, nodes: int = NODES_MAX) -> float:
    """The longest delay (s) that ``nodes`` Chebyshev intervals resolve under the rule of
    :func:`nodes_for` (inf for a zero rate)."""
    if rate <= 0:
        return math.inf
    return (nodes - NODES_MIN) / (NODES_PER_RATE * rate)



# ---------------------------------------------------------------------------------------
# the discretised system
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class DiscretisedSystem(System):
    """The ODE of the pseudospectral discretisation of a delay system (module docstring):
    state (x, Y_1, ..., Y_K) with x the current state (its first ``n_state`` entries) and
    Y_k the signal k at the N nodes theta_1..theta_N of [-tau_k, 0], node-major.

    ``dde`` is the delay system, ``nodes`` N. Eigenvectors at Hopf points are normalised
    on the current state (``normal_form_dim`` = n), so l1 does not depend on N.
    """

    dde: Any = None
    nodes: int = 0

    @property
    def n_state(self) -> int:
        return self.dde.dim

    @property
    def normal_form_dim(self) -> int:
        return self.dde.dim

    #: Floquet multipliers by orthogonal iteration for the largest ones
    #: (:func:`~maglev_match.dynamics.floquet.dominant_multipliers`): the discretised past
    #: makes every interval's transfer matrix ill-conditioned, and all but a few multipliers
    #: are far below round-off
    floquet_method = "dominant"

    @property
    def delays(self) -> tuple[str, ...]:
        return self.dde.delays

    def history_slices(self) -> list[slice]:
        """Slice of each delay's history block in the discretised state."""
        out, off = [], self.n_state
        for m in self.dde.signal_sizes:
            out.append(slice(off, off + self.nodes * m))
            off += self.nodes * m
        return out

    def current(self, X: np.ndarray) -> np.ndarray:
        """The current state x (rows: states) of discretised state(s) X."""
        X = np.asarray(X, float)
        return X[..., : self.n_state]

    def lift(self, x: np.ndarray, p: np.ndarray | None = None) -> np.ndarray:
        """The discretised state of a constant past: x(theta) = x for theta <= 0 (every
        node holds g_k(x)). ``x`` of shape (n,) or (batch, n); a state that is already
        discretised (dim entries) is returned unchanged."""
        x = np.asarray(x, float)
        if x.shape[-1] == self.dim:
            return x
        if x.shape[-1] != self.n_state:
            raise ValueError(f"state has {x.shape[-1]} entries; the system has "
                             f"{self.n_state} (or {self.dim} discretised)")
        pv = jnp.asarray(self.p if p is None else p, jnp.float64)
        lift = _lift_kernel(self.dde.signals, self.n_state, self.nodes)
        if x.ndim == 1:
            return np.asarray(lift(jnp.asarray(x), pv))
        return np.asarray(jax.vmap(lift, in_axes=(0, None))(jnp.asarray(x), pv))


@cache
def _lift_kernel(signals: tuple[Callable, ...], n: int, N: int) -> Callable:
    def lift(x, p):
        parts = [x]
        for g in signals:
            y = jnp.reshape(g(x, p), (-1,))
            parts.append(jnp.tile(y, N))
        return jnp.concatenate(parts)

    return jax.jit(lift)


@cache
def _discretised_rhs(rhs: Callable, signals: tuple[Callable, ...], n: int,
                     sizes: tuple[int, ...], delay_idx: tuple[int, ...], N: int) -> Callable:
    """The discretised right-hand side (cached, so every system with the same model and N
    shares compiled code). The Chebyshev matrix is built from N at trace time."""

    def f(X, p):
        _, D = chebyshev_nodes(N)
        D = jnp.asarray(D)
        x = X[:n]
        yd, hist = [], []
        off = n
        for k, g in enumerate(signals):
            m = sizes[k]
            H = jnp.reshape(X[off: off + N * m], (N, m))
            Y = jnp.concatenate([jnp.reshape(g(x, p), (1, m)), H], axis=0)
            hist.append(jnp.reshape(D[1:, :] @ Y / p[delay_idx[k]], (-1,)))
            yd.append(H[-1])
            off += N * m
        return jnp.concatenate([jnp.reshape(rhs(x, tuple(yd), p), (-1,)), *hist])

    f.__name__ = f"discretised_{getattr(rhs, '__name__', 'rhs')}_{N}"
    return f


@cache
def _sliced_observable(g: Callable, n: int) -> Callable:
    def h(X, p):
        return g(X[:n], p)

    h.__name__ = getattr(g, "__name__", "observable")
    return h


def _signal_scale(dde: DelayDifferentialSystem) -> list[np.ndarray]:
    """Typical size of each signal entry: sum_j |dg_i/dx_j| scale_j (ones where zero)."""
    out = []
    for g in dde.signals:
        G = np.atleast_2d(np.asarray(jax.jacfwd(lambda x, g=g: jnp.reshape(
            g(x, jnp.asarray(dde.p)), (-1,)))(jnp.asarray(dde.x_guess))))
        s = np.abs(G) @ dde.state_scale
        out.append(np.where(s > 0, s, 1.0))
    return out


def discretise(dde: DelayDifferentialSystem, nodes: int | None = None, *,
               tau_max: float | None = None) -> DiscretisedSystem:
    """The discretised system of ``dde`` with ``nodes`` Chebyshev intervals per delay
    (default: :func:`nodes_for` the largest delay, or ``tau_max`` if larger, and the
    system's rate bound).

    Raises :class:`DelayNodesError` when a delay is negative, or when the delays need more
    than :data:`NODES_MAX` intervals. The discretised system's ``param_ranges`` bound each
    delay to (0, the longest delay N intervals resolve] (by the rule of :func:`nodes_for`;
    when both ``nodes`` and ``tau_max`` are given, the caller has chosen the resolution for
    delays up to ``tau_max``, and that is the bound).
    """
    taus = dde.delay_values()
    for name, t in zip(dde.delays, taus, strict=True):
        if not t >= 0 or not math.isfinite(t):
            raise DelayNodesError(name, float(t), "a delay must be a finite number >= 0 s")
    longest = max([float(np.max(taus))] + ([float(tau_max)] if tau_max is not None else []))
    rate = dde.rate_bound()
    chosen = nodes is not None  # the caller's resolution: its tau_max is the delays' bound
    if nodes is None:
        nodes = nodes_for(longest, rate)
        if nodes > NODES_MAX:
            name = dde.delays[int(np.argmax(taus))] if tau_max is None or float(
                np.max(taus)) >= tau_max else dde.delays[0]
            raise DelayNodesError(
                name, longest,
                f"needs {nodes} Chebyshev intervals on the delay interval (N = {NODES_MIN} "
                f"+ {NODES_PER_RATE:g} rho tau with rho = {rate:.4g} rad/s, the fastest "
                f"rate of the model), more than the maximum {NODES_MAX}: the delay must be "
                f"at most {max_delay_for(rate):.4g} s")
    nodes = int(nodes)
    if not 1 <= nodes <= NODES_MAX:
        raise DelayNodesError("nodes", nodes, f"must lie in 1..{NODES_MAX}")
    n = dde.dim
    sizes = dde.signal_sizes
    rhs = _discretised_rhs(dde.rhs, dde.signals, n, sizes, dde.delay_indices(), nodes)
    names = list(dde.state_names)
    scales = [dde.state_scale]
    for k, sc in enumerate(_signal_scale(dde)):
        for j in range(1, nodes + 1):
            names.extend(f"{s}[theta{j}]" for s in dde.signal_names[k])
        scales.append(np.tile(sc, nodes))
    X0 = np.asarray(_lift_kernel(dde.signals, n, nodes)(jnp.asarray(dde.x_guess),
                                                        jnp.asarray(dde.p)))
    hi = max_delay_for(rate, nodes)
    if chosen and tau_max is not None:
        hi = max(hi, float(tau_max))
    ranges = dict(dde.param_ranges)
    for d in dde.delays:
        lo_d, hi_d = ranges.get(d, (0.0, math.inf))
        ranges[d] = (max(0.0, lo_d), min(hi_d, hi))
    return DiscretisedSystem(
        rhs=rhs, p=dde.p, param_names=dde.param_names, state_names=tuple(names),
        x_guess=X0, state_scale=np.concatenate(scales),
        observables={k: _sliced_observable(g, n) for k, g in dde.observables.items()},
        name=f"{dde.name} (delay, N = {nodes})", param_ranges=ranges, dde=dde, nodes=nodes)


def is_delay_parameter(system: Any, name: str) -> bool:
    """True when ``name`` is a delay of a discretised delay system."""
    return isinstance(system, DiscretisedSystem) and name in system.delays

