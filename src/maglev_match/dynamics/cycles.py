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

from maglev_match.core.aot import cached_kernel
from maglev_match.core.reprs import compact_repr
from maglev_match.core.results import Plottable
from maglev_match.dynamics.collocation import (
    CollocationBVP,
    CondensedLU,
    LinearSolver,
    NewtonStats,
    adapt_mesh,
    chord_newton,
    collocation_kernel,
    collocation_newton,
    collocation_tables,
    evaluate_profile,
    interval_nodes,
    lagrange_basis,
    node_times,
    remesh,
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
    signed_geometric_mean,
)
from maglev_match.dynamics.floquet import floquet_multipliers_from_blocks
from maglev_match.dynamics.system import System, chart_kernels

__all__ = [
    "HopfStart",
    "PeriodicOrbit",
    "CyclePoint",
    "SpecialPoint",
    "CycleBranch",
    "CycleOptions",
    "CorrectionResult",
    "CycleStop",
    "MultipliersAt",
    "NewtonMode",
    "Stability",
    "RestartState",
    "cycle_options",
    "first_harmonic",
    "stability_of",
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
        return node_times(self.mesh, self.ncol)

    @property
    def times(self) -> np.ndarray:
        """Times of the nodes (s)."""
        return self.node_times * self.period

    def evaluate(self, s: Array) -> np.ndarray:
        """States at normalised times s in [0, 1] (periodic extension), shape (len(s), dim)."""
        return evaluate_profile(self.mesh, self.ncol, self.states, np.asarray(s, float) % 1.0)


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
    kind: str = "step"  # "step", "stop_at", "contact", "bound", or a special-point type
    reliable: bool = True  # |trivial multiplier - 1| within tolerance: stability trusted
    restart: RestartState | None = None  # to continue from this point (saved branches)
    stability: str = ""  # Stability: stable, unstable, neutral (|mu| ~ 1) or unknown

    def max(self, name: str) -> float:
        return self.extrema[name][0]

    def min(self, name: str) -> float:
        return self.extrema[name][1]


@dataclass(frozen=True)
class CycleBranch(Plottable):
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
    message: str = ""  # how the branch ended, in words (a homoclinic approach, a Hopf point)
    chart_from: float | None = None  # parameter where the regular chart took over (or None)

    @property
    def closed_at(self) -> SpecialPoint | None:
        """The Hopf point where the family of cycles ends (special point H), if it does."""
        return next((sp for sp in self.special_points
                     if sp.type == SpecialPointKind.HOPF), None)

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
    idx = interval_nodes(ntst, m)
    e = np.zeros_like(orbit.p)
    _, _, J, _ = collocation_kernel(system.rhs, m)(
        jnp.asarray(orbit.states[idx]), jnp.asarray(h), orbit.period, jnp.asarray(orbit.p),
        jnp.asarray(e),
    )
    return floquet_multipliers_from_blocks(np.asarray(J), orbit.period, h, m,
                                           method=getattr(system, "floquet_method", "auto"))


@cache
def _local_basis(m: int, npts: int) -> np.ndarray:
    """Lagrange basis of degree m at npts equally spaced local points: (npts, m+1)."""
    return lagrange_basis(np.linspace(0.0, 1.0, m + 1), np.linspace(0.0, 1.0, npts))[0]


def _lagrange_jnp(m: int) -> Callable:
    """tau -> the m + 1 Lagrange basis values at local time tau in [0, 1] (nodes k / m), as
    a JAX function (differentiable in tau)."""
    c = np.linspace(0.0, 1.0, m + 1)
    others = np.array([[i for i in range(m + 1) if i != k] for k in range(m + 1)])
    denom = np.array([np.prod(c[k] - c[others[k]]) for k in range(m + 1)])
    co, de = jnp.asarray(c[others]), jnp.asarray(denom)

    def basis(tau):
        return jnp.prod(tau - co, axis=1) / de

    return basis


@cache
def _extrema_kernel(gs: tuple[Callable, ...], m: int, refine: int) -> Callable:
    """One jitted call giving (max, min) of each observable in ``gs`` over an orbit: the
    coarse pass over 4 NCOL + 1 points per interval, the intervals around each extreme, the
    fine pass (``refine`` + 1 points per interval) over those, and the vertex of the
    parabola through the best fine sample and its two neighbours, where the observable is
    evaluated once more (cached per observables, NCOL, refine; see :func:`orbit_extrema`).
    The fine samples alone carry a sampling error up to g'' (dt / 2)^2 / 2 (~4e-8 relative
    on model A's gap), and a margin built on them would be rough at that level; the vertex
    is within O(dt^2) of the polynomial's own extremum, so its value is within O(dt^4)
    (~1e-13 relative there): a smooth function of the orbit to the branch tolerance."""
    Lc = jnp.asarray(_local_basis(m, 4 * m + 1))
    Lf = jnp.asarray(_local_basis(m, refine + 1))
    npts = Lf.shape[0]
    dtau = 1.0 / (npts - 1.0)
    basis = _lagrange_jnp(m)
    batches = [jax.vmap(g, (0, None)) for g in gs]

    def vertex(g, nodes_j, v3, i, comp, p, sign):
        """sign * g at the vertex of the parabola through local samples i-1, i, i+1."""
        fm, f0, fp = sign * v3[0], sign * v3[1], sign * v3[2]
        den = fm - 2.0 * f0 + fp
        off = jnp.where(den < 0, 0.5 * (fm - fp) / jnp.where(den < 0, den, -1.0), 0.0)
        tau = (i + jnp.clip(off, -1.0, 1.0)) * dtau
        val = sign * jnp.ravel(g(basis(tau) @ nodes_j, p))[comp]
        return sign * jnp.maximum(val, f0)

    def kernel(nodes, p):
        ntst, n = nodes.shape[0], nodes.shape[2]
        X = jnp.einsum("sk,jkn->jsn", Lc, nodes).reshape(-1, n)
        out = []
        for g, gb in zip(gs, batches, strict=True):
            vals = gb(X, p).reshape(ntst, Lc.shape[0], -1)
            jmax = jnp.argmax(vals.reshape(-1)) // (vals.shape[1] * vals.shape[2])
            jmin = jnp.argmax(-vals.reshape(-1)) // (vals.shape[1] * vals.shape[2])
            js = jnp.stack([(jmax - 1) % ntst, jmax, (jmax + 1) % ntst,
                            (jmin - 1) % ntst, jmin, (jmin + 1) % ntst])
            Xf = jnp.einsum("sk,jkn->jsn", Lf, nodes[js]).reshape(-1, n)
            vf = gb(Xf, p).reshape(6, npts, -1)
            ncomp = vf.shape[2]
            res = []
            for sign, first in ((1.0, 0), (-1.0, 3)):
                part = vf[first:first + 3]
                k = jnp.argmax(sign * part.reshape(-1))
                blk, rest = k // (npts * ncomp), k % (npts * ncomp)
                i, comp = rest // ncomp, rest % ncomp
                i = jnp.clip(i, 1, npts - 2)  # three samples of the same interval
                v3 = jax.lax.dynamic_slice(part[blk][:, comp], (i - 1,), (3,))
                res.append(vertex(g, nodes[js[first + blk]], v3, i, comp, p, sign))
            out.append(jnp.stack([jnp.maximum(res[0], jnp.max(vals)),
                                  jnp.minimum(res[1], jnp.min(vals))]))
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
    nodes = orbit.states[interval_nodes(orbit.ntst, orbit.ncol)]  # (ntst, m+1, n)
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
    """Why a cycle branch stopped (the strings of JSON and files)."""

    STOP_AT = "reached stop_at"
    CONTACT = "contact with a physical limit"
    LIMIT = "contact with a physical limit"  # the earlier name of CONTACT (alias)
    BOUND = "left parameter range"
    RANGE = "reached the end of the parameter's valid range"
    HOMOCLINIC = "homoclinic approach"
    PERIOD = "homoclinic approach"  # the earlier name of HOMOCLINIC (alias)
    HOPF = "the family closed at a Hopf point"
    STEP_TOO_SMALL = "step too small"
    NEWTON_FAILED = "newton failed"
    MAX_STEPS = "max_steps"


class NewtonMode(StrEnum):
    """The corrector of a cycle branch."""

    CHORD = "chord"  # kept factorisation, rate-monitored (collocation.chord_newton)
    FULL = "full"  # a new factorisation every iteration (collocation.collocation_newton)


class MultipliersAt(StrEnum):
    """Where a cycle branch computes Floquet multipliers."""

    ALL = "all"  # every point the branch keeps
    LAST = "last"  # only the last point (callers that read only the end point)


class Stability(StrEnum):
    """Stability of a cycle from its nontrivial multipliers mu (tolerance ``neutral_tol``
    of :class:`CycleOptions`): unstable when some |mu| > 1 + tol; neutral when none is,
    but some |mu| >= 1 - tol (at a Hopf point, a fold, a PD, NS or BP the multipliers
    cannot decide; the first points of a branch next to its Hopf point are neutral);
    stable otherwise; unknown without (reliable) multipliers."""

    STABLE = "stable"
    UNSTABLE = "unstable"
    NEUTRAL = "neutral"
    UNKNOWN = "unknown"


_FLOQUET_METHODS = ("auto", "periodic_qz", "cyclic_qr")


@dataclass(frozen=True)
class CycleOptions:
    """Options of :func:`cycle_branch`, checked on construction (a wrong value raises
    ``ValueError`` naming the field, the value and the rule).

    Parameters
    ----------
    ntst, ncol : mesh intervals (>= 4) and collocation points per interval (2..7).
    max_steps : maximum accepted continuation steps.
    ds, ds_min, ds_max : initial, smallest and largest arclength step (scaled units: the
        profile in units of ``system.state_scale`` RMS over the mesh, the period in units
        of the Hopf period, the parameter in units of ``lam_scale``).
    param_bounds : (lo, hi): the branch stops when the parameter reaches a bound (solved
        there). The system's valid range of the parameter always bounds the branch too.
    tol : Newton tolerance on the scaled update (the branch tolerance).
    max_newton : Newton iterations per corrector (the chord corrector gets 8 more).
    adapt_every : adapt the mesh every this many steps (0: never).
    lam_scale : unit of the parameter in the arclength norm (None: 5 % of |value| at the
        Hopf point, or 0.05 when that is zero to rounding).
    max_period_factor : the branch ends as a homoclinic approach when the period exceeds
        this multiple of the Hopf period.
    trivial_tol : largest accepted |mu_trivial - 1| for reliable multipliers.
    neutral_tol : the band around |mu| = 1 in which a multiplier decides nothing (see
        :class:`Stability`); also the band of n_unstable (|mu| > 1 + neutral_tol).
    detect_special_points : locate LPC, BP, PD, NS (False: only the limit contact and the
        stop value, which end the branch; saves the solves when only the branch matters).
    linear_solver : "condensed" (default, :class:`~maglev_match.dynamics.collocation.
        CondensedLU`) or "sparse_lu" (a sparse LU of the whole system, kept as baseline).
    floquet_method : "auto", "periodic_qz" or "cyclic_qr"
        (:func:`~maglev_match.dynamics.floquet.floquet_analysis`).
    predictor_tol : target distance between predicted and corrected point (scaled units)
        by which easy steps may grow faster than the Newton-count rule allows; None: the
        Newton-count rule alone.
    newton : "chord" (default: a kept factorisation while the iteration contracts fast)
        or "full" (a factorisation every iteration).
    multipliers_at : "all" (default) or "last" (with no special-point detection: only the
        last point gets its multipliers; the others report none, ``reliable`` False).
    locate_limit : True (default): a contact with a physical limit is solved on the branch
        (its margin to the branch tolerance). False: it is only bracketed inside the step
        where the margin changes sign (one secant trial), for callers that need only
        whether and on which side a limit is reached.
    use_chart : continue in the system's regular chart (:class:`~maglev_match.dynamics.
        system.RegularChart`) once an orbit comes near the set where its equations are
        singular (model A: gap 0). False: never (the earlier behaviour).
    factor_at_solution : whether the chord corrector factorises the Jacobian once more at
        each solution (for the tangent, the Floquet transfer matrices and the next
        corrector). None (default): yes, unless neither special points nor multipliers are
        wanted along the branch (``detect_special_points`` False and ``multipliers_at``
        "last", the matching index's route), where the factorisation in force serves the
        tangent and the next corrector and the last point's Jacobian is evaluated for its
        multipliers: about one factorisation per step less.
    """

    ntst: int = 80
    ncol: int = 4
    max_steps: int = 300
    ds: float = 0.05
    ds_min: float = 1e-6
    ds_max: float = 4.0
    param_bounds: tuple[float, float] | None = None
    tol: float = 1e-10
    max_newton: int = 8
    adapt_every: int = 3
    lam_scale: float | None = None
    max_period_factor: float = 50.0
    trivial_tol: float = 1e-4
    neutral_tol: float = 1e-6
    detect_special_points: bool = True
    linear_solver: str = LinearSolver.CONDENSED
    floquet_method: str = "auto"
    predictor_tol: float | None = 0.05
    newton: str = NewtonMode.CHORD
    multipliers_at: str = MultipliersAt.ALL
    locate_limit: bool = True
    use_chart: bool = True
    factor_at_solution: bool | None = None

    def __post_init__(self) -> None:
        def bad(name, rule):
            raise ValueError(f"CycleOptions.{name} = {getattr(self, name)!r}: {rule}")

        def integer(name, lo, hi=None):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | np.integer) or v < lo or (
                    hi is not None and v > hi):
                bad(name, f"must be an integer >= {lo}" + (f" and <= {hi}" if hi else ""))

        def positive(name, allow_none=False):
            v = getattr(self, name)
            if v is None and allow_none:
                return
            if isinstance(v, bool) or not (isinstance(v, int | float | np.floating)
                                           and math.isfinite(v) and v > 0):
                bad(name, "must be a positive finite number" + (" or None" if allow_none
                                                                 else ""))

        integer("ntst", 4)
        integer("ncol", 2, 7)
        integer("max_steps", 1)
        integer("max_newton", 1)
        integer("adapt_every", 0)
        for name in ("ds", "ds_min", "ds_max", "tol", "trivial_tol", "neutral_tol"):
            positive(name)
        positive("lam_scale", allow_none=True)
        positive("predictor_tol", allow_none=True)
        if not self.ds_min <= self.ds_max:
            bad("ds_min", f"must not exceed ds_max = {self.ds_max!r}")
        if not (isinstance(self.max_period_factor, int | float)
                and math.isfinite(self.max_period_factor) and self.max_period_factor > 1):
            bad("max_period_factor", "must be a finite number > 1")
        if self.param_bounds is not None:
            try:
                lo, hi = (float(v) for v in self.param_bounds)
            except (TypeError, ValueError):
                bad("param_bounds", "must be None or (lo, hi)")
            if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
                bad("param_bounds", "must be finite with lo < hi")
            object.__setattr__(self, "param_bounds", (lo, hi))
        for name, enum in (("linear_solver", LinearSolver), ("newton", NewtonMode),
                           ("multipliers_at", MultipliersAt)):
            v = getattr(self, name)
            if v not in tuple(enum):
                bad(name, "must be one of " + ", ".join(map(str, enum)))
            object.__setattr__(self, name, enum(v))
        if self.floquet_method not in _FLOQUET_METHODS:
            bad("floquet_method", "must be one of " + ", ".join(_FLOQUET_METHODS))
        for name in ("detect_special_points", "locate_limit", "use_chart"):
            if not isinstance(getattr(self, name), bool | np.bool_):
                bad(name, "must be True or False")
        if self.factor_at_solution not in (None, True, False):
            bad("factor_at_solution", "must be None, True or False")


