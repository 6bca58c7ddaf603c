"""The branch of cycles from a Hopf point: :func:`cycle_branch` starts the family at the Hopf
point (or at a saved point, :class:`~maglev_match.dynamics.cycles.results.RestartState`),
runs the package's pseudo-arclength driver on
:class:`~maglev_match.dynamics.cycles.problem.CycleProblem`, and assembles the
:class:`~maglev_match.dynamics.cycles.results.CycleBranch`: the points with their
multipliers and restart states, the special points labelled as AUTO-07p and MatCont label
them, and the end of the branch in words (a homoclinic approach; the family closing at a
second Hopf point, refined on the Hopf defining system,
:func:`~maglev_match.dynamics.hopf.refine_hopf_point`; the end of the parameter's valid
range). :func:`correct_cycle` solves one cycle at a fixed parameter value.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from maglev_match.dynamics.collocation import (
    CollocationBVP,
    LinearSolver,
    collocation_newton,
    node_times,
)
from maglev_match.dynamics.continuation import (
    SOLVED,
    BranchPoint,
    ContinuationOptions,
    Correction,
    SpecialPoint,
    SpecialPointKind,
    StopReason,
    continuation,
    label_points,
)
from maglev_match.dynamics.cycles.options import (
    CycleOptions,
    MultipliersAt,
    NewtonMode,
    cycle_options,
)
from maglev_match.dynamics.cycles.orbits import (
    HopfStart,
    PeriodicOrbit,
    as_hopf_start,
    first_harmonic_mean,
    orbit_extrema,
)
from maglev_match.dynamics.cycles.problem import CycleProblem, LimitFn, limit_margin
from maglev_match.dynamics.cycles.results import (
    CorrectionResult,
    CycleBranch,
    CyclePoint,
    CycleStop,
    RestartState,
)
from maglev_match.dynamics.cycles.stability import (
    Stability,
    blocks_at,
    split_trivial,
    stability_of,
)
from maglev_match.dynamics.floquet import floquet_multipliers_from_blocks
from maglev_match.dynamics.system import System, chart_kernels

__all__ = [
    "CONTACT_SOLVED",
    "LAM_ZERO",
    "correct_cycle",
    "cycle_branch",
]


# parameter values this close to zero are zero to rounding (a located root at 0)
LAM_ZERO = 1e-12


def cycle_branch(
    system: System,
    hopf: Any,
    param: str,
    stop_at: float | None = None,
    *,
    options: CycleOptions | None = None,
    limits: LimitFn | None = None,
    progress: Callable[[int, CyclePoint], None] | None = None,
    observables: Sequence[str] | None = None,
    restart: RestartState | None = None,
    restart_param: str | None = None,
    **settings: Any,
) -> CycleBranch:
    """Continue the cycles born at a Hopf point in the parameter ``param``.

    The branch is followed by the package's one pseudo-arclength driver
    (:func:`~maglev_match.dynamics.continuation.continuation`) on the collocation problem
    (:class:`CycleProblem`). Special points are zeros of test functions located by solving
    inside the step where they change sign (each a converged periodic orbit), with the
    labels of AUTO-07p and MatCont:

    * LPC (fold of cycles): the parameter component of the tangent;
    * BP (branch point of cycles): a bordered test function of the arclength-extended
      Jacobian, which changes sign at a branch point and not at a fold;
    * PD / NS: products over the nontrivial multipliers (:func:`multiplier_tests`); NS
      only for a complex pair on the unit circle;
    * contact (not a bifurcation): the smallest margin to a physical limit, solved to the
      branch tolerance (terminal: the branch ends on the contact);
    * the stop value ``stop_at`` (terminal; the last point is then solved at exactly it).

    The ends of a branch are events too: a family that shrinks to an equilibrium ends at
    that (second) Hopf point, refined on the Hopf defining system and reported as the
    special point H (the family is closed between its two Hopf points); a period beyond
    ``max_period_factor`` times the Hopf period ends the branch as a homoclinic approach,
    with the last point whose multipliers are reliable named; the parameter's valid range
    (``system.param_ranges``) ends it like a bound.

    The trivial multiplier is checked at every point: when |mu_trivial - 1| exceeds
    ``trivial_tol`` the point's stability is marked unreliable (``CyclePoint.reliable``)
    and no test function (LPC, BP, PD, NS) is evaluated there. Systems with a
    :class:`~maglev_match.dynamics.system.RegularChart` are continued in it once an orbit
    comes near the set where their equations are singular; orbits are reported in the
    system's own coordinates.

    Parameters
    ----------
    system : the ODE system.
    hopf : a :class:`HopfStart` or a HopfPoint (attributes x, p, frequency, q, l1).
    param : continuation parameter name.
    stop_at : stop when the branch reaches this parameter value; the last point is the
        cycle solved exactly there (kind "stop_at").
    options : :class:`CycleOptions` (mesh, steps, tolerances, corrector, what to detect).
    limits : ``limits(system, orbit)`` -> mapping of limit name -> margin (positive
        inside, in any unit) or the name of the touched limit (None if none), called with
        the system and orbit in the coordinates of the continuation (use observables, which
        mean the same in every chart). The branch stops at the first contact, a solved
        orbit on the limit (kind "contact").
    progress : called as progress(step, point) after each accepted step.
    observables : names of the system's observables to read out (default: all).
    restart : continue from this saved point (:func:`load_restart`) instead of the Hopf
        point (``hopf`` still gives the scales); the new branch holds the points after it.
    restart_param : the parameter the restart state was continued in; when it differs
        from ``param`` the saved cycle is continued in ``param`` (a second parameter),
        towards larger values, the other parameters fixed at the saved point.
    **settings : any field of :class:`CycleOptions` by name (``ntst=60``, ``ds_max=0.5``,
        ...), applied over ``options``: the keyword form of earlier versions.

    Returns
    -------
    CycleBranch with the accepted points, special points (LPC, BP, PD, NS, H, contact),
    the reason the continuation stopped and warnings. Failure is reported, never raised.
    """
    opt = cycle_options(options, **settings)
    start = as_hopf_start(system, hopf, param)
    ipar = system.param_index(param)
    new_param = restart is not None and restart_param is not None and restart_param != param
    if new_param:  # continue the saved cycle in another parameter
        p_r = np.array(start.p, float)
        p_r[system.param_index(restart_param)] = restart.value
        start = dataclasses.replace(start, param=param, value=float(p_r[ipar]), p=p_r)
    names = tuple(system.observables) if observables is None else tuple(observables)
    T0 = 2.0 * math.pi / start.frequency
    lam0 = start.value
    lam_scale = opt.lam_scale
    if lam_scale is None:
        # 5 % of the parameter's size; a Hopf point located at a parameter value that is
        # zero to rounding (e.g. -3e-30 for a root at 0) has no size of its own: unit scale
        lam_scale = 0.05 * abs(lam0) if abs(lam0) > LAM_ZERO else 0.05
    m, ntst, tol = opt.ncol, opt.ntst, opt.tol
    max_newton = opt.max_newton
    # the chord iteration takes about twice Newton's iterations for the same step (linear
    # convergence at rate <= CHORD_MAX_RATE instead of quadratic): the Newton-count rule
    # reads "easy" as <= 5 and "slow" as >= 10 iterations then, and allows 8 more
    chord = opt.newton == NewtonMode.CHORD
    bounds = system.valid_bounds(param, opt.param_bounds)
    options = ContinuationOptions(
        ds=min(max(opt.ds, opt.ds_min), opt.ds_max), ds_min=opt.ds_min, ds_max=opt.ds_max,
        max_steps=opt.max_steps, newton_tol=tol,
        newton_max_iter=max_newton + (8 if chord else 0),
        predictor_tol=opt.predictor_tol, fast_iterations=5 if chord else 3,
        slow_iterations=10 if chord else 6, param_bounds=bounds)
    prob = CollocationBVP(system=system, ipar=ipar, p0=np.array(start.p, float),
                    mesh=np.linspace(0.0, 1.0, ntst + 1), m=m,
                    scale=np.asarray(system.state_scale, float), T_scale=T0,
                    lam_scale=float(lam_scale), linear_solver=LinearSolver(opt.linear_solver))
    W = prob.W()
    # --- the start: the Hopf point as a constant profile, tangent = eigenvector profile
    s_nodes = node_times(prob.mesh, m)
    qv = np.asarray(start.q, complex)
    V = np.real(qv[None, :] * np.exp(2j * math.pi * s_nodes)[:, None])
    Ueq = np.tile(start.x, (prob.N, 1))
    Yh = prob.pack(Ueq, T0, lam0)
    tY = np.concatenate([(V / prob.scale).ravel(), [0.0, 0.0]])
    tY /= math.sqrt(float(np.sum(W * tY * tY)))
    start_orbit = PeriodicOrbit(mesh=prob.mesh.copy(), ncol=m, states=Ueq, period=T0,
                                p=prob.params(lam0))
    cyc = CycleProblem(prob, names, limits, stop_at, opt, opt.max_period_factor * T0,
                       start_orbit)
    first = Correction(u=Yh, iterations=0, residual=0.0, solve=lambda e: tY,
                       data=(None, prob.mesh.copy(), None, None))

    def failed(why: str) -> CycleBranch:
        return CycleBranch(param=param, hopf=start, points=(), special_points=(),
                           stopped_reason=CycleStop.NEWTON_FAILED, warnings=(why,),
                           ntst=ntst, ncol=m, message=why)

    if restart is not None:
        prob.mesh = np.array(restart.mesh, float)
        U_r, tU_r = np.asarray(restart.states, float), np.asarray(restart.t_states, float)
        lam_r = lam0 if new_param else restart.value
        if cyc.chart is not None:  # a saved point near the singular set: in the chart
            k = chart_kernels(cyc.chart)
            p_r = prob.params(lam_r)
            d = float(np.min(np.asarray(k["distance"](U_r, p_r))))
            if d < cyc.chart.switch_below:
                dp = np.zeros_like(p_r)
                dp[ipar] = 0.0 if new_param else restart.t_value
                U_r, tU_r = (np.asarray(v) for v in k["to_tangent"](U_r, tU_r, p_r, dp))
                prob.system = system.in_chart()
                prob.scale = np.asarray(cyc.chart.state_scale, float)
                cyc.in_chart, cyc.chart_at = True, float(lam_r)
    if new_param:
        Yh = prob.pack(U_r, restart.period, lam0)
        fixed = _fixed_param(prob, Yh, lam0, tol, max_newton + 4)
        if fixed is None:
            return failed("the restart point does not converge")
        # the tangent in the new parameter: [A; e_lambda] t = e_last, towards larger values
        e_last = np.zeros(prob.size)
        e_last[-1] = 1.0
        tY = fixed.correction.solve(e_last)
        tY /= math.sqrt(float(np.sum(W * tY * tY)))
        cyc.restarting = True
        first = fixed.correction
        Yh = fixed.u
    elif restart is not None:
        Yh = prob.pack(U_r, restart.period, restart.value)
        tY = prob.pack(tU_r, restart.t_period, restart.t_value)
        tY /= math.sqrt(float(np.sum(W * tY * tY)))
        cyc.accepted = int(restart.accepted)
        cyc.restarting = True
        options = dataclasses.replace(options, ds=float(np.clip(restart.ds, opt.ds_min,
                                                                opt.ds_max)))
        row = W * tY
        first = cyc.correct(Yh, row, float(row @ Yh), max_newton)
        if opt.adapt_every and cyc.accepted % opt.adapt_every == 0:
            # the saved point had its mesh adapted: the uninterrupted run went on without a
            # kept factorisation from there, and so does the restart (same steps)
            cyc.chord_lu = None
        if first is None:
            return failed("the restart point does not converge")

    def notify(step, pt):
        if progress is not None and "cycle" in pt.info:
            cyc.complete(pt)
            progress(step, pt.info["cycle"])

    res = continuation(cyc, Yh, tY, options, progress=notify, first=first)
    return _assemble(cyc, res, start, param, stop_at, opt, limits, system, T0)


def _assemble(cyc: CycleProblem, res: Any, start: HopfStart, param: str,
              stop_at: float | None, opt: CycleOptions, limits: LimitFn | None,
              system: System, T0: float) -> CycleBranch:
    """The :class:`CycleBranch` from the driver's result: points with their multipliers and
    restart states, special points labelled, the end of the branch explained."""
    prob, tol, ntst, m = cyc.prob, opt.tol, opt.ntst, opt.ncol
    every = opt.multipliers_at == MultipliersAt.ALL or opt.detect_special_points
    # a branch ending at the stop value gets that cycle re-solved (with its multipliers)
    resolved = any(ev.kind == "STOP" and ev.point is not None for ev in res.events)
    for pt in res.points[1:]:
        if every or (pt is res.points[-1] and not resolved):
            cyc.complete(pt)
    for ev in res.events:
        cyc.complete(ev.point)
    warnings = list(cyc.warnings)
    points: list[CyclePoint] = []
    for pt in res.points[1:]:
        if "cycle" not in pt.info:
            continue
        c = pt.info["cycle"]
        if "state" in pt.info:
            phys, acc = pt.info["state"]
            c = dataclasses.replace(c, restart=cyc.restart_state(
                phys, float(pt.info.get("ds_next", opt.ds)), acc))
            pt.info["cycle"] = c
        points.append(c)
    specials: list[SpecialPoint] = []
    message = ""
    stopped: str = {StopReason.MAX_STEPS: CycleStop.MAX_STEPS,
                    StopReason.BOUND: CycleStop.BOUND}.get(res.stop_reason, "")
    if res.stop_reason == StopReason.PROBLEM:
        stopped = CycleStop(res.message)
    if res.stop_reason in (StopReason.STEP_TOO_SMALL, StopReason.NEWTON_FAILED):
        stopped = CycleStop.STEP_TOO_SMALL if points else CycleStop.NEWTON_FAILED
        message = (f"continuation stopped: no convergence after step {len(points)} "
                   f"with the smallest step {opt.ds_min:g} ({res.message})")
        warnings.append(message)
        if _homoclinic_trend(points, T0):
            stopped = CycleStop.HOMOCLINIC
    if stopped == CycleStop.HOMOCLINIC:
        message = _homoclinic_message(points, cyc.last_reliable, param, T0)
        warnings.append(message)
    if stopped == CycleStop.HOPF:
        # the last point passed the equilibrium (or fell onto it): the family closed
        # between the last two points; the Hopf point there is solved on its own system
        past = points.pop() if points else None
        sp, message = _closing_hopf(cyc, res, start, param, past, points, opt)
        if sp is not None:
            specials.append(sp)
        warnings.extend([message] if sp is None or sp.located != SOLVED else [])
    for ev in res.events:
        if ev.kind == SpecialPointKind.BOUND:
            if ev.point is not None and "cycle" in ev.point.info and points:
                points[-1] = dataclasses.replace(points[-1], kind="bound")
            ub = opt.param_bounds
            where = points[-1].value if points else float("nan")
            if ub is None or min(abs(where - ub[0]), abs(where - ub[1])) > \
                    1e-9 * max(1.0, abs(where)):  # not a bound the caller gave
                stopped = CycleStop.RANGE
                message = range_end_message(system, param, where)
                warnings.append(message)
            continue
        if ev.kind == "STOP":
            if ev.point is None:
                warnings.append(f"could not solve the cycle at {param} = {stop_at:g}")
                continue
            # the located point is refined at exactly the stop value
            fixed = _fixed_param(prob, ev.point.u, float(stop_at), tol, opt.max_newton + 4)
            if fixed is not None:
                c = cyc.cycle_point(fixed, kind="stop_at")
            else:  # reported, never passed off as the cycle at the stop value
                cyc.complete(ev.point)
                c = dataclasses.replace(ev.point.info["cycle"], kind="stop_at",
                                        converged=False)
                warnings.append(f"the cycle at {param} = {stop_at:g} did not converge; the "
                                f"branch point found near it ({param} = {c.value:.8g}) is "
                                "reported, marked not converged")
            if points and points[-1] is ev.point.info.get("cycle"):
                points[-1] = c
            else:
                points.append(c)
            stopped = CycleStop.STOP_AT
            continue
        kind = SpecialPointKind(ev.kind)
        if ev.point is None or "cycle" not in ev.point.info:
            warnings.append(f"{_kind_words(kind)} between steps {ev.step} and {ev.step + 1} "
                            f"not located: {ev.located}")
            if kind == SpecialPointKind.CONTACT:
                stopped = CycleStop.CONTACT
            continue
        c = ev.point.info["cycle"]
        detail, located = "", ev.located
        direct = ""
        confirm = bool(ev.point.info.get("bp_confirm"))
        polish = False
        if kind == SpecialPointKind.BP and located == SOLVED and not confirm:
            # "solved" with its multiplier still away from +1 (a zero pinned by a small
            # test value at the end of a long step): polished on the branch-point system
            mlt = np.asarray(c.multipliers)
            polish = bool(mlt.size and float(np.min(np.abs(mlt - 1.0))) > 1e-7)
        if kind == SpecialPointKind.BP and (located != SOLVED or confirm or polish):
            # the corrector failed next to the branch point: its own system instead
            ends = res.points[ev.step:ev.step + 2] if ev.step + 2 <= len(res.points) else []
            solved = _branch_point_directly(cyc, ev.point, opt, ends)
            if isinstance(solved, str) and confirm:
                continue  # a weak zero of the test that the system does not confirm
            if isinstance(solved, str) and polish:
                mlt = np.asarray(c.multipliers)
                located = (f"not solved: the test's zero was pinned at a trial whose "
                           f"multiplier is {float(np.min(np.abs(mlt - 1.0))):.1e} from +1; "
                           f"{solved}")
            elif isinstance(solved, str):
                located = f"{located}; {solved}"
            else:
                c, located = solved, SOLVED
                direct = "; solved on the branch-point system (the corrector failed inside " \
                    "the step)"
        if kind == SpecialPointKind.CONTACT:
            mg_c, lname = limit_margin(limits, prob.system, ev.point.info["orbit_here"])
            detail = lname
            if not opt.locate_limit:
                located = f"bracketed (margin {mg_c:.2e}; not solved: locate_limit=False)"
            elif located != SOLVED or abs(mg_c) > CONTACT_SOLVED:
                located = f"bracketed (margin {mg_c:.2e}): {ev.located}"
                warnings.append(f"contact with the limit '{lname}' bracketed, not solved: "
                                f"the corrector failed closer to it (margin {mg_c:.2e})")
            c = dataclasses.replace(c, kind="contact")
            if points and points[-1] is ev.point.info["cycle"]:
                points[-1] = c
            else:
                points.append(c)
            stopped = CycleStop.CONTACT
        else:
            c = dataclasses.replace(c, kind=str(kind), restart=cyc.restart_state(
                ev.point.info["phys"], float(opt.ds), 0))
            if kind in (SpecialPointKind.PD, SpecialPointKind.NS, SpecialPointKind.BP):
                mult = np.asarray(c.multipliers)
                target = {SpecialPointKind.PD: -1.0, SpecialPointKind.BP: 1.0}.get(kind)
                if target is None:
                    k = int(np.argmin(np.abs(np.abs(mult) - 1.0) + (np.abs(mult.imag) < 1e-9)))
                else:
                    k = int(np.argmin(np.abs(mult - target)))
                detail = f"multiplier {mult[k].real:.6g}{mult[k].imag:+.6g}j" + direct
            if located != SOLVED:
                warnings.append(f"{kind} at {param} = {c.value:.8g}: {located}")
        specials.append(SpecialPoint(type=kind, value=c.value, period=c.period,
                                     extrema=c.extrema, step=ev.step - 1, located=located,
                                     detail=detail, point=c))
    specials = label_points(_distinct_branch_points(specials, warnings, param))
    if cyc.chart_at is not None:
        warnings_note = (f"continued in the system's regular chart from {param} = "
                         f"{cyc.chart_at:.8g} on (an orbit came near the set where the "
                         "system's own equations are singular)")
        message = (message + "; " if message else "") + warnings_note
    if not stopped:
        stopped = str(res.stop_reason)
    return CycleBranch(param=param, hopf=start, points=tuple(points),
                       special_points=tuple(specials), stopped_reason=stopped,
                       warnings=tuple(warnings), ntst=ntst, ncol=m,
                       steps=max(len(res.points) - 1, 0), rejected_steps=res.rejected,
                       newton_iterations=cyc.stats.iterations,
                       factorizations=cyc.stats.factorizations, message=message,
                       chart_from=cyc.chart_at)


def _distinct_branch_points(specials: list[SpecialPoint], warnings: list[str], param: str
                            ) -> list[SpecialPoint]:
    """One report per branch point: two events solved onto the same point (1e-9 relative)
    keep the first, with a warning."""
    out: list[SpecialPoint] = []
    for sp in specials:
        same = [o for o in out if o.type == sp.type == SpecialPointKind.BP
                and abs(o.value - sp.value) <= 1e-9 * max(1.0, abs(sp.value))]
        if same:
            warnings.append(f"two sign changes of the BP test were solved onto the same branch "
                            f"point ({param} = {sp.value:.10g}): reported once")
            continue
        out.append(sp)
    return out


def _branch_point_directly(cyc: CycleProblem, pt: BranchPoint, opt: CycleOptions,
                           ends: Sequence[BranchPoint] = ()) -> CyclePoint | str:
    """The branch point near the event's best trial ``pt`` solved on the minimally
    augmented branch-point system (:func:`~maglev_match.dynamics.cycles.bp.
    solve_branch_point`), on that point's mesh; its cycle, or why not (kept only with a
    nontrivial multiplier within 1e-3 of 1, beta within 1e-8 and the parameter within 1 %
    of its scale of the trial, and, given the step's ``ends`` on the same mesh, inside the
    step along its first point's tangent: the branch point that was bracketed, not a
    neighbour beyond the step)."""
    from maglev_match.dynamics.cycles.bp import solve_branch_point

    if cyc.chart_at is not None:
        return "not solved on the branch-point system (the branch changed coordinates)"
    prob = cyc.prob
    mesh_now = prob.mesh
    prob.mesh = np.array(pt.correction.data[1], float)
    try:
        sol = solve_branch_point(prob, pt.u, tol=opt.tol, max_iter=opt.max_newton + 4)
        if not sol.converged:
            return f"the branch-point system did not converge either ({sol.message})"
        lam = float(prob.unpack(sol.Y)[2])
        corr = Correction(u=sol.Y, iterations=sol.iterations, residual=sol.residual,
                          solve=pt.correction.solve, data=(None, prob.mesh.copy(), None, None))
        c = cyc.cycle_point(BranchPoint(u=sol.Y, t=np.zeros_like(sol.Y), value=lam,
                                        correction=corr), kind="BP")
    finally:
        prob.mesh = mesh_now
    mult = np.asarray(c.multipliers)
    if not (c.reliable and mult.size and float(np.min(np.abs(mult - 1.0))) <= 1e-3
            and abs(sol.beta) <= 1e-8 and abs(lam - pt.value) <= 0.01 * prob.lam_scale):
        return (f"the branch-point system converged to {cyc.prob.system.param_names[prob.ipar]}"
                f" = {lam:.10g} (beta = {sol.beta:.2e}), not accepted")
    if len(ends) == 2 and all(np.array_equal(e.correction.data[1], pt.correction.data[1])
                              for e in ends):
        a, b = ends
        W = cyc.weights
        s_b = float(np.sum(W * a.t * (b.u - a.u)))
        s_bp = float(np.sum(W * a.t * (sol.Y - a.u)))
        if not -1e-9 * abs(s_b) <= s_bp <= s_b * (1.0 + 1e-9):
            return (f"the branch-point system converged to a branch point beyond the step "
                    f"({cyc.prob.system.param_names[prob.ipar]} = {lam:.10g})")
    return c


#: A contact whose margin is within this of zero is reported solved (the location runs to
#: CONTACT_TOL; this allows for the margin's rounding at the located orbit).
CONTACT_SOLVED = 1e-9


def range_end_message(system: System, param: str, where: float) -> str:
    """Why a branch stopped at the end of ``param``'s range, at ``where``: for the delay of
    a discretised delay system, the longest delay its intervals resolve (the equations go
    on beyond it: a discretisation for a longer delay continues further) or a delay
    shrinking to 0 (the delay-free system); else the model's own valid range."""
    lo, hi = (system.param_ranges or {}).get(param, (-np.inf, np.inf))
    dde = getattr(system, "dde", None)
    if dde is not None and param in getattr(dde, "delays", ()):
        if abs(where - hi) <= abs(where - lo):
            return (f"{param} reached {where:.8g}, at the longest delay ({hi:.6g}) that the "
                    f"discretisation of the delay ({getattr(system, 'nodes', '?')} Chebyshev "
                    "intervals) resolves: the delay equations go on beyond it; a larger "
                    "range of the delay (e.g. a larger --to) resolves longer delays")
        return (f"{param} reached {where:.8g}, next to {param} = 0, where the delay vanishes "
                "(the delay-free system); the continuation of the delay stops there")
    return (f"{param} reached the end of its valid range [{lo:.6g}, {hi:.6g}] at "
            f"{where:.8g}: the model is not defined beyond it")


