"""Periodic orbits of x' = f(x, p): orthogonal collocation, pseudo-arclength continuation
from a Hopf point, Floquet multipliers and cycle bifurcations.

Model-agnostic: works on any :class:`~maglev_match.dynamics.system.System`; observables
(read-outs) and physical limits come in as names and callables.

Discretisation (as in AUTO-07p / MATCONT). Time is rescaled to [0, 1], u' = T f(u, p).
The mesh 0 = t_0 < ... < t_NTST = 1 carries on each interval a polynomial of degree NCOL,
given by its values at NCOL + 1 equally spaced nodes (shared at interval ends, so the
profile is continuous). The equations are

* collocation at the NCOL Gauss-Legendre points of every interval: u'(z) - T f(u(z), p) = 0,
* periodicity u(1) - u(0) = 0,
* the integral phase condition  int_0^1 <u(t) - u_ref(t), u_ref'(t)> dt = 0,
* the pseudo-arclength condition <X - X_prev, X'_prev>_W - ds = 0 (or a fixed parameter),

for the unknowns X = (profile, period T, parameter). Newton's method uses the exact
Jacobian (JAX, vmapped over collocation points); by default the interior collocation
unknowns of each interval are condensed out and the small mesh-node system is factorised
by sparse LU (:class:`~maglev_match.dynamics.collocation.CondensedLU`; ``linear_solver=
"sparse_lu"`` factorises the whole system instead); the corrector is the chord iteration,
which keeps the factorisation of the previous solution while it contracts fast
(``newton="full"``: a factorisation per iteration). Floquet multipliers are those of the
product of the interval transfer matrices of the variational equation (taken from the
condensation at each solution), computed without forming the product
(:mod:`~maglev_match.dynamics.floquet`). The mesh is adapted by
equidistributing |u^(NCOL+1)|^(1/(NCOL+1)) (de Boor's criterion, as AUTO does).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from enum import StrEnum
from functools import cache
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from maglev_match.aot import cached_kernel
from maglev_match.dynamics.collocation import (
    CondensedLU,
    LinearSolver,
    NewtonStats,
    _adapt_mesh,
    _chord_newton,
    _evaluate_profile,
    _interval_index,
    _kernel,
    _lagrange,
    _newton,
    _node_times,
    _Problem,
    _remesh,
)
from maglev_match.dynamics.continuation import (
    SOLVED,
    BranchPoint,
    ContinuationOptions,
    Correction,
    SpecialPointKind,
    StopReason,
    continuation,
    signed_geometric_mean,
)
from maglev_match.dynamics.floquet import floquet_multipliers_from_blocks
from maglev_match.dynamics.system import System
from maglev_match.reprs import compact_repr

__all__ = [
    "HopfStart",
    "PeriodicOrbit",
    "CyclePoint",
    "SpecialPoint",
    "CycleBranch",
    "CorrectionResult",
    "CycleStop",
    "NewtonMode",
    "RestartState",
    "branch_to_xarray",
    "load_restart",
    "CycleProblem",
    "multiplier_tests",
    "hopf_start",
    "cycle_branch",
    "correct_cycle",
    "floquet_multipliers",
    "orbit_extrema",
]

Array = Any


# ---------------------------------------------------------------------------------------
# data
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class HopfStart:
    """What a cycle branch needs from a Hopf point.

    Parameters
    ----------
    param : name of the continuation parameter.
    value : its value at the Hopf point.
    x : equilibrium state at the Hopf point.
    p : full parameter vector at the Hopf point.
    frequency : omega (rad/s) of the critical pair +-i omega.
    q : complex right eigenvector, J q = i omega q.
    l1 : first Lyapunov coefficient if known (sign: < 0 supercritical, > 0 subcritical).
    """

    param: str
    value: float
    x: np.ndarray
    p: np.ndarray
    frequency: float
    q: np.ndarray
    l1: float | None = None


@dataclass(frozen=True)
class PeriodicOrbit:
    """A periodic orbit as a piecewise-polynomial collocation profile.

    ``mesh`` (NTST + 1,) in [0, 1]; ``states`` (NTST NCOL + 1, dim) at the nodes
    t_j + k/NCOL (t_{j+1} - t_j); time t = T s for the normalised time s.
    """

    __repr__ = compact_repr

    mesh: np.ndarray
    ncol: int
    states: np.ndarray
    period: float  # s
    p: np.ndarray

    @property
    def ntst(self) -> int:
        return self.mesh.size - 1

    @property
    def node_times(self) -> np.ndarray:
        """Normalised times of all nodes (NTST NCOL + 1,)."""
        return _node_times(self.mesh, self.ncol)

    @property
    def times(self) -> np.ndarray:
        """Times of the nodes (s)."""
        return self.node_times * self.period

    def evaluate(self, s: Array) -> np.ndarray:
        """States at normalised times s in [0, 1] (periodic extension), shape (len(s), dim)."""
        return _evaluate_profile(self.mesh, self.ncol, self.states, np.asarray(s, float) % 1.0)


@dataclass(frozen=True)
class RestartState:
    """What a continuation needs to go on from a cycle: the profile on its mesh, period,
    parameter, the tangent (same layout, physical units: d profile, d T, d lambda per unit
    of scaled arclength), the next step size and the count of accepted steps (for the mesh
    adaptation schedule)."""

    mesh: np.ndarray
    states: np.ndarray
    period: float
    value: float
    t_states: np.ndarray
    t_period: float
    t_value: float
    ds: float
    accepted: int


@dataclass(frozen=True)
class CyclePoint:
    """One converged cycle on a branch with its Floquet multipliers and read-outs."""

    __repr__ = compact_repr

    value: float  # continuation parameter
    period: float  # s
    orbit: PeriodicOrbit
    multipliers: np.ndarray  # nontrivial Floquet multipliers (the one nearest 1 removed)
    trivial_multiplier: complex  # should be 1: its distance to 1 is an accuracy check
    n_unstable: int  # multipliers with |mu| > 1 (trivial excluded)
    stable: bool
    extrema: Mapping[str, tuple[float, float]]  # observable -> (max, min) over the cycle
    converged: bool
    iterations: int
    residual: float
    kind: str = "step"  # "step", "stop_at", "limit", "bound", or a special-point type
    reliable: bool = True  # |trivial multiplier - 1| within tolerance: stability trusted
    restart: RestartState | None = None  # to continue from this point (saved branches)

    def max(self, name: str) -> float:
        return self.extrema[name][0]

    def min(self, name: str) -> float:
        return self.extrema[name][1]


@dataclass(frozen=True)
class SpecialPoint:
    """A bifurcation of cycles (LPC, BP, PD, NS) or a physical-limit contact (LIMIT),
    located by solving its test function inside the step where it changed sign.

    ``type`` is a :class:`~maglev_match.dynamics.continuation.SpecialPointKind` value;
    ``located`` is "solved" or the reason it could not be solved; ``label`` is unique
    along the branch (PD1, LPC2, ...); ``point`` is the solved cycle there."""

    type: str
    value: float
    period: float
    extrema: Mapping[str, tuple[float, float]]
    step: int  # index of the branch point just before it
    located: str  # "solved" or the reason it was not
    detail: str = ""
    label: str = ""
    point: CyclePoint | None = None


@dataclass(frozen=True)
class CycleBranch:
    """A branch of periodic orbits continued in one parameter from a Hopf point."""

    __repr__ = compact_repr

    param: str
    hopf: HopfStart
    points: tuple[CyclePoint, ...]
    special_points: tuple[SpecialPoint, ...]
    stopped_reason: str
    warnings: tuple[str, ...] = ()
    ntst: int = 0
    ncol: int = 0
    steps: int = 0  # continuation steps taken (accepted)
    rejected_steps: int = 0
    newton_iterations: int = 0  # corrector iterations over the whole run (linear solves)
    factorizations: int = 0  # factorisations of the bordered Jacobian over the run

    @property
    def values(self) -> np.ndarray:
        return np.array([c.value for c in self.points])

    @property
    def periods(self) -> np.ndarray:
        return np.array([c.period for c in self.points])

    @property
    def stable(self) -> np.ndarray:
        return np.array([c.stable for c in self.points], dtype=bool)

    @property
    def n_unstable(self) -> np.ndarray:
        return np.array([c.n_unstable for c in self.points], dtype=int)

    @property
    def converged(self) -> np.ndarray:
        return np.array([c.converged for c in self.points], dtype=bool)

    def observable_max(self, name: str) -> np.ndarray:
        return np.array([c.extrema[name][0] for c in self.points])

    def observable_min(self, name: str) -> np.ndarray:
        return np.array([c.extrema[name][1] for c in self.points])

    @property
    def last(self) -> CyclePoint | None:
        return self.points[-1] if self.points else None

    def to_xarray(self, system: System | None = None, param_unit: str = "",
                  state_units: Sequence[str] | None = None):
        """The full branch as an xarray Dataset (see :func:`branch_to_xarray`)."""
        return branch_to_xarray(self, system, param_unit, state_units)


@dataclass(frozen=True)
class CorrectionResult:
    """A cycle solved at a fixed parameter value (Newton on the collocation system)."""

    point: CyclePoint | None
    converged: bool
    iterations: int
    message: str = ""


# parameter values this close to zero are zero to rounding (a located root at 0)
LAM_ZERO = 1e-12


# ---------------------------------------------------------------------------------------
# collocation tables and JAX kernels
# ---------------------------------------------------------------------------------------










# ---------------------------------------------------------------------------------------
# the discretised boundary-value problem
# ---------------------------------------------------------------------------------------






# ---------------------------------------------------------------------------------------
# Floquet multipliers, read-outs, mesh adaptation
# ---------------------------------------------------------------------------------------
def _split_trivial(mult: np.ndarray) -> tuple[complex, np.ndarray]:
    k = int(np.argmin(np.abs(mult - 1.0)))
    return complex(mult[k]), np.delete(mult, k)


def floquet_multipliers(system: System, orbit: PeriodicOrbit) -> np.ndarray:
    """Floquet multipliers of a collocation orbit (all n, including the trivial one)."""
    m = orbit.ncol
    ntst = orbit.ntst
    h = np.diff(orbit.mesh)
    idx = _interval_index(ntst, m)
    e = np.zeros_like(orbit.p)
    _, _, J, _ = _kernel(system.rhs, m)(
        jnp.asarray(orbit.states[idx]), jnp.asarray(h), orbit.period, jnp.asarray(orbit.p),
        jnp.asarray(e),
    )
    return floquet_multipliers_from_blocks(np.asarray(J), orbit.period, h, m,
                                           method=getattr(system, "floquet_method", "auto"))


@cache
def _local_basis(m: int, npts: int) -> np.ndarray:
    """Lagrange basis of degree m at npts equally spaced local points: (npts, m+1)."""
    return _lagrange(np.linspace(0.0, 1.0, m + 1), np.linspace(0.0, 1.0, npts))[0]


@cache
def _extrema_kernel(gs: tuple[Callable, ...], m: int, refine: int) -> Callable:
    """One jitted call giving (max, min) of each observable in ``gs`` over an orbit: the
    coarse pass over 4 NCOL + 1 points per interval, the intervals around each extreme, and
    the fine pass (``refine`` + 1 points per interval) over those (cached per observables,
    NCOL, refine; see :func:`orbit_extrema`)."""
    Lc = jnp.asarray(_local_basis(m, 4 * m + 1))
    Lf = jnp.asarray(_local_basis(m, refine + 1))
    batches = [jax.vmap(g, (0, None)) for g in gs]

    def kernel(nodes, p):
        ntst, n = nodes.shape[0], nodes.shape[2]
        X = jnp.einsum("sk,jkn->jsn", Lc, nodes).reshape(-1, n)
        out = []
        for g in batches:
            vals = g(X, p).reshape(ntst, Lc.shape[0], -1)
            jmax = jnp.argmax(vals.reshape(-1)) // (vals.shape[1] * vals.shape[2])
            jmin = jnp.argmax(-vals.reshape(-1)) // (vals.shape[1] * vals.shape[2])
            js = jnp.stack([(jmax - 1) % ntst, jmax, (jmax + 1) % ntst,
                            (jmin - 1) % ntst, jmin, (jmin + 1) % ntst])
            Xf = jnp.einsum("sk,jkn->jsn", Lf, nodes[js]).reshape(-1, n)
            vf = g(Xf, p).reshape(6 * Lf.shape[0], -1)
            half = vf.shape[0] // 2
            out.append(jnp.stack([jnp.maximum(jnp.max(vf[:half]), jnp.max(vals)),
                                  jnp.minimum(jnp.min(vf[half:]), jnp.min(vals))]))
        return jnp.stack(out)

    return cached_kernel(kernel, gs, m, refine)


# the last few orbits' extrema: a branch point's read-out and its limit margins ask for
# the same orbit (entries hold the orbit itself, so an id is never reused while cached)
_EXTREMA_MEMO: list[tuple[System, PeriodicOrbit, int, dict[str, tuple[float, float]]]] = []


def orbit_extrema(
    system: System, orbit: PeriodicOrbit, names: Sequence[str], refine: int = 200
) -> dict[str, tuple[float, float]]:
    """Max and min of each named observable over the orbit (over all components of a
    vector observable), from the collocation polynomial: a coarse pass over 4 NCOL + 1
    points per interval, then a fine pass (``refine`` + 1 points per interval) over the
    intervals around the extreme values. All observables in one compiled call
    (:func:`_extrema_kernel`); the values of an orbit asked again are remembered."""
    names = list(names)
    if not names:
        return {}
    for sys_, orb, ref, ext in _EXTREMA_MEMO:
        if sys_ is system and orb is orbit and ref == refine and all(k in ext for k in names):
            return {k: ext[k] for k in names}
    nodes = orbit.states[_interval_index(orbit.ntst, orbit.ncol)]  # (ntst, m+1, n)
    gs = tuple(system.observables[name] for name in names)
    v = np.asarray(_extrema_kernel(gs, orbit.ncol, refine)(nodes, np.asarray(orbit.p, float)))
    out = {name: (float(v[k, 0]), float(v[k, 1])) for k, name in enumerate(names)}
    _EXTREMA_MEMO.insert(0, (system, orbit, refine, out))
    del _EXTREMA_MEMO[4:]
    return dict(out)


# ---------------------------------------------------------------------------------------
# Hopf start
# ---------------------------------------------------------------------------------------
def hopf_start(
    system: System,
    x_eq: Array,
    p: Array,
    param: str,
    omega: float,
    q: Array,
    l1: float | None = None,
) -> HopfStart:
    """The data a cycle branch starts from: the equilibrium x_eq at parameters p (the Hopf
    point along ``param``), the critical frequency omega (rad/s) and eigenvector q."""
    p = np.asarray(p, float)
    return HopfStart(param=param, value=float(p[system.param_index(param)]),
                     x=np.asarray(x_eq, float), p=p, frequency=float(omega),
                     q=np.asarray(q, complex), l1=None if l1 is None else float(l1))


def _as_start(system: System, hopf: Any, param: str) -> HopfStart:
    if isinstance(hopf, HopfStart):
        return hopf
    # duck-typed HopfPoint from dynamics.hopf
    p = np.asarray(hopf.p, float)
    l1 = getattr(hopf, "l1", None)
    l1 = None if l1 is None or not np.isfinite(l1) else float(l1)
    return hopf_start(system, hopf.x, p, param, float(hopf.frequency), hopf.q, l1)


# ---------------------------------------------------------------------------------------
# continuation
# ---------------------------------------------------------------------------------------
LimitFn = Callable[[System, PeriodicOrbit], Any]


def _margin(limits: LimitFn | None, system: System, orbit: PeriodicOrbit) -> tuple[float, str]:
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


class CycleStop(StrEnum):
    """Why a cycle branch stopped (same strings as before in JSON)."""

    STOP_AT = "reached stop_at"
    LIMIT = "limit"
    BOUND = "left parameter range"
    PERIOD = "period too large (homoclinic?)"
    STEP_TOO_SMALL = "step too small"
    NEWTON_FAILED = "newton failed"
    MAX_STEPS = "max_steps"


class NewtonMode(StrEnum):
    """The corrector of a cycle branch."""

    CHORD = "chord"  # kept factorisation, rate-monitored (collocation._chord_newton)
    FULL = "full"  # a new factorisation every iteration (collocation._newton)


def _blocks_at(prob: _Problem, Y: np.ndarray, mesh: np.ndarray
               ) -> tuple[np.ndarray, float, np.ndarray]:
    """(J, T, h) at the solution Y on ``mesh`` (the problem's mesh may have moved on)."""
    m = prob.m
    U, T, lam = prob.unpack(Y)
    h = np.diff(mesh)
    p = prob.params(lam)
    _, _, J, _ = _kernel(prob.system.rhs, m)(
        U[_interval_index(mesh.size - 1, m)], h, T, p, np.zeros_like(p))
    return np.asarray(J), T, h


def _transfer(prob: _Problem, lu: Any) -> np.ndarray | None:
    """The Floquet transfer matrices from a condensed factorisation at the solution (None
    for the whole-system sparse LU, which does not form them)."""
    return lu.transfer_matrices(prob.scale) if isinstance(lu, CondensedLU) else None


# multiplier test functions and the kinds they detect
_MULTIPLIER_TESTS = {"PD": SpecialPointKind.PD, "NS": SpecialPointKind.NS,
                     "BP": SpecialPointKind.BP}


def multiplier_tests(mult: np.ndarray) -> dict[str, float]:
    """Test functions of the nontrivial multipliers mu_i (Kuznetsov 2004, sec. 10.3.2):

    * PD: prod (mu_i + 1) / (1 + |mu_i|)          zero when a real mu passes -1;
    * NS: prod_{i<j} (mu_i mu_j - 1) / (1 + |mu_i mu_j|)   zero on a complex pair with
      |mu| = 1 (and on a real pair mu, 1/mu, which is no bifurcation: see the classifier);
    * BP: prod (mu_i - 1) / (1 + |mu_i|)          zero when a real mu passes +1 (also at a
      fold, where the LPC test changes sign too).

    Each is returned as a signed geometric mean of its factors (same sign as the product)."""
    mult = np.asarray(mult, complex)
    i, j = np.triu_indices(mult.size, 1)
    prod = mult[i] * mult[j]
    return {
        "PD": signed_geometric_mean((mult + 1.0) / (1.0 + np.abs(mult))),
        "NS": signed_geometric_mean((prod - 1.0) / (1.0 + np.abs(prod))),
        "BP": signed_geometric_mean((mult - 1.0) / (1.0 + np.abs(mult))),
    }


def _n_complex_outside(mult) -> int:
    """Number of non-real multipliers with |mu| > 1."""
    mult = np.asarray(mult, complex)
    return int(np.sum((np.abs(mult.imag) > 1e-6 * np.maximum(1.0, np.abs(mult)))
                      & (np.abs(mult) > 1.0)))


def _ns_pair_real(mult) -> bool:
    """Whether the pair of multipliers with mu_i mu_j nearest 1 is real."""
    mult = np.asarray(mult, complex)
    if mult.size < 2:
        return True
    i, j = np.triu_indices(mult.size, 1)
    k = int(np.argmin(np.abs(mult[i] * mult[j] - 1.0)))
    return bool(abs(mult[i[k]].imag) <= 1e-6 * max(1.0, abs(mult[i[k]]))
                and abs(mult[j[k]].imag) <= 1e-6 * max(1.0, abs(mult[j[k]])))


class CycleProblem:
    """The collocation BVP of periodic orbits in one parameter as a problem for
    :func:`~maglev_match.dynamics.continuation.continuation`: corrector (sparse Newton on
    the bordered system), weights, read-outs (a :class:`CyclePoint` per point) and test
    functions (LPC from the tangent, PD / NS / BP from the multipliers, the limit margin,
    the stop value)."""

    def __init__(self, prob: _Problem, names, limits, stop_at, trivial_tol: float,
                 max_period: float, adapt_every: int, tol: float, start_orbit):
        self.prob = prob
        self.names = names
        self.limits = limits
        self.stop_at = stop_at
        self.trivial_tol = trivial_tol
        self.max_period = max_period
        self.adapt_every = adapt_every
        self.tol = tol
        self.weights = prob.W()
        self.start_orbit = start_orbit
        self.accepted = 0
        self.warnings: list[str] = []
        self.restarting = False
        self.detect = True
        self.floquet_method = "auto"
        self.newton = NewtonMode.CHORD
        self.chord_lu: Any = None  # the last corrector's factorisation (same mesh)
        self.stats = NewtonStats()
        self.locate_limit = True  # False: a limit contact is only bracketed (one trial)

    # --- corrector and read-outs ---
    def correct(self, u_pred, row, target, max_iter):
        Uref, _, _ = self.prob.unpack(u_pred)
        if self.newton == NewtonMode.CHORD:
            cr = _chord_newton(self.prob, u_pred, Uref, row, target, self.tol, max_iter,
                               lu0=self.chord_lu, stats=self.stats)
            if not cr.converged:
                return None
            self.chord_lu = cr.lu
            return Correction(u=cr.Y, iterations=cr.iterations, residual=cr.residual,
                              solve=cr.lu.solve,
                              data=(cr.blocks, self.prob.mesh.copy(), _transfer(self.prob,
                                                                                cr.lu)))
        Y, ok, its, res, lu, blocks = _newton(self.prob, u_pred, Uref, row, target,
                                              self.tol, max_iter, lazy_blocks=True)
        self.stats.correctors += 1
        self.stats.iterations += its
        self.stats.factorizations += its
        if not ok:
            return None
        return Correction(u=Y, iterations=its, residual=res, solve=lu.solve,
                          data=(blocks, self.prob.mesh.copy(), None))

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
        blocks, mesh, P = pt.correction.data
        J, Tb, h = blocks if blocks is not None else _blocks_at(self.prob, pt.u, mesh)
        triv, mult = _split_trivial(floquet_multipliers_from_blocks(
            J, Tb, h, self.prob.m, transfer=P,
            method=getattr(self.prob.system, "floquet_method", self.floquet_method)))
        nun = int(np.sum(np.abs(mult) > 1.0 + 1e-6))
        return {"multipliers": mult, "trivial_multiplier": triv, "n_unstable": nun,
                "stable": nun == 0,
                "reliable": bool(abs(triv - 1.0) <= self.trivial_tol)}

    def cycle_point(self, pt: BranchPoint, kind: str = "step", floquet: bool = True
                    ) -> CyclePoint:
        """The read-out of a branch point. ``floquet`` False leaves the multipliers out
        (placeholders, marked in ``pt.info["lazy"]``) for :meth:`complete` to fill in."""
        prob = self.prob
        mesh = pt.correction.data[1]
        U, T, lam = prob.unpack(pt.u)
        if floquet:
            fields = self._floquet_fields(pt)
        else:
            fields = {"multipliers": np.zeros(0), "trivial_multiplier": complex("nan"),
                      "n_unstable": 0, "stable": False, "reliable": False}
        pt.info["lazy"] = not floquet
        orbit = PeriodicOrbit(mesh=mesh, ncol=prob.m, states=U, period=T, p=prob.params(lam))
        return CyclePoint(value=lam, period=T, orbit=orbit,
                          extrema=orbit_extrema(prob.system, orbit, self.names),
                          converged=True, iterations=pt.correction.iterations,
                          residual=pt.correction.residual, kind=kind, **fields)

    def complete(self, pt: BranchPoint | None) -> None:
        """Fill in the multipliers of a point read out without them (in place)."""
        if pt is not None and pt.info.get("lazy") and "cycle" in pt.info:
            pt.info["cycle"] = dataclasses.replace(pt.info["cycle"],
                                                   **self._floquet_fields(pt))
            pt.info["lazy"] = False

    # --- test functions ---
    def test_functions(self, pt: BranchPoint) -> dict[str, float]:
        if pt.kind == "start" and not self.restarting:  # the Hopf point: no multipliers
            out = {}
            if self.limits is not None:
                out["LIMIT"] = _margin(self.limits, self.prob.system, self.start_orbit)[0]
            if self.stop_at is not None:
                out["STOP"] = pt.value - self.stop_at
            return out
        # without special points the multipliers are needed only at the points the branch
        # keeps (filled in afterwards), not at the trial points of the event location
        c = self.cycle_point(pt, floquet=self.detect)
        pt.info["cycle"] = c
        out = {"LPC": float(pt.t[-1])} if self.detect else {}
        if c.reliable and self.detect:
            out.update(multiplier_tests(np.asarray(c.multipliers)))
        if self.limits is not None:
            out["LIMIT"], pt.info["limit"] = _margin(self.limits, self.prob.system, c.orbit)
        if self.stop_at is not None:
            out["STOP"] = c.value - self.stop_at
        return out

    def event_kind(self, name: str) -> str:
        return {"LPC": SpecialPointKind.LPC, "LIMIT": SpecialPointKind.LIMIT,
                "STOP": "STOP", **_MULTIPLIER_TESTS}[name]

    def terminal(self, name: str) -> bool:
        return name in ("LIMIT", "STOP")

    def event_tolerance(self, name: str) -> float | None:
        """The stop value needs one secant trial inside the step: the cycle there is then
        solved at exactly the stop value (:func:`_fixed_param`), whatever the trial's
        distance from it. Every other event is located to ``event_tol``."""
        if name == "STOP" or (name == "LIMIT" and not self.locate_limit):
            return 1.0
        return None

    def worth_locating(self, name: str, a: BranchPoint, b: BranchPoint) -> bool:
        """Skip sign changes that the end points show are no special point: BP in a step
        where the tangent turns (the fold's multiplier +1), NS when the number of
        non-real multipliers outside the unit circle is the same at both ends (the NS test
        then changed sign on a real pair mu, 1/mu)."""
        if name == "BP":
            return a.tests.get("LPC", 0.0) * b.tests.get("LPC", 0.0) >= 0
        if name == "NS":
            return _n_complex_outside(a.info["cycle"].multipliers) != \
                _n_complex_outside(b.info["cycle"].multipliers)
        return True

    def classify(self, name: str, pt: BranchPoint, a: BranchPoint, b: BranchPoint):
        if name not in _MULTIPLIER_TESTS:
            return self.event_kind(name)
        c = pt.info.get("cycle")
        if c is None or not c.reliable:
            self.warnings.append(f"{name} test changed sign between {a.value:.8g} and "
                                 f"{b.value:.8g}, but the multipliers there are unreliable "
                                 "(trivial multiplier away from 1): not reported")
            return None
        mult = np.asarray(c.multipliers)
        if name == "BP":
            # a multiplier through +1 is a fold when the tangent turns in the same step
            if a.tests.get("LPC", 0.0) * b.tests.get("LPC", 0.0) < 0:
                return None
            return SpecialPointKind.BP
        if name == "PD":
            k = int(np.argmin(np.abs(mult + 1.0)))
            return SpecialPointKind.PD if abs(mult[k] + 1.0) < 1e-3 else None
        # NS: the pair with mu_i mu_j = 1 must be complex (a real pair mu, 1/mu is a
        # neutral saddle cycle, no bifurcation)
        i, j = np.triu_indices(mult.size, 1)
        k = int(np.argmin(np.abs(mult[i] * mult[j] - 1.0)))
        mu = mult[i[k]]
        if _ns_pair_real(mult) or abs(abs(mu) - 1.0) > 1e-3:
            return None
        return SpecialPointKind.NS

    # --- hooks ---
    def restart_state(self, u: np.ndarray, t: np.ndarray, mesh: np.ndarray, ds: float
                      ) -> RestartState:
        prob = self.prob
        U, T, lam = prob.unpack(u)
        tU, tT, tl = prob.unpack(t)
        return RestartState(mesh=np.array(mesh), states=U, period=T, value=lam, t_states=tU,
                            t_period=tT, t_value=tl, ds=float(ds), accepted=self.accepted)

    def after_accept(self, pt: BranchPoint) -> BranchPoint:
        self.accepted += 1
        pt = self._adapt(pt)
        pt.info["state"] = (pt.u, pt.t, self.prob.mesh.copy(), self.accepted)
        return pt

    def _adapt(self, pt: BranchPoint) -> BranchPoint:
        if not (self.adapt_every and self.accepted % self.adapt_every == 0):
            return pt
        prob = self.prob
        U, T, lam = prob.unpack(pt.u)
        Ut, Tt, lt = prob.unpack(pt.t)
        new_mesh = _adapt_mesh(prob.mesh, prob.m, U, prob.scale)
        U2 = _remesh(prob.mesh, prob.m, U, new_mesh)
        Ut2 = _remesh(prob.mesh, prob.m, Ut, new_mesh)
        prob.mesh = new_mesh
        self.chord_lu = None  # the kept factorisation belongs to the old mesh
        t = prob.pack(Ut2, Tt, lt)
        t /= math.sqrt(float(np.sum(self.weights * t * t)))
        return BranchPoint(u=prob.pack(U2, T, lam), t=t, value=pt.value,
                           correction=pt.correction, tests=pt.tests, kind=pt.kind,
                           info=pt.info)

    def stop(self, pt: BranchPoint) -> str | None:
        c = pt.info["cycle"]
        if c.period > self.max_period:
            return CycleStop.PERIOD
        return None


def cycle_branch(
    system: System,
    hopf: Any,
    param: str,
    stop_at: float | None = None,
    *,
    ntst: int = 80,
    ncol: int = 4,
    max_steps: int = 300,
    limits: LimitFn | None = None,
    progress: Callable[[int, CyclePoint], None] | None = None,
    observables: Sequence[str] | None = None,
    ds: float = 0.05,
    ds_min: float = 1e-6,
    ds_max: float = 4.0,
    param_bounds: tuple[float, float] | None = None,
    tol: float = 1e-10,
    max_newton: int = 8,
    adapt_every: int = 3,
    lam_scale: float | None = None,
    max_period_factor: float = 50.0,
    trivial_tol: float = 1e-4,
    restart: RestartState | None = None,
    detect_special_points: bool = True,
    restart_param: str | None = None,
    linear_solver: str = "condensed",
    floquet_method: str = "auto",
    predictor_tol: float | None = 0.05,
    newton: str = "chord",
    multipliers_at: str = "all",
    locate_limit: bool = True,
) -> CycleBranch:
    """Continue the cycles born at a Hopf point in the parameter ``param``.

    The branch is followed by the package's one pseudo-arclength driver
    (:func:`~maglev_match.dynamics.continuation.continuation`) on the collocation problem
    (:class:`CycleProblem`). Special points are zeros of test functions located by solving
    inside the step where they change sign (each a converged periodic orbit):

    * LPC (fold of cycles): the parameter component of the tangent;
    * PD / NS / BP: products over the nontrivial multipliers (:func:`multiplier_tests`);
      NS only for a complex pair on the unit circle, BP only without a fold in the step;
    * LIMIT: the smallest limit margin (terminal: the branch ends on the contact);
    * the stop value ``stop_at`` (terminal; the last point is then solved at exactly it).

    The trivial multiplier is checked at every point: when |mu_trivial - 1| exceeds
    ``trivial_tol`` the point's stability is marked unreliable (``CyclePoint.reliable``)
    and no PD / NS / BP is declared from it.

    Parameters
    ----------
    system : the ODE system.
    hopf : a :class:`HopfStart` or a HopfPoint (attributes x, p, frequency, q, l1).
    param : continuation parameter name.
    stop_at : stop when the branch reaches this parameter value; the last point is the
        cycle solved exactly there (kind "stop_at").
    ntst, ncol : mesh intervals and collocation points per interval (NCOL 2..7).
    max_steps : maximum accepted continuation steps.
    limits : ``limits(system, orbit)`` -> mapping of limit name -> margin (positive
        inside, in any unit) or the name of the touched limit (None if none). The branch
        stops at the first contact, a solved orbit on the limit (kind "limit").
    progress : called as progress(step, point) after each accepted step.
    observables : names of the system's observables to read out (default: all).
    ds, ds_min, ds_max : initial, smallest and largest arclength step (scaled units: the
        profile in units of ``system.state_scale`` RMS over the mesh, the period in units
        of the Hopf period, the parameter in units of ``lam_scale``).
    param_bounds : stop when the parameter reaches a bound of this interval (solved there).
    tol : Newton tolerance on the scaled update.
    adapt_every : adapt the mesh every this many steps (0: never).
    lam_scale : unit of the parameter in the arclength norm (default 5 % of |value|, or
        0.05 when |value| <= ``LAM_ZERO``).
    max_period_factor : stop when the period exceeds this multiple of the Hopf period
        (approach to a homoclinic orbit).
    trivial_tol : largest accepted |mu_trivial - 1| for reliable multipliers.
    restart : continue from this saved point (:func:`load_restart`) instead of the Hopf
        point (``hopf`` still gives the scales); the new branch holds the points after it.
    restart_param : the parameter the restart state was continued in; when it differs
        from ``param`` the saved cycle is continued in ``param`` (a second parameter),
        towards larger values, the other parameters fixed at the saved point.
    detect_special_points : locate LPC, BP, PD, NS (False: only the limit contact and the
        stop value, which end the branch; saves the solves when only the branch matters).
    linear_solver : "condensed" (default: the interior collocation unknowns condensed per
        interval, :class:`~maglev_match.dynamics.collocation.CondensedLU`) or "sparse_lu"
        (a sparse LU of the whole system, the earlier code path, kept as the baseline).
    floquet_method : "auto" (default), "periodic_qz" or "cyclic_qr": how the multipliers
        are computed (:func:`~maglev_match.dynamics.floquet.floquet_analysis`).
    predictor_tol : target distance between predicted and corrected point (scaled units,
        as ``ds``) by which easy steps may grow faster than the Newton-count rule allows
        (:class:`~maglev_match.dynamics.continuation.ContinuationOptions`); None: the
        Newton-count rule alone.
    newton : "chord" (default: the factorisation at the previous solution is kept while
        the iteration contracts fast: the chord iteration of the collocation module; the
        Floquet transfer matrices come from the factorisation at each
        solution) or "full" (a new factorisation every iteration, the earlier path).
    multipliers_at : "all" (default) or "last": with "last" (and no special-point
        detection) only the last point of the branch gets its Floquet multipliers; the
        other points have none (empty ``multipliers``, ``reliable`` False). For callers
        that read only the end point (the matching index).
    locate_limit : True (default): the first limit contact is solved (margin 0 to 1e-6).
        False: it is only bracketed inside the step where the margin changes sign (one
        secant trial, the branch ends there, ``located`` says "bracketed"), for callers
        that need only whether and on which side a limit is reached (the matching index).

    Returns
    -------
    CycleBranch with the accepted points, special points (LPC, BP, PD, NS, LIMIT), the
    reason the continuation stopped and warnings. Failure is reported, never raised.
    """
    start = _as_start(system, hopf, param)
    ipar = system.param_index(param)
    new_param = restart is not None and restart_param is not None and restart_param != param
    if new_param:  # continue the saved cycle in another parameter
        p_r = np.array(start.p, float)
        p_r[system.param_index(restart_param)] = restart.value
        start = dataclasses.replace(start, param=param, value=float(p_r[ipar]), p=p_r)
    names = tuple(system.observables) if observables is None else tuple(observables)
    T0 = 2.0 * math.pi / start.frequency
    lam0 = start.value
    if lam_scale is None:
        # 5 % of the parameter's size; a Hopf point located at a parameter value that is
        # zero to rounding (e.g. -3e-30 for a root at 0) has no size of its own: unit scale
        lam_scale = 0.05 * abs(lam0) if abs(lam0) > LAM_ZERO else 0.05
    m = int(ncol)
    if not 2 <= m <= 7:
        raise ValueError("ncol must be between 2 and 7")
    if not (math.isfinite(max_period_factor) and max_period_factor > 1):
        raise ValueError(f"max_period_factor = {max_period_factor!r}: must be a finite "
                         "number > 1")
    if not trivial_tol > 0:
        raise ValueError(f"trivial_tol = {trivial_tol!r}: must be > 0")
    if newton not in tuple(NewtonMode):
        raise ValueError(f"newton = {newton!r}: must be one of "
                         f"{', '.join(map(str, NewtonMode))}")
    if multipliers_at not in ("all", "last"):
        raise ValueError(f"multipliers_at = {multipliers_at!r}: must be all or last")
    if linear_solver not in tuple(LinearSolver):
        raise ValueError(f"linear_solver = {linear_solver!r}: must be one of "
                         f"{', '.join(map(str, LinearSolver))}")
    # the chord iteration takes about twice Newton's iterations for the same step (linear
    # convergence at rate <= CHORD_MAX_RATE instead of quadratic): the Newton-count rule
    # reads "easy" as <= 5 and "slow" as >= 10 iterations then, and allows 8 more
    chord = newton == NewtonMode.CHORD
    options = ContinuationOptions(
        ds=min(max(ds, ds_min), ds_max), ds_min=ds_min, ds_max=ds_max, max_steps=max_steps,
        newton_tol=tol, newton_max_iter=max_newton + (8 if chord else 0),
        predictor_tol=predictor_tol, fast_iterations=5 if chord else 3,
        slow_iterations=10 if chord else 6,
        param_bounds=None if param_bounds is None else tuple(map(float, param_bounds)))
    prob = _Problem(system=system, ipar=ipar, p0=np.array(start.p, float),
                    mesh=np.linspace(0.0, 1.0, ntst + 1), m=m,
                    scale=np.asarray(system.state_scale, float), T_scale=T0,
                    lam_scale=float(lam_scale), linear_solver=LinearSolver(linear_solver))
    W = prob.W()
    # --- the start: the Hopf point as a constant profile, tangent = eigenvector profile
    s_nodes = _node_times(prob.mesh, m)
    qv = np.asarray(start.q, complex)
    V = np.real(qv[None, :] * np.exp(2j * math.pi * s_nodes)[:, None])
    Ueq = np.tile(start.x, (prob.N, 1))
    Yh = prob.pack(Ueq, T0, lam0)
    tY = np.concatenate([(V / prob.scale).ravel(), [0.0, 0.0]])
    tY /= math.sqrt(float(np.sum(W * tY * tY)))
    start_orbit = PeriodicOrbit(mesh=prob.mesh.copy(), ncol=m, states=Ueq, period=T0,
                                p=prob.params(lam0))
    cyc = CycleProblem(prob, names, limits, stop_at, trivial_tol, max_period_factor * T0,
                       adapt_every, tol, start_orbit)
    cyc.detect = bool(detect_special_points)
    if floquet_method not in ("auto", "periodic_qz", "cyclic_qr"):
        raise ValueError(f"floquet_method = {floquet_method!r}: must be auto, periodic_qz "
                         "or cyclic_qr")
    cyc.floquet_method = floquet_method
    cyc.newton = NewtonMode(newton)
    cyc.locate_limit = bool(locate_limit)
    first = Correction(u=Yh, iterations=0, residual=0.0, solve=lambda e: tY, data=None)
    if new_param:
        prob.mesh = np.array(restart.mesh, float)
        Yh = prob.pack(restart.states, restart.period, lam0)
        fixed = _fixed_param(prob, Yh, lam0, tol, max_newton + 4)
        if fixed is None:
            return CycleBranch(param=param, hopf=start, points=(), special_points=(),
                               stopped_reason=CycleStop.NEWTON_FAILED,
                               warnings=("the restart point does not converge",), ntst=ntst,
                               ncol=m)
        # the tangent in the new parameter: [A; e_lambda] t = e_last, towards larger values
        e_last = np.zeros(prob.size)
        e_last[-1] = 1.0
        tY = fixed.correction.solve(e_last)
        tY /= math.sqrt(float(np.sum(W * tY * tY)))
        cyc.restarting = True
        first = fixed.correction
        Yh = fixed.u
    elif restart is not None:
        prob.mesh = np.array(restart.mesh, float)
        Yh = prob.pack(restart.states, restart.period, restart.value)
        tY = prob.pack(restart.t_states, restart.t_period, restart.t_value)
        tY /= math.sqrt(float(np.sum(W * tY * tY)))
        cyc.accepted = int(restart.accepted)
        cyc.restarting = True
        options = dataclasses.replace(options, ds=float(np.clip(restart.ds, ds_min, ds_max)))
        row = W * tY
        first = cyc.correct(Yh, row, float(row @ Yh), max_newton)
        if adapt_every and cyc.accepted % adapt_every == 0:
            # the saved point had its mesh adapted: the uninterrupted run went on without a
            # kept factorisation from there, and so does the restart (same steps)
            cyc.chord_lu = None
        if first is None:
            return CycleBranch(param=param, hopf=start, points=(), special_points=(),
                               stopped_reason=CycleStop.NEWTON_FAILED,
                               warnings=("the restart point does not converge",), ntst=ntst,
                               ncol=m)

    def notify(step, pt):
        if progress is not None and "cycle" in pt.info:
            cyc.complete(pt)
            progress(step, pt.info["cycle"])

    res = continuation(cyc, Yh, tY, options, progress=notify, first=first)
    every = multipliers_at == "all" or bool(detect_special_points)
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
            u, t, mesh, acc = pt.info["state"]
            U, T, lam = prob.unpack(u)
            tU, tT, tl = prob.unpack(t)
            c = dataclasses.replace(c, restart=RestartState(
                mesh=mesh, states=U, period=T, value=lam, t_states=tU, t_period=tT,
                t_value=tl, ds=float(pt.info.get("ds_next", ds)), accepted=acc))
            pt.info["cycle"] = c
        points.append(c)
    specials: list[SpecialPoint] = []
    counts: dict[str, int] = {}
    stopped: str = {StopReason.MAX_STEPS: CycleStop.MAX_STEPS,
                    StopReason.BOUND: CycleStop.BOUND,
                    StopReason.PROBLEM: CycleStop.PERIOD}.get(res.stop_reason, "")
    if res.stop_reason in (StopReason.STEP_TOO_SMALL, StopReason.NEWTON_FAILED):
        stopped = CycleStop.STEP_TOO_SMALL if points else CycleStop.NEWTON_FAILED
        warnings.append(f"continuation stopped: no convergence after step {len(points)} "
                        f"with the smallest step {ds_min:g} ({res.message})")
    if stopped == CycleStop.PERIOD:
        warnings.append(f"period {points[-1].period:.3g} s exceeds {max_period_factor} x "
                        "the Hopf period")
    for ev in res.events:
        if ev.kind == SpecialPointKind.BOUND:
            if ev.point is not None and "cycle" in ev.point.info:
                points[-1] = dataclasses.replace(points[-1], kind="bound")
            continue
        if ev.kind == "STOP":
            if ev.point is None:
                warnings.append(f"could not solve the cycle at {param} = {stop_at:g}")
                continue
            # the located point is refined at exactly the stop value
            fixed = _fixed_param(prob, ev.point.u, float(stop_at), tol, max_newton + 4)
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
        counts[kind] = counts.get(kind, 0) + 1
        label = f"{kind}{counts[kind]}"
        if ev.point is None or "cycle" not in ev.point.info:
            warnings.append(f"{kind} between steps {ev.step} and {ev.step + 1} not located: "
                            f"{ev.located}")
            if kind == SpecialPointKind.LIMIT:
                stopped = CycleStop.LIMIT
            continue
        c = ev.point.info["cycle"]
        detail, located = "", ev.located
        if kind == SpecialPointKind.LIMIT:
            mg_c, lname = _margin(limits, system, c.orbit)
            detail = lname
            located = SOLVED if abs(mg_c) <= 1e-6 else f"bracketed (margin {mg_c:.2e})"
            if located != SOLVED and not locate_limit:
                located = f"bracketed (margin {mg_c:.2e}; not solved: locate_limit=False)"
            elif located != SOLVED:
                warnings.append(f"limit contact '{lname}' bracketed, not solved: the "
                                f"corrector failed closer to it (margin {mg_c:.2e})")
            c = dataclasses.replace(c, kind="limit")
            if points and points[-1] is ev.point.info["cycle"]:
                points[-1] = c
            else:
                points.append(c)
            stopped = CycleStop.LIMIT
        else:
            mesh = ev.point.correction.data[1]
            U, T, lam = prob.unpack(ev.point.u)
            tU, tT, tl = prob.unpack(ev.point.t)
            c = dataclasses.replace(c, kind=str(kind), restart=RestartState(
                mesh=mesh, states=U, period=T, value=lam, t_states=tU, t_period=tT,
                t_value=tl, ds=float(ds), accepted=0))
            if kind in (SpecialPointKind.PD, SpecialPointKind.NS, SpecialPointKind.BP):
                mult = np.asarray(c.multipliers)
                target = {SpecialPointKind.PD: -1.0, SpecialPointKind.BP: 1.0}.get(kind)
                if target is None:
                    k = int(np.argmin(np.abs(np.abs(mult) - 1.0) + (np.abs(mult.imag) < 1e-9)))
                else:
                    k = int(np.argmin(np.abs(mult - target)))
                detail = f"multiplier {mult[k].real:.6g}{mult[k].imag:+.6g}j"
            if located != SOLVED:
                warnings.append(f"{label} at {param} = {c.value:.8g}: {located}")
        specials.append(SpecialPoint(type=kind, value=c.value, period=c.period,
                                     extrema=c.extrema, step=ev.step - 1, located=located,
                                     detail=detail, label=label, point=c))
    if not stopped:
        stopped = str(res.stop_reason)
    return CycleBranch(param=param, hopf=start, points=tuple(points),
                       special_points=tuple(specials), stopped_reason=stopped,
                       warnings=tuple(warnings), ntst=ntst, ncol=m,
                       steps=max(len(res.points) - 1, 0), rejected_steps=res.rejected,
                       newton_iterations=cyc.stats.iterations,
                       factorizations=cyc.stats.factorizations)


def _fixed_param(prob: _Problem, Y: np.ndarray, value: float, tol: float, max_iter: int
                 ) -> BranchPoint | None:
    """The cycle at ``param`` = value exactly, from a nearby point Y (Newton)."""
    row = np.zeros(prob.size)
    row[-1] = 1.0
    Uref, _, _ = prob.unpack(Y)
    Yv, ok, its, res, lu, blocks = _newton(prob, Y, Uref, row, value / prob.lam_scale, tol,
                                           max_iter)
    if not ok:
        return None
    corr = Correction(u=Yv, iterations=its, residual=res, solve=lu.solve,
                      data=(blocks, prob.mesh.copy(), None))
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
    prob = _Problem(system=system, ipar=ipar, p0=np.array(orbit.p, float),
                    mesh=np.array(orbit.mesh), m=orbit.ncol,
                    scale=np.asarray(system.state_scale, float), T_scale=orbit.period,
                    lam_scale=abs(value) if value != 0 else 1.0)
    p = np.array(orbit.p, float)
    p[ipar] = value
    Y0 = prob.pack(orbit.states, orbit.period, value)
    row = np.zeros(prob.size)
    row[-1] = 1.0
    Y, ok, its, res, _, blocks = _newton(prob, Y0, orbit.states, row,
                                         value / prob.lam_scale, tol, max_iter)
    if not ok:
        return CorrectionResult(None, False, its, f"no convergence (residual {res:.2e})")
    U, T, lam = prob.unpack(Y)
    J, Tb, h = blocks if blocks is not None else _blocks_at(prob, Y, prob.mesh)
    triv, mult = _split_trivial(floquet_multipliers_from_blocks(
        J, Tb, h, orbit.ncol, method=getattr(system, "floquet_method", "auto")))
    nun = int(np.sum(np.abs(mult) > 1.0 + 1e-6))
    orb = PeriodicOrbit(prob.mesh, orbit.ncol, U, T, prob.params(lam))
    pt = CyclePoint(value=lam, period=T, orbit=orb, multipliers=mult,
                    trivial_multiplier=triv, n_unstable=nun, stable=nun == 0,
                    extrema=orbit_extrema(system, orb, names), converged=True,
                    iterations=its, residual=res, kind="stop_at")
    return CorrectionResult(pt, True, its)



# ---------------------------------------------------------------------------------------
# saved branches (netCDF through xarray)
# ---------------------------------------------------------------------------------------
def _point_labels(branch: CycleBranch) -> list[str]:
    return [f"P{k}" for k in range(len(branch.points))]


def branch_to_xarray(branch: CycleBranch, system: System | None = None,
                     param_unit: str = "", state_units: Sequence[str] | None = None):
    """The full branch as an :class:`xarray.Dataset`: parameter values, periods, profiles on
    each point's mesh, multipliers, stability, the continuation state needed to restart
    (tangent, next step, accepted steps), the special points with their labels and solved
    orbits, and the Hopf start. Every variable has ``units`` and ``long_name``."""
    import xarray as xr

    pts = list(branch.points)
    sps = [sp for sp in branch.special_points if sp.point is not None]
    n = len(branch.hopf.x)
    N = pts[0].orbit.states.shape[0] if pts else (sps[0].point.orbit.states.shape[0]
                                                    if sps else 1)
    names = list(system.state_names) if system is not None else [f"x{k}" for k in range(n)]
    su = list(state_units) if state_units is not None else [""] * n
    unit_of_states = ", ".join(f"{a} [{b}]" for a, b in zip(names, su, strict=True))
    pname = branch.param

    def cyc_arrays(cs: list[CyclePoint]):
        k = len(cs)
        nm = n - 1
        rs = [c.restart for c in cs]
        mult = np.full((k, nm), np.nan, complex)
        for i, c in enumerate(cs):
            mu = np.asarray(c.multipliers, complex)
            mult[i, : mu.size] = mu
        def rv(attr, shape):
            out = np.full((k, *shape), np.nan)
            for i, r in enumerate(rs):
                if r is not None:
                    out[i] = getattr(r, attr)
            return out
        return {
            "value": np.array([c.value for c in cs]),
            "period": np.array([c.period for c in cs]),
            "profile": np.array([c.orbit.states for c in cs]).reshape(k, N, n),
            "mesh": np.array([c.orbit.mesh for c in cs]).reshape(k, -1),
            "mult_re": mult.real, "mult_im": mult.imag,
            "triv_re": np.array([complex(c.trivial_multiplier).real for c in cs]),
            "triv_im": np.array([complex(c.trivial_multiplier).imag for c in cs]),
            "stable": np.array([c.stable for c in cs], np.int8),
            "reliable": np.array([c.reliable for c in cs], np.int8),
            "n_unstable": np.array([c.n_unstable for c in cs], np.int32),
            "kind": np.array([c.kind for c in cs], object),
            "r_mesh": rv("mesh", (branch.ntst + 1,)),
            "r_states": rv("states", (N, n)), "r_period": rv("period", ()),
            "r_value": rv("value", ()), "r_t_states": rv("t_states", (N, n)),
            "r_t_period": rv("t_period", ()), "r_t_value": rv("t_value", ()),
            "r_ds": rv("ds", ()), "r_accepted": rv("accepted", ()),
        }

    def add(ds_vars, prefix, dim, arr):
        pr = f"{prefix}_" if prefix else ""
        what = "special point" if prefix else "branch point"
        spec = [
            ("value", (dim,), param_unit, f"{pname} at the {what}"),
            ("period", (dim,), "s", "period of the cycle"),
            ("profile", (dim, "node", "state"), "state units",
             f"cycle states at the collocation nodes ({unit_of_states})"),
            ("mesh", (dim, "mesh_node"), "1", "mesh in normalised time t / T"),
            ("mult_re", (dim, "multiplier"), "1", "nontrivial Floquet multipliers, real part"),
            ("mult_im", (dim, "multiplier"), "1", "nontrivial Floquet multipliers, imag part"),
            ("triv_re", (dim,), "1", "trivial Floquet multiplier (should be 1), real part"),
            ("triv_im", (dim,), "1", "trivial Floquet multiplier, imaginary part"),
            ("stable", (dim,), "1", "1 if no multiplier lies outside the unit circle"),
            ("reliable", (dim,), "1", "1 if the trivial multiplier is within tolerance of 1"),
            ("n_unstable", (dim,), "1", "number of multipliers outside the unit circle"),
            ("kind", (dim,), "1", "kind of point (step, stop_at, limit, LPC, PD, ...)"),
            ("r_mesh", (dim, "mesh_node"), "1", "restart: mesh the continuation went on with"),
            ("r_states", (dim, "node", "state"), "state units",
             "restart: profile on the restart mesh"),
            ("r_period", (dim,), "s", "restart: period"),
            ("r_value", (dim,), param_unit, f"restart: {pname}"),
            ("r_t_states", (dim, "node", "state"), "state units per unit arclength",
             "restart: tangent of the profile"),
            ("r_t_period", (dim,), "s per unit arclength", "restart: tangent of the period"),
            ("r_t_value", (dim,), f"{param_unit} per unit arclength".strip(),
             f"restart: tangent of {pname}"),
            ("r_ds", (dim,), "1", "restart: next arclength step (scaled units)"),
            ("r_accepted", (dim,), "1", "restart: accepted steps so far (mesh schedule)"),
        ]
        for key, dims, units, long in spec:
            ds_vars[pr + key] = (dims, arr[key], {"units": units, "long_name": long})

    data: dict[str, Any] = {}
    coords: dict[str, Any] = {"state": ("state", names, {"long_name": "state name",
                                                          "units": "1"})}
    if pts:
        add(data, "", "point", cyc_arrays(pts))
        coords["label"] = ("point", _point_labels(branch), {"long_name": "point label",
                                                              "units": "1"})
    if sps:
        add(data, "special", "special", cyc_arrays([sp.point for sp in sps]))
        coords["special_label"] = ("special", [sp.label for sp in sps],
                                   {"long_name": "special point label", "units": "1"})
        for key, vals, long in (("special_type", [sp.type for sp in sps], "type (LPC, BP, "
                                 "PD, NS, LIMIT)"),
                                ("special_located", [sp.located for sp in sps], "how it was "
                                 "located: solved, or why not"),
                                ("special_detail", [sp.detail for sp in sps], "detail")):
            data[key] = (("special",), np.array(vals, object), {"units": "1",
                                                                 "long_name": long})
        data["special_step"] = (("special",), np.array([sp.step for sp in sps], np.int32),
                                {"units": "1", "long_name": "index of the point before it"})
    h = branch.hopf
    data["hopf_x"] = (("state",), np.asarray(h.x, float),
                      {"units": "state units", "long_name": "equilibrium at the Hopf point"})
    data["hopf_q_re"] = (("state",), np.real(h.q), {"units": "1", "long_name":
                                                   "critical eigenvector, real part"})
    data["hopf_q_im"] = (("state",), np.imag(h.q), {"units": "1", "long_name":
                                                   "critical eigenvector, imaginary part"})
    pnames = list(system.param_names) if system is not None else \
        [f"p{k}" for k in range(len(h.p))]
    coords["parameter"] = ("parameter", pnames, {"long_name": "parameter name", "units": "1"})
    data["hopf_p"] = (("parameter",), np.asarray(h.p, float),
                      {"units": "parameter units", "long_name": "parameters at the Hopf point"})
    attrs = {"param": pname, "param_unit": param_unit, "ntst": branch.ntst,
             "ncol": branch.ncol, "stopped_reason": str(branch.stopped_reason),
             "hopf_value": h.value, "hopf_frequency": h.frequency,
             "hopf_l1": np.nan if h.l1 is None else h.l1,
             "title": f"branch of periodic orbits in {pname} from a Hopf point"}
    return xr.Dataset(data, coords=coords, attrs=attrs)


def load_restart(path_or_dataset, label: str) -> tuple[HopfStart, RestartState, str]:
    """The Hopf start and the restart state of the point ``label`` (P<k> for a branch
    point, or a special point's label such as LPC1) of a saved branch; also the parameter
    name. Raises KeyError naming the labels on offer when ``label`` is not there."""
    import xarray as xr

    ds = path_or_dataset if isinstance(path_or_dataset, xr.Dataset) else \
        xr.load_dataset(path_or_dataset, engine="h5netcdf")
    labels = [str(v) for v in ds["label"].values] if "label" in ds.coords else []
    specials = [str(v) for v in ds["special_label"].values] if "special_label" in ds.coords \
        else []
    if label in labels:
        k, pre = labels.index(label), ""
    elif label in specials:
        k, pre = specials.index(label), "special_"
    else:
        raise KeyError(f"label '{label}' is not in the saved branch; it has: "
                       + ", ".join(labels[:3] + (["..."] if len(labels) > 4 else [])
                                   + labels[-1:] + specials))

    def v(name):
        return np.asarray(ds[pre + name].values[k])

    if not np.isfinite(float(v("r_period"))):
        raise KeyError(f"point '{label}' has no restart data (a located end point)")
    state = RestartState(mesh=v("r_mesh"), states=v("r_states"), period=float(v("r_period")),
                         value=float(v("r_value")), t_states=v("r_t_states"),
                         t_period=float(v("r_t_period")), t_value=float(v("r_t_value")),
                         ds=float(v("r_ds")), accepted=int(v("r_accepted")))
    l1 = float(ds.attrs["hopf_l1"])
    start = HopfStart(param=str(ds.attrs["param"]), value=float(ds.attrs["hopf_value"]),
                      x=np.asarray(ds["hopf_x"].values), p=np.asarray(ds["hopf_p"].values),
                      frequency=float(ds.attrs["hopf_frequency"]),
                      q=np.asarray(ds["hopf_q_re"].values) + 1j * np.asarray(
                          ds["hopf_q_im"].values),
                      l1=None if not np.isfinite(l1) else l1)
    return start, state, str(ds.attrs["param"])