_OPTION_NAMES = frozenset(f.name for f in dataclasses.fields(CycleOptions))


def cycle_options(options: CycleOptions | None = None, **changes: Any) -> CycleOptions:
    """``options`` (default :class:`CycleOptions`) with ``changes`` applied by field name;
    an unknown name raises TypeError as an unknown keyword argument would."""
    unknown = sorted(set(changes) - _OPTION_NAMES)
    if unknown:
        raise TypeError(f"cycle_branch() got an unexpected keyword argument {unknown[0]!r}")
    base = CycleOptions() if options is None else options
    if not isinstance(base, CycleOptions):
        raise TypeError(f"options must be a CycleOptions, not {type(base).__name__}")
    return dataclasses.replace(base, **changes) if changes else base


def _blocks_at(prob: CollocationBVP, Y: np.ndarray, mesh: np.ndarray
               ) -> tuple[np.ndarray, float, np.ndarray]:
    """(J, T, h) at the solution Y on ``mesh`` (the problem's mesh may have moved on)."""
    m = prob.m
    U, T, lam = prob.unpack(Y)
    h = np.diff(mesh)
    p = prob.params(lam)
    _, _, J, _ = collocation_kernel(prob.system.rhs, m)(
        U[interval_nodes(mesh.size - 1, m)], h, T, p, np.zeros_like(p))
    return np.asarray(J), T, h


