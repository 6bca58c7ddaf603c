"""Delay-differential systems with constant delays, turned into ODEs the rest of the engine
analyses unchanged.

Nothing here knows about maglev. A :class:`DelayDifferentialSystem` is

    x'(t) = f(x(t), y_1(t - tau_1), ..., y_K(t - tau_K), p),     y_k = g_k(x, p)  (m_k entries)

with the delays tau_k entries of the parameter vector. Only the *signals* y_k (the
quantities the equation reads late, m_k of them) need a past; a user model that reads the
whole state late has g_k(x) = x.

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
(:meth:`DelayDifferentialSystem.ode_system`). The equilibria do not depend on the delays:
X* = (x*, g(x*) at every node).

**Characteristic roots** (:func:`characteristic_roots`). Linearised at an equilibrium,
x' = A_0 x(t) + sum_k A_k x(t - tau_k), with A_0 = df/dx and A_k = (df/dy_k)(dg_k/dx); the
characteristic matrix is Delta(lambda) = lambda I - A_0 - sum_k A_k exp(-lambda tau_k).
The eigenvalues of the discretised system's Jacobian approximate the rightmost roots of
det Delta = 0 with an error that falls exponentially in N (the eigenfunction
exp(lambda theta) on the interval is resolved when N >> |lambda| tau / 2; Breda et al. 2005);
each approximation is then corrected by Newton's method on the exact equations
Delta(lambda) v = 0, c^H v = 1 (as DDE-BIFTOOL does; Engelborghs, Luzyanina & Roose 2002,
ACM TOMS 28:1). A root is *trusted* when Newton's method, started from its approximations
with N and with a larger N (both within ``APPROX_TOL``), converges to the same root (to
``TRUST_TOL``), and the larger N shows no further root to its right; the trusted roots are
the leading ones (by real part) up to the first one that fails. (For tiny delays, tau
|lambda| < 1e-5 or so, the discretised matrix has entries ~ N^2 / tau and its eigenvalues
carry round-off far above the spectral error; the Newton correction removes it.)

**Hopf points in a delay** (:func:`delay_crossings`, :func:`critical_delay`). The
equilibrium does not move with a delay, so its Hopf points in tau_k are the delays at which
a root crosses the imaginary axis: Delta(i omega; tau_k) v = 0. For each omega the
candidates solve a generalised eigenvalue problem in z = exp(-i omega tau_k),

    (i omega I - A_0 - sum_{j != k} A_j exp(-i omega tau_j)) v = z A_k v,

and a crossing needs |z| = 1 (the classical frequency sweep, e.g. Michiels & Niculescu 2014,
*Stability, Control and Computation for Time-Delay Systems*, ch. 4). All crossings lie at
omega <= ||A_0|| + sum_j ||A_j||; they are bracketed on a frequency grid by the count of
|z| < 1, refined by Newton on (v, omega, tau_k), and each gives the delays
tau_k + 2 pi j / omega. This needs no discretisation and holds at tau_k = 0.

**First Lyapunov coefficient of a DDE** (:func:`delay_first_lyapunov_coefficient`), from the
characteristic matrix (Janssens 2010, *On a normalization technique for codimension two
bifurcations of equilibria of delay differential equations*, MSc thesis, Utrecht; Bosschaert,
Janssens & Kuznetsov 2020, SIAM J. Appl. Dyn. Syst. 19:252): with Delta(i omega) q = 0,
p^H Delta(i omega) = 0, |q| = 1, p^H Delta'(i omega) q = 1 and the multilinear forms B, C of
F(u_0, u_1, ..., u_K) = f(u_0, g_1(u_1), ..., g_K(u_K)) evaluated on the functions
phi(theta) = v exp(mu theta) at (theta = 0, -tau_1, ..., -tau_K),

    h20 = Delta(2 i omega)^-1 B(q e^{i w .}, q e^{i w .})     (times e^{2 i w theta})
    h11 = Delta(0)^-1 B(q e^{i w .}, qbar e^{-i w .})
    l1  = Re p^H [C(q, q, qbar) + B(qbar, h20) + 2 B(q, h11)] / (2 omega),

which is Kuznetsov's ODE formula (:mod:`maglev_match.dynamics.normal_forms`) when every delay
is 0. The discretised system computes the same number with its own formula when its
eigenvectors are normalised on the current state (``normal_form_dim``); the two agree as N
grows (tested).

**Simulation** (:func:`simulate_delay`): the method of steps with a dense-output Runge-Kutta
method (Bellen & Zennaro 2003, *Numerical Methods for Delay Differential Equations*,
ch. 3-4): steps no longer than the smallest delay, so the delayed arguments of every stage lie
in steps already taken and are read from their interpolants; the first breakpoints
t = j tau (where the solution's derivatives jump after a constant initial function) end
steps; limit events end the run as a collision. It is the reference for the discretised
system's simulation (whose error it measures).
"""

from __future__ import annotations

import bisect
import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from functools import cache
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import scipy.linalg

from maglev_match.core import jax_setup  # noqa: F401  (float64 on)
from maglev_match.core.reprs import compact_repr
from maglev_match.dynamics.system import System

Array = Any

__all__ = [
    "NODES_MIN",
    "NODES_MAX",
    "NODES_PER_RATE",
    "TRUST_TOL",
    "DelayDifferentialSystem",
    "DiscretisedSystem",
    "DelayNodesError",
    "CharacteristicRoots",
    "DelayCrossing",
    "CriticalDelay",
    "DelaySimulation",
    "chebyshev_nodes",
    "nodes_for",
    "max_delay_for",
    "discretise",
    "is_delay_parameter",
    "delay_jacobians",
    "characteristic_matrix",
    "discretised_matrix",
    "characteristic_roots",
    "refine_characteristic_root",
    "delay_first_lyapunov_coefficient",
    "delay_crossings",
    "critical_delay",
    "delay_hopf_points",
    "simulate_delay",
]

