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
time (:mod:`maglev_match.core.aot`), so a new process does not trace them again.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from functools import cache
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from maglev_match.core import jax_setup  # noqa: F401  (float64 on, compilation cache)
from maglev_match.core.aot import cached_kernel
from maglev_match.core.jax_setup import kernel_arg
from maglev_match.core.reprs import compact_repr

Array = Any
RHS = Callable[[Array, Array], Array]

__all__ = ["System", "RegularChart", "chart_kernels", "compiled"]


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
class RegularChart:
    """Coordinates y = phi(x, p) in which a vector field that is singular on some set of
    states stays smooth: the same dynamics, written so that numerical methods keep their
    accuracy near that set.

    Example (model A of the maglev package): the magnet force K (i / c)^2 / 2 and the
    induction term (i / c) c' make the vector field singular at gap c = 0, but along every
    trajectory the ratio r = i / c obeys a smooth equation (flux linkage), so a periodic
    orbit that reaches c = 0 passes it with i = 0 at the same instant. In (c, i) a
    collocation polynomial cannot keep i / c bounded there (its zeros of i and c do not
    coincide), Newton's matrices grow like 1 / c and the Floquet multipliers lose their
    accuracy; in (c, r) nothing is singular. A branch of cycles changes to the chart when
    an orbit comes within ``switch_below`` of the singular set (in the units of
    ``distance``) and reports its orbits back in the original coordinates.

    Parameters
    ----------
    rhs : the vector field in chart coordinates, y' = rhs(y, p) (pure JAX).
    to_chart, from_chart : y = phi(x, p) and its inverse x = phi^{-1}(y, p) (pure JAX, one
        state; they may depend on the parameters).
    distance : d(x, p), a scalar that measures how far the original coordinates are from
        their singular set (model A: c / c0, the gap over the rated gap).
    state_scale : typical magnitudes of the chart's states.
    switch_below : change to the chart when an orbit's smallest ``distance`` falls below.
    """

    rhs: RHS
    to_chart: Callable[[Array, Array], Array]
    from_chart: Callable[[Array, Array], Array]
    distance: Callable[[Array, Array], Array]
    state_scale: np.ndarray
    switch_below: float = 0.05

    def __hash__(self) -> int:  # functions and the threshold identify the chart
        return hash((self.rhs, self.to_chart, self.from_chart, self.distance,
                     self.switch_below))

    def __eq__(self, other: object) -> bool:
        return isinstance(other, RegularChart) and hash(self) == hash(other) and \
            np.array_equal(self.state_scale, other.state_scale)


@cache
def chart_kernels(chart: RegularChart) -> dict[str, Callable]:
    """Compiled maps of a chart over the nodes of an orbit (rows of a (N, n) array):
    ``to`` / ``from`` the states, ``to_tangent`` / ``from_tangent`` a tangent (states and
    the direction of the parameter vector, by forward-mode differentiation: the chart may
    depend on the parameters) and ``distance`` at every node."""

    def to_t(X, V, p, dp):
        return jax.vmap(lambda x, v: jax.jvp(chart.to_chart, (x, p), (v, dp)), (0, 0))(X, V)

    def from_t(Y, W, p, dp):
        return jax.vmap(lambda y, w: jax.jvp(chart.from_chart, (y, p), (w, dp)), (0, 0))(Y, W)

    statics = (chart.rhs, chart.to_chart, chart.from_chart, chart.distance)
    return {
        "to": cached_kernel(jax.vmap(chart.to_chart, (0, None)), *statics, name="chart.to"),
        "from": cached_kernel(jax.vmap(chart.from_chart, (0, None)), *statics,
                              name="chart.from"),
        "to_tangent": cached_kernel(to_t, *statics, name="chart.to_tangent"),
        "from_tangent": cached_kernel(from_t, *statics, name="chart.from_tangent"),
        "distance": cached_kernel(jax.vmap(chart.distance, (0, None)), *statics,
                                  name="chart.distance"),
    }


