"""The driver of a two-parameter curve of cycle bifurcations: :func:`cycle_curve` corrects a
cycle at a located LPC or PD onto the minimally augmented system
(:mod:`~maglev_match.dynamics.cycle_curves.augmented`) and follows it by pseudo-arclength
continuation in (p1, p2), with Newton's method on the exact Jacobian (sparse LU), step
control, mesh adaptation and the Floquet multipliers of every point.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import scipy.sparse

from maglev_match.dynamics.collocation import (
    CollocationProblem,
    adapt_mesh,
    factorize,
    remesh,
)
from maglev_match.dynamics.continuation import SpecialPoint, label_points
from maglev_match.dynamics.cycle_curves.augmented import (
    AugmentedCycleSystem,
    CurveKind,
    Evaluation,
)
from maglev_match.dynamics.cycle_curves.codim2 import (
    codim2_rest,
    codim2_tests,
    detect_codim2,
    torus_pair,
)
from maglev_match.dynamics.cycle_curves.cusp import solve_cusp
from maglev_match.dynamics.cycle_curves.flip import flip_coefficient
from maglev_match.dynamics.cycle_curves.illinois import illinois
from maglev_match.dynamics.cycle_curves.ns import NSCycleSystem, critical_angle
from maglev_match.dynamics.cycle_curves.results import CurveStop, CycleCurve, CycleCurvePoint
from maglev_match.dynamics.cycle_curves.torus import torus_coefficient
from maglev_match.dynamics.cycles.orbits import PeriodicOrbit, orbit_extrema
from maglev_match.dynamics.cycles.problem import LimitFn, limit_margin
from maglev_match.dynamics.cycles.stability import floquet_multipliers, split_trivial
from maglev_match.dynamics.floquet import floquet_multipliers_from_blocks
from maglev_match.dynamics.system import System

__all__ = ["cycle_curve"]


def _scale_of(value: float, given: float | None) -> float:
    if given is not None:
        return float(given)
    return 0.05 * abs(value) if abs(value) > 1e-12 else 0.05


class _Newton:
    """Newton's method on (augmented system; one linear row) = (0; target)."""

    def __init__(self, aug: AugmentedCycleSystem, tol: float, max_iter: int):
        self.aug, self.tol, self.max_iter = aug, tol, max_iter

    def __call__(self, z, row, target, Uref):
        aug = self.aug
        phase = aug.prob.phase_row(Uref)
        for it in range(1, self.max_iter + 1):
            try:
                ev = aug.evaluate(z, phase, Uref)
                F = np.append(ev.resid, float(row @ z) - target)
                lu = factorize(_with_row(ev.jac, row))
                dz = lu.solve(-F)
            except (RuntimeError, ValueError, np.linalg.LinAlgError):
                return None
            if not np.all(np.isfinite(dz)):
                return None
            z = z + dz
            if float(np.max(np.abs(dz))) < self.tol:
                # converged: the last iterate's evaluation and factorisation serve the
                # borders, the reported test value and residual, and the tangent (they are
                # within the tolerance of the solution's)
                return z, ev, lu, it, float(np.max(np.abs(F)))
        return None


def _with_row(jac: scipy.sparse.coo_matrix, row: np.ndarray) -> scipy.sparse.csc_matrix:
    """The square Newton matrix: the augmented Jacobian with the linear row below."""
    n = row.size
    return scipy.sparse.csc_matrix(
        (np.concatenate([jac.data, row]),
         (np.concatenate([jac.row, np.full(n, jac.shape[0])]),
          np.concatenate([jac.col, np.arange(n)]))), shape=(jac.shape[0] + 1, n))


def _tangent(lu: Any, W: np.ndarray, orient: np.ndarray | None) -> np.ndarray:
    """The unit tangent from the factorised Newton matrix (its last row the linear
    condition): the solution of [jac; row] t = e_last, oriented along ``orient``."""
    e = np.zeros(W.size)
    e[-1] = 1.0
    t = lu.solve(e)
    t /= math.sqrt(float(np.sum(W * t * t)))
    if orient is not None and float(np.sum(W * t * orient)) < 0:
        t = -t
    return t


