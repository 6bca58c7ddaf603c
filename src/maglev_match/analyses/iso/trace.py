"""The level set chi(p1, p2) = target continued in two parameters, for any evaluator of the
headline index and its two parts.

Method (pseudo-arclength continuation of a scalar level set, Allgower & Georg 1990, ch. 2
and 10): the unknowns are the two parameters scaled to their ranges,
u_i = (p_i - lo_i) / (hi_i - lo_i), so that a step means the same fraction of either range.
With F(u) = chi(u) - target and g its gradient, the tangent t is g turned by 90 degrees;
the predictor steps ds along t and the corrector solves F = 0 on the line through the
predicted point along the normal g (Newton with the gradient's slope, then secant steps),
to |F| <= tol * target; a corrector whose iterates move further from the root twice in a
row without a sign change gives up (no root near the prediction on that line). Steps grow
after easy corrections (at most 2 iterations) and halve after a failed one or a turn of the
tangent by more than about 37 degrees; below the smallest step the curve ends with its
reason and a warning. Both directions are followed from the start; a curve that leaves the
ranges ends on their edge (the last point solved on the edge line).

The gradient is the exact one of the deciding part where the evaluator gives it (a
``gradient(p1, p2, sample)`` method returning each part's gradient, e.g. the index's
analytic sensitivities): no extra evaluation. Where the deciding part has no derivative
(a simulated part only bracketed by its bisection, a parameter without an analytic
derivative) or the evaluator gives none, it is a forward difference of two more
evaluations; every point records which (``IsoPoint.gradient``).

Between two neighbouring points where the deciding part switches (paper <-> simulation)
the switch is the point where both parts equal the target: started where D = chi_paper -
chi_simulation interpolates to 0 on the chord (corrected onto the curve), located by Newton
on (chi_paper - target, chi_simulation - target) = 0 with the two parts' exact gradients
as its Jacobian (a forward difference where one has none), to 10 tol * target in both; a
change of the simulated part's mechanism (a discrete label) is located by bisection of the
same kind to 1/32 of the step. Both are special points.

Every point records which parts were solved: the simulated part's critical size may only
be bracketed by its bisection (no solved condition, chi known only to the bisection's
tolerance). Such a point is marked, never smoothed over; where the corrector cannot
converge because of it, the curve ends there and says why.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from maglev_match.analyses.iso.records import IsoPoint, IsoSpecial, Sample, Traced
from maglev_match.dynamics.continuation import (
    ContinuationOptions,
    Correction,
    StopReason,
    continuation,
)

__all__ = ["Sample", "IsoPoint", "IsoSpecial", "TraceSettings", "DEFAULT_SETTINGS", "Traced",
           "trace_iso", "extend_iso"]

#: why a direction ended when the curve came back to its start (not continued by a restart)
CLOSED = "the curve closed on its start"
#: how the warning of a direction that ended on a failure begins
ENDED = "the curve ended"


@dataclass(frozen=True)
class TraceSettings:
    """Tolerances and step control of :func:`trace_iso` (steps in range fractions)."""

    tol: float = 1e-7
    ds: float = 0.05
    ds_min: float = 2e-3
    ds_max: float = 0.2
    max_points: int = 30
    fd_step: float = 1e-4
    max_iter: int = 12
    scan: int = 7  # the start's scan along the free parameter (points, >= 2)
    max_inexact: int = 3  # the corrector gives up after this many bracketed iterates
    min_cos: float = 0.8


#: the default tolerances and steps
DEFAULT_SETTINGS = TraceSettings()

Evaluate = Callable[[float, float], Sample]


class _Tracer:
    def __init__(self, evaluate: Evaluate, box: Sequence[tuple[float, float]],
                 target: float, settings: TraceSettings,
                 stage: Callable[[str], None] | None) -> None:
        self.evaluate = evaluate
        self.lo = np.array([b[0] for b in box], float)
        self.width = np.array([b[1] - b[0] for b in box], float)
        self.target = float(target)
        self.s = settings
        self.say = stage or (lambda text: None)
        self.cache: dict[tuple[float, float], Sample] = {}
        self.evaluations = 0
        self.warnings: list[str] = []
        self.exact = getattr(evaluate, "gradient", None)
        self.part_cache: dict[tuple[float, float], tuple[dict[str, np.ndarray], str]] = {}
        self.grad_how: dict[tuple[float, float], str] = {}

    # -- evaluation ------------------------------------------------------------------
    def params(self, u: np.ndarray) -> tuple[float, float]:
        p = self.lo + self.width * np.asarray(u, float)
        return float(p[0]), float(p[1])

    def sample(self, u: np.ndarray) -> Sample:
        key = self.params(u)
        if key not in self.cache:
            self.evaluations += 1
            self.cache[key] = self.evaluate(*key)
        return self.cache[key]

    def F(self, u: np.ndarray) -> float:
        return self.sample(u).chi - self.target

    def part_gradients(self, u: np.ndarray) -> tuple[dict[str, np.ndarray], str]:
        """The evaluator's exact gradients of the two parts at u, in the scaled unknowns
        ({} and why not, where it has none)."""
        if self.exact is None:
            return {}, "the evaluator gives no derivative"
        key = self.params(u)
        if key not in self.part_cache:
            parts, why = self.exact(*key, self.sample(u))
            self.part_cache[key] = ({k: np.asarray(v, float) * self.width
                                     for k, v in parts.items()}, why)
        return self.part_cache[key]

    def gradient(self, u: np.ndarray, f0: float) -> np.ndarray | None:
        """The gradient of F at u: the deciding part's exact gradient where there is one,
        else a forward difference (how: ``self.grad_how``)."""
        key = self.params(u)
        smp = self.sample(u)
        if self.exact is None:
            why = "the evaluator gives no derivative"
        elif not smp.exact:
            why = "the deciding simulated part is only bracketed: no derivative"
        else:
            parts, why = self.part_gradients(u)
            g = parts.get(smp.basis)
            if g is not None and np.all(np.isfinite(g)) and np.linalg.norm(g) > 0:
                self.grad_how[key] = "exact"
                return g
            why = why or f"the {smp.basis} part has no derivative"
        self.grad_how[key] = f"difference: {why}"
        g = np.zeros(2)
        for i in range(2):
            h = self.s.fd_step if u[i] + self.s.fd_step <= 1.0 + 1e-12 else -self.s.fd_step
            e = np.zeros(2)
            e[i] = h
            fi = self.F(u + e)
            if not math.isfinite(fi):
                return None
            g[i] = (fi - f0) / h
        return g if np.linalg.norm(g) > 0 else None

    def converged(self, f: float) -> bool:
        return math.isfinite(f) and abs(f) <= self.s.tol * self.target

    # -- 1-D solves ------------------------------------------------------------------
    def line_solve(self, u0: np.ndarray, d: np.ndarray, slope: float
                   ) -> tuple[np.ndarray, float, int]:
        """F = 0 on u0 + s d: Newton's first step with ``slope`` (dF/ds), then secant
        steps; once F has changed sign (at a kink of the headline, where the deciding part
        switches, secant steps can cycle) regula falsi (Illinois) inside the bracket.
        Returns (the best iterate, its F, iterations); converged iff :meth:`converged` of
        that F."""
        f0 = self.F(u0)
        if not math.isfinite(f0) or self.converged(f0):
            return u0, f0, 0
        best = (u0, f0)
        prev = (0.0, f0)
        lo: tuple[float, float] | None = (0.0, f0) if f0 < 0 else None  # F < 0 end
        hi: tuple[float, float] | None = (0.0, f0) if f0 > 0 else None  # F > 0 end
        s = -f0 / slope
        moved = 0  # the end replaced last (-1 lo, +1 hi), for Illinois
        inexact = 0  # iterates whose deciding part is only a bracket (a step function)
        away = 0  # secant steps in a row that moved away from the root (|F| grew)
        for it in range(1, self.s.max_iter + 1):
            u = u0 + s * d
            f = self.F(u)
            if not math.isfinite(f):
                return best[0], float("nan"), it
            away = away + 1 if abs(f) > abs(prev[1]) else 0
            if abs(f) < abs(best[1]):
                best = (u, f)
            if self.converged(f):
                return u, f, it
            inexact += not self.sample(u).exact
            if inexact >= self.s.max_inexact:  # no Newton on a bracket's midpoint
                return best[0], best[1], it
            if f < 0:
                if hi is not None and moved == -1:
                    hi = (hi[0], hi[1] / 2)
                lo, moved = (s, f), -1
            else:
                if lo is not None and moved == 1:
                    lo = (lo[0], lo[1] / 2)
                hi, moved = (s, f), 1
            if away >= 2 and (lo is None or hi is None):
                # twice further from the root without a sign change: no root along this
                # line near the prediction (a shorter step is the driver's to try)
                return best[0], best[1], it
            if lo is not None and hi is not None:  # bracketed: Illinois
                s_new = (lo[0] * hi[1] - hi[0] * lo[1]) / (hi[1] - lo[1])
            else:  # secant from the last two iterates
                if f == prev[1]:
                    break
                s_new = s - f * (s - prev[0]) / (f - prev[1])
            prev, s = (s, f), s_new
        return best[0], best[1], self.s.max_iter

    def bracket_solve(self, ua: np.ndarray, ub: np.ndarray, fa: float, fb: float,
                      fn: Callable[[np.ndarray], float], tol: float, iters: int = 40
                      ) -> tuple[float, float, bool]:
        """Illinois regula falsi for fn = 0 on the segment ua..ub (fa, fb of opposite
        sign); returns (theta, fn there, converged)."""
        a, b = 0.0, 1.0
        side = 0
        theta, f = (a, fa) if abs(fa) < abs(fb) else (b, fb)
        for _ in range(iters):
            theta = (a * fb - b * fa) / (fb - fa)
            f = fn(ua + theta * (ub - ua))
            if not math.isfinite(f):
                return theta, f, False
            if abs(f) <= tol:
                return theta, f, True
            if (f > 0) == (fa > 0):
                a, fa = theta, f
                if side == -1:
                    fb /= 2
                side = -1
            else:
                b, fb = theta, f
                if side == 1:
                    fa /= 2
                side = 1
            if b - a < 1e-10:
                break
        return theta, f, False

    # -- the start -------------------------------------------------------------------
    def start(self, fixed: int, value: float, scan: int | None = None
              ) -> tuple[np.ndarray | None, str]:
        """Solve chi = target along the free parameter with parameter ``fixed`` at
        ``value`` (its range fraction): a scan of up to ``scan`` points (from the middle
        outwards, until the sign change nearest the middle of the range is known), then
        regula falsi on that sign change."""
        free = 1 - fixed
        scan = max(2, int(scan or self.s.scan))
        grid = np.linspace(0.0, 1.0, scan)
        us = []
        for c in grid:
            u = np.zeros(2)
            u[fixed], u[free] = value, c
            us.append(u)
        self.say(f"start: chi along the free parameter at up to {scan} points ...")

        def key(j: int) -> tuple[float, int]:  # the pair nearest the middle, then the first
            return abs(0.5 - 0.5 * (grid[j] + grid[j + 1])), j

        def changes(j: int) -> bool:
            a, b = fs[j], fs[j + 1]
            return (a is not None and b is not None and math.isfinite(a)
                    and math.isfinite(b) and (a > 0) != (b > 0))

        # from the middle outwards, stopping once the sign change nearest the middle is
        # known (every pair nearer the middle evaluated): the pair the whole scan would
        # choose, without evaluating the ends of the range far from the curve
        fs: list[float | None] = [None] * scan
        pairs: list[int] = []
        for i in sorted(range(scan), key=lambda i: (abs(grid[i] - 0.5), i)):
            fs[i] = self.F(us[i])
            pairs = [j for j in range(scan - 1) if changes(j)]
            if pairs:
                best = key(min(pairs, key=key))
                if all(fs[j] is not None and fs[j + 1] is not None
                       for j in range(scan - 1) if key(j) < best):
                    break
        if not pairs:
            finite = [f + self.target for f in fs if f is not None and math.isfinite(f)]
            span = (f"chi from {min(finite):.4g} to {max(finite):.4g}" if finite
                    else "chi could not be computed at any of them")
            return None, (f"no sign change of chi - {self.target:g} along the free "
                          f"parameter's range ({scan} points; {span})")
        k = min(pairs, key=key)
        theta, f, ok = self.bracket_solve(us[k], us[k + 1], fs[k], fs[k + 1], self.F,
                                          self.s.tol * self.target)
        u = us[k] + theta * (us[k + 1] - us[k])
        if not ok:
            return None, (f"the start did not converge: chi - target = {f:.3g} after the "
                          "bracketed search" + self._why(u))
        return u, ""

    def _why(self, u: np.ndarray) -> str:
        smp = self.sample(u)
        if not math.isfinite(smp.chi):
            return f" (the index failed there: {smp.reason})"
        if not smp.exact:
            return (" (the deciding simulated part is only bracketed there, "
                    f"{smp.simulation_status}: chi is known only to the bisection's "
                    "tolerance)")
        return ""

    # -- the curve -------------------------------------------------------------------
    def branch(self, u0: np.ndarray, g0: np.ndarray, sign: int, n_max: int,
               first: list[IsoPoint], label: int | None = None,
               home: np.ndarray | None = None
               ) -> tuple[list[IsoPoint], list[IsoSpecial], str]:
        """One direction of the curve from the start, by the package's continuation driver
        (:func:`~maglev_match.dynamics.continuation.continuation`) on the scalar equation
        F(u) = 0 (:class:`_LevelSet`): its predictor, bordered corrector (solved here on the
        line normal to the tangent), tangent and step control. Returns the points (without
        the start), the special points between neighbours and why the direction ended.
        ``sign`` orients the tangent (g turned by +-90 degrees); ``label`` marks the points
        (default ``sign``; a restarted end keeps its direction's label); ``home`` the start
        a forwards direction may close on (default ``u0``)."""
        label = sign if label is None else label
        t0 = sign * np.array([-g0[1], g0[0]]) / np.linalg.norm(g0)
        if self._step(u0, t0, self.s.ds) is None:  # on the edge, pointing out of the box
            return [], [], "reached the edge of the ranges"
        problem = _LevelSet(self, u0, g0, label, home)
        res = continuation(problem, u0, t0, problem.options(n_max),
                           first=problem.correction(u0, g0, None, 0))
        pts: list[IsoPoint] = []
        grads = [g0]
        for bp in res.points[1:]:
            p1, p2 = self.params(bp.u)
            smp = self.sample(bp.u)
            pts.append(IsoPoint(p1, p2, smp, self.F(bp.u), bp.correction.iterations,
                                "solved" if smp.exact else "bracketed", label,
                                self.grad_how.get((p1, p2), "")))
            grads.append(bp.correction.data)
        specials: list[IsoSpecial] = []
        for a, b, ga, gb in zip([first[0], *pts], pts, grads, grads[1:], strict=False):
            specials += self.specials_between(a, b, ga, gb)
        if problem.ended:
            return pts, specials, problem.ended
        if res.stop_reason == StopReason.STEP_TOO_SMALL and problem.failed is not None:
            new, f, its, ok = problem.failed
            if math.isfinite(f):
                p1, p2 = self.params(new)
                pts.append(IsoPoint(p1, p2, self.sample(new), f, its, "not converged",
                                    label))
            return pts, specials, self._fail_reason(new, f, ok)
        return pts, specials, f"the number of points ({n_max} in this direction) reached"

    def _step(self, u: np.ndarray, t: np.ndarray, ds: float
              ) -> tuple[float, int | None] | None:
        """The step along t that stays in the unit box: (ds, None), or the step to the box
        edge and the index of the parameter held there; None when already on it."""
        limit, edge = ds, None
        for i in range(2):
            if t[i] > 1e-14:
                room = (1.0 - u[i]) / t[i]
            elif t[i] < -1e-14:
                room = -u[i] / t[i]
            else:
                continue
            if room < limit:
                limit, edge = room, i
        if edge is not None and limit < 1e-9:
            return None
        return limit, edge

    def note_end(self, name: str, why: str) -> None:
        """A warning for the direction ``name`` when it ended on a failure (``why``)."""
        if "did not converge" in why or "turns faster" in why or "left the ranges" in why:
            self.warnings.append(f"{ENDED} {name}: {why}")

    def _fail_reason(self, u: np.ndarray, f: float, in_range: bool) -> str:
        p1, p2 = self.params(u)
        where = f"near p1 = {p1:.6g}, p2 = {p2:.6g}"
        if math.isfinite(f) and not in_range and self.converged(f):
            return f"the corrector left the ranges {where}"
        if math.isfinite(f) and self.converged(f):
            return (f"the curve turns faster than the smallest step "
                    f"({self.s.ds_min:g}) can follow {where}")
        return (f"the corrector did not converge at the smallest step ({self.s.ds_min:g}) "
                f"{where}: chi - target = {f:.3g}" + self._why(u))

    # -- special points between neighbours --------------------------------------------
    def on_curve(self, u: np.ndarray, g: np.ndarray) -> tuple[np.ndarray, bool]:
        gn = np.linalg.norm(g)
        new, f, _ = self.line_solve(u, g / gn, gn)
        return new, self.converged(f)

    def specials_between(self, a: IsoPoint, b: IsoPoint, ga: np.ndarray,
                         gb: np.ndarray) -> list[IsoSpecial]:
        sa, sb = a.sample, b.sample
        ua = (np.array([a.p1, a.p2]) - self.lo) / self.width
        ub = (np.array([b.p1, b.p2]) - self.lo) / self.width
        g = 0.5 * (ga + gb)
        out = []
        if sa.basis != sb.basis:
            out.append(self.locate_switch(ua, ub, sa, sb, g))
        if (sa.mechanism != sb.mechanism and sa.basis == sb.basis == "simulation"
                and sa.mechanism is not None and sb.mechanism is not None):
            out.append(self.locate_change(ua, ub, sa, sb, g))
        return out

    def _difference(self, smp: Sample) -> float:
        if smp.chi_simulation is None or not math.isfinite(smp.chi_paper):
            return float("nan")
        return smp.chi_paper - smp.chi_simulation

    def _parts(self, u: np.ndarray) -> np.ndarray:
        smp = self.sample(u)
        sim = float("nan") if smp.chi_simulation is None else smp.chi_simulation
        return np.array([smp.chi_paper, sim]) - self.target

    def _parts_jacobian(self, u: np.ndarray, G: np.ndarray) -> np.ndarray:
        """d (chi_paper, chi_simulation) / du: the exact gradients of both parts where the
        evaluator gives them, else a forward difference."""
        parts, _ = self.part_gradients(u) if self.sample(u).simulation_status == "solved" \
            else ({}, "")
        if "paper" in parts and "simulation" in parts:
            return np.vstack([parts["paper"], parts["simulation"]])
        J = np.empty((2, 2))
        for k in range(2):
            e = np.zeros(2)
            e[k] = self.s.fd_step
            J[:, k] = (self._parts(u + e) - G) / self.s.fd_step
        return J

    def locate_switch(self, ua, ub, sa: Sample, sb: Sample, g) -> IsoSpecial:
        """Where both parts equal the target between the points a and b: Newton on
        (chi_paper - target, chi_simulation - target) = 0 (the Jacobian of the two parts:
        their exact gradients where the evaluator gives them, else a forward difference),
        from the chord point where chi_paper - chi_simulation interpolates to 0, corrected
        onto the curve."""
        self.say("locating the switch of the deciding part ...")
        kind = "basis switch"
        da, db = self._difference(sa), self._difference(sb)
        if not (math.isfinite(da) and math.isfinite(db)) or (da > 0) == (db > 0):
            u = 0.5 * (ua + ub)
            return IsoSpecial(kind, *self.params(u), sa.basis, sb.basis, self.sample(u),
                              False, float("nan"), "not located: a part is missing on one "
                              "side")
        theta = da / (da - db)
        u, _ = self.on_curve(ua + theta * (ub - ua), g)
        tol = 10 * self.s.tol * self.target
        G = self._parts(u)
        for _ in range(8):
            if not np.all(np.isfinite(G)) or np.max(np.abs(G)) <= tol:
                break
            J = self._parts_jacobian(u, G)
            try:
                du = np.linalg.solve(J, -G)
            except np.linalg.LinAlgError:
                break
            if not np.all(np.isfinite(du)) or np.linalg.norm(du) > 2 * np.linalg.norm(ub - ua):
                break
            u = u + du
            G = self._parts(u)
        ok = bool(np.all(np.isfinite(G)) and np.max(np.abs(G)) <= tol)
        d = float(G[0] - G[1])
        msg = "" if ok else (f"not converged: chi_paper - target = {G[0]:.3g}, "
                             f"chi_simulation - target = {G[1]:.3g}")
        return IsoSpecial(kind, *self.params(u), sa.basis, sb.basis, self.sample(u), ok,
                          d, msg)

    def locate_change(self, ua, ub, sa: Sample, sb: Sample, g) -> IsoSpecial:
        self.say("locating the change of mechanism ...")
        a, b = 0.0, 1.0
        last = None
        for _ in range(5):
            mid = 0.5 * (a + b)
            uu, ok = self.on_curve(ua + mid * (ub - ua), g)
            if not ok:
                break
            last = uu
            if self.sample(uu).mechanism == sa.mechanism:
                a = mid
            else:
                b = mid
        u = last if last is not None else 0.5 * (ua + ub)
        located = last is not None and b - a <= 1.0 / 32
        if located:
            msg = f"bracketed to {b - a:.3g} of the step"
        else:
            msg = (f"not located: the corrector failed between the points (bracketed to "
                   f"{b - a:.3g} of the step)")
        return IsoSpecial("mechanism change", *self.params(u), str(sa.mechanism),
                          str(sb.mechanism), self.sample(u), located, float("nan"), msg)


class _LevelSet:
    """The level set F(u) = chi(u) - target as a problem of the continuation driver
    (:class:`~maglev_match.dynamics.continuation.ContinuationProblem`): unknowns u (the two
    scaled parameters, one equation), unit weights. Its corrector solves F = 0 on the line
    {row . u = target} through the predicted point (:meth:`_Tracer.line_solve`, along the
    last gradient, the normal of the tangent), or, where the step would leave the box, on
    the box's edge from the point where the tangent meets it (the direction then ends
    there). The bordered matrix [g; row], g the gradient at the solution, gives the driver
    its next tangent. A corrected point whose tangent turned by more than acos(min_cos)
    is not admissible (the driver halves the step), except at the smallest step, on the
    edge, and where the deciding part switches (a corner of the level set of a
    minimum)."""

    def __init__(self, tr: _Tracer, u0: np.ndarray, g0: np.ndarray, sign: int,
                 home: np.ndarray | None = None) -> None:
        self.tr, self.sign = tr, sign
        self.u0 = u0 if home is None else home  # the start the curve may close on
        self.weights = np.ones(2)
        self.anchor, self.anchor_gradient = u0, g0  # the last accepted point, its gradient
        self.edge: int | None = None  # the box edge the last correction was solved on
        self.ended = ""  # why the direction ended (the box's edge, closed)
        self.failed: tuple[np.ndarray, float, int, bool] | None = None  # the last failure
        self.steps = 0
        self.s_last = 0.0

    def options(self, n_max: int) -> ContinuationOptions:
        st = self.tr.s
        return ContinuationOptions(
            ds=st.ds, ds_min=st.ds_min, ds_max=st.ds_max, max_steps=max(1, n_max),
            newton_max_iter=st.max_iter, grow=1.5, shrink=0.5, fast_iterations=2,
            slow_iterations=10 ** 9)

    def correction(self, u: np.ndarray, g: np.ndarray, row: np.ndarray | None,
                   its: int) -> Correction:
        """The corrected point u with gradient g; its bordered solve gives the tangent
        (t . g = 0, t . row = 1; at the start, without a row, g turned by 90 degrees)."""
        def solve(b: np.ndarray) -> np.ndarray:
            if row is None:
                return np.array([-g[1], g[0]]) / np.linalg.norm(g)
            return np.linalg.solve(np.vstack([g, row]), b)

        return Correction(u=u, iterations=its, residual=abs(self.tr.F(u)), solve=solve,
                          data=g)

    def correct(self, u_pred: np.ndarray, row: np.ndarray, target: float,
                max_iter: int) -> Correction | None:
        tr = self.tr
        if self.ended:
            return None
        t = np.asarray(row, float)  # (unit weights: the row is the last tangent)
        step = tr._step(self.anchor, t, float(target - row @ self.anchor))
        if step is None:  # already on the edge, the tangent pointing out of the box
            self.ended = "reached the edge of the ranges"
            return None
        g_old = self.anchor_gradient
        gn = np.linalg.norm(g_old)
        limit, self.edge = step
        if self.edge is None:
            new, f, its = tr.line_solve(np.asarray(u_pred, float), g_old / gn, gn)
        else:  # the step leaves the box: solve along its edge
            d = np.zeros(2)
            d[1 - self.edge] = 1.0
            slope = g_old[1 - self.edge] if abs(g_old[1 - self.edge]) > 1e-12 * gn else gn
            new, f, its = tr.line_solve(self.anchor + limit * t, d, slope)
        ok = tr.converged(f) and bool(np.all(new >= -1e-9) and np.all(new <= 1 + 1e-9))
        g_new = tr.gradient(new, f) if ok else None
        if g_new is None:
            self.failed = (new, f, its, ok)
            return None
        return self.correction(new, g_new, t, its)

    def admissible(self, a, u: np.ndarray, s: float) -> bool:
        tr = self.tr
        self.s_last = s
        g = tr.gradient(u, tr.F(u))  # (cached: the correction's)
        t_new = np.array([-g[1], g[0]]) / np.linalg.norm(g)
        if t_new @ (u - a.u) < 0:  # onwards: away from the previous point
            t_new = -t_new
        corner = tr.sample(u).basis != tr.sample(a.u).basis
        if (t_new @ a.t < tr.s.min_cos and s > tr.s.ds_min and not corner
                and self.edge is None):
            self.failed = (u, tr.F(u), 0, True)  # turned too fast: a shorter step
            return False
        return True

    def parameter(self, u: np.ndarray) -> float:
        return self.tr.params(u)[1]

    def test_functions(self, point) -> dict[str, float]:
        return {}  # (the special points are located between neighbours afterwards)

    def event_kind(self, name: str) -> str:
        return name

    def after_accept(self, point):
        self.anchor, self.anchor_gradient = point.u, point.correction.data
        self.steps += 1
        return point

    def stop(self, point) -> str | None:
        if self.edge is not None:
            self.ended = f"reached the end of the {('p1', 'p2')[self.edge]} range"
        elif (self.sign > 0 and self.steps > 2
              and np.linalg.norm(point.u - self.u0) < 0.75 * self.s_last):
            self.ended = CLOSED
        return self.ended or None


def trace_iso(evaluate: Evaluate, box: Sequence[tuple[float, float]], target: float, *,
              fixed: int, value: float, settings: TraceSettings = DEFAULT_SETTINGS,
              stage: Callable[[str], None] | None = None) -> Traced:
    """The curve chi(p1, p2) = ``target`` inside ``box`` ((lo1, hi1), (lo2, hi2)), started
    where parameter ``fixed`` (0 or 1) equals ``value`` (solving for the other over its
    range), followed both ways. ``evaluate(p1, p2)`` returns a :class:`Sample`."""
    cpu = time.process_time()
    tr = _Tracer(evaluate, box, target, settings, stage)
    lo, hi = box[fixed]
    u0, why = tr.start(fixed, (value - lo) / (hi - lo))

    def done(points, start, specials, ends) -> Traced:
        return Traced(tuple(points), start, tuple(specials), ends, tuple(tr.warnings),
                      tr.evaluations, time.process_time() - cpu)

    if u0 is None:
        tr.warnings.append(f"the curve could not start: {why}")
        return done([], None, [], (why, why))
    f0 = tr.F(u0)
    smp = tr.sample(u0)
    p1, p2 = tr.params(u0)
    first = IsoPoint(p1, p2, smp, f0, 0, "solved" if smp.exact else "bracketed", 0)
    if settings.max_points <= 1:  # the start alone: chi = target along one parameter
        why = "one point asked: the start alone"
        return done([first], 0, [], (why, why))
    g0 = tr.gradient(u0, f0)
    first = dataclasses.replace(first, gradient=tr.grad_how.get((p1, p2), ""))
    if g0 is None:
        why = "the gradient of chi could not be computed at the start" + tr._why(u0)
        tr.warnings.append(why)
        return done([first], 0, [], (why, why))
    # the points after the start, both directions together: backwards gets half (rounded
    # down), forwards the rest, so that max_points = 2 is the start and one point forwards
    per = (settings.max_points - 1) // 2
    stage = stage or (lambda text: None)
    stage("following the curve forwards ...")
    fwd, sp_f, end_f = tr.branch(u0, g0, +1, settings.max_points - 1 - per, [first])
    if end_f == CLOSED:
        bwd, sp_b, end_b = [], [], CLOSED
    elif per == 0:
        bwd, sp_b, end_b = [], [], "the number of points (0 in this direction) reached"
    else:
        stage("following the curve backwards ...")
        bwd, sp_b, end_b = tr.branch(u0, g0, -1, per, [first])
    for end, name in ((end_f, "forwards"), (end_b, "backwards")):
        tr.note_end(name, end)
    points = list(reversed(bwd)) + [first] + fwd
    return done(points, len(bwd), list(reversed(sp_b)) + sp_f, (end_b, end_f))



def extend_iso(evaluate: Evaluate, box: Sequence[tuple[float, float]], target: float,
               points: Sequence[IsoPoint], start: int | None, ends: tuple[str, str], *,
               specials: Sequence[IsoSpecial] = (),
               settings: TraceSettings = DEFAULT_SETTINGS,
               stage: Callable[[str], None] | None = None) -> Traced:
    """A curve of :func:`trace_iso` (``points`` in order, ``start`` the start's position,
    ``ends`` why each direction ended) continued beyond both of its ends, inside ``box``
    (which may be wider than the one it was followed in), with ``settings.max_points``
    new points in all (backwards half of them, rounded down, as :func:`trace_iso` shares
    them). Each end is evaluated again (a new evaluation: the saved curve keeps no state)
    and the direction goes on away from its neighbour; a last point that did not converge
    is dropped and its direction goes on from the point before it. A curve that closed on
    its start is not continued. Returns the whole curve (the saved points and ``specials``
    unchanged, with the special points between the new ones) and the new ends;
    ``evaluations`` counts the new evaluations only."""
    cpu = time.process_time()
    tr = _Tracer(evaluate, box, target, settings, stage)
    pts = list(points)
    if start is None or not pts:
        raise ValueError("a curve without points (it did not start) cannot be continued")
    home = (np.array([pts[start].p1, pts[start].p2]) - tr.lo) / tr.width
    # a last point that did not converge is where its direction failed: go on from before it
    while len(pts) > 1 and pts[-1].status == "not converged" and len(pts) - 1 > start:
        pts.pop()
    while len(pts) > 1 and pts[0].status == "not converged" and start > 0:
        pts.pop(0)
        start -= 1
    n_new = max(int(settings.max_points), 0)
    per = n_new // 2
    new_ends = list(ends)
    added: dict[int, tuple[list[IsoPoint], list[IsoSpecial]]] = {-1: ([], []), 1: ([], [])}
    for side, budget in ((1, n_new - per), (-1, per)):
        if budget <= 0 or CLOSED in ends:
            continue
        end = pts[-1] if side > 0 else pts[0]
        inner = (pts[-2] if side > 0 else pts[1]) if len(pts) > 1 else None
        u = (np.array([end.p1, end.p2]) - tr.lo) / tr.width
        if np.any(u < -1e-9) or np.any(u > 1 + 1e-9):
            new_ends[(side + 1) // 2] = "the saved end lies outside the ranges given"
            continue
        u = np.clip(u, 0.0, 1.0)
        tr.say(f"following the curve {'forwards' if side > 0 else 'backwards'} from its "
               "saved end ...")
        f = tr.F(u)
        g = tr.gradient(u, f) if math.isfinite(f) else None
        if g is None:
            why = "the gradient of chi could not be computed at the saved end" + tr._why(u)
            tr.warnings.append(why)
            new_ends[(side + 1) // 2] = why
            continue
        turn = np.array([-g[1], g[0]])
        if inner is not None:
            back = (np.array([inner.p1, inner.p2]) - tr.lo) / tr.width
            orient = 1 if turn @ (u - back) >= 0 else -1
        else:  # the start alone: the two directions of trace_iso
            orient = side
        first = dataclasses.replace(end, sample=tr.sample(u))
        more, found, why = tr.branch(u, g, orient, budget, [first], label=side, home=home)
        added[side] = (more, found)
        new_ends[(side + 1) // 2] = why
        tr.note_end("forwards" if side > 0 else "backwards", why)
    bwd, sp_b = added[-1]
    fwd, sp_f = added[1]
    out = list(reversed(bwd)) + pts + fwd
    return Traced(tuple(out), start + len(bwd),
                  tuple(list(reversed(sp_b)) + list(specials) + sp_f),
                  (new_ends[0], new_ends[1]), tuple(tr.warnings), tr.evaluations,
                  time.process_time() - cpu)
