"""The flow of a hybrid system with forward sensitivities, switches located as events.

**The flow with forward sensitivities** (:func:`hybrid_flow`): x(t) and
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

(the state part R_x + (f+ - R_x f-) h_x / (h_x f-) is the saltation matrix,
:func:`~maglev_match.dynamics.hybrid.saltation.saltation_matrix`; the P terms carry
parameter directions). A run can end at a *stop*: the first downward zero of
``a . f(x) + b . x + c`` after the run starts (an extremum of a linear observable w . x
with a = +-w, or a hyperplane section with a = 0).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from enum import IntEnum
from functools import cache, lru_cache
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from maglev_match.core import jax_setup  # noqa: F401  (float64)
from maglev_match.core.aot import cached_kernel
from maglev_match.core.beside import stop_point
from maglev_match.core.jax_setup import kernel_arg
from maglev_match.core.reprs import compact_repr
from maglev_match.dynamics.hybrid.system import HybridSystem, identity_project

Array = Any

__all__ = [
    "FlowOptions",
    "FlowStatus",
    "LinearStop",
    "HybridFlow",
    "hybrid_flow",
    "COLUMN_BUCKET",
    "SAVE_BUCKET",
]


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
    stop_point()  # a part run beside another stops here when asked (core/beside.py)
    kern = _flow_kernel(hs.rhs, hs.guards, hs.project or identity_project,
                        hs.domain or _whole_space, int(k), int(ts.shape[1]),
                        int(opts.max_switches))
    out = kern(kernel_arg(x0 / sc), kernel_arg(Zs), kernel_arg(s), kernel_arg(pp),
               kernel_arg(Ps), kernel_arg(sc), kernel_arg(t0), kernel_arg(t1),
               kernel_arg(a), kernel_arg(b), kernel_arg(c),
               kernel_arg(ts if ts.size else np.zeros((B, 1))),
               kernel_arg(opts.rtol), kernel_arg(opts.atol),
               kernel_arg(np.full(B, opts.h0)), kernel_arg(opts.max_steps))
    o = {key: np.asarray(v) for key, v in out.items()}
    phi = (o["phi"] / colscale[:, None, :])[:, :, :k_req]
    if tangents is None and param_tangents is None:
        phi = phi[:, :, :0]
    return HybridFlow(t=o["t"], x=o["x"], phi=phi, s=o["s"], status=o["status"],
                      switch_times=o["swt"], switch_index=o["swk"], n_switches=o["nsw"],
                      steps=o["steps"], saved=o["ys"][:, :n_req] if n_req else None)

