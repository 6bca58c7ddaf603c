"""The compiled integrator kernel of :mod:`maglev_match.dynamics.integrate.simulate`: one
run of x' = rhs(x, p) with terminal limit events, as a single XLA program.

The kernel is a hand-written step loop (``jax.lax.while_loop``) around an explicit
Runge-Kutta method of diffrax (Dopri8 by default; Dopri5, Tsit5) and its PID step-size
controller, in the scaled coordinates z = x / state_scale. Every accepted step is inspected
through the solver's dense interpolant: the limit events are sampled inside the step, a
possible grazing is refined by zooming in on the smallest sample, and the first crossing is
located by repeated 16-section; the convergence test (the reference state an attracting
equilibrium by Lyapunov's first method, Kuznetsov 2004, Theorem 2.1 and sec. 2.1) and the
saved times are evaluated on the way (the semantics are described in the docstring of
:mod:`~maglev_match.dynamics.integrate.simulate`).

For explicit first-same-as-last methods the stages are written out from the Butcher tableau
(:func:`_unrolled_fsal_step`; Hairer, Norsett & Wanner, *Solving ODEs I*, sec. II.4-II.6):
the same arithmetic as diffrax's stage loop, without a loop iteration per stage.
:func:`compiled_kernel` builds the kernel (vmapped over initial states and/or parameters
for a batch) and caches it per (right-hand side, event function, solver, options) through
:func:`maglev_match.core.aot.cached_kernel`, so repeated calls do not recompile. The
outcome codes the kernel returns are :data:`RUNNING`, :data:`COLLISION`, :data:`CONVERGED`
and :data:`FAILED`.
"""

from __future__ import annotations

from functools import lru_cache

import jax
import jax.numpy as jnp
import numpy as np

from maglev_match.core import jax_setup  # noqa: F401  (float64 on)
from maglev_match.core.aot import cached_kernel

__all__ = [
    "RUNNING",
    "COLLISION",
    "CONVERGED",
    "FAILED",
    "SOLVERS",
    "UNROLL_MAX_DIM",
    "SAVE_BLOCK",
    "compiled_kernel",
]

# outcome codes used inside the kernel
RUNNING, COLLISION, CONVERGED, FAILED = 0, 1, 2, 3

UNROLL_MAX_DIM = 16  # systems up to this many states get the written-out RK stages
SAVE_BLOCK = 8  # saved times written per vectorised interpolant evaluation

# solver name -> diffrax class name (diffrax is imported when a kernel is first built, so
# commands that never simulate do not pay its import, ~0.3 s)
SOLVERS = {
    "dopri8": "Dopri8",
    "dopri5": "Dopri5",
    "tsit5": "Tsit5",
}


