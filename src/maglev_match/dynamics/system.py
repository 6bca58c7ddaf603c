"""A model-agnostic autonomous ODE system x' = f(x, p) and its exact derivatives.

Nothing here knows about maglev. A :class:`System` bundles a JAX right-hand side
``rhs(x, p)`` (``x`` state vector, ``p`` flat parameter vector) with names for states and
parameters, typical magnitudes of the states (for scaled residuals and norms) and named
observables (functions ``g(x, p)`` such as a gap or a current, used by read-outs).

Derivatives come from automatic differentiation (never finite differences):

* ``jacobian(x, p)``            d f / d x
* ``param_derivative(x, p, k)`` d f / d p_k
* ``B(x, p, u, v)``             second derivative d^2 f / dx^2 [u, v]
* ``C(x, p, u, v, w)``          third derivative d^3 f / dx^3 [u, v, w]

``B`` and ``C`` accept complex directions (by multilinearity), as the Lyapunov-coefficient
formulas need. Compiled functions are cached per right-hand side, so building many
:class:`System` objects for the same model costs no recompilation, and exported ahead of
time (:mod:`maglev_match.aot`), so a new process does not trace them again.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from functools import cache
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from maglev_match import jax_setup  # noqa: F401  (float64 on, compilation cache)
from maglev_match.aot import cached_kernel
from maglev_match.reprs import compact_repr

Array = Any
RHS = Callable[[Array, Array], Array]

__all__ = ["System", "compiled"]


@dataclass(frozen=True)
class CompiledDerivatives:
    """Jitted functions of one right-hand side (shared by every System that uses it)."""

    f: Callable[[Array, Array], Array]
    jacobian: Callable[[Array, Array], Array]
    jacobian_batch: Callable[[Array, Array], Array]
    f_batch: Callable[[Array, Array], Array]
    param_jacobian: Callable[[Array, Array], Array]
    f_and_jacobian: Callable[[Array, Array], tuple[Array, Array]]
    B: Callable[..., Array]
    C: Callable[..., Array]


@cache
def compiled(rhs: RHS) -> CompiledDerivatives:
    """Compile f, its Jacobians and the multilinear forms B and C for ``rhs`` (cached)."""

    def second(x, p, u, v):
        def df_v(y):
            return jax.jvp(lambda z: rhs(z, p), (y,), (v,))[1]

        return jax.jvp(df_v, (x,), (u,))[1]

    def third(x, p, u, v, w):
        return jax.jvp(lambda y: second(y, p, u, v), (x,), (w,))[1]

    jac = jax.jacfwd(rhs, argnums=0)

    def kernel(fn, what):
        return cached_kernel(fn, rhs, name=f"system.{what}")

    return CompiledDerivatives(
        f=kernel(rhs, "f"),
        jacobian=kernel(jac, "jacobian"),
        jacobian_batch=kernel(jax.vmap(jac), "jacobian_batch"),
        f_batch=kernel(jax.vmap(rhs), "f_batch"),
        param_jacobian=kernel(jax.jacfwd(rhs, argnums=1), "param_jacobian"),
        f_and_jacobian=kernel(lambda x, p: (rhs(x, p), jac(x, p)), "f_and_jacobian"),
        B=kernel(second, "B"),
        C=kernel(third, "C"),
    )


@cache
def _observable_single(g: Callable) -> Callable:
    return cached_kernel(g, g, name="system.observable")


@cache
def _observable_gradient(g: Callable) -> Callable:
    return cached_kernel(jax.jacfwd(g, argnums=0), g, name="system.observable_gradient")


@cache
def _observable_batch(g: Callable) -> Callable:
    return cached_kernel(jax.vmap(g, in_axes=(0, None)), g, name="system.observable_batch")


def _split(z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    z = np.asarray(z)
    return np.real(z).astype(float), np.imag(z).astype(float)


@dataclass(frozen=True)
class System:
    """An autonomous ODE ``x' = rhs(x, p)`` with named states and parameters.

    Parameters
    ----------
    rhs : pure JAX function ``(x, p) -> dx/dt`` (float64 arrays).
    p : default parameter vector (1-D), in the order of ``param_names``.
    param_names : names of the entries of ``p``.
    state_names : names of the states.
    x_guess : a starting guess for the equilibrium (defaults to zeros).
    state_scale : typical magnitude of each state (for scaled residuals and norms).
    observables : named functions ``g(x, p)`` (scalar or 1-D) for read-outs.
    name : a label for reports.
    param_ranges : optional valid range (lo, hi) of some parameters (e.g. a frequency
        must be positive); solvers reject solutions outside them.
    """

    __repr__ = compact_repr

    rhs: RHS
    p: np.ndarray
    param_names: tuple[str, ...]
    state_names: tuple[str, ...]
    x_guess: np.ndarray | None = None
    state_scale: np.ndarray | None = None
    observables: Mapping[str, Callable[[Array, Array], Array]] = field(default_factory=dict)
    name: str = ""
    param_ranges: Mapping[str, tuple[float, float]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        p = np.asarray(self.p, dtype=float).ravel()
        object.__setattr__(self, "p", p)
        if len(self.param_names) != p.size:
            raise ValueError(f"{len(self.param_names)} parameter names for {p.size} parameters")
        n = len(self.state_names)
        xg = np.zeros(n) if self.x_guess is None else np.asarray(self.x_guess, dtype=float)
        if xg.shape != (n,):
            raise ValueError(f"x_guess has shape {xg.shape}, expected ({n},)")
        object.__setattr__(self, "x_guess", xg)
        sc = np.ones(n) if self.state_scale is None else np.asarray(self.state_scale, float)
        object.__setattr__(self, "state_scale", sc)

    # ----- parameters ------------------------------------------------------------------
    @property
    def dim(self) -> int:
        return len(self.state_names)

    def param_index(self, name: str) -> int:
        try:
            return self.param_names.index(name)
        except ValueError:
            raise KeyError(
                f"system '{self.name}' has no parameter '{name}'; it has: "
                + ", ".join(self.param_names)
            ) from None

    def param(self, name: str, p: np.ndarray | None = None) -> float:
        return float((self.p if p is None else p)[self.param_index(name)])

    def params_with(self, p: np.ndarray | None = None, **values: float) -> np.ndarray:
        """A copy of the parameter vector with some entries changed by name."""
        q = np.array(self.p if p is None else p, dtype=float)
        for k, v in values.items():
            q[self.param_index(k)] = v
        return q

    def with_params(self, **values: float) -> System:
        return dataclasses.replace(self, p=self.params_with(**values))

    # ----- evaluation ------------------------------------------------------------------
    @property
    def derivatives(self) -> CompiledDerivatives:
        return compiled(self.rhs)

    def _p(self, p: np.ndarray | None) -> jnp.ndarray:
        return jnp.asarray(self.p if p is None else p, dtype=jnp.float64)

    def f(self, x: Array, p: np.ndarray | None = None) -> np.ndarray:
        return np.asarray(self.derivatives.f(jnp.asarray(x, jnp.float64), self._p(p)))

    def jacobian(self, x: Array, p: np.ndarray | None = None) -> np.ndarray:
        """d f / d x at (x, p), exact (forward-mode autodiff)."""
        return np.asarray(self.derivatives.jacobian(jnp.asarray(x, jnp.float64), self._p(p)))

    def param_jacobian(self, x: Array, p: np.ndarray | None = None) -> np.ndarray:
        """d f / d p at (x, p): shape (dim, n_params)."""
        return np.asarray(
            self.derivatives.param_jacobian(jnp.asarray(x, jnp.float64), self._p(p))
        )

    def param_derivative(self, x: Array, p: np.ndarray | None, name: str) -> np.ndarray:
        """d f / d p_name at (x, p)."""
        return self.param_jacobian(x, p)[:, self.param_index(name)]

    def B(self, x: Array, p: np.ndarray | None, u: Array, v: Array) -> np.ndarray:
        """Second derivative d^2 f/dx^2 [u, v] at (x, p); u, v may be complex."""
        d = self.derivatives.B
        xj, pj = jnp.asarray(x, jnp.float64), self._p(p)
        ur, ui = _split(u)
        vr, vi = _split(v)

        def b(a, c):
            return np.asarray(d(xj, pj, jnp.asarray(a), jnp.asarray(c)))

        re = b(ur, vr)
        if not (ui.any() or vi.any()):
            return re
        return re - b(ui, vi) + 1j * (b(ur, vi) + b(ui, vr))

    def C(self, x: Array, p: np.ndarray | None, u: Array, v: Array, w: Array) -> np.ndarray:
        """Third derivative d^3 f/dx^3 [u, v, w] at (x, p); u, v, w may be complex."""
        d = self.derivatives.C
        xj, pj = jnp.asarray(x, jnp.float64), self._p(p)
        parts = [_split(a) for a in (u, v, w)]
        total = np.zeros(self.dim, dtype=complex)
        # expand the trilinear form over real and imaginary parts
        for su in (0, 1):
            for sv in (0, 1):
                for sw in (0, 1):
                    a, b, c = parts[0][su], parts[1][sv], parts[2][sw]
                    if not (a.any() and b.any() and c.any()):
                        continue
                    val = np.asarray(d(xj, pj, jnp.asarray(a), jnp.asarray(b), jnp.asarray(c)))
                    total += (1j ** (su + sv + sw)) * val
        if not np.iscomplexobj(u) and not np.iscomplexobj(v) and not np.iscomplexobj(w):
            return total.real
        return total

    def observe(self, name: str, x: Array, p: np.ndarray | None = None) -> np.ndarray:
        """Evaluate a named observable at one state or at a batch of states (rows)."""
        if name not in self.observables:
            raise KeyError(f"system '{self.name}' has no observable '{name}'; it has: "
                           + ", ".join(self.observables))
        g = self.observables[name]
        x = jnp.asarray(x, jnp.float64)
        pj = self._p(p)
        if x.ndim == 1:
            return np.asarray(_observable_single(g)(x, pj))
        return np.asarray(_observable_batch(g)(x, pj))

    def observable_gradient(self, name: str, x: Array, p: np.ndarray | None = None
                            ) -> np.ndarray:
        """d g / d x of a named observable at one state (exact, forward-mode autodiff):
        shape (dim,) for a scalar observable, (k, dim) for one with k components."""
        if name not in self.observables:
            raise KeyError(f"system '{self.name}' has no observable '{name}'; it has: "
                           + ", ".join(self.observables))
        g = _observable_gradient(self.observables[name])
        return np.asarray(g(np.asarray(x, np.float64),
                            np.asarray(self.p if p is None else p, np.float64)))

    def f_and_jacobian(self, x: Array, p: np.ndarray | None = None
                       ) -> tuple[np.ndarray, np.ndarray]:
        """f(x, p) and d f / d x in one compiled call."""
        fx, J = self.derivatives.f_and_jacobian(np.asarray(x, float),
                                                np.asarray(self.p if p is None else p, float))
        return np.asarray(fx), np.asarray(J)

    def residual_scale(self, J: np.ndarray) -> np.ndarray:
        """Per-equation scale sum_j |J_ij| scale_j used by :meth:`scaled_residual`."""
        denom = np.abs(J) @ self.state_scale
        return np.where(denom > 0, denom, 1.0)

    def scaled_residual(self, x: Array, p: np.ndarray | None = None) -> float:
        """max_i |f_i(x)| / sum_j |J_ij| scale_j: a dimensionless size of the residual."""
        fx, J = self.f_and_jacobian(x, p)
        return float(np.max(np.abs(fx) / self.residual_scale(J)))