def cycle_curve(
    system: System,
    orbit: PeriodicOrbit,
    kind: str,
    params: tuple[str, str],
    *,
    ranges: dict[str, tuple[float, float]] | None = None,
    direction: int = 1,
    max_steps: int = 200,
    ds: float = 0.02,
    ds_min: float = 1e-7,
    ds_max: float = 0.5,
    tol: float = 1e-10,
    max_newton: int = 10,
    adapt_every: int = 0,
    scales: tuple[float | None, float | None] = (None, None),
    trivial_tol: float = 1e-4,
    observables: Sequence[str] | None = None,
    detect: bool = True,
    marks: Sequence[float] = (),
    limits: LimitFn | None = None,
) -> CycleCurve:
    """Continue a fold (``kind="LPC"``), period doubling (``"PD"``) or Neimark-Sacker
    bifurcation (``"NS"``; the start angle theta from the orbit's complex pair of
    multipliers nearest the unit circle) of cycles in the two
    parameters ``params`` = (p1, p2), from a cycle ``orbit`` at (or near) the bifurcation
    (e.g. the solved cycle of a special point of a one-parameter branch,
    ``SpecialPoint.point.orbit``; its mesh and NCOL are kept).

    The start is first corrected onto the curve at the orbit's p2 (p1, the profile and the
    period free), then the curve is followed towards increasing p2 (``direction=-1``:
    decreasing; ``0``: both ways, one curve ordered from its decreasing end) with the
    arclength weights of the cycle branch (profile RMS in
    ``system.state_scale``, period in units of the start period, p1 and p2 in ``scales``:
    default 5 % of their start values, 0.05 at zero).

    Parameters
    ----------
    ranges : {name: (lo, hi)} for p1 and/or p2: the curve ends on the first bound it
        reaches, with a point solved exactly there (kind "bound").
    max_steps, ds, ds_min, ds_max : accepted steps and the arclength step (scaled units).
    tol, max_newton : Newton's tolerance on the scaled update and iterations per corrector.
    adapt_every : adapt the mesh every this many steps (0: never).
    trivial_tol : largest |mu_trivial - 1| at which the multipliers are reported (and the
        codimension-two test functions evaluated).
    observables : names whose max/min over each cycle are read out (default: all).
    marks : values of p2 at which a point is solved exactly on the curve (kind "mark"),
        e.g. to compare with one-parameter branches there.
    detect : locate the codimension-two points (:mod:`~maglev_match.dynamics.
        cycle_curves.codim2`).
    limits : ``limits(system, orbit)`` -> mapping of limit name -> margin (positive
        inside), as for cycle branches: where the smallest margin of the curve's cycle
        passes zero (e.g. the cycle's largest gap deviation reaches a gap limit) the curve
        stops, with the point solved on the curve there (kind "contact", a special point
        "contact") and the reason CONTACT.

    An NS curve ends where its angle theta reaches pi (R2, the point solved at theta =
    pi) or 0 (R1, bracketed): ``stopped_reason`` RESONANCE, the point in ``message``.

    Returns
    -------
    :class:`CycleCurve`. A failure (the start not corrected, the step falling below
    ``ds_min``) ends the curve with its reason and a warning; it never raises.
    """
    if direction == 0:
        return _both_ways(system, orbit, kind, params, **{
            k: v for k, v in locals().items() if k not in ("system", "orbit", "kind", "params",
                                                           "direction")})
    kind = CurveKind(kind)
    p1n, p2n = params
    i1, i2 = system.param_index(p1n), system.param_index(p2n)
    if i1 == i2:
        raise ValueError(f"params = {params!r}: the two parameters must differ")
    names = tuple(system.observables) if observables is None else tuple(observables)
    p = np.array(orbit.p, float)
    s1, s2 = _scale_of(p[i1], scales[0]), _scale_of(p[i2], scales[1])
    prob = CollocationProblem(system=system, ipar=i1, p0=p.copy(), mesh=np.array(orbit.mesh),
                              m=orbit.ncol, scale=np.asarray(system.state_scale, float),
                              T_scale=float(orbit.period), lam_scale=s1)
    theta0 = None
    if kind == CurveKind.NS:  # the start angle: the pair of the start orbit's multipliers
        theta0 = critical_angle(floquet_multipliers(system, orbit))
        aug: AugmentedCycleSystem = NSCycleSystem(
            prob, i2, s2, math.nan if theta0 is None else theta0)
    else:
        aug = AugmentedCycleSystem(prob, i2, s2, kind)
    W = aug.weights()
    newton = _Newton(aug, tol, max_newton)
    bounds = {}
    for name, (lo, hi) in (ranges or {}).items():
        if name not in params:
            raise ValueError(f"ranges: {name!r} is not one of the curve's parameters "
                             f"{params!r}")
        bounds[aug.i_p1 if name == p1n else aug.i_p2] = (float(lo), float(hi))
    warnings: list[str] = []
    stats = {"iterations": 0, "rejected": 0}

    def make_point(z, ev: Evaluation, its, res, kind_="step") -> CycleCurvePoint:
        U, T, v1, v2 = aug.unpack(z)
        J, Tb, h = prob.jacobian_blocks(aug.split(z)[0])
        mult = floquet_multipliers_from_blocks(
            J, Tb, h, prob.m, method=getattr(system, "floquet_method", "auto"))
        triv, rest = split_trivial(mult)
        reliable = bool(abs(triv - 1.0) <= trivial_tol)
        orb = PeriodicOrbit(mesh=prob.mesh.copy(), ncol=prob.m, states=U.copy(), period=T,
                            p=prob.params(v1))
        amp = float(np.max(np.linalg.norm((U - U[:-1].mean(axis=0)) / prob.scale, axis=1)))
        fc = flip_coefficient(system, orb) if kind == CurveKind.PD and reliable else None
        flip = dict(flip=fc.c, flip_error=fc.error) if fc is not None and fc.ok else {}
        if kind == CurveKind.NS and reliable:  # the NS coefficient d (CH where it vanishes)
            tc = torus_coefficient(system, orb, aug.angle(z))
            if tc.ok:
                flip = dict(ns_coefficient=tc.d, ns_error=tc.error)
        return CycleCurvePoint(values=(v1, v2), period=T, amplitude=amp, orbit=orb,
                               multipliers=rest if reliable else np.zeros(0, complex),
                               trivial_multiplier=triv, reliable=reliable, test=ev.g,
                               iterations=its, residual=res,
                               extrema=orbit_extrema(system, orb, names), kind=kind_,
                               angle=aug.angle(z), **flip)

    states: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []  # (z, t, mesh) per point

    def finish(points, reason, message="", end: SpecialPoint | None = None):
        sps = detect_codim2(kind, points, params) if detect else []
        if sps and len(states) == len(points):
            sps = [_solve(sp, states, aug, newton, make_point, W, tol) for sp in sps]
        if end is not None:  # the resonance the NS curve ended on, and no duplicate of it
            sps = [sp for sp in sps if sp is None or sp.type != end.type
                   or sp.step < end.step - 1] + [end]
        if sps:
            sps = label_points([sp for sp in sps if sp is not None])
        return CycleCurve(kind=str(kind), params=(p1n, p2n), points=tuple(points),
                          special_points=tuple(sps), stopped_reason=str(reason),
                          warnings=tuple(warnings), message=message, ntst=prob.mesh.size - 1,
                          ncol=prob.m, steps=max(len(points) - 1, 0),
                          rejected_steps=stats["rejected"],
                          newton_iterations=stats["iterations"])

    # --- the start: correct onto the curve at fixed p2
    if kind == CurveKind.NS and theta0 is None:
        warnings.append(f"the start at {p2n} = {p[i2]:.10g} has no complex pair of "
                        "Floquet multipliers: it is not at a Neimark-Sacker point")
        return finish([], CurveStop.START_FAILED)
    z = aug.join(prob.pack(orbit.states, orbit.period, p[i1]), p[i2])
    aug.init_borders(z)
    e2 = np.zeros(aug.size)
    e2[aug.i_p2] = 1.0
    out = newton(z, e2, float(z[aug.i_p2]), orbit.states)
    if out is None:
        warnings.append(f"the start at {p2n} = {p[i2]:.10g} could not be corrected onto the "
                        f"{kind} curve (Newton's method failed): is the orbit at a {kind}?")
        return finish([], CurveStop.START_FAILED)
    z, ev, J, its, res = out
    stats["iterations"] += its
    aug.update_borders(ev)
    points = [make_point(z, ev, its, res, "start")]
    t = _tangent(J, W, None) * (1.0 if direction >= 0 else -1.0)
    states.append((z, t, prob.mesh.copy()))
    h = min(max(ds, ds_min), ds_max)
    accepted = 0
    while accepted < max_steps:
        z_pred = z + h * t
        row = W * t
        U_prev = aug.unpack(z)[0]
        out = newton(z_pred, row, float(row @ z_pred), U_prev)
        if out is not None:
            z_new = out[0]
            d = z_new - z
            if float(np.sqrt(np.sum(W * d * d))) > 3.0 * h or not aug.unpack(z_new)[1] > 0:
                out = None
        if out is None:
            stats["rejected"] += 1
            h *= 0.5
            if h < ds_min:
                U, T, v1, v2 = aug.unpack(z)
                warnings.append(f"the {kind} curve stopped at ({p1n}, {p2n}) = ({v1:.10g}, "
                                f"{v2:.10g}): the step fell below ds_min = {ds_min:g} "
                                "(Newton's method failed to converge on the curve)")
                return finish(points, CurveStop.STEP_TOO_SMALL)
            continue
        z_new, ev, J, its, res = out
        stats["iterations"] += its
        # a bound crossed: the marks before it, the point exactly on it, and the end
        hit = _crossed(bounds, z, z_new, aug)
        frac = 1.0
        if hit is not None:
            idx, bound = hit
            frac = (bound / _sc(aug, idx) - z[idx]) / (z_new[idx] - z[idx])
        z2, dz2 = float(z[aug.i_p2]), float(z_new[aug.i_p2] - z[aug.i_p2])
        inside = _marks_inside(marks, z2 * aug.scale2, (z2 + frac * dz2) * aug.scale2) \
            if dz2 else []
        for mark in inside:
            fm = (mark / aug.scale2 - z2) / dz2
            e = np.zeros(aug.size)
            e[aug.i_p2] = 1.0
            om = newton(z + fm * (z_new - z), e, mark / aug.scale2, U_prev)
            if om is None:
                warnings.append(f"the point at {p2n} = {mark:.10g} (a value asked for) "
                                "could not be solved")
                continue
            points.append(make_point(om[0], om[1], om[3], om[4], "mark"))
            states.append((om[0], t, prob.mesh.copy()))
        if hit is not None:
            e = np.zeros(aug.size)
            e[idx] = 1.0
            ob = newton(z + frac * (z_new - z), e, bound / _sc(aug, idx), U_prev)
            if ob is not None:
                zb, evb, _, itb, resb = ob
                aug.update_borders(evb)
                points.append(make_point(zb, evb, itb, resb, "bound"))
                states.append((zb, t, prob.mesh.copy()))
                return finish(points, CurveStop.BOUND)
            warnings.append(f"the point on the bound {bound:g} could not be solved; the "
                            "curve ends at the last point before it")
            return finish(points, CurveStop.BOUND)
        if limits is not None:  # a physical limit reached over the step: the curve ends
            con = _contact(limits, system, aug, newton, points[-1], z, z_new, t, W,
                           U_prev, make_point, tol)
            if con is not None:
                pt, z_end, sp = con
                points.append(pt)
                states.append((z_end, t, prob.mesh.copy()))
                v1, v2 = pt.values
                return finish(points, CurveStop.CONTACT, f"the cycle reaches the limit "
                              f"{sp.detail} at ({p1n}, {p2n}) = ({v1:.10g}, {v2:.10g})",
                              dataclasses.replace(sp, step=len(points) - 1))
        if kind == CurveKind.NS:  # the NS curve ends where theta reaches pi (R2) or 0 (R1)
            end = _resonance_end(aug, newton, z, z_new, U_prev, make_point, len(points))
            if end is not None:
                pt, z_end, sp, note = end
                if pt is not None:
                    points.append(pt)
                    states.append((z_end, t, prob.mesh.copy()))
                v1, v2 = sp.values
                return finish(points, CurveStop.RESONANCE, f"the NS curve ends at a "
                              f"{note} at ({p1n}, {p2n}) = ({v1:.10g}, {v2:.10g})", sp)
        aug.update_borders(ev)
        t = _tangent(J, W, t)
        z = z_new
        accepted += 1
        points.append(make_point(z, ev, its, res))
        states.append((z, t, prob.mesh.copy()))
        if its <= 3:
            h = min(h * 1.5, ds_max)
        elif its >= 7:
            h = max(h * 0.6, ds_min)
        if adapt_every and accepted % adapt_every == 0:
            z, t = _adapt(aug, z, t, W)
    return finish(points, CurveStop.MAX_STEPS)


