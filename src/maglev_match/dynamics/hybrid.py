"""Piecewise-smooth (hybrid) systems: smooth vector fields joined at event surfaces.

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

Three things are computed here:

* **The flow with forward sensitivities** (:func:`hybrid_flow`): x(t) and
  Phi(t) = dx(t)/dtheta for chosen directions theta (initial-state directions and parameter
  directions), integrated as one augmented system ``x' = f, Phi' = f_x Phi + f_p P`` by the
  Dormand-Prince 8(5,3) pair (Hairer, Norsett & Wanner, *Solving ODEs I*, sec. II.5, II.10;
  the tableau of :mod:`diffrax`) with step-size control on x and Phi together. At a switch
  the event time is located by the Illinois method on single Runge-Kutta steps from the
  start of the step (so to the integrator's own accuracy, not to an interpolant's), and the
  sensitivities jump by the saltation matrix (Aizerman & Gantmakher 1958; Leine &
  Nijmeijer 2004, *Dynamics and Bifurcations of Non-smooth Mechanical Systems*, sec. 3.5;
  di Bernardo et al. 2008, sec. 2.5). With the reset R (the projection), the guard h and
  the fields f- before and f+ after the switch::

      Phi+ = R_x Phi- + R_p P + (f+ - R_x f-) (h_x Phi- + h_p P) / (h_x f-)

  (the state part R_x + (f+ - R_x f-) h_x / (h_x f-) is the saltation matrix; the P terms
  carry parameter directions). A run can end at a *stop*: the first downward zero of
  ``a . f(x) + b . x + c`` after the run starts (an extremum of a linear observable w . x
  with a = +-w, or a hyperplane section with a = 0).
* **Periodic orbits by collocation per segment** (:func:`hybrid_periodic_orbit`): an orbit
  visiting the modes s_0, ..., s_{S-1} is S segments u_i'(tau) = T_i f(u_i, p, s_i) on
  tau in [0, 1], each by orthogonal collocation on its own mesh (the Gauss points, Lagrange
  basis and collocation kernel of :mod:`maglev_match.dynamics.collocation`), joined by the
  boundary conditions of COCO's 'hspo' toolbox (Dankowicz & Schilder 2013, *Recipes for
  Continuation*, sec. 9.3 and 17.2): each segment ends on the event surface of its switch,
  h_{k_i}(u_i(1)) = 0, and the next starts at the reset image,
  u_{i+1}(0) = R(u_i(1)) (circularly). The event conditions fix the phase, so no phase
  condition is needed; the unknowns are the node values and the durations T_i, solved by
  Newton's method on the sparse system.
* **Floquet multipliers of a hybrid orbit**: of the monodromy matrix
  M = S_{S-1} Phi_{S-1} ... S_0 Phi_0, with Phi_i the fundamental matrix of segment i (from
  its collocation blocks: the condensed end-point relations of
  :func:`~maglev_match.dynamics.floquet.condensed_pairs`) and S_i the saltation matrix at
  the end of segment i; the eigenvalues of the formal product by the periodic Schur
  algorithm of :func:`~maglev_match.dynamics.floquet.periodic_eigenvalues`. A sliding
  segment entered through a projection makes one multiplier exactly 0.

:func:`shoot_hybrid_orbit` computes the same orbits by single shooting on the flow (Newton on
the return to a section, with the sensitivities above): an independent method, used to start
the collocation and to check it.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from enum import IntEnum
from functools import cache, lru_cache
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import scipy.sparse
import scipy.sparse.linalg

from maglev_match.core import jax_setup  # noqa: F401  (float64)
from maglev_match.core.aot import cached_kernel
from maglev_match.core.reprs import compact_repr
from maglev_match.dynamics.collocation import node_times

Array = Any

__all__ = [
    "HybridSystem",
    "FlowOptions",
    "FlowStatus",
    "LinearStop",
    "HybridFlow",
    "hybrid_flow",
    "Segment",
    "HybridOrbit",
    "hybrid_periodic_orbit",
    "shoot_hybrid_orbit",
    "hybrid_floquet",
    "HybridFloquet",
    "ShotOrbit",
    "saltation_matrix",
    "segments_from_flow",
    "orbit_parameter_derivative",
]


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
        return np.asarray(_jit_rhs(self.rhs)(jnp.asarray(x, float), self._p(p),
                                             jnp.asarray(s, float)))

    def guard_values(self, x: Array, s: Array, p: Array | None = None) -> np.ndarray:
        return np.asarray(_jit_rhs(self.guards)(jnp.asarray(x, float), self._p(p),
                                                jnp.asarray(s, float)))

    def _p(self, p: Array | None) -> jnp.ndarray:
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
    return jax.jit(fn)


def _identity_project(x, p, s):
    return x


def _whole_space(x, p, s):
    return jnp.ones((), x.dtype)


# ---------------------------------------------------------------------------------------
# the flow with sensitivities
# ---------------------------------------------------------------------------------------
class FlowStatus(IntEnum):
    """How a run of :func:`hybrid_flow` ended."""

    RUNNING = 0  # (inside the kernel only)
    REACHED = 1  # reached the end time
    STOPPED = 2  # ended at the stop condition
    FAILED = 3  # step budget exhausted, non-finite state or step size underflow
    OUTSIDE = 4  # left the system's domain (e.g. approached a singularity of the field)


@dataclass(frozen=True)
class FlowOptions:
    """Integrator settings of :func:`hybrid_flow`.

    rtol, atol : relative and absolute tolerance (absolute in units of ``state_scale``;
        the sensitivities are scaled per column to order one); h0 : first step (s);
    max_steps : bound on attempted steps per call; max_switches : switch events recorded
        per run (all are handled; only the first ones are returned).
    """

    rtol: float = 1e-10
    atol: float = 1e-10
    h0: float = 1e-4
    max_steps: int = 100_000
    max_switches: int = 64

    def __post_init__(self) -> None:
        for name in ("rtol", "atol", "h0"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"FlowOptions.{name} = {v!r}: must be a positive number")
        if self.max_steps < 1 or self.max_switches < 1:
            raise ValueError("FlowOptions.max_steps and max_switches must be at least 1")


@dataclass(frozen=True)
class LinearStop:
    """Stop condition q(x) = a . f(x, p, s) + b . x + c: a run ends at the first zero of q
    crossed from above after its start (a zero at the start does not count).

    Examples: the maximum of a linear observable w . x is ``LinearStop(a=w)`` (its rate
    turns negative), a minimum ``LinearStop(a=-w)``; the hyperplane n . (x - x_s) = 0
    crossed in the direction n is ``LinearStop(b=-n, c=n . x_s)``.
    """

    a: np.ndarray | None = None
    b: np.ndarray | None = None
    c: Any = 0.0

    def arrays(self, n: int, batch: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(a, b, c) broadcast to the runs of a batch: (B, n), (B, n), (B,). ``a``, ``b``
        may be given per run as (B, n), ``c`` as (B,)."""
        def rows(v):
            v = np.zeros(n) if v is None else np.asarray(v, float)
            if v.shape[-1] != n:
                raise ValueError(f"LinearStop: a and b must have {n} entries per run")
            return np.broadcast_to(v, (batch, n)).copy()

        return rows(self.a), rows(self.b), np.broadcast_to(np.asarray(self.c, float),
                                                           (batch,)).copy()


