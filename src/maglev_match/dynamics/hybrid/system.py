"""The piecewise-smooth (hybrid) system itself: smooth vector fields joined at event surfaces.

Model-agnostic. A :class:`HybridSystem` has K *switches*, each on or off; a *mode* is the
vector s in {0, 1}^K of their states, and every mode has a smooth vector field
``rhs(x, p, s)``. Switch k toggles when its guard ``guards(x, p, s)[k]`` (positive while the
mode holds) crosses zero from above; after a toggle the state may be projected onto the new
mode's constraint surface (``project(x, p, s_new)``, e.g. a clamped current set exactly to
its bound). This covers the Filippov systems of saturations and clamps: a coil current that
may not reverse has the modes "free" (the smooth model) and "held" (current at zero, its
rate 0: the sliding vector field on i = 0), entered when i reaches 0 and left when the free
rate of the current turns positive (Filippov 1988, ch. 2; di Bernardo, Budd, Champneys &
Kowalczyk 2008, *Piecewise-smooth Dynamical Systems*, sec. 2.4).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from functools import cache
from typing import Any

import jax.numpy as jnp
import numpy as np

from maglev_match.core import jax_setup  # noqa: F401  (float64)
from maglev_match.core.reprs import compact_repr

Array = Any

__all__ = ["HybridSystem", "identity_project"]


# ---------------------------------------------------------------------------------------
# the system
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class HybridSystem:
    """A piecewise-smooth system with K two-state switches.

    rhs : ``rhs(x, p, s) -> dx/dt`` (JAX), s of shape (K,) with entries 0.0 or 1.0.
    guards : ``guards(x, p, s) -> (K,)``: switch k toggles when entry k crosses zero from
        above (entry k is positive while the current mode holds for that switch).
    project : ``project(x, p, s) -> x`` applied after a toggle into mode s (a reset map onto
        the mode's constraint surface), or None for the identity.
    n_switches : K.
    p : default parameter vector; param_names, state_names : names; state_scale : typical
        size of each state (error control and scaled norms); observables : named read-outs
        ``g(x, p)``.
    domain : ``domain(x, p, s) -> scalar``, positive where the vector field of mode s is
        regular; a run that reaches zero ends there with :attr:`FlowStatus.OUTSIDE` instead
        of grinding towards a singularity (None: everywhere).

    The functions must be stable objects (module-level or cached) so compiled kernels are
    reused.
    """

    __repr__ = compact_repr

    rhs: Callable
    guards: Callable
    n_switches: int
    p: np.ndarray
    param_names: tuple[str, ...]
    state_names: tuple[str, ...]
    project: Callable | None = None
    state_scale: np.ndarray | None = None
    observables: Mapping[str, Callable] = field(default_factory=dict)
    name: str = ""
    domain: Callable | None = None

    def __post_init__(self) -> None:
        p = np.asarray(self.p, dtype=float).ravel()
        object.__setattr__(self, "p", p)
        n = len(self.state_names)
        sc = np.ones(n) if self.state_scale is None else np.asarray(self.state_scale, float)
        object.__setattr__(self, "state_scale", sc)
        if len(self.param_names) != p.size:
            raise ValueError(f"{len(self.param_names)} parameter names for {p.size} parameters")

    @property
    def dim(self) -> int:
        return len(self.state_names)

    def param_index(self, name: str) -> int:
        return self.param_names.index(name)

    def mode_rhs(self, s: tuple[int, ...]) -> Callable:
        """The smooth vector field ``f(x, p)`` of mode ``s`` (a stable object per mode)."""
        return _mode_rhs(self.rhs, tuple(int(v) for v in s))

    def f(self, x: Array, s: Array, p: Array | None = None) -> np.ndarray:
        return np.asarray(_jit_rhs(self.rhs)(jnp.asarray(x, float), self.param_array(p),
                                             jnp.asarray(s, float)))

    def guard_values(self, x: Array, s: Array, p: Array | None = None) -> np.ndarray:
        return np.asarray(_jit_rhs(self.guards)(jnp.asarray(x, float), self.param_array(p),
                                                jnp.asarray(s, float)))

    def param_array(self, p: Array | None) -> jnp.ndarray:
        """The parameter vector ``p`` (default: the system's) as a float64 JAX array."""
        return jnp.asarray(self.p if p is None else p, jnp.float64)


@cache
def _mode_rhs(rhs: Callable, s: tuple[int, ...]) -> Callable:
    mode = np.asarray(s, float)

    def f(x, p):
        return rhs(x, p, jnp.asarray(mode))

    f.__qualname__ = f"mode_rhs_{''.join(map(str, s))}"
    return f


@cache
def _jit_rhs(fn: Callable) -> Callable:
    from maglev_match.core.aot import cached_kernel

    return cached_kernel(fn, fn, name="hybrid.pointwise")


def identity_project(x, p, s):
    """The reset of a system without a projection: the state unchanged."""
    return x

