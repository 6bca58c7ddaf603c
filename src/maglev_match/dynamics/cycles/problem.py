"""The continuation problem of a cycle branch: :class:`CycleProblem` puts the collocation
BVP (:class:`~maglev_match.dynamics.collocation.CollocationProblem`) in one parameter
before the package's pseudo-arclength driver
(:func:`~maglev_match.dynamics.continuation.continuation`): the corrector (AUTO's chord
iteration or Newton's method on the bordered system), the arclength weights, the read-out
of each point (a :class:`~maglev_match.dynamics.cycles.results.CyclePoint` with its
Floquet multipliers), the test functions of the special points (LPC; BP by a bordered
test function, Govaerts 2000, ch. 3, and Allgower & Georg 1990, sec. 8.1; PD and NS from
the multipliers, Kuznetsov 2004, sec. 10.3.2; a contact with a physical limit; the stop
value), mesh adaptation and the change to the system's regular chart. The physical limits
come in as a callable (:data:`LimitFn`), read by :func:`limit_margin`.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from maglev_match.dynamics.collocation import (
    CollocationBVP,
    CondensedLU,
    NewtonStats,
    adapt_mesh,
    chord_newton,
    collocation_newton,
    collocation_tables,
    remesh,
)
from maglev_match.dynamics.continuation import (
    BranchPoint,
    Correction,
    SpecialPointKind,
)
from maglev_match.dynamics.cycles.options import CycleOptions, MultipliersAt, NewtonMode
from maglev_match.dynamics.cycles.orbits import PeriodicOrbit, first_harmonic, orbit_extrema
from maglev_match.dynamics.cycles.results import CyclePoint, CycleStop, RestartState
from maglev_match.dynamics.cycles.stability import (
    BIFURCATION_TESTS,
    MULTIPLIER_TESTS,
    Stability,
    blocks_at,
    multiplier_tests,
    n_complex_outside,
    ns_pair_real,
    split_trivial,
    stability_of,
)
from maglev_match.dynamics.floquet import floquet_multipliers_from_blocks
from maglev_match.dynamics.system import System, chart_kernels

__all__ = [
    "CONTACT_TOL",
    "CycleProblem",
    "LimitFn",
    "limit_margin",
]


LimitFn = Callable[[System, PeriodicOrbit], Any]


def limit_margin(limits: LimitFn | None, system: System, orbit: PeriodicOrbit) -> tuple[float, str]:
    """Smallest limit margin (negative when touched) and its name. ``limits`` returns a
    mapping name -> margin (positive inside), or the name of the touched limit / None."""
    if limits is None:
        return np.inf, ""
    out = limits(system, orbit)
    if out is None:
        return 1.0, ""
    if isinstance(out, str):
        return -1.0, out
    if isinstance(out, Mapping):
        if not out:
            return np.inf, ""
        name = min(out, key=lambda k: out[k])
        return float(out[name]), str(name)
    return float(out), "limit"


#: A contact with a physical limit is solved when its (dimensionless) margin is within
#: this of zero: the margin is a smooth function of the branch (the extremum of an
#: observable over the orbit, refined to the polynomial's own extremum).
CONTACT_TOL = 1e-12


def _transfer(prob: CollocationBVP, lu: Any) -> np.ndarray | None:
    """The Floquet transfer matrices from a condensed factorisation at the solution (None
    for the whole-system sparse LU, which does not form them)."""
    return lu.transfer_matrices(prob.scale) if isinstance(lu, CondensedLU) else None


class _TangentMemo:
    """A factorisation's solve that remembers its solution for e_last (the tangent's
    right-hand side, asked for again by the BP test function at the same point)."""

    __slots__ = ("_solve", "_e")

    def __init__(self, solve: Callable[[np.ndarray], np.ndarray]):
        self._solve, self._e = solve, None

    def __call__(self, b: np.ndarray) -> np.ndarray:
        if b[-1] == 1.0 and not np.any(b[:-1]):
            if self._e is None:
                self._e = self._solve(b)
            return self._e.copy()
        return self._solve(b)


#: A step whose ends both have a real nontrivial multiplier within this of +1 (on the same
#: side) is checked inside for two branch points (:meth:`CycleProblem.double_zero_suspect`).
BP_SUSPECT = 1e-2


class CycleProblem:
    """The collocation BVP of periodic orbits in one parameter as a problem for
    :func:`~maglev_match.dynamics.continuation.continuation`: corrector (Newton on the
    bordered system), weights, read-outs (a :class:`CyclePoint` per point), test functions
    and the hooks of the driver.

    Test functions (zeros located by solving inside the step where they change sign):

    * LPC: the parameter component of the tangent (a fold of cycles);
    * BP: the bordered test function psi = -1 / <c, A^-1 b>_W of the arclength-extended
      Jacobian A = [F_Y; (W t)^T] (Govaerts 2000, "Numerical methods for bifurcations of
      dynamical equilibria", ch. 3, bordered matrices; Allgower & Georg 1990, sec. 8.1):
      A is singular exactly at a branch point and regular at a fold (the arclength row
      keeps it regular there), so psi changes sign at a BP only. b is a fixed smooth
      forcing of the collocation rows, c the direction of A^-1 b at the previous point;
      psi is smooth inside a step and vanishes linearly at the branch point;
    * PD, NS: products over the nontrivial multipliers (:func:`multiplier_tests`);
    * contact: the smallest margin to a physical limit (terminal);
    * STOP: the stop value (terminal).

    LPC, BP, PD and NS are evaluated only where the Floquet data are reliable (trivial
    multiplier within ``trivial_tol`` of 1): no special point is declared from points whose
    discretisation has lost its accuracy (near a homoclinic orbit). The family's end at an
    equilibrium (a second Hopf point) is watched through the first Fourier coefficient of
    the profile (:func:`first_harmonic`), and a period beyond ``max_period_factor`` times
    the Hopf period ends the branch as a homoclinic approach (:meth:`stop`).
    """

    def __init__(self, prob: CollocationBVP, names, limits, stop_at, options: CycleOptions,
                 max_period: float, start_orbit):
        self.prob = prob
        self.names = names
        self.limits = limits
        self.stop_at = stop_at
        self.opt = options
        self.trivial_tol = options.trivial_tol
        self.max_period = max_period
        self.adapt_every = options.adapt_every
        self.tol = options.tol
        self.weights = prob.W()
        self.start_orbit = start_orbit
        self.accepted = 0
        self.warnings: list[str] = []
        self.restarting = False
        self.detect = bool(options.detect_special_points)
        self.floquet_method = options.floquet_method
        self.newton = NewtonMode(options.newton)
        self.chord_lu: Any = None  # the last corrector's factorisation (same mesh)
        self.stats = NewtonStats()
        self.locate_limit = bool(options.locate_limit)
        self.factor_at_solution = options.factor_at_solution is not False and not (
            options.factor_at_solution is None and not self.detect
            and options.multipliers_at == MultipliersAt.LAST)
        # the original system and its regular chart (None: no chart, or not used)
        self.system = prob.system
        self.chart = prob.system.chart if options.use_chart else None
        self.in_chart = False
        self.chart_at: float | None = None  # parameter value where the chart took over
        # step-local test functions: the BP border c and the first harmonic's reference
        self.bp_c: np.ndarray | None = None
        self.amp_ref: np.ndarray | None = None
        self.amp_max = 0.0
        self.last_reliable: CyclePoint | None = None

    # --- corrector and read-outs ---
    def correct(self, u_pred, row, target, max_iter):
        Uref, _, _ = self.prob.unpack(u_pred)
        if self.newton == NewtonMode.CHORD:
            cr = chord_newton(self.prob, u_pred, Uref, row, target, self.tol, max_iter,
                               lu0=self.chord_lu, stats=self.stats,
                               at_solution=self.factor_at_solution)
            if not cr.converged:
                return None
            self.chord_lu = cr.lu
            at_solution = cr.blocks is not None
            return Correction(u=cr.Y, iterations=cr.iterations, residual=cr.residual,
                              solve=_TangentMemo(cr.lu.solve),
                              data=(cr.blocks, self.prob.mesh.copy(),
                                    _transfer(self.prob, cr.lu) if at_solution else None,
                                    np.array(row, float)))
        Y, ok, its, res, lu, blocks = collocation_newton(self.prob, u_pred, Uref, row, target,
                                              self.tol, max_iter, lazy_blocks=True)
        self.stats.correctors += 1
        self.stats.iterations += its
        self.stats.factorizations += its
        if not ok:
            return None
        return Correction(u=Y, iterations=its, residual=res, solve=lu.solve,
                          data=(blocks, self.prob.mesh.copy(), None, np.array(row, float)))

    def parameter(self, u) -> float:
        return self.prob.unpack(u)[2]

    def admissible(self, a, u_new, s) -> bool:
        """A positive period, and no jump to another branch: the corrected point stays
        within 3 s of the point before (the arclength constraint fixes only the tangent
        component)."""
        if not self.prob.unpack(u_new)[1] > 0:
            return False
        d = u_new - a.u
        return float(np.sqrt(np.sum(self.weights * d * d))) <= 3.0 * s

    def _floquet_fields(self, pt: BranchPoint) -> dict[str, Any]:
        blocks, mesh, P, _ = pt.correction.data
        J, Tb, h = blocks if blocks is not None else blocks_at(self.prob, pt.u, mesh)
        triv, mult = split_trivial(floquet_multipliers_from_blocks(
            J, Tb, h, self.prob.m, transfer=P,
            method=getattr(self.prob.system, "floquet_method", self.floquet_method)))
        tol = self.opt.neutral_tol
        nun = int(np.sum(np.abs(mult) > 1.0 + tol))
        reliable = bool(abs(triv - 1.0) <= self.trivial_tol)
        stab = stability_of(mult, tol) if reliable else Stability.UNKNOWN
        return {"multipliers": mult, "trivial_multiplier": triv, "n_unstable": nun,
                "stable": stab == Stability.STABLE if reliable else nun == 0,
                "stability": stab, "reliable": reliable}

    def orbit_of(self, mesh: np.ndarray, U: np.ndarray, T: float, lam: float
                 ) -> tuple[PeriodicOrbit, PeriodicOrbit]:
        """The orbit in the coordinates of the continuation and in the system's own ones
        (the same object without a chart)."""
        p = self.prob.params(lam)
        here = PeriodicOrbit(mesh=mesh, ncol=self.prob.m, states=U, period=T, p=p)
        if not self.in_chart:
            return here, here
        X = np.asarray(chart_kernels(self.chart)["from"](U, p))
        return here, PeriodicOrbit(mesh=mesh, ncol=self.prob.m, states=X, period=T, p=p)

    def cycle_point(self, pt: BranchPoint, kind: str = "step", floquet: bool = True
                    ) -> CyclePoint:
        """The read-out of a branch point. ``floquet`` False leaves the multipliers out
        (placeholders, marked in ``pt.info["lazy"]``) for :meth:`complete` to fill in.
        The orbit is reported in the system's own coordinates; the read-outs are taken on
        the profile the continuation solved (the same quantities, observables composed
        with the chart's map)."""
        prob = self.prob
        mesh = pt.correction.data[1]
        U, T, lam = prob.unpack(pt.u)
        if floquet:
            fields = self._floquet_fields(pt)
        else:
            fields = {"multipliers": np.zeros(0), "trivial_multiplier": complex("nan"),
                      "n_unstable": 0, "stable": False, "reliable": False,
                      "stability": Stability.UNKNOWN}
        pt.info["lazy"] = not floquet
        here, orbit = self.orbit_of(mesh, U, T, lam)
        pt.info["orbit_here"] = here
        return CyclePoint(value=lam, period=T, orbit=orbit,
                          extrema=orbit_extrema(prob.system, here, self.names),
                          converged=True, iterations=pt.correction.iterations,
                          residual=pt.correction.residual, kind=kind, **fields)

    def complete(self, pt: BranchPoint | None) -> None:
        """Fill in the multipliers of a point read out without them (in place)."""
        if pt is not None and pt.info.get("lazy") and "cycle" in pt.info:
            pt.info["cycle"] = dataclasses.replace(pt.info["cycle"],
                                                   **self._floquet_fields(pt))
            pt.info["lazy"] = False

    # --- test functions ---
    def _bp_border(self) -> np.ndarray:
        key = (self.prob.mesh.tobytes(), self.prob.m, self.prob.n)
        if getattr(self, "_border_key", None) != key:
            self._border = self._make_bp_border()
            self._border_key = key
        return self._border

    def _make_bp_border(self) -> np.ndarray:
        """The fixed right-hand side b of the BP test: a smooth forcing of the collocation
        rows (the mean and three harmonics with fixed pseudo-random coefficients per state,
        evaluated at
        the Gauss points and scaled by h_j like the rows), fixed numbers in the phase and
        arclength rows; the same function of time on every mesh."""
        prob = self.prob
        m, n = prob.m, prob.n
        _, z, _, _, _ = collocation_tables(m)
        h = np.diff(prob.mesh)
        t = (prob.mesh[:-1, None] + h[:, None] * z[None, :])  # (ntst, m)
        rng = np.random.default_rng(20251)
        a = rng.standard_normal((4, 2, n))
        k = np.arange(0, 4)[:, None, None, None]  # with the mean: the adjoint null vector
        # of a branch point may be constant in time (a transverse mode of a circle)
        ang = 2.0 * np.pi * k * t[None, :, :, None]
        f = np.sum(a[:, 0][:, None, None, :] * np.cos(ang) + a[:, 1][:, None, None, :]
                   * np.sin(ang), axis=0)  # (ntst, m, n)
        col = (f * h[:, None, None]).ravel()
        return np.concatenate([col, np.zeros(n), [0.37, 0.61]])

    def _bp_vector(self, pt: BranchPoint, row: np.ndarray | None = None) -> np.ndarray:
        """v = A^-1 b at a point, A its extended Jacobian with the last row ``row`` (default:
        the row it was corrected with; another row by a rank-one update of the same
        factorisation, Sherman-Morrison)."""
        corr = pt.correction
        b = self._bp_border()
        v = np.asarray(corr.solve(b), float)
        old = corr.data[3] if corr.data is not None and len(corr.data) > 3 else None
        if row is None or old is None:
            return v
        e = np.zeros(v.size)
        e[-1] = 1.0
        w = np.asarray(corr.solve(e), float)
        d = row - old
        den = 1.0 + float(d @ w)
        if den == 0.0:
            return v
        return v - w * (float(d @ v) / den)

    def _wdot(self, a: np.ndarray, b: np.ndarray) -> float:
        return float(np.sum(self.weights * a * b))

    def _step_local_tests(self, pt: BranchPoint) -> None:
        """Make ``pt`` the reference of the step-local test functions (the BP border c and
        the first harmonic) for the next step, with its own values in that frame. The BP
        frame is v = A^-1 b at ``pt`` with the row of the next step, W t (``bp_v``, computed
        before a mesh adaptation and remapped with the point)."""
        if self.detect and "BP" in pt.tests and np.isfinite(pt.tests["BP"]):
            v = pt.info.pop("bp_v", None)
            if v is None:
                v = self._bp_vector(pt, row=self.weights * pt.t)
            nv = math.sqrt(self._wdot(v, v))
            if nv > 0 and np.isfinite(nv):
                self.bp_c = v / nv
                pt.tests["BP"] = -1.0 / nv
            else:
                pt.tests["BP"] = np.nan  # no frame: no BP located in the next step
        c1 = pt.info.get("c1")
        if c1 is not None:
            self.amp_ref = c1
            pt.tests["AMP"] = float(np.linalg.norm(c1))

    def test_functions(self, pt: BranchPoint) -> dict[str, float]:
        if pt.kind == "start" and not self.restarting:  # the Hopf point: no multipliers
            out = {}
            if self.limits is not None:
                out["CONTACT"] = limit_margin(self.limits, self.prob.system,
                                              self.start_orbit)[0]
            if self.stop_at is not None:
                out["STOP"] = pt.value - self.stop_at
            return out
        # without special points the multipliers are needed only at the points the branch
        # keeps (filled in afterwards), not at the trial points of the event location
        c = self.cycle_point(pt, floquet=self.detect)
        pt.info["cycle"] = c
        pt.info["phys"] = self.physical_state(pt)
        out: dict[str, float] = {}
        if self.detect:
            # the fold is where the branch turns back in the parameter: the parameter
            # component of the tangent, which needs no multipliers (a fold between points
            # whose multipliers are unreliable, e.g. in a canard explosion, was missed)
            out["LPC"] = float(pt.t[-1])
            if c.reliable:
                out.update({k: v for k, v in multiplier_tests(np.asarray(c.multipliers))
                            .items() if k in MULTIPLIER_TESTS})
                if self.bp_c is not None:
                    v = self._bp_vector(pt)
                    d = self._wdot(self.bp_c, v)
                    out["BP"] = -1.0 / d if d != 0 and np.isfinite(d) else np.nan
                else:
                    out["BP"] = -1.0  # the frame is set at the first accepted point
            else:  # no multiplier test from unreliable Floquet data
                out.update({k: np.nan for k in BIFURCATION_TESTS if k != "LPC"})
        U, _, _ = self.prob.unpack(pt.u)
        c1 = first_harmonic(pt.correction.data[1], self.prob.m, U) / self.prob.scale
        pt.info["c1"] = c1
        amp = float(np.linalg.norm(c1))
        if self.amp_ref is not None:
            r = self.amp_ref
            out["AMP"] = float(np.real(np.vdot(r, c1))) / max(float(np.linalg.norm(r)),
                                                               1e-300)
        else:
            out["AMP"] = amp
        pt.info["amp"] = amp
        pt.info["amp_signed"] = out["AMP"]
        if self.limits is not None:
            out["CONTACT"], pt.info["limit"] = limit_margin(self.limits, self.prob.system,
                                                            pt.info["orbit_here"])
        if self.stop_at is not None:
            out["STOP"] = c.value - self.stop_at
        return out

    def event_tests(self, name: str, pt: BranchPoint) -> dict[str, float]:
        """At a trial point of an event's location: the test functions that the location
        and the classification of that event need. LPC, a contact and the stop value need
        no Floquet multipliers (the located point gets them afterwards, :meth:`complete`);
        PD, NS and BP are read out in full."""
        if name in ("PD", "NS", "BP") or name.startswith("__"):
            return self.test_functions(pt)
        c = self.cycle_point(pt, floquet=False)
        pt.info["cycle"] = c
        pt.info["phys"] = self.physical_state(pt)
        out: dict[str, float] = {}
        if name == "LPC":
            out["LPC"] = float(pt.t[-1])
        if self.limits is not None:
            out["CONTACT"], pt.info["limit"] = limit_margin(self.limits, self.prob.system,
                                                            pt.info["orbit_here"])
        if self.stop_at is not None:
            out["STOP"] = c.value - self.stop_at
        return out

    def event_kind(self, name: str) -> str:
        return {"LPC": SpecialPointKind.LPC, "CONTACT": SpecialPointKind.CONTACT,
                "BP": SpecialPointKind.BP, "STOP": "STOP", "AMP": "AMP",
                **MULTIPLIER_TESTS}[name]

    def terminal(self, name: str) -> bool:
        return name in ("CONTACT", "STOP")

    def event_tolerance(self, name: str) -> float | None:
        """The stop value needs one secant trial inside the step: the cycle there is then
        solved at exactly the stop value (:func:`_fixed_param`), whatever the trial's
        distance from it; so does a contact that is only to be bracketed. Every other event
        is located to ``event_tol``."""
        if name == "STOP" or (name == "CONTACT" and not self.locate_limit):
            return 1.0
        return None

    def event_value_tolerance(self, name: str) -> float | None:
        """A contact is solved when its margin (dimensionless) is within 1e-12 of zero."""
        return CONTACT_TOL if name == "CONTACT" and self.locate_limit else None

    def _past_end(self, b: BranchPoint) -> bool:
        """Whether the step to b passed the equilibrium (the first harmonic turned through
        zero, or collapsed onto the trivial branch: the family closed at a Hopf point)."""
        amp = b.info.get("amp")
        if amp is None or "amp_signed" not in b.info or not self.amp_max > 0:
            return False
        return b.info["amp_signed"] <= 0.0 or amp < 1e-6 * self.amp_max

    def worth_locating(self, name: str, a: BranchPoint, b: BranchPoint) -> bool:
        """Skip sign changes that the end points show are no special point: NS when the
        number of non-real multipliers outside the unit circle is the same at both ends
        (the NS test then changed sign on a real pair mu, 1/mu); nothing but the stop
        value and a contact in a step that passed the family's end at an equilibrium; the
        first harmonic's sign is watched by :meth:`stop`, never located."""
        if name == "AMP":
            return False
        if self._past_end(b) and name not in ("STOP", "CONTACT"):
            return False
        if name == "NS":
            return n_complex_outside(a.info["cycle"].multipliers) != \
                n_complex_outside(b.info["cycle"].multipliers)
        return True

    def corrector_state(self) -> Any:
        """The chord iterations' kept factorisation (restored after a check inside a step
        that found nothing, :func:`~maglev_match.dynamics.continuation.continuation`)."""
        return self.chord_lu

    def set_corrector_state(self, state: Any) -> None:
        self.chord_lu = state

    def double_zero_suspect(self, name: str, a: BranchPoint, b: BranchPoint) -> bool:
        """Whether the BP test may have changed sign twice in the step (two branch points
        in one step, e.g. side by side next to a fold): a real nontrivial multiplier within
        :data:`BP_SUSPECT` of +1 at both ends (reliable), on the same side of it; the
        driver then checks the test's sign inside the step (1 to 3 more corrections)."""
        if name != "BP":
            return False
        side = []
        for pt in (a, b):
            c = pt.info.get("cycle")
            if c is None or not c.reliable or pt.info.get("lazy"):
                return False
            mult = np.asarray(c.multipliers, complex)
            real = mult[np.abs(mult.imag) <= 1e-9 * np.maximum(1.0, np.abs(mult))].real
            if real.size == 0:
                return False
            d = real[int(np.argmin(np.abs(real - 1.0)))] - 1.0
            if abs(d) > BP_SUSPECT:
                return False
            side.append(d > 0)
        return side[0] == side[1]

    def classify(self, name: str, pt: BranchPoint, a: BranchPoint, b: BranchPoint):
        if name not in ("PD", "NS", "BP"):
            return self.event_kind(name)
        c = pt.info.get("cycle")
        if c is None or not c.reliable:
            self.warnings.append(f"{name} test changed sign between {a.value:.8g} and "
                                 f"{b.value:.8g}, but the multipliers there are unreliable "
                                 "(trivial multiplier away from 1): not reported")
            return None
        mult = np.asarray(c.multipliers)
        if name == "BP":
            # a zero of psi (not a pole, where it changes sign through infinity), with a
            # nontrivial multiplier at +1 as a branch point of cycles has
            g = abs(pt.tests.get("BP", np.inf))
            ends = max(abs(a.tests.get("BP", 0.0)), abs(b.tests.get("BP", 0.0)))
            if mult.size == 0 or float(np.min(np.abs(mult - 1.0))) > 1e-3:
                return None
            if g <= 1e-3 * ends:
                return SpecialPointKind.BP
            if g <= 0.1 * ends:
                # a smaller drop (the corrector failed close to it): reported only if the
                # branch-point system confirms it (cycle_branch drops it otherwise)
                pt.info["bp_confirm"] = True
                return SpecialPointKind.BP
            return None
        if name == "PD":
            k = int(np.argmin(np.abs(mult + 1.0)))
            return SpecialPointKind.PD if abs(mult[k] + 1.0) < 1e-3 else None
        # NS: the pair with mu_i mu_j = 1 must be complex (a real pair mu, 1/mu is a
        # neutral saddle cycle, no bifurcation)
        i, j = np.triu_indices(mult.size, 1)
        k = int(np.argmin(np.abs(mult[i] * mult[j] - 1.0)))
        mu = mult[i[k]]
        if ns_pair_real(mult) or abs(abs(mu) - 1.0) > 1e-3:
            return None
        return SpecialPointKind.NS

    # --- hooks ---
    def physical_state(self, pt: BranchPoint) -> tuple:
        """(U, T, lambda, tU, tT, tlambda, mesh, in_chart) of a point in physical units of
        the coordinates it was computed in (kept with the point: the problem's scales
        change when the chart takes over)."""
        prob = self.prob
        U, T, lam = prob.unpack(pt.u)
        tU, tT, tl = prob.unpack(pt.t)
        return (U, T, lam, tU, tT, tl, np.array(prob.mesh), self.in_chart)

    def restart_state(self, phys: tuple, ds: float, accepted: int) -> RestartState:
        """The continuation state of :meth:`physical_state` in the system's own
        coordinates."""
        U, T, lam, tU, tT, tl, mesh, in_chart = phys
        if in_chart:
            k = chart_kernels(self.chart)
            p = self.prob.params(lam)
            dp = np.zeros_like(p)
            dp[self.prob.ipar] = tl
            U, tU = (np.asarray(a) for a in k["from_tangent"](U, tU, p, dp))
        return RestartState(mesh=np.array(mesh), states=U, period=T, value=lam, t_states=tU,
                            t_period=tT, t_value=tl, ds=float(ds), accepted=accepted)

    def after_accept(self, pt: BranchPoint) -> BranchPoint:
        self.accepted += 1
        c = pt.info.get("cycle")
        if c is not None and c.reliable and not pt.info.get("lazy"):
            self.last_reliable = c
        self.amp_max = max(self.amp_max, float(pt.info.get("amp", 0.0)))
        if self.detect and "BP" in pt.tests and np.isfinite(pt.tests["BP"]):
            pt.info["bp_v"] = self._bp_vector(pt, row=self.weights * pt.t)
        pt = self._adapt(pt)
        self._step_local_tests(pt)
        pt.info["state"] = (self.physical_state(pt), self.accepted)
        return pt

    def _adapt(self, pt: BranchPoint) -> BranchPoint:
        if not (self.adapt_every and self.accepted % self.adapt_every == 0):
            return pt
        prob = self.prob
        U, T, lam = prob.unpack(pt.u)
        Ut, Tt, lt = prob.unpack(pt.t)
        old_mesh = prob.mesh
        new_mesh = adapt_mesh(old_mesh, prob.m, U, prob.scale)
        U2 = remesh(old_mesh, prob.m, U, new_mesh)
        Ut2 = remesh(old_mesh, prob.m, Ut, new_mesh)
        v = pt.info.get("bp_v")
        if v is not None:  # the BP frame is remapped like the tangent (a function of time)
            Uv, Tv, lv = prob.unpack(v)
            pt.info["bp_v"] = (remesh(old_mesh, prob.m, Uv, new_mesh), Tv, lv)
        prob.mesh = new_mesh
        self.chord_lu = None  # the kept factorisation belongs to the old mesh
        if v is not None:
            pt.info["bp_v"] = prob.pack(*pt.info["bp_v"])
        t = prob.pack(Ut2, Tt, lt)
        t /= math.sqrt(float(np.sum(self.weights * t * t)))
        return BranchPoint(u=prob.pack(U2, T, lam), t=t, value=pt.value,
                           correction=pt.correction, tests=pt.tests, kind=pt.kind,
                           info=pt.info)

    def rebase(self, a: BranchPoint, corr: Correction) -> BranchPoint | None:
        """Change to the system's regular chart when the corrected next point comes within
        ``chart.switch_below`` of the singular set (its smallest ``distance`` over the
        nodes): ``a`` is mapped to the chart (profile by the chart's map, tangent by its
        derivative), corrected there (the same orbit on the chart's discretisation), and
        the step is taken again from it. Once in the chart, the branch stays in it."""
        if self.chart is None or self.in_chart:
            return None
        prob = self.prob
        k = chart_kernels(self.chart)
        U_new, _, lam_new = prob.unpack(corr.u)
        d = float(np.min(np.asarray(k["distance"](U_new, prob.params(lam_new)))))
        if not d < self.chart.switch_below:
            return None
        U, T, lam = prob.unpack(a.u)
        tU, tT, tl = prob.unpack(a.t)
        p = prob.params(lam)
        dp = np.zeros_like(p)
        dp[prob.ipar] = tl
        Uy, tUy = (np.asarray(v) for v in k["to_tangent"](U, tU, p, dp))
        prob.system = self.system.in_chart()
        prob.scale = np.asarray(self.chart.state_scale, float)
        self.in_chart = True
        self.chart_at = float(lam)
        self.chord_lu = None
        u = prob.pack(Uy, T, lam)
        t = prob.pack(tUy, tT, tl)
        t /= math.sqrt(float(np.sum(self.weights * t * t)))
        row = self.weights * t
        c = self.correct(u, row, float(row @ u), self.opt.max_newton + 8)
        if c is None:  # keep going in the original coordinates
            self.warnings.append(f"the regular chart could not take over at {prob.ipar} = "
                                 f"{lam:.8g}: the branch goes on in the system's own "
                                 "coordinates")
            prob.system = self.system
            prob.scale = np.asarray(self.system.state_scale, float)
            self.in_chart = False
            self.chart = None
            self.chord_lu = None
            return None
        new = BranchPoint(u=c.u, t=t, value=a.value, correction=c, tests=dict(a.tests),
                          kind=a.kind, info=dict(a.info))
        new.info.pop("bp_v", None)
        if self.detect and "BP" in new.tests and np.isfinite(new.tests["BP"]):
            new.tests["BP"] = 0.0  # recomputed below in the chart's frame
        Uc, _, _ = prob.unpack(c.u)
        new.info["c1"] = first_harmonic(c.data[1], prob.m, Uc) / prob.scale
        self._step_local_tests(new)
        return new

    def stop(self, pt: BranchPoint) -> str | None:
        c = pt.info["cycle"]
        if self._past_end(pt):
            return CycleStop.HOPF
        if c.period > self.max_period:
            return CycleStop.HOMOCLINIC
        return None