def _both_ways(system, orbit, kind, params, **kw) -> CycleCurve:
    """Both halves of the curve from the start (decreasing p2, then increasing), as one
    curve ordered by increasing p2 at its ends; the special points renumbered."""
    down = cycle_curve(system, orbit, kind, params, direction=-1, **kw)
    up = cycle_curve(system, orbit, kind, params, direction=1, **kw)
    if not down.points or not up.points:
        return up if up.points else down
    nb = len(down.points)
    points = list(reversed(down.points)) + list(up.points[1:])
    sps = [dataclasses.replace(sp, step=nb - 2 - sp.step) for sp in down.special_points]
    sps += [dataclasses.replace(sp, step=nb - 1 + sp.step) for sp in up.special_points]
    sps.sort(key=lambda sp: sp.step)
    reason = down.stopped_reason if not down.ok else up.stopped_reason  # a failure first
    return dataclasses.replace(
        up, points=tuple(points), special_points=tuple(label_points(sps)),
        stopped_reason=reason,
        message=f"decreasing {params[1]}: {down.stopped_reason}; increasing: "
                f"{up.stopped_reason}",
        warnings=down.warnings + up.warnings, steps=down.steps + up.steps,
        rejected_steps=down.rejected_steps + up.rejected_steps,
        newton_iterations=down.newton_iterations + up.newton_iterations)