def _transfer(prob: CollocationBVP, lu: Any) -> np.ndarray | None:
    """The Floquet transfer matrices from a condensed factorisation at the solution (None
    for the whole-system sparse LU, which does not form them)."""
    return lu.transfer_matrices(prob.scale) if isinstance(lu, CondensedLU) else None


# multiplier test functions and the kinds they detect
_MULTIPLIER_TESTS = {"PD": SpecialPointKind.PD, "NS": SpecialPointKind.NS}
# the test functions that are only evaluated where the Floquet data are reliable
_BIFURCATION_TESTS = ("LPC", "PD", "NS", "BP")


def multiplier_tests(mult: np.ndarray) -> dict[str, float]:
    """Test functions of the nontrivial multipliers mu_i (Kuznetsov 2004, sec. 10.3.2):

    * PD: prod (mu_i + 1) / (1 + |mu_i|)          zero when a real mu passes -1;
    * NS: prod_{i<j} (mu_i mu_j - 1) / (1 + |mu_i mu_j|)   zero on a complex pair with
      |mu| = 1 (and on a real pair mu, 1/mu, which is no bifurcation: see the classifier);
    * BP: prod (mu_i - 1) / (1 + |mu_i|)          zero when a real mu passes +1 (at a
      branch point and at a fold alike; the branch uses the bordered test function of
      :meth:`CycleProblem.bp_test` instead, which a fold leaves alone).

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


def stability_of(mult: np.ndarray, tol: float) -> Stability:
    """The :class:`Stability` of a cycle from its nontrivial multipliers."""
    mult = np.asarray(mult)
    if mult.size == 0:
        return Stability.STABLE
    a = np.abs(mult)
    if np.any(a > 1.0 + tol):
        return Stability.UNSTABLE
    if np.any(a >= 1.0 - tol):
        return Stability.NEUTRAL
    return Stability.STABLE


@cache
def _first_harmonic_weights(m: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss weights and the Lagrange basis at the Gauss points (for the quadrature of
    the first Fourier coefficient of a profile)."""
    _, z, w, L, _ = collocation_tables(m)
    return z, w, L


