"""The critical member of a one-parameter family of initial states x0(d): the size d_c that
separates runs that stay inside a region from runs that leave it, solved as an equation.

Model-agnostic (any :class:`~maglev_match.dynamics.hybrid.HybridSystem`). Two mechanisms can
decide d_c, and each gives a smooth scalar equation in d with a derivative, so d_c follows
by Newton's method and its dependence on the parameters by the implicit function theorem:

* **Grazing** (:func:`solve_grazing`). The run touches the limit g = w . x = L of a linear
  observable tangentially at a finite time t*: the extremum of g along the run reaches the
  limit. The conditions

      w . x(t*; d) = L,      w . f(x(t*; d)) = 0      (an extremum: the rate of g vanishes)

  are solved for (d, t*): t* is located for each d as the stop of the flow at the extremum
  (:class:`~maglev_match.dynamics.hybrid.LinearStop`), which solves the second equation
  exactly, and d by Newton on the first with dG/dd = w . dx(t*)/dd (the rate term vanishes at
  t*: the envelope theorem). At the solution dd_c/dp = -(w . dx(t*)/dp) / (w . dx(t*)/dd) and
  dd_c/dL = 1 / (w . dx(t*)/dd) (Dankowicz & Schilder 2013, ch. 17, grazing conditions;
  di Bernardo et al. 2008, sec. 2.6 on grazing).
* **A basin boundary** (:func:`solve_basin_boundary`). The run lands on the stable manifold
  of a saddle-type periodic orbit (one Floquet multiplier mu_u outside the unit circle): runs
  on either side follow the orbit for a time that grows like log|d - d_c| / log|mu_u| per
  period, then leave on opposite sides. Near the orbit point x* (a section point of the
  cycle) the local stable manifold is, to first order, {x : l . (x - x*) = 0} with l the
  left eigenvector of the monodromy matrix for mu_u (l . f(x*) = 0, so the condition does not
  depend on where along the orbit direction the run is read). The condition

      G(d) = l . (x(t_k; d) - x*) = 0

  at the k-th crossing t_k of the section through x*, with k chosen where the near-critical
  run is closest to the orbit, is solved by Newton's method; its error is quadratic in the
  distance |x(t_k) - x*| (the curvature of the manifold). The parameter derivative adds the
  motion of the orbit: dG/dp = l . (dx(t_k)/dp - dx*/dp), dx*/dp from the periodic-orbit
  condition (:func:`~maglev_match.dynamics.hybrid.shoot_hybrid_orbit`).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from maglev_match.core.reprs import compact_repr
from maglev_match.dynamics.hybrid import (
    FlowOptions,
    FlowStatus,
    HybridFlow,
    HybridSystem,
    LinearStop,
    hybrid_flow,
)

__all__ = ["GrazingSolution", "solve_grazing", "grazing_derivative", "extrema_walk",
           "run_to_extremum", "BoundarySolution", "solve_basin_boundary", "section_walk",
           "basin_boundary_derivative"]


@dataclass(frozen=True)
class GrazingSolution:
    """The solved grazing condition.

    size : d_c (units of d); t_star : time of the tangency (s); x_star : the state there;
    s_star : the mode there; converged : Newton met the tolerance; iterations : Newton
    steps; residual : w . x(t*) - L at the last iterate (units of g); slope : dG/dd at the
    solution (side * w . dx(t*)/dd: the rate at which the extremum passes the limit per unit
    of d; > 0 for a clean crossing); curvature : d^2 g/dt^2 at t* (units of g per s^2; the
    tangency is non-degenerate where it is not 0); message : why not converged;
    singular : the limit is a singularity of the field (e.g. a magnet force growing without
    bound at gap 0): runs past it have no extremum, the extremum reaches the limit without a
    finite slope, and the size is converged by closing the bracket of sizes (to ``tol``)
    with the residual small (|G| <= SINGULAR_RESIDUAL |L|) rather than by the residual
    alone.
    """

    __repr__ = compact_repr

    size: float
    t_star: float
    x_star: np.ndarray
    s_star: np.ndarray
    converged: bool
    iterations: int
    residual: float
    slope: float
    curvature: float
    message: str = ""
    history: tuple[tuple[float, float], ...] = field(default=(), repr=False)
    singular: bool = False  # a contact at a singular limit: converged by the size bracket


#: a contact at a singular limit is accepted with the extremum within this fraction of the
#: limit's magnitude (8 mm gap deviation: 0.8 um) once the bracket of sizes has closed
SINGULAR_RESIDUAL = 1e-4


def _batch_size(b: int) -> int:
    """Batches are padded to a power of two, so a few compiled shapes serve every size."""
    return 1 << max(0, (int(b) - 1).bit_length())


def _pad(a: np.ndarray, B: int) -> np.ndarray:
    a = np.asarray(a)
    if a.shape[0] == B:
        return a
    return np.concatenate([a, np.repeat(a[-1:], B - a.shape[0], axis=0)], axis=0)


def run_to_extremum(hs: HybridSystem, x0: np.ndarray, tangents: np.ndarray | None,
                    param_tangents: np.ndarray | None, stop: LinearStop, t_arm: np.ndarray,
                    t_max: np.ndarray, p: np.ndarray, s0: np.ndarray | None,
                    options: FlowOptions):
    """The flow to ``t_arm``, then on to the first stop after it (two calls of the same
    kernel; the stop condition is off in the first). Batched: x0 (B, n), t_arm and t_max
    (B,), p (B, np). Returns the second call's :class:`~maglev_match.dynamics.hybrid.HybridFlow`
    (runs that did not reach t_arm keep their first-call status)."""
    first = hybrid_flow(hs, x0, t_arm, s0=s0, p=p, tangents=tangents,
                        param_tangents=param_tangents, options=options)
    second = hybrid_flow(hs, first.x, t_max, t_start=first.t, s0=first.s, p=p,
                         tangents=first.phi if tangents is not None else None,
                         param_tangents=param_tangents, stop=stop, options=options)
    bad = first.status != FlowStatus.REACHED
    if np.any(bad):
        status = np.where(bad, first.status, second.status)
        second = HybridFlow(**{**second.__dict__, "status": status})
    return second


def solve_grazing(
    hs: HybridSystem,
    x0_of: Callable[[np.ndarray], np.ndarray],
    dx0_dd: Callable[[np.ndarray], np.ndarray],
    w: np.ndarray,
    limit: Any,
    side: Any,
    d0: Any,
    t_arm: Any,
    t_max: Any,
    *,
    p: np.ndarray | None = None,
    s0: np.ndarray | None = None,
    tol: float = 1e-12,
    max_iter: int = 30,
    bracket: tuple[Any, Any] | None = None,
    options: FlowOptions | None = None,
) -> list[GrazingSolution]:
    """Solve the grazing conditions (module docstring) for the size d of each of B runs at
    once (one batched flow per Newton step).

    Parameters
    ----------
    hs : the system; x0_of(d) (B, n) and dx0_dd(d) (B, n) : the family of initial states
        and its tangent, for sizes d (B,).
    w : the linear observable g = w . x, (n,) or (B, n) (a gap deviation, say).
    limit : L (units of g), scalar or (B,).
    side : +1 where the run's maximum of g grazes L from below, -1 for a minimum from above.
    d0 : starting sizes (e.g. the midpoint of a bisection bracket).
    t_arm : times before the grazing extremum after which the rate of side * g is positive
        (e.g. half-way from the previous extremum of the other kind) (s); t_max : bounds on
        t* (s).
    p, s0 : parameters (np,) or (B, np) and initial modes.
    tol : relative tolerance on d (and |G| <= tol |L| + 1e-15).
    bracket : (lo, hi) within which each solution is looked for, sizes above the solution
        colliding; a Newton step leaving it is replaced by bisection of it, and an iterate
        whose run has no extremum in its window (it went through the limit) becomes the
        bracket's upper end.
    options : integrator settings (tight by default: rtol = atol = 1e-10).

    Returns
    -------
    One :class:`GrazingSolution` per run (converged False with a message when Newton fails,
    a run has no extremum in its window, or the derivative vanishes).
    """
    opts = options or FlowOptions()
    d = np.atleast_1d(np.asarray(d0, float)).copy()
    nb = d.size
    B = _batch_size(nb)
    n = hs.dim
    pp = np.asarray(hs.p if p is None else p, float)
    pp = _pad(np.broadcast_to(np.atleast_2d(pp), (nb, pp.shape[-1])), B)
    W = np.broadcast_to(np.atleast_2d(np.asarray(w, float)), (nb, n))
    L = np.broadcast_to(np.asarray(limit, float), (nb,)).copy()
    sd = np.broadcast_to(np.asarray(side, float), (nb,)).copy()
    ta = _pad(np.broadcast_to(np.asarray(t_arm, float), (nb,)), B)
    tm = _pad(np.broadcast_to(np.asarray(t_max, float), (nb,)), B)
    s_init = None if s0 is None else _pad(np.broadcast_to(np.atleast_2d(s0),
                                                          (nb, hs.n_switches)), B)
    stop = LinearStop(a=_pad(sd[:, None] * W, B))
    if bracket is None:
        lo, hi = np.full(nb, -math.inf), np.full(nb, math.inf)
    else:
        lo = np.broadcast_to(np.asarray(bracket[0], float), (nb,)).copy()
        hi = np.broadcast_to(np.asarray(bracket[1], float), (nb,)).copy()
    active = np.ones(nb, bool)
    conv = np.zeros(nb, bool)
    msgs = [""] * nb
    its = np.zeros(nb, int)
    G = np.full(nb, np.nan)
    dG = np.full(nb, np.nan)
    xs = np.full((nb, n), np.nan)
    ss = np.zeros((nb, hs.n_switches))
    tstar = np.full(nb, np.nan)
    d_ok = np.full(nb, np.nan)  # the last size whose run had its extremum (x*, t* are its)
    lo_set = np.zeros(nb, bool)
    hi_set = np.zeros(nb, bool)
    singular = np.zeros(nb, bool)
    hist: list[list[tuple[float, float]]] = [[] for _ in range(nb)]
    for _ in range(max_iter):
        if not active.any():
            break
        dp = _pad(d, B)
        X0 = np.asarray(x0_of(dp), float)
        T0 = np.asarray(dx0_dd(dp), float).reshape(B, n, 1)
        fl = run_to_extremum(hs, X0, T0, None, stop, ta, tm, pp, s_init, opts)
        for b in np.flatnonzero(active):
            its[b] += 1
            if fl.status[b] != FlowStatus.STOPPED:
                # no extremum: the run went through the limit (or into a singularity of the
                # field beyond it, e.g. a force that grows without bound at gap 0); within a
                # bracket that side is the colliding one: bisect back towards it
                if math.isfinite(lo[b]) and lo[b] < d[b] < hi[b]:
                    hi[b], hi_set[b] = d[b], True
                    hist[b].append((float(d[b]), math.nan))
                    # a contact at a singular limit: the extremum approaches the limit
                    # without a finite slope, the bracket of sizes closes instead
                    if (lo_set[b] and hi[b] - lo[b] <= 4 * tol * abs(d[b]) and G[b] < 0
                            and abs(G[b]) <= SINGULAR_RESIDUAL * abs(L[b]) + 1e-12):
                        conv[b], singular[b], active[b] = True, True, False
                        continue
                    d[b] = 0.5 * (lo[b] + hi[b])
                    continue
                msgs[b] = (f"the run at size {d[b]:.10g} has no extremum of the observable "
                           f"between t = {ta[b]:.6g} s and {tm[b]:.6g} s")
                active[b] = False
                continue
            xs[b], ss[b], tstar[b] = fl.x[b], fl.s[b], fl.t[b]
            d_ok[b] = d[b]
            G[b] = sd[b] * (float(W[b] @ fl.x[b]) - L[b])
            dG[b] = sd[b] * float(W[b] @ fl.phi[b][:, 0])
            hist[b].append((float(d[b]), float(G[b])))
            ftol = tol * abs(L[b]) + 1e-15
            if abs(G[b]) <= ftol:
                conv[b], active[b] = True, False
                continue
            if not (math.isfinite(dG[b]) and dG[b] != 0.0):
                msgs[b] = (f"the extremum does not move with the size at {d[b]:.10g} "
                           f"(dG/dd = {dG[b]:.3g})")
                active[b] = False
                continue
            # G < 0: the extremum stays short of the limit; the side of d_c follows dG
            if (G[b] < 0) == (dG[b] > 0):
                lo[b], lo_set[b] = max(lo[b], d[b]), True
            else:
                hi[b], hi_set[b] = min(hi[b], d[b]), True
            d_new = d[b] - G[b] / dG[b]
            if not (lo[b] < d_new < hi[b]) and math.isfinite(lo[b]) and math.isfinite(hi[b]):
                d_new = 0.5 * (lo[b] + hi[b])
            if abs(d_new - d[b]) <= tol * max(abs(d[b]), 1e-300):
                conv[b] = abs(G[b]) <= 1e3 * ftol
                if (not conv[b] and G[b] < 0 and abs(G[b]) <= SINGULAR_RESIDUAL * abs(L[b])
                        and not (hi_set[b] and hi[b] - d[b] <= 4 * tol * abs(d[b]))):
                    # the extremum is still short of the limit but barely moves: probe just
                    # above, where a singular limit has no extremum (closing the bracket)
                    d[b] = d[b] + 2 * tol * abs(d[b]) * (1 if dG[b] > 0 else -1)
                    continue
                if not conv[b]:
                    msgs[b] = f"Newton stalled at size {d[b]:.12g} with residual {G[b]:.3g}"
                d[b] = d_new
                active[b] = False
                continue
            d[b] = d_new
    for b in np.flatnonzero(active):
        msgs[b] = f"Newton did not converge in {max_iter} steps (residual {G[b]:.3g})"
    out = []
    for b in range(nb):
        curv = math.nan
        ok = bool(conv[b])
        msg = msgs[b]
        if ok:
            curv = _curvature(hs, xs[b], ss[b], pp[b], W[b])
            if not (math.isfinite(curv) and sd[b] * curv < 0):
                ok = False
                msg = (f"the extremum at t* = {tstar[b]:.6g} s is not a clean tangency (second "
                       f"derivative {curv:.3g})")
        size = float(d_ok[b]) if singular[b] else float(d[b])
        out.append(GrazingSolution(size=size, t_star=float(tstar[b]), x_star=xs[b],
                                   s_star=ss[b], converged=ok, iterations=int(its[b]),
                                   residual=float(G[b]), slope=float(dG[b]), curvature=curv,
                                   message=msg, history=tuple(hist[b]),
                                   singular=bool(singular[b])))
    return out


def _curvature(hs: HybridSystem, x: np.ndarray, s: np.ndarray, p: np.ndarray,
               w: np.ndarray) -> float:
    """d^2 (w . x)/dt^2 = w . f_x f at (x, s) (one compiled kernel per vector field, so
    that it is not traced primitive by primitive at every call)."""
    from maglev_match.core.jax_setup import kernel_arg

    jf = _curvature_kernel(hs.rhs)(kernel_arg(x, float), kernel_arg(p, float),
                                   kernel_arg(s, float))
    return float(np.asarray(w) @ np.asarray(jf))


@functools.cache
def _curvature_kernel(rhs: Callable) -> Callable:
    """x, p, s -> f_x f of the vector field ``rhs`` (jitted, exported ahead of time)."""
    import jax

    from maglev_match.core.aot import cached_kernel

    def fxf(x, p, s):
        f = rhs(x, p, s)
        return jax.jvp(lambda y: rhs(y, p, s), (x,), (f,))[1]

    return cached_kernel(fxf, rhs, name="escape.curvature")


def grazing_derivative(
    hs: HybridSystem,
    sizes: Any,
    x0_of: Callable[[np.ndarray], np.ndarray],
    dx0_dd: Callable[[np.ndarray], np.ndarray],
    w: np.ndarray,
    side: Any,
    t_arm: Any,
    t_max: Any,
    *,
    p: np.ndarray | None = None,
    s0: np.ndarray | None = None,
    dx0_dp: np.ndarray | None = None,
    options: FlowOptions | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """dd_c/dp (every parameter of ``hs``) and dd_c/dL at converged grazing sizes (B,), by
    the implicit function theorem on G(d, p) = side (w . x(t*; d, p) - L) = 0 (module
    docstring): one flow with 1 + n_params sensitivity columns. ``dx0_dp`` (n, np) or
    (B, n, np): how the initial state moves with the parameters (zeros by default).
    Returns (dd_dp (B, np), dd_dL (B,), t* (B,)); NaN where the run has no extremum."""
    opts = options or FlowOptions()
    d = np.atleast_1d(np.asarray(sizes, float))
    nb = d.size
    B = _batch_size(nb)
    n = hs.dim
    pp = np.asarray(hs.p if p is None else p, float)
    npar = pp.shape[-1]
    pp = _pad(np.broadcast_to(np.atleast_2d(pp), (nb, npar)), B)
    W = np.broadcast_to(np.atleast_2d(np.asarray(w, float)), (nb, n))
    sd = np.broadcast_to(np.asarray(side, float), (nb,))
    dp = _pad(d, B)
    tang = np.zeros((B, n, 1 + npar))
    tang[:, :, 0] = np.asarray(dx0_dd(dp), float)
    if dx0_dp is not None:
        tang[:, :, 1:] = np.broadcast_to(np.asarray(dx0_dp, float), (B, n, npar))
    ptang = np.zeros((B, npar, 1 + npar))
    ptang[:, :, 1:] = np.eye(npar)
    s_init = None if s0 is None else _pad(np.broadcast_to(np.atleast_2d(s0),
                                                          (nb, hs.n_switches)), B)
    stop = LinearStop(a=_pad(sd[:, None] * W, B))
    fl = run_to_extremum(hs, np.asarray(x0_of(dp), float), tang, ptang, stop,
                         _pad(np.broadcast_to(np.asarray(t_arm, float), (nb,)), B),
                         _pad(np.broadcast_to(np.asarray(t_max, float), (nb,)), B), pp,
                         s_init, opts)
    dd_dp = np.full((nb, npar), np.nan)
    dd_dL = np.full(nb, np.nan)
    ts = np.full(nb, np.nan)
    for b in range(nb):
        if fl.status[b] != FlowStatus.STOPPED:
            continue
        dg = sd[b] * (W[b] @ fl.phi[b])  # (1 + np,)
        dd_dp[b] = -dg[1:] / dg[0]
        dd_dL[b] = sd[b] / dg[0]
        ts[b] = fl.t[b]
    return dd_dp, dd_dL, ts


def extrema_walk(hs: HybridSystem, x0: np.ndarray, w: np.ndarray, t_end: float,
                 *, p: np.ndarray | None = None, s0: np.ndarray | None = None,
                 max_extrema: int = 400, options: FlowOptions | None = None
                 ) -> list[tuple[float, float, int]]:
    """The successive extrema of g = w . x along one run from t = 0 up to ``t_end``:
    [(t_k, g_k, kind_k)] with kind +1 for a maximum and -1 for a minimum, alternating. Each
    is the stop of the flow at the next extremum of the other kind, and the run continues
    from there (for choosing the window of a grazing solve, or the period of a cycle)."""
    opts = options or FlowOptions()
    n = hs.dim
    pp = np.asarray(hs.p if p is None else p, float)
    w = np.asarray(w, float)
    x = np.asarray(x0, float)
    s = np.zeros(hs.n_switches) if s0 is None else np.asarray(s0, float)
    # the first extremum: whichever kind the rate points to (the curvature decides where a
    # run starts at rest, with a zero rate)
    fx = hs.f(x, s, pp)
    rate = float(w @ fx)
    if abs(rate) <= 1e-12 * float(np.max(np.abs(fx) / hs.state_scale) * np.sum(
            np.abs(w) * hs.state_scale)):
        rate = _curvature(hs, x, s, pp, w)
    kind = 1 if rate > 0 else -1
    t = 0.0
    out: list[tuple[float, float, int]] = []
    zero = np.zeros((n, 1))
    while t < t_end and len(out) < max_extrema:
        fl = hybrid_flow(hs, x, t_end, t_start=t, s0=s, p=pp, tangents=zero,
                         stop=LinearStop(a=kind * w), options=opts)
        if fl.status[0] != FlowStatus.STOPPED:
            break
        t, x, s = float(fl.t[0]), fl.x[0], fl.s[0]
        out.append((t, float(w @ x), kind))
        kind = -kind
    return out


# ---------------------------------------------------------------------------------------
# basin boundary
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class BoundarySolution:
    """The solved basin-boundary condition.

    size : d_c; converged; iterations; residual : G at the last iterate (along the unstable
    eigenvector, in units of the state scale); distance : max_i |x_i(t_k) - x*_i| / scale_i
    at the solution (the linearisation error is quadratic in it); t_land : the crossing
    time t_k (s); slope : dG/dd; message.
    """

    __repr__ = compact_repr

    size: float
    converged: bool
    iterations: int
    residual: float
    distance: float
    t_land: float
    slope: float
    message: str = ""
    x_land: np.ndarray | None = field(default=None, repr=False)
    s_land: np.ndarray | None = field(default=None, repr=False)


def section_walk(hs: HybridSystem, x0: np.ndarray, normal: np.ndarray, point: np.ndarray,
                 t_end: float, *, p: np.ndarray | None = None, s0: np.ndarray | None = None,
                 max_crossings: int = 2000, options: FlowOptions | None = None
                 ) -> list[tuple[float, np.ndarray, np.ndarray]]:
    """The successive crossings of the hyperplane normal . (x - point) = 0 in the direction
    of ``normal`` along one run from t = 0 up to ``t_end`` (or until the flow fails):
    [(t_k, x_k, s_k)]."""
    opts = options or FlowOptions()
    pp = np.asarray(hs.p if p is None else p, float)
    nrm = np.asarray(normal, float)
    stop = LinearStop(b=-nrm, c=float(nrm @ np.asarray(point, float)))
    x = np.asarray(x0, float)
    s = np.zeros(hs.n_switches) if s0 is None else np.asarray(s0, float)
    t = 0.0
    out: list[tuple[float, np.ndarray, np.ndarray]] = []
    zero = np.zeros((hs.dim, 1))
    while t < t_end and len(out) < max_crossings:
        fl = hybrid_flow(hs, x, t_end, t_start=t, s0=s, p=pp, tangents=zero, stop=stop,
                         options=opts)
        if fl.status[0] != FlowStatus.STOPPED:
            break
        t, x, s = float(fl.t[0]), fl.x[0], fl.s[0]
        out.append((t, x.copy(), s.copy()))
    return out


def _along_section(hs: HybridSystem, phi: np.ndarray, x: np.ndarray, s: np.ndarray,
                   p: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """Sensitivities of the section crossing point: the flow component that moves the
    crossing time is removed, v - f (n . v) / (n . f)."""
    f = hs.f(x, s, p)
    return phi - np.outer(f, normal @ phi) / float(normal @ f)


def solve_basin_boundary(
    hs: HybridSystem,
    x0_of: Callable[[np.ndarray], np.ndarray],
    dx0_dd: Callable[[np.ndarray], np.ndarray],
    x_star: np.ndarray,
    left: np.ndarray,
    normal: np.ndarray,
    d0: float,
    t_arm: float,
    t_max: float,
    *,
    p: np.ndarray | None = None,
    s0: np.ndarray | None = None,
    tol: float = 1e-12,
    max_iter: int = 15,
    bracket: tuple[float, float] | None = None,
    options: FlowOptions | None = None,
) -> BoundarySolution:
    """Solve G(d) = l . (x(t_k; d) - x*) = 0 for d (module docstring).

    ``x_star`` : the orbit point on the section {normal . (x - x*) = 0}, crossed in the
    direction of ``normal``; ``left`` : the left eigenvector l of the monodromy matrix at x*
    for the unstable multiplier; ``t_arm`` : a time shortly before the crossing to use (a
    quarter of a period, say) and ``t_max`` a bound on it (s). The other arguments as in
    :func:`solve_grazing` (one run).
    """
    opts = options or FlowOptions()
    pp = np.asarray(hs.p if p is None else p, float)
    nrm = np.asarray(normal, float)
    xs = np.asarray(x_star, float)
    lv = np.asarray(left, float)
    stop = LinearStop(b=-nrm, c=float(nrm @ xs))
    sc = np.asarray(hs.state_scale, float)
    d = float(d0)
    lo, hi = (bracket if bracket is not None else (-math.inf, math.inf))
    msg = ""
    G = dG = math.nan
    conv = False
    x_land = s_land = None
    t_land = dist = math.nan
    it = 0
    while it < max_iter:
        it += 1
        X0 = np.asarray(x0_of(np.array([d])), float)
        T0 = np.asarray(dx0_dd(np.array([d])), float).reshape(1, hs.dim, 1)
        fl = run_to_extremum(hs, X0, T0, None, stop, np.array([t_arm]), np.array([t_max]),
                             pp[None], None if s0 is None else np.atleast_2d(s0), opts)
        if fl.status[0] != FlowStatus.STOPPED:
            msg = (f"the run at size {d:.10g} does not cross the orbit's section between "
                   f"t = {t_arm:.6g} s and {t_max:.6g} s")
            break
        x_land, s_land, t_land = fl.x[0], fl.s[0], float(fl.t[0])
        phi = _along_section(hs, fl.phi[0], x_land, s_land, pp, nrm)[:, 0]
        G = float(lv @ (x_land - xs))
        dG = float(lv @ phi)
        dist = float(np.max(np.abs(x_land - xs) / sc))
        if not (math.isfinite(dG) and dG != 0.0):
            msg = f"the landing point does not move with the size at {d:.10g}"
            break
        if (G < 0) == (dG > 0):
            lo = max(lo, d)
        else:
            hi = min(hi, d)
        d_new = d - G / dG
        if not (lo < d_new < hi) and math.isfinite(lo) and math.isfinite(hi):
            d_new = 0.5 * (lo + hi)
        if abs(d_new - d) <= tol * max(abs(d), 1e-300):
            d = d_new
            conv = True
            break
        d = d_new
    if not conv and not msg:
        msg = f"Newton did not converge in {max_iter} steps (residual {G:.3g})"
    return BoundarySolution(size=d, converged=conv, iterations=it, residual=G, distance=dist,
                            t_land=t_land, slope=dG, message=msg, x_land=x_land,
                            s_land=s_land)


def basin_boundary_derivative(
    hs: HybridSystem,
    size: float,
    x0_of: Callable[[np.ndarray], np.ndarray],
    dx0_dd: Callable[[np.ndarray], np.ndarray],
    x_star: np.ndarray,
    left: np.ndarray,
    normal: np.ndarray,
    dxstar_dp: np.ndarray,
    t_arm: float,
    t_max: float,
    *,
    p: np.ndarray | None = None,
    dx0_dp: np.ndarray | None = None,
    options: FlowOptions | None = None,
) -> np.ndarray:
    """dd_c/dp at a solved basin boundary of size ``size``:
    -(l . (dx(t_k)/dp - dx*/dp)) / (l . dx(t_k)/dd),
    the crossing point's sensitivities taken along the section; ``dxstar_dp`` (n, np) the
    motion of the orbit point (from the periodic-orbit condition). NaN where the run does
    not reach the section."""
    opts = options or FlowOptions()
    pp = np.asarray(hs.p if p is None else p, float)
    n, npar = hs.dim, pp.size
    nrm = np.asarray(normal, float)
    xs = np.asarray(x_star, float)
    tang = np.zeros((1, n, 1 + npar))
    tang[0, :, 0] = np.asarray(dx0_dd(np.array([size])), float)[0]
    if dx0_dp is not None:
        tang[0, :, 1:] = dx0_dp
    ptang = np.zeros((1, npar, 1 + npar))
    ptang[0, :, 1:] = np.eye(npar)
    stop = LinearStop(b=-nrm, c=float(nrm @ xs))
    fl = run_to_extremum(hs, np.asarray(x0_of(np.array([size])), float), tang, ptang,
                         stop, np.array([t_arm]), np.array([t_max]), pp[None], None, opts)
    if fl.status[0] != FlowStatus.STOPPED:
        return np.full(npar, np.nan)
    phi = _along_section(hs, fl.phi[0], fl.x[0], fl.s[0], pp, nrm)
    lv = np.asarray(left, float)
    dG = lv @ phi  # (1 + np,)
    dG_dp = dG[1:] - lv @ np.asarray(dxstar_dp, float)
    return -dG_dp / dG[0]