def _solve(sp, states, aug: AugmentedCycleSystem, newton: _Newton, make_point: Callable,
           W: np.ndarray, tol: float) -> Any:
    """Solve a bracketed codimension-two point of the multiplier (and NS angle) tests on the
    curve (R1, a singular point of the NS system, and R2 on a PD curve, a singular point of
    the PD system, stay bracketed): the
    zero of its test function along the step from point k (Illinois iterations on the
    arclength, each a point corrected onto the curve). Points of other kinds, and steps
    over which the mesh was adapted, stay bracketed; None for an NS zero that turns out to
    be a neutral saddle (no complex pair on the unit circle there)."""
    k = sp.step
    if sp.type == "CPC":
        return solve_cusp(sp, states, aug, newton, make_point, W, tol, _tangent)
    if sp.type not in ("LPPD", "LPNS", "PDNS", "R2", "R3", "R4", "GPD", "CH") \
            or (sp.type == "R2" and aug.kind != CurveKind.NS) or k + 1 >= len(states):
        return sp
    (za, ta, mesh_a), (zb, _, mesh_b) = states[k], states[k + 1]
    if not np.array_equal(mesh_a, mesh_b):
        return sp
    prob = aug.prob
    prob.mesh = mesh_a.copy()
    aug.init_borders(za)
    Ua = aug.unpack(za)[0]
    row = W * ta

    def at(s):
        z0 = za + s * ta
        out = newton(z0, row, float(row @ z0), Ua)
        if out is None:
            return None, np.nan
        pt = make_point(out[0], out[1], out[3], out[4], sp.type)
        if aug.kind == CurveKind.NS and sp.type in ("R2", "R3", "R4"):  # the solved angle
            return pt, codim2_tests(aug.kind, np.zeros(0, complex), pt.angle)[sp.type]
        if sp.type == "GPD":  # the coefficient itself, however small (its zero is sought)
            return pt, pt.flip
        if sp.type == "CH":  # the NS coefficient d, however small
            return pt, pt.ns_coefficient
        return pt, codim2_tests(aug.kind, pt.multipliers, pt.angle).get(sp.type, np.nan) \
            if pt.reliable else np.nan

    lo, hi = 0.0, float(row @ (zb - za))
    flo, fhi = at(lo)[1], at(hi)[1]
    if not (np.isfinite(flo) and np.isfinite(fhi)) or flo * fhi >= 0:
        return sp
    best, f, done = illinois(at, lo, hi, flo, fhi, tol, 1e-13)
    if not done:
        return sp
    if aug.kind != CurveKind.NS and sp.type in ("LPNS", "PDNS") and not torus_pair(
            codim2_rest(aug.kind, best.multipliers), 1e-4):
        return None  # a neutral saddle, no torus bifurcation
    if sp.type == "GPD" and not abs(f) <= max(best.flip_error, 1e-9 * max(abs(flo), 1.0)):
        return None  # the coefficient changed sign through a pole (a second -1: R2)
    if sp.type == "CH" and not abs(f) <= max(best.ns_error, 1e-9 * max(abs(flo), 1.0)):
        return None  # d changed sign through a pole (a strong resonance)
    return dataclasses.replace(sp, value=best.values[0], values=best.values, located="solved",
                               detail=f"test function {f:.2e} there", period=best.period,
                               point=best)