#: fewest Chebyshev intervals on a delay interval
NODES_MIN = 12
#: most Chebyshev intervals accepted (the discretised dimension is n + NODES_MAX * m)
NODES_MAX = 64
#: N = NODES_MIN + ceil(NODES_PER_RATE * rho * tau): the eigenfunction exp(lambda theta) of a
#: root with |lambda| <= rho is resolved to round-off (its Chebyshev coefficients on the
#: interval fall like (|lambda| tau / 4)^j / j!; 1e-16 is reached for j ~ 1.2 |lambda| tau + 12)
NODES_PER_RATE = 1.5
#: a characteristic root is trusted when Newton's method on the exact characteristic
#: equation, started from its approximations with N and with a larger N, converges from both
#: to the same root, to this relative to max(1, |lambda|) ...
TRUST_TOL = 1e-10
#: ... from approximations no further than this (relative) from it
APPROX_TOL = 1e-2


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
# the delay system
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class DelayDifferentialSystem:
    """x'(t) = rhs(x(t), (y_1(t - tau_1), ..., y_K(t - tau_K)), p), y_k = signals[k](x, p).

    Parameters
    ----------
    rhs : pure JAX function ``(x, yd, p) -> dx/dt`` with ``yd`` a tuple of K arrays, ``yd[k]``
        of shape (m_k,): the signal k at t - tau_k.
    signals : K pure JAX functions ``g_k(x, p) -> (m_k,)``: the delayed quantities.
    delays : names of the K delay parameters (entries of ``p``; seconds, or the model's
        time unit).
    p, param_names, state_names, x_guess, state_scale, observables, name, param_ranges :
        as for :class:`~maglev_match.dynamics.system.System` (observables read x).
    signal_names : a name per signal entry, per delay (for the history states' names).
    ode_rhs : the delay-free right-hand side ``(x, p)`` (all delays 0), when the model has
        one of its own (then :meth:`ode_system` uses it, so results at zero delay are
        exactly the ODE's); by default rhs(x, (g_1(x), ..., g_K(x)), p).
    ode_param_names : the parameter names of ``ode_rhs`` (a prefix of ``param_names``;
        default: all of them).
    rate : a bound (rad/s) on |lambda| of the characteristic roots of interest, used to size
        the discretisation (default: the spectral radius of the delay-free Jacobian at
        x_guess).
    """

    __repr__ = compact_repr

    rhs: Callable
    signals: tuple[Callable, ...]
    delays: tuple[str, ...]
    p: np.ndarray
    param_names: tuple[str, ...]
    state_names: tuple[str, ...]
    x_guess: np.ndarray | None = None
    state_scale: np.ndarray | None = None
    observables: Mapping[str, Callable] = field(default_factory=dict)
    name: str = ""
    param_ranges: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    signal_names: tuple[tuple[str, ...], ...] = ()
    ode_rhs: Callable | None = None
    ode_param_names: tuple[str, ...] | None = None
    rate: float | None = None

    def __post_init__(self) -> None:
        p = np.asarray(self.p, float).ravel()
        object.__setattr__(self, "p", p)
        object.__setattr__(self, "signals", tuple(self.signals))
        object.__setattr__(self, "delays", tuple(self.delays))
        if len(self.param_names) != p.size:
            raise ValueError(f"{len(self.param_names)} parameter names for {p.size} values")
        if len(self.signals) != len(self.delays) or not self.delays:
            raise ValueError("one signal function per delay, at least one delay")
        for d in self.delays:
            if d not in self.param_names:
                raise ValueError(f"delay '{d}' is not a parameter ({', '.join(self.param_names)})")
        n = len(self.state_names)
        xg = np.zeros(n) if self.x_guess is None else np.asarray(self.x_guess, float)
        object.__setattr__(self, "x_guess", xg)
        sc = np.ones(n) if self.state_scale is None else np.asarray(self.state_scale, float)
        object.__setattr__(self, "state_scale", sc)
        sizes = tuple(int(np.size(np.asarray(g(jnp.asarray(xg), jnp.asarray(p)))))
                      for g in self.signals)
        object.__setattr__(self, "_sizes", sizes)
        if not self.signal_names:
            names = tuple(tuple(f"y{k + 1}_{i + 1}" if m > 1 else f"y{k + 1}"
                                for i in range(m)) for k, m in enumerate(sizes))
            object.__setattr__(self, "signal_names", names)

    # ----- shape ---------------------------------------------------------------------
    @property
    def dim(self) -> int:
        """n, the dimension of the current state."""
        return len(self.state_names)

    @property
    def signal_sizes(self) -> tuple[int, ...]:
        """m_k, the number of delayed quantities of each delay."""
        return self._sizes  # type: ignore[attr-defined]

    def delay_indices(self) -> tuple[int, ...]:
        return tuple(self.param_names.index(d) for d in self.delays)

    def delay_values(self, p: np.ndarray | None = None) -> np.ndarray:
        """The delays (s) at parameters ``p``."""
        q = self.p if p is None else np.asarray(p, float)
        return np.array([q[i] for i in self.delay_indices()])

    def param_index(self, name: str) -> int:
        try:
            return self.param_names.index(name)
        except ValueError:
            raise KeyError(f"system '{self.name}' has no parameter '{name}'; it has: "
                           + ", ".join(self.param_names)) from None

    def params_with(self, p: np.ndarray | None = None, **values: float) -> np.ndarray:
        q = np.array(self.p if p is None else p, dtype=float)
        for k, v in values.items():
            q[self.param_index(k)] = v
        return q

    def with_params(self, **values: float) -> DelayDifferentialSystem:
        return dataclasses.replace(self, p=self.params_with(**values))

    # ----- the delay-free system and the argument function ---------------------------
    def ode_system(self) -> System:
        """The delay-free ODE x' = f(x, g_1(x), ..., g_K(x)) (every delay 0)."""
        if self.ode_rhs is not None:
            names = self.ode_param_names or self.param_names
            p = np.array([self.p[self.param_names.index(n)] for n in names])
            rhs = self.ode_rhs
        else:
            names, p = self.param_names, self.p
            rhs = _undelayed_rhs(self.rhs, self.signals)
        return System(rhs=rhs, p=p, param_names=tuple(names), state_names=self.state_names,
                      x_guess=self.x_guess, state_scale=self.state_scale,
                      observables=dict(self.observables), name=self.name,
                      param_ranges={k: v for k, v in self.param_ranges.items()
                                    if k in names})

    def ode_params(self, p: np.ndarray) -> np.ndarray:
        """The parameter vector of :meth:`ode_system` for a vector of this system."""
        names = self.ode_param_names or self.param_names
        p = np.asarray(p, float)
        return np.array([p[self.param_names.index(n)] for n in names])

    @property
    def argument_function(self) -> Callable:
        """F(U, p) = f(u_0, (g_k(u_k))_k, p) with U = (u_0, u_1, ..., u_K) stacked: the
        right-hand side as a function of the state at t, t - tau_1, ..., t - tau_K."""
        return _argument_function(self.rhs, self.signals, self.dim)

    def rate_bound(self, x: np.ndarray | None = None, p: np.ndarray | None = None) -> float:
        """|lambda| bound used to size the discretisation (rad/s): ``rate`` if given, else
        the spectral radius of the delay-free Jacobian at ``x`` (default x_guess)."""
        if self.rate is not None:
            return float(self.rate)
        xs = self.x_guess if x is None else np.asarray(x, float)
        A0, As = delay_jacobians(self, xs, self.p if p is None else p)
        J = A0 + sum(As)
        w = np.linalg.eigvals(J)
        return float(np.max(np.abs(w))) if w.size else 0.0


@cache
def _undelayed_rhs(rhs: Callable, signals: tuple[Callable, ...]) -> Callable:
    def f(x, p):
        return rhs(x, tuple(jnp.reshape(g(x, p), (-1,)) for g in signals), p)

    f.__name__ = f"undelayed_{getattr(rhs, '__name__', 'rhs')}"
    return f