def _compose(g: Callable, from_chart: Callable) -> Callable:
    def composed(y, p):
        return g(from_chart(y, p), p)

    composed.__qualname__ = f"{getattr(g, '__qualname__', 'g')}_in_chart"
    return composed


@cache
def _composed_observable(g: Callable, from_chart: Callable) -> Callable:
    return _compose(g, from_chart)


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
        must be positive); solvers reject solutions outside them, and a Newton iteration or
        a continuation that leaves them stops there, reported as not converged.
    chart : optional :class:`RegularChart`, coordinates in which ``rhs`` stays smooth where
        it is singular (used by the continuation of cycles near that set).
    param_units : optional units of the parameters (for read-outs and files).
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
    chart: RegularChart | None = None
    param_units: Mapping[str, str] = field(default_factory=dict)

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

    def range_violation(self, name: str, value: float) -> str:
        """'' when ``value`` lies in the declared valid range of parameter ``name`` (or it has
        none), else a sentence naming the parameter, the value and the range, e.g.
        "omega1 = -1.83 lies outside its valid range (0, 1e+05]". A positive quantity
        declares its lower bound as the smallest positive double (printed "(0")."""
        rng = self.param_ranges.get(name)
        if rng is None:
            return ""
        lo, hi = float(rng[0]), float(rng[1])
        if lo <= value <= hi:
            return ""
        left = "(0" if lo == math.ulp(0.0) else f"[{lo:g}"
        right = "1)" if hi == math.nextafter(1.0, 0.0) else f"{hi:g}]"
        return f"{name} = {value:.6g} lies outside its valid range {left}, {right}"

    def valid_bounds(self, name: str, bounds: tuple[float, float] | None = None
                     ) -> tuple[float, float] | None:
        """The intersection of ``bounds`` (lo, hi; None: none) with the declared valid
        range of ``name``: the interval a continuation in ``name`` may not leave."""
        rng = self.param_ranges.get(name)
        if rng is None:
            return None if bounds is None else (float(min(bounds)), float(max(bounds)))
        lo, hi = float(rng[0]), float(rng[1])
        if bounds is not None:
            lo, hi = max(lo, float(min(bounds))), min(hi, float(max(bounds)))
        return lo, hi

    def in_chart(self) -> System:
        """The same system in the coordinates of its :class:`RegularChart`: the chart's
        vector field, scales and guess, and every observable composed with the inverse map
        (so an observable means the same quantity in both). The system itself when it has
        no chart."""
        ch = self.chart
        if ch is None:
            return self
        xg = np.asarray(ch.to_chart(jnp.asarray(self.x_guess), jnp.asarray(self.p)), float)
        return dataclasses.replace(
            self, rhs=ch.rhs, x_guess=xg, state_scale=np.asarray(ch.state_scale, float),
            observables={k: _composed_observable(g, ch.from_chart)
                         for k, g in self.observables.items()},
            name=f"{self.name} (regular chart)", chart=None)

    # ----- evaluation ------------------------------------------------------------------
    @property
    def derivatives(self) -> CompiledDerivatives:
        return compiled(self.rhs)

    def _p(self, p: np.ndarray | None) -> Any:
        # host data as it is (kernel_arg): the kernels' call moves it to the device on its
        # fast path, without jnp.asarray's staging program
        return kernel_arg(self.p if p is None else p, np.float64)

    def f(self, x: Array, p: np.ndarray | None = None) -> np.ndarray:
        return np.asarray(self.derivatives.f(kernel_arg(x, np.float64), self._p(p)))

    def jacobian(self, x: Array, p: np.ndarray | None = None) -> np.ndarray:
        """d f / d x at (x, p), exact (forward-mode autodiff)."""
        return np.asarray(self.derivatives.jacobian(kernel_arg(x, np.float64), self._p(p)))

    def param_jacobian(self, x: Array, p: np.ndarray | None = None) -> np.ndarray:
        """d f / d p at (x, p): shape (dim, n_params)."""
        return np.asarray(
            self.derivatives.param_jacobian(kernel_arg(x, np.float64), self._p(p))
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