# ---------------------------------------------------------------------------------------
# the compiled kernel
# ---------------------------------------------------------------------------------------
def _unrolled_fsal_step(solver, elementwise: bool = False):
    """An explicit, first-same-as-last Runge-Kutta step written out stage by stage from the
    solver's Butcher tableau (for an autonomous vector field), or None if the solver is not
    of that kind. The same arithmetic as diffrax's step (stages ``k_i = h f(y0 + sum_j
    a_ij k_j)``, solution from the last stage, error ``sum_i e_i k_i``; Hairer, Norsett &
    Wanner, *Solving ODEs I*, sec. II.4-II.6), without diffrax's loop over the stages, which
    costs a loop iteration per stage inside every step.

    ``elementwise=False``: the stage sums are the zero-padded tableau rows dotted with a
    stage buffer, as diffrax does (the same numbers to the last bit). ``elementwise=True``:
    the sums run over the nonzero coefficients only, as plain elementwise arithmetic that
    XLA fuses into the next stage's evaluation (no buffer update, no small matrix product
    per stage). Mathematically the same step; the rounding differs in the last bits. The
    elementwise form halves a vmapped batch (256 model-A runs, measured: 0.78 against
    0.39 s CPU) but is ~20 % slower for a single run, so the kernel uses it for batches.

    Returns ``step(f, z0, f0, h) -> (z1, err, dense_info, f1)``: ``f0 = f(z0)`` from the
    previous step, ``dense_info`` as diffrax's (``y0``, ``y1``, ``k`` = stages x h).
    """
    tab = getattr(solver, "tableau", None)
    if tab is None or not (getattr(tab, "fsal", False) and getattr(tab, "ssal", False)):
        return None
    if getattr(solver, "implicit", False) or tab.c1 != 0.0:
        return None
    n_stages = len(tab.a_lower) + 1
    A = np.zeros((n_stages, n_stages))
    for i, row in enumerate(tab.a_lower):
        A[i + 1, : i + 1] = row
    b_err = np.asarray(tab.b_error, float)
    hi = jax.lax.Precision.HIGHEST

    def combo(coef, ks):
        terms = [float(c) * k for c, k in zip(coef, ks, strict=False) if c != 0.0]
        out = terms[0]
        for t in terms[1:]:
            out = out + t
        return out

    def step_elementwise(f, z0, f0, h):
        ks = [f0 * h]
        for i in range(1, n_stages):
            zi = z0 + combo(A[i, :i], ks)
            fi = f(zi)
            ks.append(fi * h)
        err = combo(b_err, ks)
        return zi, err, dict(y0=z0, y1=zi, k=jnp.stack(ks)), fi

    if elementwise:
        return step_elementwise

    def step(f, z0, f0, h):
        # the same operations as diffrax's stage loop (zero-padded tableau rows dotted
        # with the stage buffer), so the numbers are the same to the last bit
        K = jnp.zeros((n_stages,) + z0.shape, z0.dtype).at[0].set(f0 * h)
        for i in range(1, n_stages):
            zi = z0 + jnp.tensordot(jnp.asarray(A[i]), K, axes=1, precision=hi)
            fi = f(zi)
            K = K.at[i].set(fi * h)
        err = jnp.tensordot(jnp.asarray(b_err), K, axes=1, precision=hi)
        # solution = last stage's point (ssal); its f is the next step's f0 (fsal)
        return zi, err, dict(y0=z0, y1=zi, k=K), fi

    return step