@cache
def _argument_function(rhs: Callable, signals: tuple[Callable, ...], n: int) -> Callable:
    def F(U, p):
        yd = tuple(jnp.reshape(g(U[(k + 1) * n:(k + 2) * n], p), (-1,))
                   for k, g in enumerate(signals))
        return rhs(U[:n], yd, p)

    F.__name__ = f"argument_{getattr(rhs, '__name__', 'rhs')}"
    return F


@cache
def _argument_jacobian(F: Callable) -> Callable:
    return jax.jit(jax.jacfwd(F, argnums=0))


def delay_jacobians(dde: DelayDifferentialSystem, x: np.ndarray, p: np.ndarray | None = None
                    ) -> tuple[np.ndarray, tuple[np.ndarray, ...]]:
    """(A_0, (A_1, ..., A_K)): the derivatives of the right-hand side with respect to the
    state at t and at t - tau_k, at the equilibrium ``x`` (each n x n)."""
    n, K = dde.dim, len(dde.delays)
    pv = dde.p if p is None else np.asarray(p, float)
    U = np.tile(np.asarray(x, float), K + 1)
    JU = np.asarray(_argument_jacobian(dde.argument_function)(U, pv))
    return JU[:, :n], tuple(JU[:, (k + 1) * n:(k + 2) * n] for k in range(K))


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


# ---------------------------------------------------------------------------------------
# characteristic roots
# ---------------------------------------------------------------------------------------
def characteristic_matrix(A0: np.ndarray, As: Sequence[np.ndarray], taus: Sequence[float],
                          lam: complex) -> np.ndarray:
    """Delta(lambda) = lambda I - A_0 - sum_k A_k exp(-lambda tau_k)."""
    M = lam * np.eye(A0.shape[0]) - A0
    for A, t in zip(As, taus, strict=True):
        M = M - A * np.exp(-lam * t)
    return M


def _characteristic_derivative(A0, As, taus, lam) -> np.ndarray:
    """Delta'(lambda) = I + sum_k tau_k A_k exp(-lambda tau_k)."""
    M = np.eye(A0.shape[0], dtype=complex)
    for A, t in zip(As, taus, strict=True):
        M = M + t * A * np.exp(-lam * t)
    return M


@cache
def _factor_kernel(rhs: Callable, signals: tuple[Callable, ...]) -> Callable:
    """Jitted (A0, (R_k), (G_k)) at (x, p) for one delay model (compiled once)."""

    def factors(x, p):
        ys = tuple(jnp.reshape(g(x, p), (-1,)) for g in signals)
        A0 = jax.jacfwd(lambda z: rhs(z, ys, p))(x)
        R = jax.jacfwd(lambda yy: rhs(x, yy, p))(ys)
        G = tuple(jax.jacfwd(lambda z, g=g: jnp.reshape(g(z, p), (-1,)))(x) for g in signals)
        return A0, tuple(R), G

    return jax.jit(factors)


def _signal_factors(dde: DelayDifferentialSystem, x: np.ndarray, p: np.ndarray):
    """(A0, R_k, G_k): df/dx, df/dy_k (n x m_k) and dg_k/dx (m_k x n) at the equilibrium."""
    n = dde.dim
    A0, R, G = _factor_kernel(dde.rhs, dde.signals)(jnp.asarray(x, jnp.float64),
                                                    jnp.asarray(p, jnp.float64))
    return (np.asarray(A0), [np.asarray(r).reshape(n, -1) for r in R],
            [np.asarray(g).reshape(-1, n) for g in G])


def discretised_matrix(A0: np.ndarray, R: Sequence[np.ndarray], G: Sequence[np.ndarray],
                       taus: Sequence[float], nodes: int) -> np.ndarray:
    """The Jacobian of the discretised system at an equilibrium, built from the
    linearisation x' = A_0 x + sum_k R_k y_k(t - tau_k), y_k = G_k x (equal to the
    autodiff Jacobian of :func:`discretise`'s right-hand side; no compilation per N)."""
    n = A0.shape[0]
    sizes = [Gk.shape[0] for Gk in G]
    dim = n + nodes * sum(sizes)
    M = np.zeros((dim, dim))
    M[:n, :n] = A0
    _, D = chebyshev_nodes(nodes)
    off = n
    for Rk, Gk, t, m in zip(R, G, taus, sizes, strict=True):
        M[:n, off + (nodes - 1) * m: off + nodes * m] += Rk
        Dt = D / t
        block = np.kron(Dt[1:, 1:], np.eye(m))
        M[off: off + nodes * m, off: off + nodes * m] = block
        M[off: off + nodes * m, :n] = np.kron(Dt[1:, :1], Gk)
        off += nodes * m
    return M


@dataclass(frozen=True)
class CharacteristicRoots:
    """The rightmost characteristic roots of a delay system at an equilibrium.

    roots : the Newton-corrected roots (1/s), largest real part first; entries after
        ``trusted`` are the discretisation's approximations (not trusted).
    approximations : eigenvalues of the discretised Jacobian with ``nodes`` intervals
        (same order); check : the matching ones with ``check_nodes`` intervals.
    trusted : how many leading roots are trusted (module docstring, TRUST_TOL).
    residuals : |Delta(lambda) v| / (|lambda| + ||A||) of each corrected root.
    """

    __repr__ = compact_repr

    roots: np.ndarray
    approximations: np.ndarray
    check: np.ndarray
    nodes: int
    check_nodes: int
    trusted: int
    residuals: np.ndarray
    max_real_part: float

    @property
    def stable(self) -> bool | None:
        """True/False when the rightmost root is trusted; None otherwise."""
        if self.trusted == 0:
            return None
        return bool(self.max_real_part < 0)


def refine_characteristic_root(A0: np.ndarray, As: Sequence[np.ndarray],
                               taus: Sequence[float], lam: complex,
                               v: np.ndarray | None = None, tol: float = 1e-14,
                               max_iter: int = 30) -> tuple[complex, np.ndarray, float, bool]:
    """Newton's method on Delta(lambda) v = 0, c^H v = 1 from ``lam`` (and ``v``).

    Returns (lambda, v with |v| = 1, residual |Delta(lambda) v| / (|lambda| + ||A||),
    converged)."""
    n = A0.shape[0]
    lam = complex(lam)
    if v is None:
        v = _null_vector(characteristic_matrix(A0, As, taus, lam))
    v = np.asarray(v, complex)
    v = v / np.linalg.norm(v)
    c = v.copy()
    size = np.linalg.norm(A0, 2) + sum(np.linalg.norm(A, 2) for A in As)
    converged = False
    for _ in range(max_iter):
        Dl = characteristic_matrix(A0, As, taus, lam)
        F = np.concatenate([Dl @ v, [np.vdot(c, v) - 1.0]])
        Jm = np.zeros((n + 1, n + 1), complex)
        Jm[:n, :n] = Dl
        Jm[:n, n] = _characteristic_derivative(A0, As, taus, lam) @ v
        Jm[n, :n] = np.conj(c)
        try:
            d = np.linalg.solve(Jm, -F)
        except np.linalg.LinAlgError:
            break
        if not np.all(np.isfinite(d)):
            break
        v = v + d[:n]
        lam = lam + d[n]
        if abs(d[n]) <= tol * max(1.0, abs(lam)) and np.linalg.norm(d[:n]) <= 1e-12 * \
                np.linalg.norm(v):
            converged = True
            break
    v = v / np.linalg.norm(v)
    res = float(np.linalg.norm(characteristic_matrix(A0, As, taus, lam) @ v)
                / (abs(lam) + size + 1e-300))
    return lam, v, res, converged and res < 1e-12


