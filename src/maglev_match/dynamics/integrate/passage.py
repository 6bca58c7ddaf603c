"""Periodic responses of a periodically forced, piecewise-smooth system: smooth segments of
flow joined by a linear jump map (model-agnostic).

A *passage* is one period of such a system: the flow of ``x' = f(x, p_k)`` over segment
k = 0..K-1 (duration tau_k, its own parameter vector p_k: the vector field is smooth
inside a segment and may change at its ends), then the jump ``x <- R x`` (a matrix R; the
time state restarts at 0). The last state of the system is the time since the start of the
passage (``t' = 1``), so the vector field is autonomous and a segment can be integrated by
:func:`~maglev_match.dynamics.integrate.simulate.simulate` from any state.

The passage map is P(x) = R phi_{K-1} ... phi_0 (x), phi_k the flow of segment k. A periodic
response is a fixed point x* = P(x*): the period is fixed by the forcing, so, unlike an
autonomous cycle, there is no phase condition and no trivial multiplier.

Reduction by the jump. R may discard states (it is singular): with R = U C (U an orthonormal
basis of its range, from the SVD, in scaled coordinates), every image of P lies in the range
of U, so x* = U y* with y* the fixed point of the reduced map p(y) = C phi(U y) (r = rank R
unknowns), and the n - r multipliers of the discarded directions are exactly 0.

Newton's method (single shooting over the passage; the segments act as the nodes of a
condensed multiple shooting)::

    (C Phi U - I) dy = -(p(y) - y),      Phi = Phi_{K-1} ... Phi_0

with the segment transfer matrices from the variational equation Psi' = f_x(x(t)) Psi,
integrated for the r columns of an orthonormal basis along every segment and re-orthonormalised
at its end (the QR recursion Phi_0 U = Q_0 R_0, Phi_k Q_{k-1} = Q_k R_k, S = C Q_{K-1}; so
C Phi U = S R_{K-1} ... R_0 and nothing is lost to rounding in the product), never by finite
differences. While the passage map contracts strongly (the residual falls by the factor
``fast_ratio`` or more per passage), the chord iteration with the Jacobian approximated by 0
(y <- p(y)) is used, which costs one state-only passage per step; otherwise Newton's method
with the variational Jacobian, kept while it contracts (chord iterations); the first
Jacobian, which only steers Newton steps, is integrated with a tolerance 100 times looser.
The transfer matrices for the multipliers are computed at the solution with the full
tolerance (unless full-accuracy ones were computed within ``multiplier_tol`` of it).

Stability: the multipliers of the passage map (Floquet multipliers of the periodic response;
Kuznetsov 2004, sec. 1.5 and 9.3 for periodically forced systems), the eigenvalues of
S R_{K-1} ... R_0 and the n - r zeros, computed by the periodic QZ algorithm on the factors
(:func:`~maglev_match.dynamics.floquet.periodic_eigenvalues`; Bojanczyk, Golub & Van Dooren
1992) without forming the product, so tiny multipliers (long passages, strongly damped
states) keep their relative accuracy. The response is asymptotically stable when every
multiplier lies inside the unit circle.

The variational equation is integrated by diffrax's Dopri8 directly (``diffeqsolve``, one
compiled solve per right-hand side and basis size): it needs no events and no saved history,
and the simulation kernel's eigen-analysis of its reference state would cost more than the
run itself for the n (r + 1) states. Accuracy diagnostic: the variational solve integrates
the base trajectory too, with its own steps; its distance to the state-only run's end states
(scaled) measures the integration error of the flow and is reported with the result.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import cache

import jax
import jax.numpy as jnp
import numpy as np

from maglev_match.core.aot import cached_kernel
from maglev_match.core.reprs import compact_repr
from maglev_match.dynamics.floquet import periodic_eigenvalues
from maglev_match.dynamics.integrate.simulate import (
    COLLISION,
    FAILED,
    SimulationOptions,
    SimulationResult,
    simulate,
    simulate_batch,
)
from maglev_match.dynamics.system import System

__all__ = [
    "SAVE_SLOTS",
    "Segment",
    "PassageProblem",
    "PassageOptions",
    "PassageRun",
    "Multipliers",
    "PeriodicPassage",
    "ReducedFactors",
    "run_passage",
    "run_passages_batch",
    "BatchPassage",
    "reduced_factors",
    "passage_multipliers",
    "solve_periodic_passage",
    "finite_difference_jacobian",
]


#: Saved times per integrator call of a passage (see :func:`run_passage`).
SAVE_SLOTS = 256


@dataclass(frozen=True)
class Segment:
    """One smooth piece of a passage: its duration (s) and parameter vector."""

    duration: float
    p: np.ndarray


@dataclass(frozen=True)
class PassageProblem:
    """A system whose last state is the time since the start of the passage
    (``system.rhs`` returns 1 for it), the segments of one passage and the jump matrix R
    (n, n), acting on every state but the time (n = system.dim - 1)."""

    __repr__ = compact_repr

    system: System
    segments: tuple[Segment, ...]
    jump: np.ndarray

    def __post_init__(self) -> None:
        n = self.system.dim - 1
        R = np.asarray(self.jump, float)
        if R.shape != (n, n):
            raise ValueError(f"jump has shape {R.shape}, expected ({n}, {n})")
        if not self.segments or any(not s.duration > 0 for s in self.segments):
            raise ValueError("a passage needs segments of positive duration")
        object.__setattr__(self, "jump", R)
        object.__setattr__(self, "segments", tuple(self.segments))

    @property
    def n(self) -> int:
        """States without the time."""
        return self.system.dim - 1

    @property
    def scale(self) -> np.ndarray:
        """Scales of the n states (without the time)."""
        return np.asarray(self.system.state_scale, float)[: self.n]

    @property
    def period(self) -> float:
        return float(sum(s.duration for s in self.segments))

    @property
    def starts(self) -> np.ndarray:
        """Start time of every segment in the passage (s)."""
        return np.concatenate([[0.0], np.cumsum([s.duration for s in self.segments])[:-1]])

    def apply_jump(self, x_end: np.ndarray) -> np.ndarray:
        """The state after the jump (time reset to 0)."""
        return np.concatenate([self.jump @ np.asarray(x_end, float)[: self.n], [0.0]])

    def basis(self) -> tuple[np.ndarray, np.ndarray]:
        """(U, C) in scaled coordinates: D^-1 R D = U C, U (n, r) orthonormal."""
        sc = self.scale
        Rs = self.jump * sc[None, :] / sc[:, None]
        Uf, sv, Vt = np.linalg.svd(Rs)
        tol = (sv[0] if sv.size else 0.0) * self.n * np.finfo(float).eps
        r = int(np.sum(sv > tol)) if sv.size and sv[0] > 0 else 0
        return Uf[:, :r], sv[:r, None] * Vt[:r]


@dataclass(frozen=True)
class PassageOptions:
    """Settings of the periodic solve.

    rtol, atol : tolerances of the state runs (atol in units of each state's scale).
    tangent_rtol, tangent_atol : tolerances of the variational solves.
    newton_tol : converged when max_i |P(x)_i - x_i| / scale_i is below this.
    max_iter : passages (chord, Newton) at most.
    chord_ratio : keep the Jacobian while each residual is below this fraction of the last.
    fast_ratio : use y <- p(y) while the residual falls by at least this factor per passage.
    multiplier_tol : recompute the transfer matrices at the solution when they were
        computed farther than this (scaled) from it.
    max_steps : integrator step bound per segment.
    """

    rtol: float = 1e-10
    atol: float = 1e-10
    tangent_rtol: float = 1e-8
    tangent_atol: float = 1e-8
    newton_tol: float = 1e-9
    max_iter: int = 30
    chord_ratio: float = 0.2
    fast_ratio: float = 0.05
    multiplier_tol: float = 1e-7
    max_steps: int = 1_000_000

    def __post_init__(self) -> None:
        for name in ("rtol", "atol", "tangent_rtol", "tangent_atol", "newton_tol",
                     "multiplier_tol"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and 0 < v <= 0.1):
                raise ValueError(f"{name} = {v!r}: must lie in (0, 0.1]")
        if not (isinstance(self.max_iter, int) and self.max_iter >= 1):
            raise ValueError(f"max_iter = {self.max_iter!r}: must be a whole number >= 1")
        for name in ("chord_ratio", "fast_ratio"):
            v = getattr(self, name)
            if not 0 < v < 1:
                raise ValueError(f"{name} = {v!r}: must lie in (0, 1)")

    def simulation(self) -> SimulationOptions:
        return SimulationOptions(rtol=self.rtol, atol=self.atol, max_steps=self.max_steps)


@dataclass(frozen=True)
class PassageRun:
    """One passage integrated from ``x0``.

    x_end : state at the end of the last segment (before the jump); x_next : after it.
    starts : state at the start of every segment (K, dim). outcome : 'ok', 'collision' (an
    event ended a segment: its index, the time in the passage, the event entry) or
    'failed'. t, x : saved times in the passage (s) and states, when asked for.
    steps : integrator steps."""

    __repr__ = compact_repr

    x_end: np.ndarray
    x_next: np.ndarray
    starts: np.ndarray
    outcome: str
    event_segment: int | None = None
    event_time: float | None = None
    event_index: int | None = None
    t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    x: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    steps: int = 0
    message: str = ""


def run_passage(problem: PassageProblem, x0: np.ndarray, options: PassageOptions | None = None,
                *, system: System | None = None, events=None,
                t_save: Sequence[np.ndarray] | None = None,
                simulation: SimulationOptions | None = None) -> PassageRun:
    """Integrate one passage from ``x0`` (its time state is set to 0).

    ``system`` replaces the problem's system (e.g. its version with physical limits; same
    states and parameters), ``events`` ends the run at a collision
    (:func:`~maglev_match.dynamics.integrate.simulate.simulate`), ``t_save`` gives per segment the
    saved times measured from the segment's start (give arrays of :data:`SAVE_SLOTS` times,
    so that one compiled integrator serves every run), ``simulation`` overrides the
    integrator options."""
    opts = options or PassageOptions()
    sim_opts = simulation or opts.simulation()
    sys_ = system or problem.system
    x = np.array(x0, float)
    x[-1] = 0.0
    starts, ts, xs = [], [], []
    steps = 0
    for k, (seg, t0) in enumerate(zip(problem.segments, problem.starts, strict=True)):
        starts.append(x.copy())
        save = None if t_save is None else np.asarray(t_save[k], float)
        # without saved times the integrator still gets SAVE_SLOTS of them (all at 0), so one
        # compiled kernel serves the runs that save and those that do not
        res: SimulationResult = simulate(
            sys_, x, seg.duration, p=seg.p, event_fn=events, x_ref=x, options=sim_opts,
            t_save=np.zeros(SAVE_SLOTS) if save is None else save)
        steps += res.steps
        if save is not None and save.size:
            keep = np.all(np.isfinite(res.x), axis=1)
            ts.append(t0 + save[keep])
            xs.append(res.x[keep])
        if res.outcome == "failed":
            return PassageRun(x, x, np.array(starts), "failed", k, t0 + res.final_time,
                              None, _cat(ts), _cat(xs, sys_.dim), steps,
                              "; ".join(res.warnings) or "integration failed")
        if res.outcome == "collision":
            return PassageRun(res.final_state, res.final_state, np.array(starts), "collision",
                              k, t0 + float(res.event_time), res.event_index, _cat(ts),
                              _cat(xs, sys_.dim), steps)
        x = np.array(res.final_state, float)
        x[-1] = t0 + seg.duration  # the time state, exactly
    return PassageRun(x, problem.apply_jump(x), np.array(starts), "ok", t=_cat(ts),
                      x=_cat(xs, sys_.dim), steps=steps)


def _cat(parts: list, dim: int | None = None) -> np.ndarray:
    if parts:
        return np.concatenate(parts)
    return np.zeros(0) if dim is None else np.zeros((0, dim))


@dataclass(frozen=True)
class BatchPassage:
    """Many passages integrated at once (leading axis: the run).

    x_next : state after the jump (for a collided or failed run: the ``park`` state);
    collided : an event ended the run in this passage; event_time : when (s, in the
    passage; NaN if not); event_index : the event entry (-1 if not); failed : the
    integrator failed (non-finite state or step limit)."""

    __repr__ = compact_repr

    x_next: np.ndarray
    collided: np.ndarray
    event_time: np.ndarray
    event_index: np.ndarray
    failed: np.ndarray


def run_passages_batch(problem: PassageProblem, X0: np.ndarray, park: np.ndarray, *,
                       system: System | None = None, events=None,
                       simulation: SimulationOptions | None = None) -> BatchPassage:
    """One passage of many runs in one vmapped integration per segment
    (:func:`~maglev_match.dynamics.integrate.simulate.simulate_batch`). A run that collides or fails
    continues from ``park`` (e.g. the periodic state: cheap to integrate, and the batch
    keeps its size, so one compiled integrator serves every call)."""
    sim = simulation or SimulationOptions()
    sys_ = system or problem.system
    X = np.array(X0, float)
    X[:, -1] = 0.0
    b = X.shape[0]
    collided = np.zeros(b, bool)
    failed = np.zeros(b, bool)
    t_event = np.full(b, np.nan)
    i_event = np.full(b, -1)
    park = np.array(park, float)
    for seg, t0 in zip(problem.segments, problem.starts, strict=True):
        res = simulate_batch(sys_, X, seg.duration, p=seg.p, event_fn=events, x_ref=park,
                             options=sim)
        done = collided | failed
        hit = (res.outcome_code == COLLISION) & ~done
        bad = ((res.outcome_code == FAILED) | ~np.all(np.isfinite(res.final_state), axis=1)
               ) & ~done & ~hit
        t_event[hit] = t0 + res.event_time[hit]
        i_event[hit] = res.event_index[hit]
        collided |= hit
        failed |= bad
        X = np.array(res.final_state, float)
        X[:, -1] = t0 + seg.duration
        park_here = park.copy()
        park_here[-1] = t0 + seg.duration
        X[collided | failed] = park_here  # (approximately where the parked run would be)
    Xn = np.concatenate([X[:, : problem.n] @ problem.jump.T, np.zeros((b, 1))], axis=1)
    return BatchPassage(Xn, collided, t_event, i_event, failed)


# ---------------------------------------------------------------------------------------
# the variational equation
# ---------------------------------------------------------------------------------------
@cache
def _variational_solver(rhs: Callable, n: int, r: int) -> Callable:
    """Compiled ``(z0, Psi0, p, scale, duration, rtol, atol, max_steps) -> (z, Psi, steps,
    ok)``: the scaled state z = x / scale (time last) and r columns Psi (n, r) of the scaled
    variational equation Psi' = D^-1 f_x D Psi, by diffrax's Dopri8 with a PID controller."""
    import diffrax

    def field_(t, y, args):
        p, sc = args
        z, Psi = y

        def f(zz):
            return rhs(zz * sc, p) / sc

        def column(col):
            return jax.jvp(f, (z,), (jnp.concatenate([col, jnp.zeros(1)]),))[1][:n]

        return f(z), jax.vmap(column, in_axes=1, out_axes=1)(Psi)

    def solve(z0, Psi0, p, sc, duration, rtol, atol, max_steps):
        sol = diffrax.diffeqsolve(
            diffrax.ODETerm(field_), diffrax.Dopri8(), 0.0, duration, None, (z0, Psi0),
            args=(p, sc), stepsize_controller=diffrax.PIDController(rtol=rtol, atol=atol),
            saveat=diffrax.SaveAt(t1=True), max_steps=max_steps, throw=False)
        z, Psi = sol.ys
        ok = sol.result == diffrax.RESULTS.successful
        return z[-1], Psi[-1], sol.stats["num_steps"], ok

    # max_steps must be static for diffrax: bound it once (runs report failure past it)
    def solve_static(z0, Psi0, p, sc, duration, rtol, atol):
        return solve(z0, Psi0, p, sc, duration, rtol, atol, 1_000_000)

    return cached_kernel(solve_static, rhs, n, r, name="passage.variational")


@dataclass(frozen=True)
class ReducedFactors:
    """The QR-compressed transfer matrices of one passage (scaled coordinates).

    R : (K, r, r) upper triangular factors of the segments; S : (r, r) = C Q_{K-1};
    the reduced Jacobian of the passage map is S R_{K-1} ... R_0. U, C : the basis of the
    jump (see :meth:`PassageProblem.basis`). error : largest scaled distance between the
    variational solves' base end states and the state-only run's (NaN if not compared).
    steps : integrator steps of the variational solves."""

    __repr__ = compact_repr

    R: np.ndarray
    S: np.ndarray
    U: np.ndarray
    C: np.ndarray
    error: float
    steps: int

    @property
    def jacobian(self) -> np.ndarray:
        """dp/dy of the reduced map (r, r), scaled coordinates."""
        M = np.eye(self.S.shape[0])
        for Rk in self.R:
            M = Rk @ M
        return self.S @ M


def reduced_factors(problem: PassageProblem, starts: np.ndarray,
                    options: PassageOptions | None = None,
                    x_ends: np.ndarray | None = None) -> ReducedFactors:
    """The transfer matrices of every segment along the trajectory through the segment
    start states ``starts`` (K, dim), applied to the basis U of the jump's range and
    compressed by QR (module docstring). ``x_ends`` (K, dim), the state-only run's segment
    end states, give the accuracy diagnostic. Raises FloatingPointError when a variational
    solve fails."""
    opts = options or PassageOptions()
    n = problem.n
    U, C = problem.basis()
    r = U.shape[1]
    sc_all = np.asarray(problem.system.state_scale, float)
    solve = _variational_solver(problem.system.rhs, n, r)
    Q = U
    Rs = []
    err = 0.0
    steps = 0
    for k, seg in enumerate(problem.segments):
        z0 = np.asarray(starts[k], float) / sc_all
        z, Psi, st, ok = solve(jnp.asarray(z0), jnp.asarray(Q), jnp.asarray(seg.p),
                               jnp.asarray(sc_all), jnp.asarray(float(seg.duration)),
                               jnp.asarray(opts.tangent_rtol), jnp.asarray(opts.tangent_atol))
        Psi = np.asarray(Psi)
        steps += int(st)
        if not bool(ok) or not np.all(np.isfinite(Psi)):
            raise FloatingPointError(f"the variational equation could not be integrated over "
                                     f"segment {k + 1} ({seg.duration:.6g} s)")
        if x_ends is not None:
            d = np.asarray(z)[:n] - np.asarray(x_ends[k], float)[:n] / sc_all[:n]
            err = max(err, float(np.max(np.abs(d))))
        Q, Rk = np.linalg.qr(Psi)
        Rs.append(Rk)
    return ReducedFactors(R=np.array(Rs).reshape(len(Rs), r, r), S=C @ Q, U=U, C=C,
                          error=err if x_ends is not None else float("nan"), steps=steps)


@dataclass(frozen=True)
class Multipliers:
    """Multipliers of the passage map, sorted by |mu| descending, with ln|mu| (usable where
    |mu| underflows; -inf for the exact zeros of states the jump discards) and how they
    were computed: 'periodic_qz', 'product' (a compressed factor was singular: eigenvalues of
    the explicit reduced product) or 'jump' (the jump discards every state)."""

    __repr__ = compact_repr

    values: np.ndarray
    log_abs: np.ndarray
    method: str

    @property
    def largest(self) -> float:
        """The spectral radius max |mu|."""
        return float(np.exp(self.log_abs[0])) if self.log_abs.size else 0.0

    @property
    def critical(self) -> complex:
        """The multiplier of largest modulus."""
        return complex(self.values[0]) if self.values.size else 0j


def passage_multipliers(factors: ReducedFactors, n: int) -> Multipliers:
    """The n multipliers: the eigenvalues of S R_{K-1} ... R_0 by the periodic QZ algorithm
    and n - r exact zeros. A singular S (the basis carries directions the jump discards,
    e.g. a span that has left the model and no longer acts on anything) is deflated first:
    with S = V_1 Sigma_1 W_1^T (its nonzero singular values), the nonzero eigenvalues of
    S X (X = R_{K-1} ... R_0) are those of Sigma_1 W_1^T X V_1, compressed again by the same
    QR recursion, and the others are exact zeros. If the periodic QZ does not converge the
    eigenvalues of the explicit product are used (``method = 'product'``). Conjugate pairs of
    the real product are made exact and real eigenvalues real."""
    Rk = np.array(factors.R, float)
    S = np.array(factors.S, float)
    r = S.shape[0]
    zeros = n - r
    while r > 0:
        V, sv, Wt = np.linalg.svd(S)
        keep = int(np.sum(sv > max(sv[0], 1e-300) * 1e-10)) if sv[0] > 0 else 0
        if keep == r:
            break
        zeros += r - keep
        r = keep
        if r == 0:
            break
        Q = V[:, :r]
        comp = []
        for F in Rk:
            Q, Rq = np.linalg.qr(F @ Q)
            comp.append(Rq)
        Rk = np.array(comp).reshape(len(comp), r, r)
        S = (sv[:r, None] * Wt[:r]) @ Q
    if r == 0:
        return Multipliers(np.zeros(n), np.full(n, -np.inf), "jump")
    seq = np.concatenate([Rk, S[None]])
    method = "periodic_qz"
    la = ph = None
    try:
        pe = periodic_eigenvalues(seq)
        if pe.converged and np.all(np.isfinite(pe.phase)):
            la, ph = np.asarray(pe.log_abs, float), np.asarray(pe.phase, float)
    except (ZeroDivisionError, FloatingPointError, ValueError):
        la = None
    if la is None:
        method = "product"
        P = S
        for F in Rk[::-1]:
            P = P @ F
        ev = np.linalg.eigvals(P)
        with np.errstate(divide="ignore"):
            la = np.log(np.abs(ev))
        ph = np.angle(ev)
    la = np.concatenate([la, np.full(zeros, -np.inf)])
    ph = np.concatenate([ph, np.zeros(zeros)])
    la, ph = _real_pairs(la, ph)
    order = np.argsort(-la, kind="stable")
    la, ph = la[order], ph[order]
    with np.errstate(over="ignore", under="ignore", invalid="ignore"):
        vals = np.where(np.isfinite(la), np.exp(la) * np.exp(1j * ph), 0.0)
    if np.all(np.abs(np.sin(ph)) == 0.0):
        vals = vals.real
    return Multipliers(values=vals, log_abs=la, method=method)


def _real_pairs(la: np.ndarray, ph: np.ndarray, tol: float = 1e-7
                ) -> tuple[np.ndarray, np.ndarray]:
    """Snap near-real eigenvalues of a real product to real and pair conjugates exactly
    (distance |ln|mu_i| - ln|mu_k|| + |arg mu_i + arg mu_k|)."""
    la, ph = la.copy(), ph.copy()
    used = np.zeros(la.size, bool)
    for i in np.argsort(-np.abs(np.sin(ph))):
        if used[i]:
            continue
        used[i] = True
        if abs(np.sin(ph[i])) <= tol or not np.isfinite(la[i]):
            ph[i] = 0.0 if np.cos(ph[i]) >= 0 else np.pi
            continue
        cand = [k for k in range(la.size) if not used[k]]
        if not cand:
            continue
        d = [abs(la[k] - la[i]) + abs(np.angle(np.exp(1j * (ph[k] + ph[i])))) for k in cand]
        k = cand[int(np.argmin(d))]
        used[k] = True
        la[i] = la[k] = 0.5 * (la[i] + la[k])
        ph[k] = -ph[i]
    return la, ph


# ---------------------------------------------------------------------------------------
# the periodic solve
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class PeriodicPassage:
    """A periodic response x* = P(x*) with its multipliers and diagnostics.

    x0 : the state at the start of the passage (time 0).
    converged : the scaled residual max |P(x0) - x0| / scale fell below ``newton_tol``.
    residual : that residual. passages : state-only passages run. jacobians : variational
    solves (one per passage). fast_steps : passages of the y <- p(y) iteration.
    factors : the compressed transfer matrices at x0 (None if not converged).
    multipliers : :class:`Multipliers` at x0 (None if not converged).
    integration_error : the variational solve's distance to the state run (scaled).
    run : the state-only passage from x0 (segment start states).
    problem : the problem solved. message : why it failed."""

    __repr__ = compact_repr

    problem: PassageProblem
    x0: np.ndarray
    converged: bool
    residual: float
    passages: int
    jacobians: int
    fast_steps: int
    factors: ReducedFactors | None
    multipliers: Multipliers | None
    integration_error: float
    run: PassageRun | None
    message: str = ""

    @property
    def stable(self) -> bool | None:
        if self.multipliers is None:
            return None
        return self.multipliers.largest < 1.0


def solve_periodic_passage(problem: PassageProblem, x_guess: np.ndarray,
                           options: PassageOptions | None = None) -> PeriodicPassage:
    """The fixed point of the passage map from ``x_guess``, and its multipliers (module
    docstring: y <- p(y) while it contracts fast, else Newton with the variational Jacobian,
    chord iterations while they contract). Failure is reported in the result."""
    opts = options or PassageOptions()
    n = problem.n
    sc = problem.scale
    U, C = problem.basis()
    r = U.shape[1]
    y = U.T @ (np.asarray(x_guess, float)[:n] / sc)

    def state(yy: np.ndarray) -> np.ndarray:
        return np.concatenate([(U @ yy) * sc, [0.0]])

    J = None  # reduced Jacobian (scaled), and where it was computed
    J_at = None
    fac: ReducedFactors | None = None
    jac = fast = 0
    last_res = np.inf
    res = np.inf
    run: PassageRun | None = None
    passages = 0
    newton = False

    def fail(msg: str) -> PeriodicPassage:
        return PeriodicPassage(problem, state(y), False, res, passages, jac, fast, None, None,
                               float("nan"), run, msg)

    while True:
        if passages >= opts.max_iter:
            return fail(f"no convergence in {opts.max_iter} passages (scaled residual "
                        f"{res:.3g})")
        run = run_passage(problem, state(y), opts)
        passages += 1
        if run.outcome != "ok":
            return fail(f"the passage could not be integrated ({run.message})")
        py = U.T @ (run.x_next[:n] / sc)
        G = py - y
        # the residual in the original scaled coordinates (the jump's range)
        res = float(np.max(np.abs(U @ G)))
        if res < opts.newton_tol:
            break
        if not newton and (passages == 1 or res <= opts.fast_ratio * last_res):
            y = py  # chord step with the Jacobian approximated by 0
            fast += 1
            last_res = res
            continue
        newton = True
        if J is None or res > opts.chord_ratio * last_res:
            # a Jacobian for Newton steps only needs a few digits: the first one is
            # integrated 100 times looser (about 40 % fewer steps); the multipliers come
            # from a full-accuracy solve at the solution
            newton_opts = opts if J is not None else dataclasses.replace(
                opts, tangent_rtol=min(100 * opts.tangent_rtol, 1e-4),
                tangent_atol=min(100 * opts.tangent_atol, 1e-4))
            try:
                newton_fac = reduced_factors(
                    problem, run.starts, newton_opts,
                    x_ends=np.vstack([run.starts[1:], run.x_end[None, :]]))
            except FloatingPointError as exc:
                return fail(str(exc))
            # only a full-accuracy solve may serve for the multipliers
            fac = newton_fac if newton_opts is opts else None
            J = newton_fac.jacobian
            J_at = y.copy()
            jac += 1
        last_res = res
        try:
            d = np.linalg.solve(J - np.eye(r), -G)
        except np.linalg.LinAlgError:
            return fail("the Newton matrix is singular (a multiplier at 1)")
        y = y + d
    x_ends = np.vstack([run.starts[1:], run.x_end[None, :]])
    if fac is None or J_at is None or np.max(np.abs(U @ (y - J_at))) > opts.multiplier_tol:
        try:
            fac = reduced_factors(problem, run.starts, opts, x_ends=x_ends)
        except FloatingPointError as exc:
            return fail(str(exc))
        jac += 1
    error = fac.error
    mult = passage_multipliers(fac, n)
    return PeriodicPassage(problem, state(y), True, res, passages, jac, fast, fac, mult, error,
                           run)


def finite_difference_jacobian(problem: PassageProblem, x0: np.ndarray, h: float = 1e-5,
                               options: PassageOptions | None = None) -> np.ndarray:
    """The reduced Jacobian dp/dy (scaled coordinates) at x0 by central differences of the
    integrated passage map, step h in each scaled direction of the basis U: an independent
    check of the variational transfer matrices (for tests)."""
    n = problem.n
    sc = problem.scale
    U, _ = problem.basis()
    r = U.shape[1]
    M = np.empty((r, r))
    for j in range(r):
        e = np.concatenate([U[:, j] * h * sc, [0.0]])
        xp = run_passage(problem, x0 + e, options).x_next[:n] / sc
        xm = run_passage(problem, x0 - e, options).x_next[:n] / sc
        M[:, j] = U.T @ (xp - xm) / (2 * h)
    return M