def _contact(limits: LimitFn, system: System, aug, newton: _Newton, last, z: np.ndarray,
             z_new: np.ndarray, t: np.ndarray, W: np.ndarray, U_prev: np.ndarray,
             make_point: Callable, tol: float) -> Any:
    """Where the smallest limit margin of the curve's cycle passes zero over the step z ->
    z_new: the point on the curve there (Illinois iterations on the arclength along the
    step, each a point corrected onto the curve), its unknowns and a special point
    "contact" (solved, or bracketed at the last point before it if the solve fails).
    None if the margin stays positive (or was negative already at z)."""
    fa, _ = limit_margin(limits, system, last.orbit)
    row = W * t
    span = float(row @ (z_new - z))
    lo, hi = 0.0, span

    def at(s):
        z0 = z + (s / span) * (z_new - z)
        out = newton(z0, row, float(row @ z0), U_prev)
        if out is None:
            return None, np.nan
        pt = make_point(out[0], out[1], out[3], out[4], "contact")
        m, name = limit_margin(limits, system, pt.orbit)
        return (pt, out[0], name), m

    end, fb = at(hi)
    if not (fa >= 0 and np.isfinite(fb) and fb < 0):
        return None
    name = end[2]
    found, f, _ = illinois(at, lo, hi, fa, fb, tol, 1e-12)
    best = found[:2] if found is not None else None
    if found is not None:
        name = found[2]
    if best is None or not abs(f) < 1e-8:
        return None if end is None else (end[0], end[1], SpecialPoint(
            type="contact", value=end[0].values[0], values=end[0].values, step=0,
            located="bracketed: the first point past the limit (the contact could not be "
            "solved)", detail=name or "limit", period=end[0].period, point=end[0]))
    pt, zc = best
    return pt, zc, SpecialPoint(type="contact", value=pt.values[0], values=pt.values,
                                step=0, located="solved", detail=name or "limit",
                                period=pt.period, point=pt)