def _make_kernel(rhs, event_fn, solver_name: str, samples: int, n_save: int,
                 stop_on_converged: bool, unroll_stages: bool | None = None,
                 batched: bool = False):
    """Build the (unjitted) single-run kernel. All array inputs are traced. ``batched``:
    the kernel will be vmapped (the stages are then written as elementwise sums,
    :func:`_unrolled_fsal_step`)."""
    import diffrax
    import equinox.internal as eqxi

    solver = getattr(diffrax, SOLVERS[solver_name])()
    unrolled0 = (_unrolled_fsal_step(solver, elementwise=batched)
                 if unroll_stages is not False else None)
    interp_cls = solver.interpolation_cls
    eps = float(np.finfo(float).eps)

    def kernel(x0, p, scale, x_ref, t_end, ts_save, rtol, atol, converge_tol, hold_time,
               max_steps, dt0, decay_floor, event_args):
        term = diffrax.ODETerm(lambda t, z, args: rhs(z * scale, args) / scale)
        controller = diffrax.PIDController(rtol=rtol, atol=atol)
        order = solver.error_order(term)
        z0 = x0 / scale
        zref = x_ref / scale
        t0 = jnp.asarray(0.0)

        def g_of_z(z):
            return event_fn(z * scale, p, event_args)

        m = int(jax.eval_shape(g_of_z, z0).shape[0])
        sstate = solver.init(term, t0, t_end, z0, p)
        # written-out stages: 2.4x faster steps for model A (9 states); for model B (39
        # states) diffrax's stage loop is faster (58 against 77 ms for 5 s, measured)
        unrolled = unrolled0 if (unroll_stages or z0.shape[0] <= UNROLL_MAX_DIM) else None
        if unrolled is not None:  # first-same-as-last: carry f(z) from step to step
            sstate = rhs(z0 * scale, p) / scale
        tnext, cstate = controller.init(term, t0, t_end, z0, None, p, solver.func, order)
        tnext = jnp.where(dt0 > 0, t0 + dt0, tnext)
        tnext = jnp.minimum(tnext, t_end)
        dim = z0.shape[0]
        d0 = jnp.max(jnp.abs(z0 - zref))
        inside0 = d0 <= converge_tol

        # is the reference state an attracting equilibrium? (scaled coordinates: same
        # eigenvalues as the original ones)
        def f_z(z):
            return rhs(z * scale, p) / scale

        ref_residual = jnp.max(jnp.abs(f_z(zref)))
        ref_max_real = jnp.max(jnp.real(jnp.linalg.eigvals(jax.jacfwd(f_z)(zref))))
        attracting = (ref_max_real < 0) & (ref_residual * hold_time <= converge_tol)

        def settled_of(c):
            held = (c["t"] - c["conv_since"]) >= hold_time
            return held & (attracting | (c["peak"] <= decay_floor))

        carry = dict(
            t=t0, tnext=tnext, z=z0, sstate=sstate, cstate=cstate,
            made_jump=jnp.asarray(False),
            status=jnp.asarray(RUNNING), t_event=jnp.asarray(jnp.nan),
            i_event=jnp.asarray(-1), z_event=jnp.full((dim,), jnp.nan),
            conv_since=jnp.where(inside0, t0, jnp.inf),
            peak=d0,  # largest d seen since conv_since (steps' ends and event samples)
            ys=jnp.full((n_save, dim), jnp.nan), save_idx=jnp.asarray(0),
            steps=jnp.asarray(0), accepted=jnp.asarray(0), rejected=jnp.asarray(0),
            flagged=jnp.asarray(False), stuck=jnp.asarray(False),
            gmin=g_of_z(z0) if m else jnp.zeros((0,)),
        )
        # a start outside the limits is a collision at t = 0
        if m:
            g0 = g_of_z(z0)
            bad0 = jnp.any(g0 < 0)
            carry["status"] = jnp.where(bad0, COLLISION, RUNNING)
            carry["t_event"] = jnp.where(bad0, t0, jnp.nan)
            carry["i_event"] = jnp.where(bad0, jnp.argmin(g0), -1)
            carry["z_event"] = jnp.where(bad0, z0, jnp.nan)

        def cond(c):
            go = ((c["status"] == RUNNING) & (c["t"] < t_end) & (c["steps"] < max_steps)
                  & ~c["stuck"])
            if stop_on_converged:
                go = go & ~settled_of(c)
            return go

        def sample_events(interp, ta, tb):
            """g on samples + 1 equally spaced points of the step's interpolant: the
            samples, their g values, the entries with a negative sample, the entries whose
            sampled minimum is below their variation over the step (a dip between samples
            is possible), and the largest scaled distance to the reference seen."""
            s = ta + (tb - ta) * jnp.linspace(0.0, 1.0, samples + 1)
            zs = jax.vmap(interp.evaluate)(s)  # (samples+1, dim)
            G = jax.vmap(g_of_z)(zs)  # (samples+1, m)
            d_seen = jnp.max(jnp.abs(zs - zref))
            any_neg = jnp.any(G < 0, axis=0)
            g_lo = jnp.min(G, axis=0)
            spread = jnp.max(G, axis=0) - g_lo
            near = (g_lo <= spread) & ~any_neg
            return s, G, any_neg, near, d_seen

        def locate_event(interp, ta, tb, active):
            """First time in [ta, tb] at which an entry of g is negative (inf if none),
            the entry, and the smallest value of each entry seen in the step."""
            s, G, any_neg, _, d_seen = sample_events(interp, ta, tb)
            neg = G < 0
            first = jnp.argmax(neg, axis=0)  # first negative sample per entry
            kmin = jnp.argmin(G, axis=0)
            g_lo = jnp.min(G, axis=0)
            spread = jnp.max(G, axis=0) - g_lo

            def gj(j, tt):
                return g_of_z(interp.evaluate(tt))[j]

            # Grazing: an entry can dip below zero between samples only if its sampled
            # minimum is smaller than its variation within the step. Every entry at risk
            # gets its minimum refined by zooming in on the two sub-intervals around its
            # smallest sample. unvmap_any keeps this a real branch under vmap (taken if
            # any run of a batch needs it).
            near = (g_lo <= spread) & ~any_neg & active

            def refine_min():
                # every entry at risk at once (model B: two points may graze in one step):
                # zoom, sampling 8 sub-intervals at once and keeping the two around the
                # smallest value (the bracket shrinks 4x per round, 4^6 ~ 4e3 in all)
                def one(j):
                    k = kmin[j]
                    lo = s[jnp.maximum(k - 1, 0)]
                    hi = s[jnp.minimum(k + 1, samples)]

                    def body(_, carry):
                        lo, hi, best_t, best_g = carry
                        tt = jnp.linspace(lo, hi, 9)
                        vals = jax.vmap(lambda u: gj(j, u))(tt)
                        kk = jnp.argmin(vals)
                        better = vals[kk] < best_g
                        return (tt[jnp.maximum(kk - 1, 0)], tt[jnp.minimum(kk + 1, 8)],
                                jnp.where(better, tt[kk], best_t),
                                jnp.where(better, vals[kk], best_g))

                    _, _, tm, gm = jax.lax.fori_loop(0, 6, body, (lo, hi, s[k], g_lo[j]))
                    return tm, gm

                return jax.vmap(one)(jnp.arange(m))

            t_min, g_min = jax.lax.cond(
                eqxi.unvmap_any(jnp.any(near)), refine_min,
                lambda: (s[kmin], g_lo))
            graze = near & (g_min < 0)
            # candidate brackets [a_j, b_j] with g_j(a_j) >= 0 > g_j(b_j)
            a_j = s[jnp.maximum(first - 1, 0)]
            b_j = jnp.where(any_neg, s[first], jnp.inf)
            a_j = jnp.where(graze, s[jnp.maximum(kmin - 1, 0)], a_j)
            b_j = jnp.where(graze, t_min, b_j)
            hit = any_neg | graze
            # the earliest bracket holds the first crossing (entries that cross inside the
            # same sub-interval are told apart by their order in g only)
            j_hit = jnp.argmin(b_j)

            def bisect():
                # 16-section: evaluate 15 interior points at once and keep the sub-interval
                # of the first negative one (16^13 ~ 5e15 in all); taking the *first*
                # negative point never skips over an earlier dip
                def body(_, ab):
                    lo, hi = ab
                    tt = jnp.linspace(lo, hi, 17)
                    neg = jax.vmap(lambda u: gj(j_hit, u))(tt) < 0
                    neg = neg.at[16].set(True)
                    kk = jnp.maximum(jnp.argmax(neg), 1)
                    return tt[kk - 1], tt[kk]

                lo, hi = jax.lax.fori_loop(0, 13, body, (a_j[j_hit], b_j[j_hit]))
                return hi  # first time found outside the limit

            # under vmap, finished runs keep being stepped (and masked): exclude them
            any_hit = jnp.any(hit) & active
            t_cross = jax.lax.cond(eqxi.unvmap_any(any_hit), bisect, lambda: jnp.inf)
            t_cross = jnp.where(any_hit, t_cross, jnp.inf)
            g_seen = jnp.where(near, jnp.minimum(g_lo, g_min), g_lo)
            return t_cross, j_hit, g_seen, d_seen

        def save_until(c, interp, t_stop, keep):
            """Write the saved times in (t, t_stop] of an accepted step, SAVE_BLOCK at a
            time (one vectorised interpolant evaluation and one scatter; only the rows
            written are touched, never the whole history)."""
            def block(k, ys):
                idx = k + jnp.arange(SAVE_BLOCK)
                tt = ts_save[jnp.minimum(idx, n_save - 1)]
                mask = (idx < n_save) & (tt <= t_stop) & keep
                vals = jax.vmap(interp.evaluate)(tt) * scale
                ys = ys.at[jnp.where(mask, idx, n_save)].set(vals, mode="drop")
                return k + jnp.sum(mask), ys

            def more(sc):
                k, _ = sc
                return keep & (k < n_save) & (ts_save[jnp.minimum(k, n_save - 1)] <= t_stop)

            # the first block always (most steps hold fewer than SAVE_BLOCK saved times)
            k, ys = block(c["save_idx"], c["ys"])
            return jax.lax.while_loop(more, lambda sc: block(*sc), (k, ys))

        def step(c, full):
            """One attempted step; a no-op once the run is over (``cond`` false), so that
            several steps can share one loop iteration.

            ``full=False`` (the inner loop): the event samples are checked, and a step in
            which a limit may have been crossed or grazed is *not* taken but flagged, so
            the loop contains no conditional (an XLA conditional costs ~6 us per step on
            CPU even when not taken). ``full=True`` takes the flagged step again with the
            complete search (grazing refinement, crossing bisection)."""
            active = cond(c)
            t, tn = c["t"], c["tnext"]
            if unrolled is not None:
                z1, zerr, dense, sstate1 = unrolled(
                    lambda z: rhs(z * scale, p) / scale, c["z"], c["sstate"], tn - t)
            else:
                z1, zerr, dense, sstate1, _ = solver.step(
                    term, t, tn, c["z"], p, c["sstate"], c["made_jump"])
            zerr = jnp.where(jnp.isnan(zerr), jnp.inf, zerr)
            keep, tprev2, tnext2, made_jump2, cstate2, _ = controller.adapt_step_size(
                t, tn, c["z"], z1, p, zerr, order, c["cstate"])
            finite = jnp.all(jnp.isfinite(z1))
            interp = interp_cls(t0=t, t1=tn, **dense)
            flag = jnp.asarray(False)
            if m and not full:
                _, G, any_neg, near, d_seen = sample_events(interp, t, tn)
                flag = active & keep & finite & jnp.any(any_neg | near)
                active = active & ~flag
            keep = keep & finite & active
            tnext2 = jnp.where(tnext2 > t_end - 100 * eps * jnp.abs(t_end), t_end, tnext2)
            tnext2 = jnp.where(finite, tnext2, t + 0.25 * (tn - t))
            tprev2 = jnp.where(keep, tprev2, t)
            tnext2 = jnp.where(active, tnext2, tn)
            cstate2 = jax.tree_util.tree_map(lambda a, b: jnp.where(active, a, b),
                                             cstate2, c["cstate"])

            if m and full:
                t_hit, j_hit, gmin_step, d_seen = locate_event(interp, t, tn, keep)
            elif m:  # nothing near a limit in this step (else it was flagged)
                t_hit, j_hit, gmin_step = jnp.asarray(jnp.inf), jnp.asarray(0), jnp.min(G, 0)
            if m:
                collide = keep & jnp.isfinite(t_hit)
                # values past a collision inside the step are not part of the run
                gmin_step = jnp.where(collide, jnp.maximum(gmin_step, 0.0), gmin_step)
                gmin = jnp.where(keep, jnp.minimum(c["gmin"], gmin_step), c["gmin"])
            else:
                t_hit, j_hit, collide, gmin = jnp.inf, -1, jnp.asarray(False), c["gmin"]
                d_seen = jnp.asarray(0.0)

            t_stop = jnp.where(collide, t_hit, tn)
            if n_save:
                save_idx, ys = save_until(c, interp, t_stop, keep)
            else:
                save_idx, ys = c["save_idx"], c["ys"]

            z_new = jnp.where(keep, z1, c["z"])
            z_hit = interp.evaluate(jnp.where(collide, t_hit, tn))
            d = jnp.max(jnp.abs(z_new - zref))
            inside = d <= converge_tol
            conv_since = jnp.where(
                keep, jnp.where(inside, jnp.minimum(c["conv_since"], tn), jnp.inf),
                c["conv_since"])
            was_inside = jnp.isfinite(c["conv_since"])
            peak = jnp.where(keep, jnp.where(
                inside, jnp.where(was_inside, jnp.maximum(c["peak"], jnp.maximum(d, d_seen)), d),
                jnp.inf), c["peak"])
            status = jnp.where(collide, COLLISION, c["status"])
            steps = c["steps"] + active.astype(int)
            return dict(
                t=jnp.where(collide, t_hit, tprev2),
                tnext=tnext2,
                z=jnp.where(collide, z_hit, z_new),
                sstate=jax.tree_util.tree_map(lambda a, b: jnp.where(keep, a, b),
                                              sstate1, c["sstate"]),
                cstate=cstate2,
                made_jump=jnp.where(keep, made_jump2, c["made_jump"]),
                status=status,
                t_event=jnp.where(collide, t_hit, c["t_event"]),
                i_event=jnp.where(collide, j_hit, c["i_event"]),
                z_event=jnp.where(collide, z_hit, c["z_event"]),
                conv_since=conv_since,
                peak=peak,
                ys=ys, save_idx=save_idx, steps=steps,
                accepted=c["accepted"] + keep.astype(int),
                rejected=c["rejected"] + (active & ~keep).astype(int),
                gmin=gmin, flagged=flag,
                # a rejected step that can no longer shrink: the step is at the resolution
                # of t (a singularity, e.g. a finite-time blow-up); the run fails now
                # instead of spending max_steps on it (and, in a batch, every run with it)
                stuck=c["stuck"] | (active & ~keep & (tn - t <= 64 * eps * jnp.abs(tn))),
            )

        c = jax.lax.while_loop(cond, lambda cc: step(cc, True), carry)
        conv_done = settled_of(c)
        finite = jnp.all(jnp.isfinite(c["z"]))
        incomplete = (c["status"] == RUNNING) & (c["t"] < t_end) & ~conv_done
        status = jnp.where(c["status"] == COLLISION, COLLISION,
                           jnp.where(~finite | incomplete, FAILED,
                                     jnp.where(conv_done, CONVERGED, RUNNING)))
        return dict(
            status=status, t_event=c["t_event"], i_event=c["i_event"],
            t_final=c["t"], x_final=c["z"] * scale,
            conv_since=jnp.where(conv_done, c["conv_since"], jnp.inf),
            ys=c["ys"], gmin=c["gmin"], steps=c["steps"], accepted=c["accepted"],
            rejected=c["rejected"], ref_max_real=ref_max_real, ref_residual=ref_residual,
            near=jnp.isfinite(c["conv_since"]) & ((c["t"] - c["conv_since"]) >= hold_time),
            stuck=c["stuck"],
        )

    return kernel


@lru_cache(maxsize=64)
def compiled_kernel(rhs, event_fn, solver_name: str, samples: int, n_save: int,
                     stop_on_converged: bool, batch_x: bool, batch_p: bool,
                     unroll_stages: bool | None = None):
    def kernel(*args):
        # built when traced, not here: a kernel loaded ahead of time (aot.py) then never
        # imports diffrax (~0.45 s of a warm command's start-up)
        return _make_kernel(rhs, event_fn, solver_name, samples, n_save, stop_on_converged,
                            unroll_stages, batched=batch_x or batch_p)(*args)

    if batch_x or batch_p:
        axes = (0 if batch_x else None, 0 if batch_p else None) + (None,) * 12
        kernel = jax.vmap(kernel, in_axes=axes)
    return cached_kernel(kernel, rhs, event_fn, solver_name, samples, n_save,
                         stop_on_converged, batch_x, batch_p, unroll_stages)
