"""Periodic orbits of a hybrid system by collocation per segment.

**Periodic orbits by collocation per segment** (:func:`hybrid_periodic_orbit`): an orbit
visiting the modes s_0, ..., s_{S-1} is S segments u_i'(tau) = T_i f(u_i, p, s_i) on
tau in [0, 1], each by orthogonal collocation on its own mesh (the Gauss points, Lagrange
basis and collocation kernel of :mod:`maglev_match.dynamics.collocation`), joined by the
boundary conditions of COCO's 'hspo' toolbox (Dankowicz & Schilder 2013, *Recipes for
Continuation*, sec. 9.3 and 17.2): each segment ends on the event surface of its switch,
h_{k_i}(u_i(1)) = 0, and the next starts at the reset image,
u_{i+1}(0) = R(u_i(1)) (circularly). The event conditions fix the phase, so no phase
condition is needed; the unknowns are the node values and the durations T_i, solved by
Newton's method on the sparse system. The initial segments come from a run of the flow
(:func:`segments_from_flow`); the derivative of the orbit with respect to the parameters
follows from the implicit function theorem on the same system
(:func:`orbit_parameter_derivative`); the multipliers are those of
:mod:`maglev_match.dynamics.hybrid.floquet`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import cache
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import scipy.sparse
import scipy.sparse.linalg

from maglev_match.core import jax_setup  # noqa: F401  (float64)
from maglev_match.core.reprs import compact_repr
from maglev_match.dynamics.collocation import node_times
from maglev_match.dynamics.hybrid.floquet import hybrid_floquet
from maglev_match.dynamics.hybrid.flow import FlowOptions, hybrid_flow
from maglev_match.dynamics.hybrid.saltation import switch_parts
from maglev_match.dynamics.hybrid.system import HybridSystem, identity_project

__all__ = [
    "Segment",
    "HybridOrbit",
    "hybrid_periodic_orbit",
    "segments_from_flow",
    "orbit_parameter_derivative",
]


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
        proj = self.hs.project or identity_project
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
                _, _, x_new, Rx, hx, _, _ = (np.asarray(a) for a in switch_parts(
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
        proj = self.hs.project or identity_project
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
            *_, Rp, hp = (np.asarray(a) for a in switch_parts(
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

