"""A discretised delay system whose current state ends with a clock, reordered so that the
clock is the last state of the discretised state.

Nothing here knows about maglev. A periodically forced system is made autonomous by a clock
state t (t' = 1), which the periodic-response machinery expects to be the *last* state
(:mod:`maglev_match.dynamics.integrate.passage`). The pseudospectral discretisation
(:func:`~maglev_match.dynamics.delay.discretisation.discretise`) appends the history states
after the current state, so the clock would sit in the middle. :func:`clock_last` returns the
same ODE with the states permuted to (x without t, the history states, t): the right-hand
side, the names, the scales, the initial guess and the observables are those of the
discretised system, permuted; nothing else changes (the history does not read the clock's
value unless a delayed signal does, and the permutation is exact).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import cache
from typing import Any

import numpy as np

from maglev_match.dynamics.delay.discretisation import DiscretisedSystem
from maglev_match.dynamics.system import System

__all__ = ["ClockedDelaySystem", "clock_last"]


def _orders(n: int, dim: int) -> tuple[np.ndarray, np.ndarray]:
    """(new <- old, old <- new) index maps: old order (x_0..x_{n-1}, Y), new order
    (x_0..x_{n-2}, Y, x_{n-1})."""
    new_from_old = np.concatenate([np.arange(n - 1), np.arange(n, dim), [n - 1]])
    old_from_new = np.argsort(new_from_old)
    return new_from_old, old_from_new


@cache
def _clocked_rhs(rhs: Callable, n: int, dim: int) -> Callable:
    fwd, back = _orders(n, dim)

    def f(X, p):
        return rhs(X[back], p)[fwd]

    f.__name__ = f"clock_last_{getattr(rhs, '__name__', 'rhs')}"
    return f


@cache
def _clocked_observable(g: Callable, n: int, dim: int) -> Callable:
    _, back = _orders(n, dim)

    def h(X, p):
        return g(X[back], p)

    h.__name__ = getattr(g, "__name__", "observable")
    return h


@dataclass(frozen=True)
class ClockedDelaySystem(System):
    """The discretised delay system ``discretised`` with its clock moved to the end (module
    docstring). ``lift`` and ``current`` are those of the discretised system, in this
    order of the states."""

    discretised: Any = None

    @property
    def n_state(self) -> int:
        """n, the current state's dimension (clock included)."""
        return int(self.discretised.n_state)

    @property
    def nodes(self) -> int:
        return int(self.discretised.nodes)

    def to_clock_last(self, X: np.ndarray) -> np.ndarray:
        """Discretised states in the discretised system's order -> this system's order."""
        fwd, _ = _orders(self.n_state, self.dim)
        return np.asarray(X, float)[..., fwd]

    def lift(self, x: np.ndarray, p: np.ndarray | None = None) -> np.ndarray:
        """The state of a constant past x(theta) = x (``x``: the current state, n entries,
        clock last), in this system's order."""
        x = np.asarray(x, float)
        if x.shape[-1] == self.dim:
            return x
        return self.to_clock_last(self.discretised.lift(x, p))

    def current(self, X: np.ndarray) -> np.ndarray:
        """The current state (clock last) of discretised state(s) X."""
        X = np.asarray(X, float)
        return np.concatenate([X[..., : self.n_state - 1], X[..., -1:]], axis=-1)


def clock_last(disc: DiscretisedSystem, name: str | None = None) -> ClockedDelaySystem:
    """``disc`` with the history states moved before the last state of the current state
    (its clock); see the module docstring."""
    n, dim = disc.n_state, disc.dim
    fwd, _ = _orders(n, dim)
    return ClockedDelaySystem(
        rhs=_clocked_rhs(disc.rhs, n, dim), p=disc.p, param_names=disc.param_names,
        state_names=tuple(disc.state_names[i] for i in fwd),
        x_guess=np.asarray(disc.x_guess, float)[fwd],
        state_scale=np.asarray(disc.state_scale, float)[fwd],
        observables={k: _clocked_observable(g, n, dim) for k, g in disc.observables.items()},
        name=disc.name if name is None else name, param_ranges=dict(disc.param_ranges),
        discretised=disc)