def _kind_words(kind: str) -> str:
    return "contact with a physical limit" if kind == SpecialPointKind.CONTACT else str(kind)


def _homoclinic_trend(points: Sequence[CyclePoint], T0: float) -> bool:
    """Whether a failed branch was on its way to a homoclinic orbit: the period over ten
    Hopf periods and growing over the last five points."""
    if len(points) < 6:
        return False
    T = np.array([c.period for c in points[-6:]])
    return bool(T[-1] > 10.0 * T0 and np.all(np.diff(T) > 0))


def _homoclinic_message(points: Sequence[CyclePoint], last_reliable: CyclePoint | None,
                        param: str, T0: float) -> str:
    if not points:
        return "homoclinic approach"
    c = points[-1]
    text = (f"homoclinic approach: the period grows without bound (T = {c.period:.4g} s, "
            f"{c.period / T0:.3g} x the Hopf period, at {param} = {c.value:.10g}); the family "
            "ends at a homoclinic orbit near there")
    if last_reliable is not None:
        text += (f"; last point with reliable multipliers: {param} = "
                 f"{last_reliable.value:.10g}, T = {last_reliable.period:.4g} s")
    else:
        text += "; no point with reliable multipliers"
    return text


def _closing_hopf(cyc: CycleProblem, res: Any, start: HopfStart, param: str,
                  past: CyclePoint | None, points: list[CyclePoint], opt: CycleOptions
                  ) -> tuple[SpecialPoint | None, str]:
    """The Hopf point where the family of cycles ends, refined by Newton's method on the
    Hopf defining system (:func:`~maglev_match.dynamics.hopf.refine_hopf_point`) from the
    last cycle before it: its mean state, 2 pi / T and the parameter where the first
    harmonic's projection, linear in the arclength, reaches zero between the last two
    points."""
    from maglev_match.dynamics.hopf import refine_hopf_point

    pts = [pt for pt in res.points[1:] if "cycle" in pt.info]
    if len(pts) < 2 or not points:
        return None, "the family of cycles reached the equilibrium at its first step"
    a, b = pts[-2], pts[-1]
    ga = float(np.linalg.norm(a.info.get("c1", np.zeros(1))))
    gb = float(b.info.get("amp_signed", 0.0))
    frac = ga / (ga - gb) if ga - gb > 0 else 1.0
    guess = a.value + float(np.clip(frac, 0.0, 1.5)) * (b.value - a.value)
    last = points[-1]
    orbit = last.orbit
    x_mean = np.real(first_harmonic_mean(orbit))
    system = cyc.system
    bounds = system.valid_bounds(param, opt.param_bounds)
    hp = refine_hopf_point(system, param, guess, x_mean, 2.0 * math.pi / last.period,
                           p=orbit.p, value_scale=max(abs(guess), abs(a.value - start.value),
                                                      1e-12),
                           bounds=bounds)
    where = f"{param} = {hp.value:.10g}" if np.isfinite(hp.value) else f"{param} ~ {guess:.8g}"
    if hp.converged:
        same = abs(hp.value - start.value) <= 1e-8 * max(1.0, abs(start.value))
        detail = (f"the family of cycles closes at this Hopf point (frequency "
                  f"{hp.frequency:.6g} rad/s, l1 = {hp.l1:.4g})"
                  + ("; it is the Hopf point the branch started from" if same else
                     f"; born at the Hopf point {param} = {start.value:.10g}"))
        message = (f"the family of cycles closed at the Hopf point {where}: it joins the "
                   f"Hopf points {param} = {start.value:.10g} and {hp.value:.10g}")
        at_eq = {}  # the read-outs of the equilibrium where the family ends
        for name in last.extrema:
            v = np.ravel(system.observe(name, hp.x, hp.p))
            at_eq[name] = (float(np.max(v)), float(np.min(v)))
        return SpecialPoint(type=SpecialPointKind.HOPF, value=float(hp.value),
                            step=len(points) - 1, located=SOLVED, detail=detail,
                            x=np.asarray(hp.x), frequency=float(hp.frequency),
                            period=2.0 * math.pi / hp.frequency, extrema=at_eq,
                            residual=float(hp.residual)), message
    message = (f"the family of cycles shrinks to the equilibrium near {param} ~ {guess:.8g}, "
               f"but the Hopf point there was not solved: {hp.message}")
    return SpecialPoint(type=SpecialPointKind.HOPF, value=float(guess), step=len(points) - 1,
                        located=f"not solved: {hp.message}", detail=message), message