def _resonance_end(aug, newton: _Newton, z: np.ndarray, z_new: np.ndarray,
                   U_prev: np.ndarray, make_point: Callable, step: int) -> Any:
    """Where theta crossed an odd multiple of pi (R2: the critical pair meets at -1) or a
    multiple of 2 pi (R1: at +1) over the step z -> z_new: the NS curve ends there (past
    it, the same torus points are met again with the conjugate angle, or the pair is real:
    PD or LPC curves begin there). R2 is solved with theta fixed at that multiple of pi
    (the NS system is regular there); R1, a singular point of the system, is bracketed
    between the two points. Returns (the solved end point and its unknowns, or None and
    None; the special point; a phrase), or None if theta crossed neither."""
    a, b = aug.angle(z), aug.angle(z_new)
    ka, kb = math.floor(a / math.pi), math.floor(b / math.pi)
    if ka == kb:
        return None
    m = max(ka, kb)  # theta crossed m pi
    name = "R2" if m % 2 else "R1"
    f = (m * math.pi - a) / (b - a)
    note = ("1:2 resonance (theta = pi: the critical pair meets at -1)" if name == "R2"
            else "1:1 resonance (theta = 0: the critical pair meets at +1)")
    if name == "R2":
        e = np.zeros(aug.size)
        e[-1] = 1.0
        out = newton(z + f * (z_new - z), e, m * math.pi, U_prev)
        if out is not None:
            pt = make_point(out[0], out[1], out[3], out[4], "R2")
            return pt, out[0], SpecialPoint(type="R2", value=pt.values[0], values=pt.values,
                                    step=step, located="solved", detail="theta = pi there "
                                    "(the end of the NS curve)", period=pt.period,
                                    point=pt), note
    vals = tuple(float(x + f * (y - x)) for x, y in zip(aug.unpack(z)[2:], aug.unpack(
        z_new)[2:], strict=True))
    return None, None, SpecialPoint(type=name, value=vals[0], values=vals, step=step - 1,
                              located="bracketed between two consecutive points of the "
                              "curve (linear interpolation of theta, not solved; the "
                              "curve ends at the last point before it)",
                              detail=f"theta {a:.6g} and {b:.6g} at the two points"), note