@dataclass(frozen=True)
class HybridFlow:
    """Result of :func:`hybrid_flow` (leading axis: the runs of a batch).

    t : final time (s); x : final state; phi : dx(t)/dtheta for each column theta of the
        directions, shape (B, n, k), in the units of the state per unit of the column;
    s : final mode; status : :class:`FlowStatus` codes;
    switch_times, switch_index : the first switch events (time, switch k; -1 unused);
    n_switches : number of switches; steps : attempted steps; saved : states at the
        requested save times (B, S, n), NaN where not reached, or None.
    """

    __repr__ = compact_repr

    t: np.ndarray
    x: np.ndarray
    phi: np.ndarray
    s: np.ndarray
    status: np.ndarray
    switch_times: np.ndarray
    switch_index: np.ndarray
    n_switches: np.ndarray
    steps: np.ndarray
    saved: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.t)


#: sensitivity columns are padded to 1 or a multiple of this (few compiled kernels)
COLUMN_BUCKET = 32
#: save times are padded to a multiple of this
SAVE_BUCKET = 512


def _column_bucket(k: int) -> int:
    return 1 if k <= 1 else COLUMN_BUCKET * (-(-k // COLUMN_BUCKET))


@cache
def _dopri8_tableau() -> tuple[np.ndarray, np.ndarray]:
    """The Dormand-Prince 8(5,3) coefficients (A padded to a square, error weights), taken
    from :mod:`diffrax` (first-same-as-last: the last stage's point is the solution)."""
    import diffrax

    tab = diffrax.Dopri8().tableau
    n_stages = len(tab.a_lower) + 1
    A = np.zeros((n_stages, n_stages))
    for i, row in enumerate(tab.a_lower):
        A[i + 1, : i + 1] = row
    return A, np.asarray(tab.b_error, float)


def _rk_step(f: Callable, y0, f0, h):
    """One step of the Dormand-Prince 8(5,3) pair (Hairer, Norsett & Wanner, *Solving ODEs
    I*, sec. II.5 and II.10) for batched states y0 (B, N) with per-run steps h (B,), as a
    loop over the stages (the field is traced once, which keeps the compiled kernel small).

    Returns (y1, error estimate, f(y1))."""
    A, b_err = _dopri8_tableau()
    S = A.shape[0]
    Aj = jnp.asarray(A)
    hk = h[:, None]
    K0 = jnp.zeros((S,) + y0.shape, y0.dtype).at[0].set(f0 * hk)

    def stage(i, carry):
        K, _, _ = carry
        yi = y0 + jnp.tensordot(Aj[i], K, axes=1)
        fi = f(yi)
        return K.at[i].set(fi * hk), yi, fi

    K, y1, f1 = jax.lax.fori_loop(1, S, stage, (K0, y0, f0))
    err = jnp.tensordot(jnp.asarray(b_err), K, axes=1)
    return y1, err, f1


@lru_cache(maxsize=32)
def _flow_kernel(rhs: Callable, guards: Callable, project: Callable, domain: Callable, k: int,
                 n_save: int, max_switches: int):
    """The batched flow kernel (arrays carry the runs on their leading axis; the loop is not
    vmapped, so locating an event is a real branch, taken when any run needs it).

    One loop iteration attempts one step of the augmented system. When an accepted step
    crosses an event surface, the step is not taken: the crossing is located by the Illinois
    method on x-only Runge-Kutta steps from the step's start, and the next iteration takes
    exactly the step to the crossing ("landing"), where the switch (or the stop) is applied.
    """

    def kernel(z0, Z0, s0, p, Pd, sc, t0, t1, stop_a, stop_b, stop_c, t_save, rtol, atol,
               h0, max_steps):
        B, n = z0.shape
        K = s0.shape[1]
        n_ev = K + 2  # the guards, the stop condition, the domain
        tiny = 64.0 * jnp.finfo(jnp.float64).eps
        rows = jnp.arange(B)

        def f_one(z, pp, s):
            return rhs(z * sc, pp, s) / sc

        def aug_one(y, pp, s, P):
            z = y[:n]
            x = z * sc
            fx = rhs(x, pp, s) / sc
            if k == 0:
                return fx
            Z = y[n:].reshape(n, k)

            def tangent(dx, dp):
                return jax.jvp(lambda xx, qq: rhs(xx, qq, s), (x, pp), (dx, dp))[1]

            T = jax.vmap(tangent, in_axes=(1, 1), out_axes=1)(Z * sc[:, None], P)
            return jnp.concatenate([fx, (T / sc[:, None]).ravel()])

        aug = jax.vmap(aug_one)
        fx_b = jax.vmap(f_one)

        def events_one(z, pp, s, a, b, c):
            x = z * sc
            q = a @ rhs(x, pp, s) + b @ x + c
            return jnp.concatenate([guards(x, pp, s), q[None],
                                    jnp.reshape(domain(x, pp, s), (1,))])

        events = jax.vmap(events_one)

        def switch_one(y, pp, s, P, j):
            """Toggle switch j at the state y (on its surface): reset and saltation."""
            x = y[:n] * sc
            s_new = s.at[j].set(1.0 - s[j])
            Rx, Rp = jax.jacfwd(project, argnums=(0, 1))(x, pp, s_new)
            x_new = project(x, pp, s_new)
            f_old = rhs(x, pp, s)
            f_new = rhs(x_new, pp, s_new)
            hx, hp = jax.grad(lambda xx, qq: guards(xx, qq, s)[j], argnums=(0, 1))(x, pp)
            denom = hx @ f_old
            denom = jnp.where(jnp.abs(denom) > 0, denom, 1e-300)
            z_new = x_new / sc
            if k == 0:
                return z_new, s_new
            Phi = y[n:].reshape(n, k) * sc[:, None]
            lead = hx @ Phi + hp @ P  # (k,)
            Phi_new = Rx @ Phi + Rp @ P + jnp.outer(f_new - Rx @ f_old, lead / denom)
            return jnp.concatenate([z_new, (Phi_new / sc[:, None]).ravel()]), s_new

        switch = jax.vmap(switch_one)

        y0 = z0 if k == 0 else jnp.concatenate([z0, Z0.reshape(B, n * k)], axis=1)
        E0 = events(z0, p, s0, stop_a, stop_b, stop_c)
        carry = dict(
            t=t0, y=y0, f0=aug(y0, p, s0, Pd), h=h0, s=s0,
            status=jnp.where(t1 > t0, FlowStatus.RUNNING, FlowStatus.REACHED).astype(int),
            ready=E0 > 0, landing=jnp.zeros(B, bool), h_land=jnp.zeros(B),
            j_land=jnp.zeros(B, int),
            nsw=jnp.zeros(B, int), swt=jnp.full((B, max_switches), jnp.nan),
            swk=jnp.full((B, max_switches), -1), steps=jnp.zeros(B, int),
            isave=jnp.zeros(B, int),
            ys=jnp.full((B, max(n_save, 1), n), jnp.nan),
        )

        def cond(c):
            return jnp.any(c["status"] == FlowStatus.RUNNING)

        def body(c):
            active = c["status"] == FlowStatus.RUNNING
            t, y, f0, s = c["t"], c["y"], c["f0"], c["s"]
            landing = active & c["landing"]
            hh = jnp.minimum(c["h"], t1 - t)
            pending = jnp.zeros(B, bool)
            ns = t1
            if n_save:
                ns = jnp.take_along_axis(t_save, jnp.minimum(c["isave"], n_save - 1)[:, None],
                                         axis=1)[:, 0]
                pending = c["isave"] < n_save
                hh = jnp.where(pending & (ns > t), jnp.minimum(hh, ns - t), hh)
            hh = jnp.where(landing, c["h_land"], hh)
            hh = jnp.where(active, jnp.maximum(hh, 0.0), 0.0)
            y1, err, f1 = _rk_step(lambda yy: aug(yy, p, s, Pd), y, f0, hh)
            wt = atol + rtol * jnp.maximum(jnp.abs(y), jnp.abs(y1))
            en = jnp.sqrt(jnp.mean((err / wt) ** 2, axis=1))
            finite = jnp.all(jnp.isfinite(y1), axis=1) & jnp.isfinite(en)
            # a landing step is a part of a step already accepted: taken as it is
            accept = active & finite & ((en <= 1.0) | landing)
            fac = jnp.clip(0.9 * jnp.where(en > 0, en, 1e-300) ** (-1.0 / 8.0), 0.2, 5.0)
            h_next = jnp.where(finite, hh * fac, hh * 0.25)
            E1 = events(y1[:, :n], p, s, stop_a, stop_b, stop_c)
            cross = (accept & ~landing)[:, None] & c["ready"] & (E1 < 0)
            hit = jnp.any(cross, axis=1)

            def locate(_):
                f0x = f0[:, :n]
                z = y[:, :n]

                def m_of(theta):
                    zt = _rk_step(lambda zz: fx_b(zz, p, s), z, f0x, theta * hh)[0]
                    Et = events(zt, p, s, stop_a, stop_b, stop_c)
                    return jnp.min(jnp.where(c["ready"], Et, jnp.inf), axis=1)

                def ill(_, st):
                    a, fa, b, fb = st
                    den = fb - fa
                    ok = den != 0
                    cc = jnp.where(ok, (a * fb - b * fa) / jnp.where(ok, den, 1.0),
                                   0.5 * (a + b))
                    cc = jnp.clip(cc, jnp.minimum(a, b), jnp.maximum(a, b))
                    fc = m_of(cc)
                    same = jnp.sign(fc) == jnp.sign(fb)
                    return (jnp.where(same, a, b), jnp.where(same, fa / 2.0, fb), cc, fc)

                E_start = events(z, p, s, stop_a, stop_b, stop_c)
                fa = jnp.min(jnp.where(c["ready"], E_start, jnp.inf), axis=1)
                fb = jnp.min(jnp.where(c["ready"], E1, jnp.inf), axis=1)
                a, fa, b, fb = jax.lax.fori_loop(
                    0, 40, ill, (jnp.zeros(B), fa, jnp.ones(B), fb))
                theta = jnp.where(jnp.abs(fa) < jnp.abs(fb), a, b)
                zt = _rk_step(lambda zz: fx_b(zz, p, s), z, f0x, theta * hh)[0]
                Et = events(zt, p, s, stop_a, stop_b, stop_c)
                j = jnp.argmin(jnp.where(c["ready"], Et, jnp.inf), axis=1)
                return theta, j

            theta, j = jax.lax.cond(jnp.any(hit), locate,
                                    lambda _: (jnp.ones(B), jnp.zeros(B, int)), None)
            # the event is applied where a landing step was taken
            jl = c["j_land"]
            is_stop = landing & (jl == K)
            is_out = landing & (jl == K + 1)
            is_switch = landing & (jl < K)
            jj = jnp.minimum(jl, K - 1)
            y_sw, s_sw = switch(y1, p, s, Pd, jj)
            move = accept & ~hit
            y_new = jnp.where(is_switch[:, None], y_sw, jnp.where(move[:, None], y1, y))
            s_new = jnp.where(is_switch[:, None], s_sw, s)
            t_new = jnp.where(move, t + hh, t)
            f_new = jnp.where(is_switch[:, None], aug(y_new, p, s_new, Pd),
                              jnp.where(move[:, None], f1, f0))
            # an event counts only after its function was seen positive; a toggled switch
            # waits until its new guard has left zero
            E_end = events(y_new[:, :n], p, s_new, stop_a, stop_b, stop_c)
            ready = c["ready"] | (move[:, None] & ~is_switch[:, None] & (E_end > 0))
            toggled = is_switch[:, None] & (jnp.arange(n_ev)[None, :] == jj[:, None])
            ready = jnp.where(toggled, False, ready)
            slot = jnp.minimum(c["nsw"], max_switches - 1)
            rec = is_switch & (c["nsw"] < max_switches)
            swt = c["swt"].at[rows, slot].set(jnp.where(rec, t_new, c["swt"][rows, slot]))
            swk = c["swk"].at[rows, slot].set(jnp.where(rec, jj, c["swk"][rows, slot]))
            nsw = c["nsw"] + is_switch.astype(int)
            ys, isave = c["ys"], c["isave"]
            if n_save:
                at_save = (move & pending
                           & (jnp.abs(t_new - ns) <= tiny * (1.0 + jnp.abs(ns))))
                slot_s = jnp.minimum(isave, n_save - 1)
                ys = ys.at[rows, slot_s].set(jnp.where(at_save[:, None], y_new[:, :n] * sc,
                                                       ys[rows, slot_s]))
                isave = isave + at_save.astype(int)
            steps = c["steps"] + active.astype(int)
            done = move & (t_new >= t1 - tiny * (1.0 + jnp.abs(t1)))
            under = active & ~accept & (hh <= tiny * (1.0 + jnp.abs(t)))
            status = jnp.where(is_stop, FlowStatus.STOPPED, c["status"])
            status = jnp.where(is_out, FlowStatus.OUTSIDE, status)
            status = jnp.where(done & ~is_stop & ~is_out, FlowStatus.REACHED, status)
            status = jnp.where(active & ((steps >= max_steps) | under), FlowStatus.FAILED,
                               status)
            h_after = jnp.where(landing | hit, jnp.maximum(c["h"], hh), h_next)
            return dict(t=t_new, y=y_new, f0=f_new, h=jnp.where(active, h_after, c["h"]),
                        s=s_new, status=status, ready=ready,
                        landing=hit, h_land=theta * hh,
                        j_land=jnp.where(hit, j, c["j_land"]),
                        nsw=nsw, swt=swt, swk=swk, steps=steps, isave=isave, ys=ys)

        c = jax.lax.while_loop(cond, body, carry)
        y = c["y"]
        x = y[:, :n] * sc
        Phi = (y[:, n:].reshape(B, n, k) * sc[None, :, None]) if k else jnp.zeros((B, n, 0))
        return dict(t=c["t"], x=x, phi=Phi, s=c["s"], status=c["status"], swt=c["swt"],
                    swk=c["swk"], nsw=c["nsw"], steps=c["steps"], ys=c["ys"])

    return cached_kernel(kernel, rhs, guards, project, domain, k, n_save, max_switches,
                         name="hybrid.flow")


def hybrid_flow(
    hs: HybridSystem,
    x0: Array,
    t_end: Array,
    *,
    s0: Array | None = None,
    p: Array | None = None,
    t_start: Array = 0.0,
    tangents: Array | None = None,
    param_tangents: Array | None = None,
    stop: LinearStop | None = None,
    t_save: Array | None = None,
    options: FlowOptions | None = None,
) -> HybridFlow:
    """Integrate the hybrid system from ``x0`` in mode ``s0`` over [t_start, t_end] (s),
    with forward sensitivities.

    Parameters
    ----------
    hs : the system.
    x0 : initial state(s), (n,) or (B, n).
    t_end, t_start : end and start time(s) (s), scalars or (B,).
    s0 : initial mode(s) (K,) or (B, K) of 0/1 (default: every switch off).
    p : parameter vector(s) (np,) or (B, np) (default ``hs.p``).
    tangents : dx0/dtheta, (n, k) or (B, n, k): how the initial state moves with each of k
        directions theta (default: none).
    param_tangents : dp/dtheta, (np, k) or (B, np, k) (default zeros). The sensitivity of
        x(t) to parameter p_j alone is the column with dx0 = 0 and dp = e_j.
    stop : optional :class:`LinearStop` (its arrays may differ per run).
    t_save : optional increasing save times (S,) or (B, S) inside [t_start, t_end].
    options : :class:`FlowOptions`.

    Returns
    -------
    :class:`HybridFlow` (always batched: a single run has B = 1).
    """
    opts = options or FlowOptions()
    n, K = hs.dim, hs.n_switches
    x0 = np.atleast_2d(np.asarray(x0, float))
    pp = np.asarray(hs.p if p is None else p, float)
    B = max(x0.shape[0], pp.shape[0] if pp.ndim == 2 else 1)
    x0 = np.broadcast_to(x0, (B, n)).copy()
    pp = np.broadcast_to(np.atleast_2d(pp), (B, hs.p.size)).copy()
    s = np.zeros((B, K)) if s0 is None else np.broadcast_to(
        np.atleast_2d(np.asarray(s0, float)), (B, K)).copy()
    if tangents is None and param_tangents is None:
        k = 1  # one dummy column: every run shares the compiled kernel of one direction
        Z = np.zeros((B, n, 1))
        P = np.zeros((B, hs.p.size, 1))
    else:
        if tangents is None:
            P = np.asarray(param_tangents, float)
            k = P.shape[-1]
            Z = np.zeros((B, n, k))
        else:
            Z = np.asarray(tangents, float)
            k = Z.shape[-1]
        Z = np.broadcast_to(Z if Z.ndim == 3 else Z[None], (B, n, k)).copy()
        P = (np.zeros((B, hs.p.size, k)) if param_tangents is None
             else np.asarray(param_tangents, float))
        P = np.broadcast_to(P if P.ndim == 3 else P[None], (B, hs.p.size, k)).copy()
    k_req = k
    k = _column_bucket(k)
    if k > k_req:  # zero columns, so a few compiled kernels serve every request
        Z = np.concatenate([Z, np.zeros((B, n, k - k_req))], axis=2)
        P = np.concatenate([P, np.zeros((B, hs.p.size, k - k_req))], axis=2)
    sc = np.asarray(hs.state_scale, float)
    # each column scaled to order one (relative parameter changes, state changes in units
    # of the state scale) for the error control; undone on return
    colmag = np.maximum(np.max(np.abs(Z) / sc[None, :, None], axis=1),
                        np.max(np.abs(P) / np.maximum(np.abs(pp), 1e-300)[:, :, None],
                               axis=1)) if k else np.ones((B, 0))
    colscale = np.where(colmag > 0, 1.0 / np.where(colmag > 0, colmag, 1.0), 1.0)
    Zs = Z * colscale[:, None, :] / sc[None, :, None]
    Ps = P * colscale[:, None, :]
    t0 = np.broadcast_to(np.asarray(t_start, float), (B,)).copy()
    t1 = np.broadcast_to(np.asarray(t_end, float), (B,)).copy()
    a, b, c = (stop or LinearStop()).arrays(n, B)
    if t_save is None:
        ts = np.zeros((B, 0))
        n_req = 0
    else:
        ts2 = np.atleast_2d(np.asarray(t_save, float))
        n_req = ts2.shape[1]
        ts = np.broadcast_to(ts2, (B, n_req)).copy()
        n_pad = SAVE_BUCKET * (-(-n_req // SAVE_BUCKET)) - n_req
        if n_pad:  # padded with the end time (not reached by the loop's saving)
            ts = np.concatenate([ts, np.repeat(t1[:, None], n_pad, axis=1)], axis=1)
    kern = _flow_kernel(hs.rhs, hs.guards, hs.project or _identity_project,
                        hs.domain or _whole_space, int(k), int(ts.shape[1]),
                        int(opts.max_switches))
    out = kern(jnp.asarray(x0 / sc), jnp.asarray(Zs), jnp.asarray(s), jnp.asarray(pp),
               jnp.asarray(Ps), jnp.asarray(sc), jnp.asarray(t0), jnp.asarray(t1),
               jnp.asarray(a), jnp.asarray(b), jnp.asarray(c),
               jnp.asarray(ts if ts.size else np.zeros((B, 1))),
               jnp.asarray(opts.rtol), jnp.asarray(opts.atol),
               jnp.asarray(np.full(B, opts.h0)), jnp.asarray(opts.max_steps))
    o = {key: np.asarray(v) for key, v in out.items()}
    phi = (o["phi"] / colscale[:, None, :])[:, :, :k_req]
    if tangents is None and param_tangents is None:
        phi = phi[:, :, :0]
    return HybridFlow(t=o["t"], x=o["x"], phi=phi, s=o["s"], status=o["status"],
                      switch_times=o["swt"], switch_index=o["swk"], n_switches=o["nsw"],
                      steps=o["steps"], saved=o["ys"][:, :n_req] if n_req else None)


# ---------------------------------------------------------------------------------------
# saltation matrices
# ---------------------------------------------------------------------------------------
@cache
def _switch_parts(rhs: Callable, guards: Callable, project: Callable) -> Callable:
    """(f-, f+, x+, R_x, h_x, R_p, h_p) at a switch of switch j from mode s into s_new."""

    def parts(x, p, s, s_new, j):
        f_old = rhs(x, p, s)
        x_new = project(x, p, s_new)
        f_new = rhs(x_new, p, s_new)
        Rx, Rp = jax.jacfwd(project, argnums=(0, 1))(x, p, s_new)
        hx, hp = jax.grad(lambda xx, qq: guards(xx, qq, s)[j], argnums=(0, 1))(x, p)
        return f_old, f_new, x_new, Rx, hx, Rp, hp

    return jax.jit(parts)


def saltation_matrix(hs: HybridSystem, x: np.ndarray, s: np.ndarray, j: int,
                     p: np.ndarray | None = None) -> np.ndarray:
    """The saltation matrix of toggling switch ``j`` at the state ``x`` (on its surface) from
    mode ``s``: S = R_x + (f+ - R_x f-) h_x / (h_x f-) (Leine & Nijmeijer 2004, eq. 3.77;
    di Bernardo et al. 2008, sec. 2.5), R the projection into the new mode, h the guard,
    f-/f+ the fields before/after. The first-order map of perturbations across the switch."""
    s = np.asarray(s, float)
    s_new = s.copy()
    s_new[j] = 1.0 - s_new[j]
    f_old, f_new, _, Rx, hx, _, _ = (np.asarray(a) for a in _switch_parts(
        hs.rhs, hs.guards, hs.project or _identity_project)(
        jnp.asarray(x, float), hs._p(p), jnp.asarray(s), jnp.asarray(s_new), int(j)))
    return Rx + np.outer(f_new - Rx @ f_old, hx) / float(hx @ f_old)


# ---------------------------------------------------------------------------------------
# periodic orbits by collocation per segment
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Segment:
    """One smooth piece of a hybrid periodic orbit.

    mode : the switch states s_i on the segment; switch : the switch k_i toggled at its end
    (the next segment's mode is ``mode`` with k_i flipped), or -1 for a segment that ends
    on the hyperplane ``section`` = (normal, point) without a switch (an orbit that never
    switches is one such segment: the section is then its phase condition);
    duration : T_i (s); mesh : (NTST_i + 1,) mesh on [0, 1]; states : (NTST_i NCOL + 1, n)
    node values.
    """

    __repr__ = compact_repr

    mode: tuple[int, ...]
    switch: int
    duration: float
    mesh: np.ndarray
    states: np.ndarray
    section: tuple[np.ndarray, np.ndarray] | None = None

    @property
    def next_mode(self) -> tuple[int, ...]:
        s = list(self.mode)
        if self.switch >= 0:
            s[self.switch] = 1 - s[self.switch]
        return tuple(s)


@dataclass(frozen=True)
class HybridOrbit:
    """A periodic orbit of a hybrid system: segments joined at event surfaces.

    segments : the pieces in order (segment 0 starts right after the last one's switch);
    p : parameters; ncol : collocation points per interval; period : sum of the durations
    (s); multipliers : Floquet multipliers (sorted by modulus, largest first; exact zeros
    for each projection onto a constraint); converged, iterations, residual (scaled
    max-norm), message : the Newton solve.
    """

    __repr__ = compact_repr

    segments: tuple[Segment, ...]
    p: np.ndarray
    ncol: int
    multipliers: np.ndarray
    converged: bool
    iterations: int
    residual: float
    message: str = ""
    _solver: Any = field(default=None, repr=False, compare=False)

    @property
    def period(self) -> float:
        return float(sum(sg.duration for sg in self.segments))

    @property
    def n_unstable(self) -> int:
        """Multipliers outside the unit circle (the trivial one, 1, excluded by a margin)."""
        return int(np.sum(np.abs(self.multipliers) > 1.0 + 1e-6))

    def profile(self, per_segment: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(times (s), states, segment index) along the orbit: the collocation nodes, or
        ``per_segment`` equally spaced points per segment when given."""
        ts, xs, ks = [], [], []
        t0 = 0.0
        for k, sg in enumerate(self.segments):
            if per_segment:
                s = np.linspace(0.0, 1.0, per_segment)
                from maglev_match.dynamics.collocation import evaluate_profile

                X = evaluate_profile(np.asarray(sg.mesh), self.ncol, sg.states, s)
            else:
                s = node_times(np.asarray(sg.mesh), self.ncol)
                X = sg.states
            ts.append(t0 + sg.duration * s)
            xs.append(X)
            ks.append(np.full(len(s), k))
            t0 += sg.duration
        return np.concatenate(ts), np.vstack(xs), np.concatenate(ks)

    def extrema(self, g: Callable, per_segment: int = 400) -> tuple[float, float]:
        """(max, min) of a scalar observable g(x, p) over the orbit: dense sampling of the
        collocation polynomials, then Brent's method on the polynomial pieces around the
        best samples (so the extrema are those of the piecewise polynomial, to ~1e-13)."""
        import scipy.optimize

        from maglev_match.dynamics.collocation import evaluate_profile

        pj = jnp.asarray(self.p)
        gb = jax.jit(jax.vmap(lambda x: jnp.atleast_1d(g(x, pj))[0]))
        best = []
        for sign in (1.0, -1.0):
            cand = []
            for sg in self.segments:
                mesh = np.asarray(sg.mesh)
                s = np.linspace(0.0, 1.0, per_segment)
                vals = sign * np.asarray(gb(jnp.asarray(
                    evaluate_profile(mesh, self.ncol, sg.states, s))))
                k = int(np.argmax(vals))
                lo, hi = s[max(k - 1, 0)], s[min(k + 1, s.size - 1)]

                def neg(u, mesh=mesh, sg=sg, sign=sign):
                    x = evaluate_profile(mesh, self.ncol, sg.states, np.array([u]))
                    return -sign * float(np.asarray(gb(jnp.asarray(x)))[0])

                r = scipy.optimize.minimize_scalar(neg, bounds=(lo, hi), method="bounded",
                                                   options={"xatol": 1e-14})
                cand.append(max(vals[k], -float(r.fun)))
            best.append(sign * max(cand))
        return float(best[0]), float(best[1])


@cache
def _param_jacobian_gauss(rhs: Callable) -> Callable:
    """df/dp at a batch of points (B, n) -> (B, n, np)."""
    return jax.jit(jax.vmap(jax.jacfwd(rhs, argnums=1), (0, None)))


class _HybridCollocation:
    """The bordered-free system of a hybrid orbit (module docstring) in scaled unknowns
    Y = X / S, X = (U_0, T_0, U_1, T_1, ...), and its sparse Jacobian.

    Rows of segment i, in order::

        collocation   (NTST_i NCOL n)   (D U - h T_i f(L U; s_i)) / scale
        event         (1)               h_{k_i}(U_i(1); s_i) / guard scale
        reset         (n)               (U_{i+1}(0) - R(U_i(1); s_{i+1})) / scale
    """

    def __init__(self, hs: HybridSystem, modes, switches, meshes, m, p, T_scale,
                 sections=None):
        from maglev_match.dynamics.collocation import collocation_tables

        self.hs = hs
        self.sections = list(sections) if sections is not None else [None] * len(modes)
        self.modes = [tuple(int(v) for v in md) for md in modes]
        self.switches = [int(k) for k in switches]
        self.meshes = [np.asarray(ms, float) for ms in meshes]
        self.m = int(m)
        self.p = np.asarray(p, float)
        self.sc = np.asarray(hs.state_scale, float)
        self.n = hs.dim
        self.S = len(self.modes)
        self.T_scale = float(T_scale)
        self.N = [(ms.size - 1) * self.m + 1 for ms in self.meshes]
        sizes = [Ni * self.n + 1 for Ni in self.N]
        self.off = np.concatenate([[0], np.cumsum(sizes)]).astype(int)
        self.size = int(self.off[-1])
        _, _, _, self.L, self.D = collocation_tables(self.m)
        self.gscale = np.ones(self.S)

    # ----- packing ---------------------------------------------------------------------
    def pack(self, U: list[np.ndarray], T: list[float]) -> np.ndarray:
        Y = np.empty(self.size)
        for i in range(self.S):
            o = self.off[i]
            Y[o:o + self.N[i] * self.n] = (np.asarray(U[i]) / self.sc).ravel()
            Y[o + self.N[i] * self.n] = T[i] / self.T_scale
        return Y

    def unpack(self, Y: np.ndarray) -> tuple[list[np.ndarray], list[float]]:
        U, T = [], []
        for i in range(self.S):
            o = self.off[i]
            U.append(Y[o:o + self.N[i] * self.n].reshape(self.N[i], self.n) * self.sc)
            T.append(float(Y[o + self.N[i] * self.n]) * self.T_scale)
        return U, T

    # ----- residual and Jacobian ---------------------------------------------------------
    def evaluate(self, Y: np.ndarray, jac: bool = True):
        from maglev_match.dynamics.collocation import collocation_kernel, interval_nodes

        U, T = self.unpack(Y)
        n, m, sc = self.n, self.m, self.sc
        res = np.empty(self.size)
        rows: list[np.ndarray] = []
        cols: list[np.ndarray] = []
        vals: list[np.ndarray] = []
        proj = self.hs.project or _identity_project
        pj = jnp.asarray(self.p)
        for i in range(self.S):
            mesh = self.meshes[i]
            ntst = mesh.size - 1
            h = np.diff(mesh)
            idx = interval_nodes(ntst, m)
            f_i = self.hs.mode_rhs(self.modes[i])
            e0 = jnp.zeros_like(pj)
            r, F, J, _ = (np.asarray(a) for a in collocation_kernel(f_i, m)(
                jnp.asarray(U[i][idx]), jnp.asarray(h), T[i], pj, e0))
            r_rows = r * (h[:, None, None] / sc)  # (ntst, m, n)
            o = self.off[i]
            nc = ntst * m * n
            res[o:o + nc] = r_rows.ravel()
            # event and reset at the segment's end
            x_end = U[i][-1]
            s_i = np.asarray(self.modes[i], float)
            s_next = np.asarray(self.modes[(i + 1) % self.S], float)
            k = self.switches[i]
            if k >= 0:
                _, _, x_new, Rx, hx, _, _ = (np.asarray(a) for a in _switch_parts(
                    self.hs.rhs, self.hs.guards, proj)(jnp.asarray(x_end), pj,
                                                       jnp.asarray(s_i), jnp.asarray(s_next), k))
                gval = float(np.asarray(self.hs.guards(jnp.asarray(x_end), pj,
                                                       jnp.asarray(s_i)))[k])
            else:  # a section, no switch: identity reset
                nrm, pt = self.sections[i]
                x_new, Rx, hx = x_end, np.eye(n), nrm
                gval = float(nrm @ (x_end - pt))
            res[o + nc] = gval / self.gscale[i]
            j_next = (i + 1) % self.S
            o_next = self.off[j_next]
            x_start_next = U[j_next][0]
            res[o + nc + 1:o + nc + 1 + n] = (x_start_next - x_new) / sc
            if not jac:
                continue
            # collocation blocks: rows (j, l, a), cols (j, k, b)
            blk = (self.D[None, :, None, :, None] * np.eye(n)[None, None, :, None, :]
                   - (T[i] * h)[:, None, None, None, None] * self.L[None, :, None, :, None]
                   * J[:, :, :, None, :])  # (ntst, m, n, m+1, n)
            blk = blk * (sc[None, None, None, None, :] / sc[None, None, :, None, None])
            jj = np.arange(ntst)[:, None, None, None, None]
            ll = np.arange(m)[None, :, None, None, None]
            aa = np.arange(n)[None, None, :, None, None]
            kk = np.arange(m + 1)[None, None, None, :, None]
            bb = np.arange(n)[None, None, None, None, :]
            shape = blk.shape
            rows.append(np.broadcast_to(o + (jj * m + ll) * n + aa, shape).ravel())
            cols.append(np.broadcast_to(o + (jj * m + kk) * n + bb, shape).ravel())
            vals.append(blk.ravel())
            # T column
            colT = -(h[:, None, None] * F / sc) * self.T_scale
            rows.append(o + np.arange(nc))
            cols.append(np.full(nc, o + self.N[i] * n))
            vals.append(colT.ravel())
            # event row: d h / d U_i(1)
            last = o + (self.N[i] - 1) * n + np.arange(n)
            rows.append(np.full(n, o + nc))
            cols.append(last)
            vals.append(hx * sc / self.gscale[i])
            # reset rows: + I on U_{i+1}(0), - R_x on U_i(1)
            rr = o + nc + 1 + np.arange(n)
            rows.append(rr)
            cols.append(o_next + np.arange(n))
            vals.append(np.ones(n))
            rows.append(np.repeat(rr, n))
            cols.append(np.tile(last, n))
            vals.append((-Rx * sc[None, :] / sc[:, None]).ravel())
        if not jac:
            return res, None
        A = scipy.sparse.csc_matrix((np.concatenate(vals), (np.concatenate(rows),
                                                            np.concatenate(cols))),
                                    shape=(self.size, self.size))
        return res, A

    def param_derivative(self, Y: np.ndarray) -> np.ndarray:
        """dF/dp (size, np) at Y: the collocation rows through f_p, the event rows through
        h_p and the reset rows through R_p."""
        from maglev_match.dynamics.collocation import interval_nodes

        U, T = self.unpack(Y)
        n, m, sc = self.n, self.m, self.sc
        npar = self.p.size
        out = np.zeros((self.size, npar))
        pj = jnp.asarray(self.p)
        proj = self.hs.project or _identity_project
        for i in range(self.S):
            mesh = self.meshes[i]
            ntst = mesh.size - 1
            h = np.diff(mesh)
            idx = interval_nodes(ntst, m)
            Uc = np.einsum("lk,jkn->jln", self.L, U[i][idx]).reshape(-1, n)
            fp = np.asarray(_param_jacobian_gauss(self.hs.mode_rhs(self.modes[i]))(
                jnp.asarray(Uc), pj)).reshape(ntst, m, n, npar)
            o = self.off[i]
            nc = ntst * m * n
            out[o:o + nc] = (-T[i] * h[:, None, None, None] * fp
                             / sc[None, None, :, None]).reshape(nc, npar)
            s_i = np.asarray(self.modes[i], float)
            s_next = np.asarray(self.modes[(i + 1) % self.S], float)
            k = self.switches[i]
            if k < 0:  # a section: fixed in space, identity reset
                continue
            *_, Rp, hp = (np.asarray(a) for a in _switch_parts(
                self.hs.rhs, self.hs.guards, proj)(jnp.asarray(U[i][-1]), pj,
                                                   jnp.asarray(s_i), jnp.asarray(s_next), k))
            out[o + nc] = hp / self.gscale[i]
            out[o + nc + 1:o + nc + 1 + n] = -Rp / sc[:, None]
        return out


def _guard_scales(hs: HybridSystem, prob: _HybridCollocation, U: list[np.ndarray]) -> None:
    """Scale each event row to order one: |h_x| . state scale at the segment's end."""
    pj = jnp.asarray(prob.p)
    for i in range(prob.S):
        s_i = jnp.asarray(np.asarray(prob.modes[i], float))
        k = prob.switches[i]
        if k < 0:
            hx = np.asarray(prob.sections[i][0], float)
        else:
            hx = np.asarray(jax.grad(lambda x, s_i=s_i, k=k: hs.guards(x, pj, s_i)[k])(
                jnp.asarray(U[i][-1])))
        g = float(np.sum(np.abs(hx) * prob.sc))
        prob.gscale[i] = g if g > 0 else 1.0


def hybrid_periodic_orbit(
    hs: HybridSystem,
    segments: Sequence[Segment],
    *,
    p: np.ndarray | None = None,
    ncol: int = 4,
    tol: float = 1e-10,
    max_iter: int = 25,
) -> HybridOrbit:
    """A periodic orbit of ``hs`` by collocation per segment (module docstring), by Newton's
    method from the initial ``segments`` (their modes, switches, meshes, durations and node
    values; e.g. from :func:`segments_from_flow`).

    The segments' meshes are kept (uniform meshes by default in
    :func:`segments_from_flow`); ``tol`` bounds the scaled max-norm of the Newton update and
    of the residual. Returns a :class:`HybridOrbit` with its Floquet multipliers
    (:func:`hybrid_floquet`); ``converged`` False with a message when Newton fails.
    """
    pp = np.asarray(hs.p if p is None else p, float)
    segs = list(segments)
    T_scale = float(sum(sg.duration for sg in segs)) / max(len(segs), 1)
    prob = _HybridCollocation(hs, [sg.mode for sg in segs], [sg.switch for sg in segs],
                              [sg.mesh for sg in segs], ncol, pp, T_scale,
                              [sg.section for sg in segs])
    _guard_scales(hs, prob, [np.asarray(sg.states, float) for sg in segs])
    Y = prob.pack([np.asarray(sg.states, float) for sg in segs],
                  [float(sg.duration) for sg in segs])
    converged = False
    msg = ""
    res_norm = math.inf
    lu = None
    it = 0
    while it < max_iter:
        it += 1
        r, A = prob.evaluate(Y)
        res_norm = float(np.max(np.abs(r)))
        try:
            lu = scipy.sparse.linalg.splu(A)
        except RuntimeError as exc:  # singular
            msg = f"the collocation Jacobian is singular ({exc})"
            break
        dY = lu.solve(-r)
        if not np.all(np.isfinite(dY)):
            msg = "the Newton update is not finite"
            break
        # damping: keep every duration positive
        lam = 1.0
        for i in range(prob.S):
            o = prob.off[i] + prob.N[i] * prob.n
            if Y[o] + lam * dY[o] <= 0:
                lam = min(lam, 0.5 * Y[o] / max(-dY[o], 1e-300))
        Y = Y + lam * dY
        step = float(np.max(np.abs(lam * dY)))
        if step <= tol and res_norm <= max(tol, 1e-8):
            converged = True
            break
    if not converged and not msg:
        msg = f"Newton did not converge in {max_iter} iterations (residual {res_norm:.3g})"
    r, A = prob.evaluate(Y)
    res_norm = float(np.max(np.abs(r)))
    if converged and res_norm > max(10 * tol, 1e-8):
        converged = False
        msg = f"the residual {res_norm:.3g} stays above the tolerance"
    U, T = prob.unpack(Y)
    if converged and min(T) <= 0:
        converged = False
        msg = "a segment duration became non-positive"
    new_segs = tuple(Segment(mode=sg.mode, switch=sg.switch, duration=T[i], mesh=sg.mesh,
                             states=U[i], section=sg.section) for i, sg in enumerate(segs))
    orbit = HybridOrbit(segments=new_segs, p=pp, ncol=ncol, multipliers=np.array([]),
                        converged=converged, iterations=it, residual=res_norm, message=msg,
                        _solver=(prob, Y, A))
    if converged:
        mult = hybrid_floquet(hs, orbit).multipliers
        orbit = HybridOrbit(segments=new_segs, p=pp, ncol=ncol, multipliers=mult,
                            converged=True, iterations=it, residual=res_norm, message="",
                            _solver=(prob, Y, A))
    return orbit


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


def orbit_parameter_derivative(hs: HybridSystem, orbit: HybridOrbit, segment: int = 0,
                               node: int = 0) -> np.ndarray:
    """d(state at a node)/dp of a converged hybrid orbit by the implicit function theorem
    on the collocation system, dY/dp = -(dF/dY)^{-1} dF/dp (every parameter at once; one
    sparse LU). Returns (n, np): the derivative of node ``node`` of segment ``segment``."""
    prob, Y, A = orbit._solver
    lu = scipy.sparse.linalg.splu(A)
    dY = lu.solve(-prob.param_derivative(Y))
    o = prob.off[segment] + node * hs.dim
    return dY[o:o + hs.dim] * prob.sc[:, None]


def segments_from_flow(hs: HybridSystem, x0: np.ndarray, s0: np.ndarray, period: float, *,
                       p: np.ndarray | None = None, ntst: int = 40, ncol: int = 4,
                       min_ntst: int = 4, options: FlowOptions | None = None
                       ) -> list[Segment]:
    """Initial segments for :func:`hybrid_periodic_orbit` from one run of the flow near the
    orbit, from ``x0`` in mode ``s0``, with ``period`` (s) an estimate of the period.

    If the run switches within 1.3 periods, the orbit starts right after its first switch
    and closes at the switch back into that mode whose time is nearest one period later;
    the run is cut at its switches. If it does not switch, the orbit is one segment closed
    on the hyperplane through ``x0`` normal to the flow (switch -1). Each piece gets a
    uniform mesh (``ntst`` intervals over the period, at least ``min_ntst`` per piece) and
    its node values are read from the flow."""
    opts = options or FlowOptions()
    pp = np.asarray(hs.p if p is None else p, float)
    x0 = np.asarray(x0, float)
    s0 = np.asarray(s0, float)
    fl = hybrid_flow(hs, x0, 1.3 * period, s0=s0, p=pp, options=opts)
    nsw = int(fl.n_switches[0])
    if nsw == 0:  # a smooth orbit: one segment closed on a section
        mesh = np.linspace(0.0, 1.0, max(ntst, min_ntst) + 1)
        tn = period * node_times(mesh, ncol)
        fl2 = hybrid_flow(hs, x0, period, s0=s0, p=pp, t_save=tn[1:], options=opts)
        X = np.vstack([x0[None], fl2.saved[0]])
        f0 = hs.f(x0, s0, pp)
        nrm = f0 / np.linalg.norm(f0 / hs.state_scale) / hs.state_scale ** 2
        return [Segment(mode=tuple(int(v) for v in s0), switch=-1, duration=period, mesh=mesh,
                        states=X, section=(nrm, x0.copy()))]
    # start right after the first switch
    t1 = float(fl.switch_times[0][0])
    tiny = 1e-12 * max(period, 1.0)
    a = hybrid_flow(hs, x0, t1 + tiny, s0=s0, p=pp, options=opts)
    xs, ss = a.x[0], a.s[0]
    fl = hybrid_flow(hs, xs, 1.3 * period, t_start=t1 + tiny, s0=ss, p=pp, options=opts)
    times = fl.switch_times[0][: int(fl.n_switches[0])] - (t1 + tiny)
    which = fl.switch_index[0][: int(fl.n_switches[0])]
    mode = np.asarray(ss, int)
    modes, bounds, sw, closes = [], [0.0], [], []
    for q, (tq, kq) in enumerate(zip(times, which, strict=True)):
        modes.append(tuple(int(v) for v in mode))
        sw.append(int(kq))
        bounds.append(float(tq))
        mode = mode.copy()
        mode[kq] = 1 - mode[kq]
        if np.array_equal(mode, np.asarray(ss, int)):
            closes.append(q)
    if not closes:
        raise ValueError("the run's switches do not lead back to the starting mode within "
                         "1.3 periods")
    last = min(closes, key=lambda q: abs(bounds[q + 1] - period))
    modes, sw, bounds = modes[:last + 1], sw[:last + 1], bounds[:last + 2]
    total = bounds[-1]
    pieces = []
    t_all = []
    for i in range(len(modes)):
        ta, tb = bounds[i], bounds[i + 1]
        nt = max(min_ntst, int(round(ntst * (tb - ta) / total)))
        mesh = np.linspace(0.0, 1.0, nt + 1)
        tn = ta + (tb - ta) * node_times(mesh, ncol)
        pieces.append((modes[i], sw[i], tb - ta, mesh, tn))
        t_all.extend(tn)
    t_all = np.unique(np.clip(np.asarray(t_all), 0.0, total))
    t_pos = t_all[t_all > 0]
    fl2 = hybrid_flow(hs, xs, t1 + tiny + total, t_start=t1 + tiny, s0=ss, p=pp,
                      t_save=t1 + tiny + t_pos, options=opts)
    saved = np.vstack([xs[None], fl2.saved[0]])
    tsaved = np.concatenate([[0.0], t_pos])
    out = []
    for md, k, dur, mesh, tn in pieces:
        X = np.array([saved[int(np.argmin(np.abs(tsaved - t)))] for t in tn])
        out.append(Segment(mode=md, switch=k, duration=dur, mesh=mesh, states=X))
    return out


# ---------------------------------------------------------------------------------------
# single shooting (independent method)
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class ShotOrbit:
    """A hybrid periodic orbit by single shooting: the point x on the section
    n . (x - x_s) = 0, the period T, the monodromy matrix there (with every saltation),
    its eigenvalues, and the Newton record."""

    __repr__ = compact_repr

    x: np.ndarray
    s: np.ndarray
    period: float
    monodromy: np.ndarray
    multipliers: np.ndarray
    converged: bool
    iterations: int
    residual: float
    message: str = ""


def shoot_hybrid_orbit(hs: HybridSystem, x_guess: np.ndarray, s: np.ndarray, T_guess: float,
                       *, p: np.ndarray | None = None, tol: float = 1e-11,
                       max_iter: int = 20, options: FlowOptions | None = None) -> ShotOrbit:
    """A hybrid periodic orbit by single shooting on the flow with sensitivities: unknowns
    (x, T) with x on the hyperplane through ``x_guess`` normal to the flow there, equations
    x(T; x) - x = 0 and n . (x - x_guess) = 0, Jacobian [[M - I, f(x(T))], [n^T, 0]] with M
    the sensitivity of the end state to the start state (saltations included). ``x_guess``
    must lie inside a segment (away from switches), in mode ``s``."""
    opts = options or FlowOptions()
    pp = np.asarray(hs.p if p is None else p, float)
    n = hs.dim
    x = np.asarray(x_guess, float).copy()
    s = np.asarray(s, float)
    T = float(T_guess)
    f0 = hs.f(x, s, pp)
    nrm = f0 / np.linalg.norm(f0 / hs.state_scale)
    xs = x.copy()
    sc = np.asarray(hs.state_scale, float)
    conv = False
    msg = ""
    res = math.inf
    M = np.full((n, n), np.nan)
    it = 0
    while it < max_iter:
        it += 1
        fl = hybrid_flow(hs, x, T, s0=s, p=pp, tangents=np.eye(n), options=opts)
        if fl.status[0] != FlowStatus.REACHED:
            msg = "the flow failed over one period"
            break
        if not np.array_equal(fl.s[0], s):
            msg = "the run ends in another mode after one period"
            break
        xe, M = fl.x[0], fl.phi[0]
        fe = hs.f(xe, s, pp)
        r = np.concatenate([(xe - x) / sc, [float(nrm @ (x - xs))]])
        res = float(np.max(np.abs(r)))
        Jm = np.zeros((n + 1, n + 1))
        Jm[:n, :n] = (M - np.eye(n)) / sc[:, None]
        Jm[:n, n] = fe / sc
        Jm[n, :n] = nrm
        try:
            dz = np.linalg.solve(Jm, -r)
        except np.linalg.LinAlgError:
            msg = "the shooting Jacobian is singular"
            break
        x = x + dz[:n]
        T = T + dz[n]
        if float(np.max(np.abs(dz[:n] / sc))) <= tol and abs(dz[n]) <= tol * T:
            conv = True
            fl = hybrid_flow(hs, x, T, s0=s, p=pp, tangents=np.eye(n), options=opts)
            M = fl.phi[0]
            break
    if not conv and not msg:
        msg = f"shooting did not converge in {max_iter} iterations (residual {res:.3g})"
    mu = np.linalg.eigvals(M) if np.all(np.isfinite(M)) else np.full(n, np.nan)
    mu = mu[np.argsort(-np.abs(mu))]
    return ShotOrbit(x=x, s=s, period=T, monodromy=M, multipliers=mu, converged=conv,
                     iterations=it, residual=res, message=msg)