def _one_thread():
    """Small dense eigenproblems in a loop: BLAS threads only contend for the cores there
    (as in :mod:`maglev_match.analyses.matching`)."""
    from threadpoolctl import threadpool_limits

    return threadpool_limits(1)


def _null_vector(M: np.ndarray) -> np.ndarray:
    _, _, vh = scipy.linalg.svd(M)
    return np.conj(vh[-1])


def _sorted(w: np.ndarray) -> np.ndarray:
    return w[np.lexsort((-w.imag, -w.real))]


def characteristic_roots(dde: DelayDifferentialSystem, x: np.ndarray | None = None,
                         p: np.ndarray | None = None, *, count: int = 10,
                         nodes: int | None = None, check_nodes: int | None = None
                         ) -> CharacteristicRoots:
    """The ``count`` rightmost characteristic roots at the equilibrium ``x`` (the delay
    system's state, default x_guess) with their trust (module docstring).

    ``nodes`` (default :func:`nodes_for` the largest delay) and ``check_nodes`` (default
    nodes + max(8, nodes // 2)) are the two discretisations compared. With every delay 0 the
    roots are the eigenvalues of the delay-free Jacobian (all trusted).
    """
    pv = dde.p if p is None else np.asarray(p, float)
    xs = dde.x_guess if x is None else np.asarray(x, float)
    taus = dde.delay_values(pv)
    A0, R, G = _signal_factors(dde, xs, pv)
    As = [Rk @ Gk for Rk, Gk in zip(R, G, strict=True)]
    if not np.any(taus > 0):
        w = _sorted(np.linalg.eigvals(A0 + sum(As)))[:count]
        return CharacteristicRoots(roots=w, approximations=w, check=w, nodes=0, check_nodes=0,
                                   trusted=int(w.size), residuals=np.zeros(w.size),
                                   max_real_part=float(np.max(w.real)))
    if np.any(taus <= 0):
        raise ValueError("characteristic_roots: delays must be all positive or all zero")
    rate = max(float(np.max(np.abs(np.linalg.eigvals(A0 + sum(As))))), 1e-300)
    N = nodes or min(nodes_for(float(np.max(taus)), rate), NODES_MAX)
    N2 = check_nodes or N + max(8, N // 2)
    w1 = _sorted(np.linalg.eigvals(discretised_matrix(A0, R, G, taus, N)))[:count]
    w2 = _sorted(np.linalg.eigvals(discretised_matrix(A0, R, G, taus, N2)))
    roots, check, res = [], [], []
    trusted, broken = 0, False
    for lam in w1:
        k = int(np.argmin(np.abs(w2 - lam)))
        check.append(w2[k])
        lr, _, r, ok = refine_characteristic_root(A0, As, taus, lam)
        lr2, _, _, ok2 = refine_characteristic_root(A0, As, taus, w2[k])
        scale = max(1.0, abs(lr))
        # both discretisations lead Newton to the same exact root, from nearby
        good = (ok and ok2 and abs(lr - lr2) <= TRUST_TOL * scale
                and abs(lr - lam) <= APPROX_TOL * scale
                and abs(lr - w2[k]) <= APPROX_TOL * scale)
        # and the finer discretisation has no root right of it that the coarse one lacks
        missed = np.any((w2.real > lr.real + APPROX_TOL * scale)
                        & (np.min(np.abs(w2[:, None] - np.asarray(w1)[None, :]), axis=1)
                           > APPROX_TOL * np.maximum(1.0, np.abs(w2))))
        if good and not missed and not broken:
            trusted += 1
            roots.append(lr)
        else:
            broken = True
            roots.append(lam)
        res.append(r)
    roots_a = np.asarray(roots)
    return CharacteristicRoots(roots=roots_a, approximations=w1, check=np.asarray(check),
                               nodes=N, check_nodes=N2, trusted=trusted,
                               residuals=np.asarray(res),
                               max_real_part=float(np.max(roots_a.real)))


# ---------------------------------------------------------------------------------------
# the first Lyapunov coefficient of a delay system
# ---------------------------------------------------------------------------------------
def _forms(F: Callable):
    from maglev_match.dynamics.normal_forms import real_forms

    return real_forms(F)


def delay_first_lyapunov_coefficient(dde: DelayDifferentialSystem, x: np.ndarray,
                                     p: np.ndarray | None, omega: float,
                                     q: np.ndarray | None = None) -> float:
    """l1 at a Hopf point of a delay system from its characteristic matrix (module
    docstring; Janssens 2010, Bosschaert et al. 2020), with |q| = 1 on the state and
    p^H Delta'(i omega) q = 1. Equals Kuznetsov's ODE value when every delay is 0.

    Parameters: ``x`` the equilibrium (n states), ``omega`` the Hopf frequency (rad/s),
    ``q`` the eigenvector (computed when None). Returns l1 (1/s): > 0 subcritical.
    """
    from maglev_match.dynamics.normal_forms import complex_form_eval

    pv = dde.p if p is None else np.asarray(p, float)
    xs = np.asarray(x, float)
    taus = dde.delay_values(pv)
    A0, As = delay_jacobians(dde, xs, pv)
    n, K = dde.dim, len(taus)
    iw = 1j * float(omega)
    Dl = characteristic_matrix(A0, As, taus, iw)
    if q is None:
        q = _null_vector(Dl)
    q = np.asarray(q, complex)
    q = q * np.exp(-1j * np.angle(q[int(np.argmax(np.abs(q)))]))
    q = q / np.linalg.norm(q)
    padj = _null_vector(Dl.conj().T)
    padj = padj / np.conj(np.vdot(padj, _characteristic_derivative(A0, As, taus, iw) @ q))

    def U(v: np.ndarray, mu: complex) -> np.ndarray:
        return np.concatenate([v] + [v * np.exp(-mu * t) for t in taus])

    Fm = _forms(dde.argument_function)
    Ux = np.asarray(np.tile(xs, K + 1), np.float64)

    def form(k, *us):
        val = np.asarray(complex_form_eval(Fm[k], Ux, pv, list(us)))
        # all-zero directions give a zero of the directions' shape (size n (K+1))
        return val if val.shape == (n,) else np.zeros(n, complex)

    def B(a, b):
        return form(2, a, b)

    def C(a, b, c):
        return form(3, a, b, c)

    Uq, Uqb = U(q, iw), U(np.conj(q), -iw)
    h20 = np.linalg.solve(characteristic_matrix(A0, As, taus, 2 * iw), B(Uq, Uq))
    h11 = np.linalg.solve(characteristic_matrix(A0, As, taus, 0.0), B(Uq, Uqb))
    g21 = np.vdot(padj, C(Uq, Uq, Uqb) + B(Uqb, U(h20, 2 * iw)) + 2.0 * B(Uq, U(h11, 0.0)))
    return float(g21.real / (2.0 * float(omega)))


# ---------------------------------------------------------------------------------------
# Hopf points in a delay: crossings of the imaginary axis
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class DelayCrossing:
    """A pair of characteristic roots +-i omega on the imaginary axis at delay ``tau``.

    tau : the delay (s) at the crossing, the smallest one of its family
        tau + 2 pi j / omega (all of them are crossings). omega : frequency (rad/s).
    crossing_speed : d Re(lambda) / d tau there (1/s^2): > 0 the pair moves into the
        right half-plane as the delay grows. q : the eigenvector (|q| = 1).
    residual : |Delta(i omega) q| / (omega + ||A||). converged : Newton converged.
    """

    __repr__ = compact_repr

    tau: float
    omega: float
    crossing_speed: float
    q: np.ndarray
    residual: float
    converged: bool

    def delays(self, tau_max: float) -> list[float]:
        """Every delay of this family in [0, tau_max]."""
        if not self.omega > 0:
            return []
        period = 2.0 * math.pi / self.omega
        k_max = int(math.floor((tau_max - self.tau) / period + 1e-12))
        return [self.tau + j * period for j in range(max(k_max + 1, 0))]


def _rest_matrix(A0, As, taus, k, omega):
    M = 1j * omega * np.eye(A0.shape[0]) - A0
    for j, (A, t) in enumerate(zip(As, taus, strict=True)):
        if j != k:
            M = M - A * np.exp(-1j * omega * t)
    return M


def _unit_circle_candidates(A0, As, taus, k, omega) -> np.ndarray:
    """The finite z = exp(-i omega tau_k) of (i omega I - A_0 - sum_{j != k} ...) v = z A_k v."""
    M = _rest_matrix(A0, As, taus, k, omega)
    z = scipy.linalg.eigvals(M, As[k].astype(complex))
    return z[np.isfinite(z)]


def _refine_crossing(A0, As, taus, k, omega, tau, v, tol=1e-14, max_iter=40):
    """Newton on Delta(i omega; tau_k = tau) v = 0, c^H v = 1 for (v, omega, tau)."""
    n = A0.shape[0]
    v = np.asarray(v, complex) / np.linalg.norm(v)
    c = v.copy()
    t = list(taus)
    converged = False
    for _ in range(max_iter):
        t[k] = tau
        lam = 1j * omega
        Dl = characteristic_matrix(A0, As, t, lam)
        F = np.concatenate([Dl @ v, [np.vdot(c, v) - 1.0]])
        dD_domega = 1j * _characteristic_derivative(A0, As, t, lam) @ v
        dD_dtau = lam * As[k] @ v * np.exp(-lam * tau)
        # complex equations, unknowns v (complex) and omega, tau (real)
        Jc = np.zeros((n + 1, n), complex)
        Jc[:n] = Dl
        Jc[n] = np.conj(c)
        cols = np.zeros((n + 1, 2), complex)
        cols[:n, 0] = dD_domega
        cols[:n, 1] = dD_dtau
        Jr = np.block([[Jc.real, -Jc.imag, cols.real], [Jc.imag, Jc.real, cols.imag]])
        Fr = np.concatenate([F.real, F.imag])
        try:
            d = np.linalg.lstsq(Jr, -Fr, rcond=None)[0]
        except np.linalg.LinAlgError:
            break
        if not np.all(np.isfinite(d)):
            break
        v = v + d[:n] + 1j * d[n:2 * n]
        omega += d[2 * n]
        tau += d[2 * n + 1]
        if abs(d[2 * n]) <= tol * max(1.0, abs(omega)) and abs(d[2 * n + 1]) <= tol * max(
                1.0, abs(tau)) * max(1.0, abs(omega)):
            converged = True
            break
    t[k] = tau
    v = v / np.linalg.norm(v)
    size = np.linalg.norm(A0, 2) + sum(np.linalg.norm(A, 2) for A in As)
    res = float(np.linalg.norm(characteristic_matrix(A0, As, t, 1j * omega) @ v)
                / (abs(omega) + size))
    return float(omega), float(tau), v, res, converged and res < 1e-12


def _crossing_speed(A0, As, taus, k, omega, v) -> float:
    """d Re(lambda) / d tau_k at the root i omega: -Re[p^H (dDelta/dtau_k) v] / p^H Delta' v
    with p the left null vector."""
    lam = 1j * omega
    Dl = characteristic_matrix(A0, As, taus, lam)
    padj = _null_vector(Dl.conj().T)
    num = np.vdot(padj, lam * As[k] @ v * np.exp(-lam * taus[k]))
    den = np.vdot(padj, _characteristic_derivative(A0, As, taus, lam) @ v)
    return float((-num / den).real)


def _match(za: np.ndarray, zb: np.ndarray) -> list[tuple[int, int]]:
    """Pairs (i, j) matching the candidates of two neighbouring frequencies (least total
    distance, in log|z| and arg z)."""
    from scipy.optimize import linear_sum_assignment

    if za.size == 0 or zb.size == 0:
        return []
    la, lb = np.log(za), np.log(zb)  # log|z| + i arg z
    d = np.abs(la.real[:, None] - lb.real[None, :]) + np.abs(
        np.angle(np.exp(1j * (la.imag[:, None] - lb.imag[None, :]))))
    rows, cols = linear_sum_assignment(d)
    return list(zip(rows.tolist(), cols.tolist(), strict=True))


def _crossing_brackets(A0, As, taus, k, wa, wb, za, zb, depth: int, max_depth: int = 6,
                       split: int = 8) -> list[tuple[float, float, complex, complex]]:
    """Frequency intervals in which one matched candidate z passes |z| = 1, subdivided
    (``split`` parts, up to ``max_depth`` times) until each holds one crossing per
    candidate and is narrow against the frequency: near-equal roots (the six levitation
    points of a vehicle give clusters) cross within one coarse interval."""
    changes = [(za[a], zb[b]) for a, b in _match(za, zb)
               if math.log(abs(za[a])) * math.log(abs(zb[b])) <= 0.0]
    if not changes:
        return []
    if depth >= max_depth or wb - wa <= 1e-7 * wb:
        return [(wa, wb, x, y) for x, y in changes]
    ws = np.linspace(wa, wb, split + 1)
    zz = [za] + [_unit_circle_candidates(A0, As, taus, k, w) for w in ws[1:-1]] + [zb]
    out = []
    for i in range(split):
        out += _crossing_brackets(A0, As, taus, k, ws[i], ws[i + 1], zz[i], zz[i + 1],
                                  depth + 1, max_depth, split)
    return out


def delay_crossings(dde: DelayDifferentialSystem, delay: str, x: np.ndarray | None = None,
                    p: np.ndarray | None = None, *, n_grid: int = 1500
                    ) -> list[DelayCrossing]:
    """Every pair of characteristic roots that can sit on the imaginary axis as the delay
    ``delay`` varies (the other delays fixed), at the equilibrium ``x``: their frequency
    and smallest delay (module docstring).

    The frequency axis (0, ||A_0|| + sum ||A_j||] is sampled on ``n_grid`` logarithmically
    spaced points; the candidates z of neighbouring points are matched (least distance),
    every candidate whose |z| passes 1 between two points is refined by Newton's method on
    (v, omega, tau) and the distinct solutions are kept."""
    pv = dde.p if p is None else np.asarray(p, float)
    xs = dde.x_guess if x is None else np.asarray(x, float)
    k = dde.delays.index(delay)
    taus = list(dde.delay_values(pv))
    A0, As = delay_jacobians(dde, xs, pv)
    if not np.any(As[k]):
        return []
    w_max = float(np.linalg.norm(A0, 2) + sum(np.linalg.norm(A, 2) for A in As))
    if not w_max > 0:
        return []
    grid = np.geomspace(w_max * 1e-8, w_max, n_grid)
    with _one_thread():
        zs = [_unit_circle_candidates(A0, As, taus, k, w) for w in grid]
        brackets = []
        for i in range(len(grid) - 1):
            brackets += _crossing_brackets(A0, As, taus, k, grid[i], grid[i + 1], zs[i],
                                           zs[i + 1], depth=0)
    starts = []
    for wa, wb, za, zb in brackets:
        la, lb = math.log(abs(za)), math.log(abs(zb))
        f = la / (la - lb) if la != lb else 0.5
        w0 = wa + f * (wb - wa)
        z_guess = za * (zb / za) ** f
        z, V = scipy.linalg.eig(_rest_matrix(A0, As, taus, k, w0), As[k].astype(complex))
        ok = np.isfinite(z)
        z, V = z[ok], V[:, ok]
        if z.size == 0:
            continue
        j = int(np.argmin(np.abs(z - z_guess)))
        starts.append((w0, z[j] / abs(z[j]), V[:, j]))
    found: list[DelayCrossing] = []
    for w0, z0, v0 in starts:
        tau0 = (-np.angle(z0)) % (2 * math.pi) / w0
        om, tau, v, res, ok = _refine_crossing(A0, As, taus, k, w0, tau0, v0)
        if not (om > 0 and math.isfinite(tau)):
            continue
        period = 2 * math.pi / om
        tau = tau % period
        if any(abs(c.omega - om) <= 1e-8 * max(1.0, om) and abs(c.tau - tau) <= 1e-8 * period
               for c in found):
            continue
        t2 = list(taus)
        t2[k] = tau
        speed = _crossing_speed(A0, As, t2, k, om, v)
        found.append(DelayCrossing(tau=float(tau), omega=float(om), crossing_speed=speed,
                                   q=v, residual=res, converged=ok))
    found.sort(key=lambda c: c.tau)
    return found


@dataclass(frozen=True)
class CriticalDelay:
    """The smallest delay at which the equilibrium loses stability (the other parameters
    fixed), from the characteristic equation (no discretisation).

    delay : the delay parameter's name. value : the critical delay (s); 0 when the
        equilibrium is already unstable without delay; None when it stays stable for every
        delay up to ``tau_max`` (or for every delay, ``stable_for_all``).
    frequency : omega (rad/s) of the pair that crosses; crossing_speed : d Re / d tau.
    l1 : first Lyapunov coefficient there (1/s, |q| = 1 on the state): > 0 subcritical.
    stable_without_delay : stability at delay 0. unstable_roots_without_delay : count.
    crossings : every family of crossings (:class:`DelayCrossing`).
    """

    __repr__ = compact_repr

    delay: str
    value: float | None
    frequency: float | None
    crossing_speed: float | None
    l1: float | None
    stable_without_delay: bool
    unstable_roots_without_delay: int
    tau_max: float
    stable_for_all: bool
    crossings: tuple[DelayCrossing, ...]
    warnings: tuple[str, ...] = ()

    @property
    def kind(self) -> str:
        if self.l1 is None or not math.isfinite(self.l1):
            return "unknown"
        return "subcritical" if self.l1 > 0 else "supercritical" if self.l1 < 0 else \
            "degenerate"

    def as_json(self) -> dict[str, Any]:
        return {"delay": self.delay, "value": self.value, "frequency": self.frequency,
                "crossing_speed": self.crossing_speed, "l1": self.l1, "kind": self.kind,
                "stable_without_delay": self.stable_without_delay,
                "tau_max": self.tau_max, "stable_for_all": self.stable_for_all,
                "crossings": [{"tau": c.tau, "omega": c.omega,
                               "crossing_speed": c.crossing_speed, "converged": c.converged}
                              for c in self.crossings],
                "warnings": list(self.warnings)}


def critical_delay(dde: DelayDifferentialSystem, delay: str | None = None,
                   x: np.ndarray | None = None, p: np.ndarray | None = None, *,
                   tau_max: float = math.inf) -> CriticalDelay:
    """The smallest value of ``delay`` (default the first) at which the equilibrium ``x``
    loses stability, with the other delays at their values in ``p``.

    Stability at delay 0 comes from the roots with this delay removed (the delay-free
    eigenvalues for a single delay). Roots then cross only at the delays of
    :func:`delay_crossings`; walking through them in order and counting +-2 by the sign of
    each crossing speed gives the first delay at which a root enters the right half-plane.
    Its l1 is :func:`delay_first_lyapunov_coefficient`.
    """
    delay = delay or dde.delays[0]
    k = dde.delays.index(delay)
    pv = dde.p if p is None else np.asarray(p, float)
    xs = dde.x_guess if x is None else np.asarray(x, float)
    warnings: list[str] = []
    A0, As = delay_jacobians(dde, xs, pv)
    taus = dde.delay_values(pv)
    others = [j for j in range(len(taus)) if j != k]
    if not others or not np.any(taus[others] > 0):
        w0 = np.linalg.eigvals(A0 + sum(As))
        n_unst = int(np.sum(w0.real >= 0))
    else:
        # roots with this delay at 0: delay k folded into A_0, the others discretised
        _, R, G = _signal_factors(dde, xs, pv)
        red_A0 = A0 + As[k]
        red_As = [As[j] for j in others]
        red_t = [float(taus[j]) for j in others]
        rate = max(1.0, float(np.max(np.abs(np.linalg.eigvals(red_A0 + sum(red_As))))))
        N = min(nodes_for(max(red_t), rate), NODES_MAX)
        M = discretised_matrix(red_A0, [R[j] for j in others], [G[j] for j in others],
                               red_t, N)
        w = np.array([refine_characteristic_root(red_A0, red_As, red_t, lam)[0]
                      for lam in _sorted(np.linalg.eigvals(M))[:12]])
        n_unst = int(np.sum(w.real >= 0))
    crossings = delay_crossings(dde, delay, xs, pv)
    events = []
    for c in crossings:
        for t in c.delays(tau_max if math.isfinite(tau_max) else c.tau + 20 * 2 * math.pi
                          / c.omega):
            events.append((t, c))
    events.sort(key=lambda e: e[0])
    value = frequency = speed = l1 = None
    if n_unst > 0:
        value = 0.0
    else:
        count = 0
        for t, c in events:
            if c.crossing_speed == 0.0:
                warnings.append(f"a pair of roots touches the imaginary axis at {delay} = "
                                f"{t:.6g} without crossing (crossing speed 0)")
                continue
            tp = list(taus)
            tp[k] = t
            sp = _crossing_speed(A0, As, tp, k, c.omega, c.q)
            count += 2 if sp > 0 else -2
            if count > 0:
                value, frequency, speed = float(t), float(c.omega), float(sp)
                pk = dde.params_with(pv, **{delay: t})
                l1 = delay_first_lyapunov_coefficient(dde, xs, pk, c.omega, c.q)
                break
    for c in crossings:
        if not c.converged:
            warnings.append(f"the crossing near omega = {c.omega:.6g} rad/s did not converge "
                            f"(residual {c.residual:.2e})")
    stable_for_all = n_unst == 0 and not crossings  # no root can reach the axis
    if value is not None and value > tau_max:
        value = frequency = speed = l1 = None
    return CriticalDelay(delay=delay, value=value, frequency=frequency, crossing_speed=speed,
                         l1=l1, stable_without_delay=n_unst == 0,
                         unstable_roots_without_delay=n_unst, tau_max=float(tau_max),
                         stable_for_all=stable_for_all, crossings=tuple(crossings),
                         warnings=tuple(warnings))


# ---------------------------------------------------------------------------------------
# Hopf points along a delay, for the discretised system
# ---------------------------------------------------------------------------------------
def delay_hopf_points(system: DiscretisedSystem, delay: str, start: float, stop: float,
                      p: np.ndarray | None = None, n_scan: int = 100):
    """Hopf points of the equilibrium as the delay ``delay`` runs over [start, stop] (s),
    as a :class:`~maglev_match.dynamics.hopf.HopfScan` of the discretised system.

    The points are the crossings of the characteristic equation (:func:`delay_crossings`:
    exact, and valid down to delay 0, where the discretised system is singular): delay,
    frequency, crossing speed d Re(lambda)/d tau and l1
    (:func:`delay_first_lyapunov_coefficient`) come from the characteristic matrix. The
    discretised system supplies the rest of the record: the equilibrium and eigenvectors in
    its coordinates (from which cycles are continued) and whether the other roots are
    stable. Its eigenvalue nearest i omega at the crossing measures the discretisation
    error; above 1e-8 relative it is a warning. ``scan_values`` and ``max_real_part``
    sample the rightmost root of the discretised system over [start, stop] (``n_scan``
    values; the delay-free eigenvalues at delay 0).
    """
    from maglev_match.dynamics.equilibria import find_equilibrium
    from maglev_match.dynamics.hopf import HopfPoint, HopfScan

    dde = system.dde
    pv = system.p if p is None else np.asarray(p, float)
    lo, hi = sorted((float(start), float(stop)))
    warnings: list[str] = []
    if lo < 0:
        raise DelayNodesError(delay, lo, "a delay must be >= 0 s")
    eq = find_equilibrium(dde.ode_system(), dde.ode_params(pv))
    if not eq.converged:
        warnings.append(f"equilibrium not converged: {eq.message}")
    xs = eq.x
    crossings = delay_crossings(dde, delay, xs, pv)
    A0, R, G = _signal_factors(dde, xs, pv)
    As = [Rj @ Gj for Rj, Gj in zip(R, G, strict=True)]
    k = dde.delays.index(delay)

    def matrix(t: float) -> np.ndarray:
        taus = np.array(dde.delay_values(pv), float)
        taus[k] = t
        keep = [j for j in range(len(taus)) if taus[j] > 0]
        merged = A0 + sum(As[j] for j in range(len(taus)) if j not in keep)
        if not keep:
            return merged
        return discretised_matrix(merged, [R[j] for j in keep], [G[j] for j in keep],
                                  [taus[j] for j in keep], system.nodes)

    scan_values = np.linspace(lo, hi, max(int(n_scan), 2))
    with _one_thread():
        max_re = np.array([float(np.max(np.linalg.eigvals(matrix(t)).real))
                           for t in scan_values])
    X = system.lift(xs, pv)
    norm_dim = dde.dim
    points = []
    for c in crossings:
        for t in c.delays(hi):
            if t < lo - 1e-12 * max(1.0, hi):
                continue
            if t <= 0:
                warnings.append(f"a pair of roots sits on the imaginary axis at {delay} = 0 "
                                f"(omega = {c.omega:.6g} rad/s): the delay-free equilibrium is "
                                "itself at a Hopf point")
                continue
            pt = system.params_with(pv, **{delay: t})
            J = matrix(t)
            w = np.linalg.eigvals(J)
            near = int(np.argmin(np.abs(w - 1j * c.omega)))
            err = abs(w[near] - 1j * c.omega) / c.omega
            others = np.delete(w, [near, int(np.argmin(np.abs(w + 1j * c.omega)))])
            q = _null_vector(J - 1j * c.omega * np.eye(J.shape[0]))
            q = q * np.exp(-1j * np.angle(q[int(np.argmax(np.abs(q[:norm_dim])))]))
            q = q / np.linalg.norm(q[:norm_dim])
            padj = _null_vector(J.T + 1j * c.omega * np.eye(J.shape[0]))
            padj = padj / np.conj(np.vdot(padj, q))
            l1 = delay_first_lyapunov_coefficient(dde, xs, pt, c.omega, c.q)
            sp = _crossing_speed(A0, As, list(dde.delay_values(pt)), k, c.omega, c.q)
            hw: list[str] = []
            if err > 1e-8:
                hw.append(f"the discretised system (N = {system.nodes}) has its eigenvalue "
                          f"nearest i omega {err:.1e} (relative) away: the discretisation "
                          "does not resolve this root well")
            if not c.converged:
                hw.append(f"Newton on the characteristic equation did not converge "
                          f"(residual {c.residual:.1e})")
            points.append(HopfPoint(
                param=delay, value=float(t), x=X, p=pt, frequency=float(c.omega), q=q,
                p_adj=padj, crossing_speed=float(sp), l1=float(l1),
                others_stable=bool(np.all(others.real < 0)), converged=bool(c.converged),
                residual=float(c.residual), warnings=tuple(hw),
                message="" if c.converged else "the crossing did not converge"))
    points.sort(key=lambda h: h.value)
    return HopfScan(param=delay, start=float(start), stop=float(stop), points=points,
                    scan_values=scan_values, max_real_part=max_re,
                    warnings=tuple(warnings), special_points=())


# ---------------------------------------------------------------------------------------
# simulation: the method of steps
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class DelaySimulation:
    """A run of a delay system by the method of steps.

    t, x : saved times (s) and states (n_save, n) (rows after the end of the run are NaN).
    outcome : 'collision' (an event entry went negative), 'running' (the horizon was
        reached) or 'failed' (the integrator stopped: message in ``warnings``).
    event_time, event_index : the collision (s, entry of the event function) or None.
    final_time, final_state : where the run ended. steps : integrator steps taken.
    """

    __repr__ = compact_repr

    t: np.ndarray
    x: np.ndarray
    outcome: str
    event_time: float | None
    event_index: int | None
    final_time: float
    final_state: np.ndarray
    steps: int
    warnings: tuple[str, ...] = ()

    def __call__(self, t: float | np.ndarray) -> np.ndarray:
        """The dense solution at time(s) t in [0, final_time] (the history before 0)."""
        return self._dense(t)  # type: ignore[attr-defined]


@cache
def _mos_kernels(F: Callable, event_fn: Callable | None):
    f = jax.jit(F)
    e = None if event_fn is None else jax.jit(event_fn)
    return f, e


def simulate_delay(dde: DelayDifferentialSystem, x0: np.ndarray, t_end: float, *,
                   p: np.ndarray | None = None, history: Callable | None = None,
                   event_fn: Callable | None = None, rtol: float = 1e-10,
                   atol: float = 1e-12, n_save: int = 1001, t_save: np.ndarray | None = None,
                   breakpoints: int = 4, samples: int = 8, max_steps: int = 2_000_000
                   ) -> DelaySimulation:
    """Integrate the delay system over [0, t_end] (s) by the method of steps (module
    docstring) with SciPy's DOP853 (Hairer, Norsett & Wanner 1993; its 7th-order dense
    output reads the past).

    Parameters
    ----------
    x0 : the state at t = 0 (n entries). history : the state for t < 0, a function
        ``theta -> x`` (default: the constant initial function x(theta) = x0).
    event_fn : ``g(x, p) -> array``; a negative entry ends the run as a collision, located
        on the dense output (each step is also sampled at ``samples`` inner points, so an
        entry that dips below zero within a step is caught).
    rtol, atol : tolerances (atol in units of the states' scale).
    breakpoints : how many of the points t = j tau_k (where the derivatives of the
        solution jump after a non-matching initial function) end integrator steps.
    """
    from scipy.integrate import DOP853
    from scipy.optimize import brentq

    pv = dde.p if p is None else np.asarray(p, float)
    taus = dde.delay_values(pv)
    if np.any(taus <= 0):
        raise ValueError("simulate_delay needs positive delays (the delay-free ODE otherwise)")
    n = dde.dim
    x0 = np.asarray(x0, float).reshape(n)
    F, E = _mos_kernels(dde.argument_function, event_fn)
    pj = jnp.asarray(pv)
    hist = history if history is not None else (lambda theta: x0)
    t_old: list[float] = []
    dense: list[Any] = []

    def state_at(s: float) -> np.ndarray:
        if s <= 0.0 or not t_old:
            return np.asarray(hist(s), float) if s < 0.0 else (x0 if not t_old else
                                                                dense[0](0.0))
        i = bisect.bisect_right(t_old, s) - 1
        return dense[max(i, 0)](s)

    def fun(t, x):
        U = np.concatenate([x] + [state_at(t - tau) for tau in taus])
        return np.asarray(F(U, pj))

    def events_at(x):
        return np.asarray(E(jnp.asarray(x), pj)) if E is not None else None

    ends = sorted({float(j * t) for t in taus for j in range(1, breakpoints + 1)
                   if j * t < t_end} | {float(t_end)})
    h_max = float(np.min(taus))
    scale = dde.state_scale
    x, t = x0.copy(), 0.0
    steps = 0
    outcome, ev_t, ev_i, warns = "running", None, None, []
    if E is not None and np.any(events_at(x0) < 0):
        outcome, ev_t, ev_i = "collision", 0.0, int(np.argmin(events_at(x0)))
    for t_b in ends:
        if outcome != "running":
            break
        solver = DOP853(fun, t, x, t_b, rtol=rtol, atol=atol * scale, max_step=h_max)
        while solver.status == "running":
            if steps >= max_steps:
                outcome = "failed"
                warns.append(f"stopped after max_steps = {max_steps} steps at t = {t:.6g} s")
                break
            msg = solver.step()
            steps += 1
            if solver.status == "failed":
                outcome = "failed"
                warns.append(f"integrator failed at t = {solver.t:.6g} s: {msg}")
                break
            sol = solver.dense_output()
            t_old.append(solver.t_old)
            dense.append(sol)
            if E is not None:
                ts = np.linspace(solver.t_old, solver.t, samples + 2)
                vals = np.array([events_at(sol(s)) for s in ts])
                bad = np.nonzero(np.any(vals < 0, axis=1))[0]
                if bad.size:
                    j = int(bad[0])
                    times = []
                    for i in np.nonzero(vals[j] < 0)[0]:
                        a, b = ts[j - 1], ts[j]
                        times.append((brentq(lambda s, i=i, sol=sol: events_at(sol(s))[i], a, b,
                                             xtol=1e-15, rtol=1e-15), int(i)))
                    ev_t, ev_i = min(times)
                    outcome = "collision"
                    t_old.append(ev_t)  # the run ends here
                    dense.append(sol)
                    break
            t, x = solver.t, solver.y
        if outcome != "running":
            break
        t, x = solver.t, solver.y
    final_t = float(ev_t) if ev_t is not None else float(t)
    final_x = state_at(final_t) if t_old else x0
    ts = np.linspace(0.0, float(t_end), int(n_save)) if t_save is None else np.asarray(
        t_save, float)
    xs = np.full((ts.size, n), np.nan)
    for i, s in enumerate(ts):
        if s <= final_t + 1e-15:
            xs[i] = state_at(float(s)) if s > 0 else x0
    res = DelaySimulation(t=ts, x=xs, outcome=outcome, event_time=None if ev_t is None
                          else float(ev_t), event_index=ev_i, final_time=final_t,
                          final_state=np.asarray(final_x, float), steps=steps,
                          warnings=tuple(warns))
    object.__setattr__(res, "_dense", np.vectorize(state_at, signature="()->(n)"))
    return res