def _fixed_param(prob: CollocationBVP, Y: np.ndarray, value: float, tol: float, max_iter: int
                 ) -> BranchPoint | None:
    """The cycle at ``param`` = value exactly, from a nearby point Y (Newton)."""
    row = np.zeros(prob.size)
    row[-1] = 1.0
    Uref, _, _ = prob.unpack(Y)
    Yv, ok, its, res, lu, blocks = collocation_newton(
        prob, Y, Uref, row, value / prob.lam_scale, tol, max_iter)
    if not ok:
        return None
    corr = Correction(u=Yv, iterations=its, residual=res, solve=lu.solve,
                      data=(blocks, prob.mesh.copy(), None, row))
    return BranchPoint(u=Yv, t=np.zeros_like(Yv), value=value, correction=corr)


def correct_cycle(
    system: System,
    orbit: PeriodicOrbit,
    param: str,
    value: float,
    observables: Sequence[str] | None = None,
    tol: float = 1e-10,
    max_iter: int = 12,
) -> CorrectionResult:
    """Solve the periodic BVP at ``param`` = ``value`` (fixed) from a guess ``orbit``."""
    names = tuple(system.observables) if observables is None else tuple(observables)
    ipar = system.param_index(param)
    prob = CollocationBVP(system=system, ipar=ipar, p0=np.array(orbit.p, float),
                    mesh=np.array(orbit.mesh), m=orbit.ncol,
                    scale=np.asarray(system.state_scale, float), T_scale=orbit.period,
                    lam_scale=abs(value) if value != 0 else 1.0)
    p = np.array(orbit.p, float)
    p[ipar] = value
    Y0 = prob.pack(orbit.states, orbit.period, value)
    row = np.zeros(prob.size)
    row[-1] = 1.0
    Y, ok, its, res, _, blocks = collocation_newton(prob, Y0, orbit.states, row,
                                         value / prob.lam_scale, tol, max_iter)
    if not ok:
        return CorrectionResult(None, False, its, f"no convergence (residual {res:.2e})")
    U, T, lam = prob.unpack(Y)
    J, Tb, h = blocks if blocks is not None else blocks_at(prob, Y, prob.mesh)
    triv, mult = split_trivial(floquet_multipliers_from_blocks(
        J, Tb, h, orbit.ncol, method=getattr(system, "floquet_method", "auto")))
    tol_n = CycleOptions.neutral_tol
    nun = int(np.sum(np.abs(mult) > 1.0 + tol_n))
    reliable = bool(abs(triv - 1.0) <= CycleOptions.trivial_tol)
    stab = stability_of(mult, tol_n) if reliable else Stability.UNKNOWN
    orb = PeriodicOrbit(prob.mesh, orbit.ncol, U, T, prob.params(lam))
    pt = CyclePoint(value=lam, period=T, orbit=orb, multipliers=mult,
                    trivial_multiplier=triv, n_unstable=nun,
                    stable=stab == Stability.STABLE if reliable else nun == 0,
                    extrema=orbit_extrema(system, orb, names), converged=True,
                    iterations=its, residual=res, kind="stop_at", reliable=reliable,
                    stability=stab)
    return CorrectionResult(pt, True, its)