def first_harmonic(mesh: np.ndarray, m: int, U: np.ndarray) -> np.ndarray:
    """c1 = int_0^1 u(t) exp(-2 pi i t) dt (complex, one per state) of a collocation
    profile, by Gauss quadrature on its mesh (exact for the polynomial up to the
    exponential's quadrature error, and independent of the mesh to that accuracy). Near a
    Hopf point u(t) = x* + eps Re(q exp(2 pi i t)) + O(eps^2), so c1 = eps q / 2 + O(eps^2):
    a smooth function of the branch that passes through zero where the family meets the
    equilibrium."""
    z, w, L = _first_harmonic_weights(m)
    ntst = mesh.size - 1
    h = np.diff(mesh)
    Ui = U[interval_nodes(ntst, m)]  # (ntst, m+1, n)
    Uz = np.einsum("lk,jkn->jln", L, Ui)  # (ntst, m, n) at the Gauss points
    t = mesh[:-1, None] + h[:, None] * z[None, :]
    ph = np.exp(-2j * np.pi * t) * (h[:, None] * w[None, :])
    return np.einsum("jl,jln->n", ph, Uz)


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
        J, Tb, h = blocks if blocks is not None else _blocks_at(self.prob, pt.u, mesh)
        triv, mult = _split_trivial(floquet_multipliers_from_blocks(
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
                out["CONTACT"] = _margin(self.limits, self.prob.system,
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
            if c.reliable:
                out["LPC"] = float(pt.t[-1])
                out.update({k: v for k, v in multiplier_tests(np.asarray(c.multipliers))
                            .items() if k in _MULTIPLIER_TESTS})
                if self.bp_c is not None:
                    v = self._bp_vector(pt)
                    d = self._wdot(self.bp_c, v)
                    out["BP"] = -1.0 / d if d != 0 and np.isfinite(d) else np.nan
                else:
                    out["BP"] = -1.0  # the frame is set at the first accepted point
            else:  # no special point from unreliable Floquet data
                out.update({k: np.nan for k in _BIFURCATION_TESTS})
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
            out["CONTACT"], pt.info["limit"] = _margin(self.limits, self.prob.system,
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
            out["CONTACT"], pt.info["limit"] = _margin(self.limits, self.prob.system,
                                                       pt.info["orbit_here"])
        if self.stop_at is not None:
            out["STOP"] = c.value - self.stop_at
        return out

    def event_kind(self, name: str) -> str:
        return {"LPC": SpecialPointKind.LPC, "CONTACT": SpecialPointKind.CONTACT,
                "BP": SpecialPointKind.BP, "STOP": "STOP", "AMP": "AMP",
                **_MULTIPLIER_TESTS}[name]

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
            return _n_complex_outside(a.info["cycle"].multipliers) != \
                _n_complex_outside(b.info["cycle"].multipliers)
        return True

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
            if not (g <= 1e-3 * ends) or mult.size == 0 or \
                    float(np.min(np.abs(mult - 1.0))) > 1e-3:
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


#: A contact with a physical limit is solved when its (dimensionless) margin is within
#: this of zero: the margin is a smooth function of the branch (the extremum of an
#: observable over the orbit, refined to the polynomial's own extremum).
CONTACT_TOL = 1e-12


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
                message = (f"{param} reached the end of its valid range at {where:.8g}: the "
                           "model is not defined beyond it")
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
        if kind == SpecialPointKind.CONTACT:
            mg_c, lname = _margin(limits, prob.system, ev.point.info["orbit_here"])
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
                detail = f"multiplier {mult[k].real:.6g}{mult[k].imag:+.6g}j"
            if located != SOLVED:
                warnings.append(f"{kind} at {param} = {c.value:.8g}: {located}")
        specials.append(SpecialPoint(type=kind, value=c.value, period=c.period,
                                     extrema=c.extrema, step=ev.step - 1, located=located,
                                     detail=detail, point=c))
    specials = label_points(specials)
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


#: A contact whose margin is within this of zero is reported solved (the location runs to
#: CONTACT_TOL; this allows for the margin's rounding at the located orbit).
CONTACT_SOLVED = 1e-9


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


def first_harmonic_mean(orbit: PeriodicOrbit) -> np.ndarray:
    """The mean state int_0^1 u(t) dt of a collocation orbit (Gauss quadrature)."""
    z, w, L = _first_harmonic_weights(orbit.ncol)
    h = np.diff(orbit.mesh)
    Ui = orbit.states[interval_nodes(orbit.ntst, orbit.ncol)]
    Uz = np.einsum("lk,jkn->jln", L, Ui)
    return np.einsum("jl,jln->n", h[:, None] * w[None, :], Uz)


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
    J, Tb, h = blocks if blocks is not None else _blocks_at(prob, Y, prob.mesh)
    triv, mult = _split_trivial(floquet_multipliers_from_blocks(
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
            ("kind", (dim,), "1", "kind of point (step, stop_at, contact, LPC, PD, ...)"),
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
                                 "PD, NS; contact: a physical limit reached)"),
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
    end = branch.closed_at
    attrs = {"param": pname, "param_unit": param_unit, "ntst": branch.ntst,
             "ncol": branch.ncol, "stopped_reason": str(branch.stopped_reason),
             "end": branch.message,
             "closed_at_hopf": np.nan if end is None else float(end.value),
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