def _marks_inside(marks: Sequence[float], a: float, b: float) -> list[float]:
    """The marks strictly between a and b, or at b, in the order a -> b."""
    inside = [m for m in marks if (m - a) * (m - b) < 0 or m == b]
    return sorted(inside, reverse=bool(b < a))


def _sc(aug: AugmentedCycleSystem, idx: int) -> float:
    return aug.scale2 if idx == aug.i_p2 else aug.prob.lam_scale


def _crossed(bounds, z, z_new, aug) -> tuple[int, float] | None:
    for idx, (lo, hi) in bounds.items():
        a, b = z[idx] * _sc(aug, idx), z_new[idx] * _sc(aug, idx)
        for bound in (lo, hi):
            if (a - bound) * (b - bound) < 0 or (b == bound and a != bound):
                return idx, bound
    return None


def _adapt(aug: AugmentedCycleSystem, z: np.ndarray, t: np.ndarray, W: np.ndarray
           ) -> tuple[np.ndarray, np.ndarray]:
    """A new mesh (same NTST) for the profile at z: profile, tangent and the right border
    remapped, the borders refreshed."""
    prob = aug.prob
    U, T, v1, v2 = aug.unpack(z)
    Y_t = t[:aug.i_p2]
    Ut, Tt, lt = prob.unpack(Y_t)
    old = prob.mesh
    new = adapt_mesh(old, prob.m, U, prob.scale)
    U2 = remesh(old, prob.m, U, new)
    Ut2 = remesh(old, prob.m, Ut, new)
    N, n = prob.N, prob.n
    c = aug.c
    cU = remesh(old, prob.m, c[:N * n].real.reshape(N, n), new).ravel()
    if np.iscomplexobj(c):  # the NS border
        cU = cU + 1j * remesh(old, prob.m, c[:N * n].imag.reshape(N, n), new).ravel()
    prob.mesh = new
    z2 = np.concatenate([prob.pack(U2, T, v1), z[aug.i_p2:]])  # p2 (and theta) unchanged
    t2 = np.concatenate([prob.pack(Ut2, Tt, lt), t[aug.i_p2:]])
    t2 /= math.sqrt(float(np.sum(W * t2 * t2)))
    aug.init_borders(z2, np.concatenate([cU, c[N * n:]]))
    return z2, t2


def start_from(branch: Any, label: str) -> PeriodicOrbit:
    """The solved cycle of the special point ``label`` of a one-parameter cycle branch."""
    for sp in branch.special_points:
        if sp.label == label and sp.point is not None:
            return sp.point.orbit
    have = ", ".join(sp.label for sp in branch.special_points) or "none"
    raise ValueError(f"label = {label!r}: no special point with a solved cycle of that "
                     f"label on the branch (its special points: {have})")
