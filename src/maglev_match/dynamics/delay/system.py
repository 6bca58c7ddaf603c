"""The delay-differential system itself: its definition, its delay-free ODE and its
linearisation at an equilibrium.

Nothing here knows about maglev. A :class:`DelayDifferentialSystem` is

    x'(t) = f(x(t), y_1(t - tau_1), ..., y_K(t - tau_K), p),     y_k = g_k(x, p)  (m_k entries)

with the delays tau_k entries of the parameter vector. Only the *signals* y_k (the
quantities the equation reads late, m_k of them) need a past; a user model that reads the
whole state late has g_k(x) = x. At tau_k = 0 the delay-free ODE
x' = f(x, g_1(x), ..., g_K(x)) is the system (:meth:`DelayDifferentialSystem.ode_system`);
the equilibria do not depend on the delays.

Linearised at an equilibrium, x' = A_0 x(t) + sum_k A_k x(t - tau_k), with A_0 = df/dx and
A_k = (df/dy_k)(dg_k/dx) (:func:`delay_jacobians`), from the *argument function*
F(x(t), x(t - tau_1), ..., x(t - tau_K)) of the right-hand side
(:attr:`DelayDifferentialSystem.argument_function`). The setting is that of Bellen &
Zennaro 2003, *Numerical Methods for Delay Differential Equations*, and Michiels &
Niculescu 2014, *Stability, Control and Computation for Time-Delay Systems*.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from functools import cache

import jax
import jax.numpy as jnp
import numpy as np

from maglev_match.core import jax_setup  # noqa: F401  (float64 on)
from maglev_match.core.reprs import compact_repr
from maglev_match.dynamics.system import System

__all__ = ["DelayDifferentialSystem", "delay_jacobians"]


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
        # the signals' sizes from their shapes alone (traced, nothing compiled or run)
        sizes = tuple(int(np.prod(jax.eval_shape(g, xg, p).shape, dtype=int))
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
    from maglev_match.core.aot import cached_kernel

    return cached_kernel(jax.jacfwd(F, argnums=0), F, name="delay.argument_jacobian")


def delay_jacobians(dde: DelayDifferentialSystem, x: np.ndarray, p: np.ndarray | None = None
                    ) -> tuple[np.ndarray, tuple[np.ndarray, ...]]:
    """(A_0, (A_1, ..., A_K)): the derivatives of the right-hand side with respect to the
    state at t and at t - tau_k, at the equilibrium ``x`` (each n x n)."""
    n, K = dde.dim, len(dde.delays)
    pv = dde.p if p is None else np.asarray(p, float)
    U = np.tile(np.asarray(x, float), K + 1)
    JU = np.asarray(_argument_jacobian(dde.argument_function)(U, pv))
    return JU[:, :n], tuple(JU[:, (k + 1) * n:(k + 2) * n] for k in range(K))

