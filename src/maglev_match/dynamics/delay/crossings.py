"""Hopf points of a delay system in a delay: the crossings of the imaginary axis by its
characteristic roots, the critical delay, the first Lyapunov coefficient from the
characteristic matrix, and the Hopf points along a delay as a record of the discretised
system.

**Hopf points in a delay** (:func:`delay_crossings`, :func:`critical_delay`). The
equilibrium does not move with a delay, so its Hopf points in tau_k are the delays at which
a root crosses the imaginary axis: Delta(i omega; tau_k) v = 0. For each omega the
candidates solve a generalised eigenvalue problem in z = exp(-i omega tau_k),

    (i omega I - A_0 - sum_{j != k} A_j exp(-i omega tau_j)) v = z A_k v,

and a crossing needs |z| = 1 (the classical frequency sweep, e.g. Michiels & Niculescu 2014,
*Stability, Control and Computation for Time-Delay Systems*, ch. 4). All crossings lie at
omega <= ||A_0|| + sum_j ||A_j||; they are bracketed on a frequency grid by the count of
|z| < 1, refined by Newton on (v, omega, tau_k), and each gives the delays
tau_k + 2 pi j / omega. This needs no discretisation and holds at tau_k = 0.

**First Lyapunov coefficient of a DDE** (:func:`delay_first_lyapunov_coefficient`), from the
characteristic matrix (Janssens 2010, *On a normalization technique for codimension two
bifurcations of equilibria of delay differential equations*, MSc thesis, Utrecht; Bosschaert,
Janssens & Kuznetsov 2020, SIAM J. Appl. Dyn. Syst. 19:252): with Delta(i omega) q = 0,
p^H Delta(i omega) = 0, |q| = 1, p^H Delta'(i omega) q = 1 and the multilinear forms B, C of
F(u_0, u_1, ..., u_K) = f(u_0, g_1(u_1), ..., g_K(u_K)) evaluated on the functions
phi(theta) = v exp(mu theta) at (theta = 0, -tau_1, ..., -tau_K),

    h20 = Delta(2 i omega)^-1 B(q e^{i w .}, q e^{i w .})     (times e^{2 i w theta})
    h11 = Delta(0)^-1 B(q e^{i w .}, qbar e^{-i w .})
    l1  = Re p^H [C(q, q, qbar) + B(qbar, h20) + 2 B(q, h11)] / (2 omega),

which is Kuznetsov's ODE formula (:mod:`maglev_match.dynamics.normal_forms`) when every delay
is 0. The discretised system computes the same number with its own formula when its
eigenvectors are normalised on the current state (``normal_form_dim``); the two agree as N
grows (tested).

**Hopf points along a delay** (:func:`delay_hopf_points`): the crossings, with the record
of a Hopf point (:class:`~maglev_match.dynamics.hopf.HopfPoint`) completed by the
discretised system (:mod:`maglev_match.dynamics.delay.discretisation`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.linalg

from maglev_match.core.reprs import compact_repr
from maglev_match.dynamics.delay.discretisation import (
    NODES_MAX,
    DelayNodesError,
    DiscretisedSystem,
    nodes_for,
)
from maglev_match.dynamics.delay.roots import (
    characteristic_derivative,
    characteristic_matrix,
    discretised_matrix,
    refine_characteristic_root,
    rightmost_first,
    signal_factors,
)
from maglev_match.dynamics.delay.system import DelayDifferentialSystem, delay_jacobians
from maglev_match.dynamics.normal_forms import null_vector

__all__ = [
    "DelayCrossing",
    "CriticalDelay",
    "delay_first_lyapunov_coefficient",
    "delay_crossings",
    "critical_delay",
    "delay_hopf_points",
]


def _one_thread():
    """Small dense eigenproblems in a loop: BLAS threads only contend for the cores there
    (as in :mod:`maglev_match.analyses.matching`)."""
    from maglev_match.core.threads import blas_threads

    return blas_threads(1)



# ---------------------------------------------------------------------------------------
# the first Lyapunov coefficient of a delay system
# ---------------------------------------------------------------------------------------
def _forms(F: Callable):
    from maglev_match.dynamics.normal_forms import real_forms

    return real_forms(F)


def delay_first_lyapunov_coefficient(dde: DelayDifferentialSystem, x: np.ndarray,
                                     p: np.ndarray | None, omega: float,
                                     q: np.ndarray | None = None) -> float:
    """l1 at a Hopf point of a delay system from its characteristic matrix (module
    docstring; Janssens 2010, Bosschaert et al. 2020), with |q| = 1 on the state and
    p^H Delta'(i omega) q = 1. Equals Kuznetsov's ODE value when every delay is 0.

    Parameters: ``x`` the equilibrium (n states), ``omega`` the Hopf frequency (rad/s),
    ``q`` the eigenvector (computed when None). Returns l1 (1/s): > 0 subcritical.
    """
    from maglev_match.dynamics.normal_forms import complex_form_eval

    pv = dde.p if p is None else np.asarray(p, float)
    xs = np.asarray(x, float)
    taus = dde.delay_values(pv)
    A0, As = delay_jacobians(dde, xs, pv)
    n, K = dde.dim, len(taus)
    iw = 1j * float(omega)
    Dl = characteristic_matrix(A0, As, taus, iw)
    if q is None:
        q = null_vector(Dl)
    q = np.asarray(q, complex)
    q = q * np.exp(-1j * np.angle(q[int(np.argmax(np.abs(q)))]))
    q = q / np.linalg.norm(q)
    padj = null_vector(Dl.conj().T)
    padj = padj / np.conj(np.vdot(padj, characteristic_derivative(A0, As, taus, iw) @ q))

    def U(v: np.ndarray, mu: complex) -> np.ndarray:
        return np.concatenate([v] + [v * np.exp(-mu * t) for t in taus])

    Fm = _forms(dde.argument_function)
    Ux = np.asarray(np.tile(xs, K + 1), np.float64)

    def form(k, *us):
        val = np.asarray(complex_form_eval(Fm[k], Ux, pv, list(us)))
        # all-zero directions give a zero of the directions' shape (size n (K+1))
        return val if val.shape == (n,) else np.zeros(n, complex)

    def B(a, b):
        return form(2, a, b)

    def C(a, b, c):
        return form(3, a, b, c)

    Uq, Uqb = U(q, iw), U(np.conj(q), -iw)
    h20 = np.linalg.solve(characteristic_matrix(A0, As, taus, 2 * iw), B(Uq, Uq))
    h11 = np.linalg.solve(characteristic_matrix(A0, As, taus, 0.0), B(Uq, Uqb))
    g21 = np.vdot(padj, C(Uq, Uq, Uqb) + B(Uqb, U(h20, 2 * iw)) + 2.0 * B(Uq, U(h11, 0.0)))
    return float(g21.real / (2.0 * float(omega)))


# ---------------------------------------------------------------------------------------
# Hopf points in a delay: crossings of the imaginary axis
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class DelayCrossing:
    """A pair of characteristic roots +-i omega on the imaginary axis at delay ``tau``.

    tau : the delay (s) at the crossing, the smallest one of its family
        tau + 2 pi j / omega (all of them are crossings). omega : frequency (rad/s).
    crossing_speed : d Re(lambda) / d tau there (1/s^2): > 0 the pair moves into the
        right half-plane as the delay grows. q : the eigenvector (|q| = 1).
    residual : |Delta(i omega) q| / (omega + ||A||). converged : Newton converged.
    """

    __repr__ = compact_repr

    tau: float
    omega: float
    crossing_speed: float
    q: np.ndarray
    residual: float
    converged: bool

    def delays(self, tau_max: float) -> list[float]:
        """Every delay of this family in [0, tau_max]."""
        if not self.omega > 0:
            return []
        period = 2.0 * math.pi / self.omega
        k_max = int(math.floor((tau_max - self.tau) / period + 1e-12))
        return [self.tau + j * period for j in range(max(k_max + 1, 0))]


def _rest_matrix(A0, As, taus, k, omega):
    M = 1j * omega * np.eye(A0.shape[0]) - A0
    for j, (A, t) in enumerate(zip(As, taus, strict=True)):
        if j != k:
            M = M - A * np.exp(-1j * omega * t)
    return M


def _unit_circle_candidates(A0, As, taus, k, omega) -> np.ndarray:
    """The finite z = exp(-i omega tau_k) of (i omega I - A_0 - sum_{j != k} ...) v = z A_k v."""
    return _candidates_on_grid(A0, As, taus, k, np.asarray([omega], float))[0]


def _candidates_on_grid(A0, As, taus, k, omegas: np.ndarray) -> list[np.ndarray]:
    """:func:`_unit_circle_candidates` at every frequency of ``omegas``.

    When A_k has one nonzero row r (one delayed signal entering one equation: model A's
    outer loop), A_k = e_r a^T and the pencil has at most one finite eigenvalue,
    z = 1 / (a^T M^{-1} e_r) (from M v = z e_r (a^T v)), found for the whole grid by one
    batched solve instead of one QZ decomposition per frequency (1500 of them, 0.1 s of
    every index); none when a^T M^{-1} e_r = 0 or M is singular. Otherwise the QZ
    eigenvalues of the pencil (scipy.linalg.eigvals) per frequency."""
    Ak = As[k]
    z = _single_candidates(A0, As, taus, k, omegas)
    if z is None:
        out = []
        for w in omegas:
            z = scipy.linalg.eigvals(_rest_matrix(A0, As, taus, k, w), Ak.astype(complex))
            out.append(z[np.isfinite(z)])
        return out
    return [z[i:i + 1] if np.isfinite(z[i]) else z[:0] for i in range(omegas.size)]


def _single_candidates(A0, As, taus, k, omegas: np.ndarray) -> np.ndarray | None:
    """The one finite candidate z of every frequency of ``omegas`` as one array (nan where
    there is none) when A_k has one nonzero row (:func:`_candidates_on_grid`); None when
    it has several."""
    Ak = As[k]
    rows = np.flatnonzero(np.any(Ak != 0, axis=1))
    if rows.size != 1:
        return None
    r, a = int(rows[0]), Ak[rows[0]]
    n = A0.shape[0]
    M = 1j * omegas[:, None, None] * np.eye(n) - A0
    for j, (A, t) in enumerate(zip(As, taus, strict=True)):
        if j != k:
            M = M - A * np.exp(-1j * omegas * t)[:, None, None]
    e = np.zeros((omegas.size, n, 1), complex)
    e[:, r, 0] = 1.0
    with np.errstate(all="ignore"):
        try:
            s = np.linalg.solve(M, e)[:, :, 0] @ a
        except np.linalg.LinAlgError:  # a singular M somewhere: one frequency at a time
            s = np.zeros(omegas.size, complex)
            for i in range(omegas.size):
                try:
                    s[i] = np.linalg.solve(M[i], e[i])[:, 0] @ a
                except np.linalg.LinAlgError:  # i omega is a root without delay: no z
                    s[i] = 0.0
        z = 1.0 / s
    return np.where(np.isfinite(z) & (s != 0), z, np.nan + 0j)


def _refine_crossing(A0, As, taus, k, omega, tau, v, tol=1e-14, max_iter=40):
    """Newton on Delta(i omega; tau_k = tau) v = 0, c^H v = 1 for (v, omega, tau)."""
    n = A0.shape[0]
    v = np.asarray(v, complex) / np.linalg.norm(v)
    c = v.copy()
    t = list(taus)
    converged = False
    for _ in range(max_iter):
        t[k] = tau
        lam = 1j * omega
        Dl = characteristic_matrix(A0, As, t, lam)
        F = np.concatenate([Dl @ v, [np.vdot(c, v) - 1.0]])
        dD_domega = 1j * characteristic_derivative(A0, As, t, lam) @ v
        dD_dtau = lam * As[k] @ v * np.exp(-lam * tau)
        # complex equations, unknowns v (complex) and omega, tau (real)
        Jc = np.zeros((n + 1, n), complex)
        Jc[:n] = Dl
        Jc[n] = np.conj(c)
        cols = np.zeros((n + 1, 2), complex)
        cols[:n, 0] = dD_domega
        cols[:n, 1] = dD_dtau
        Jr = np.block([[Jc.real, -Jc.imag, cols.real], [Jc.imag, Jc.real, cols.imag]])
        Fr = np.concatenate([F.real, F.imag])
        try:
            d = np.linalg.lstsq(Jr, -Fr, rcond=None)[0]
        except np.linalg.LinAlgError:
            break
        if not np.all(np.isfinite(d)):
            break
        v = v + d[:n] + 1j * d[n:2 * n]
        omega += d[2 * n]
        tau += d[2 * n + 1]
        if abs(d[2 * n]) <= tol * max(1.0, abs(omega)) and abs(d[2 * n + 1]) <= tol * max(
                1.0, abs(tau)) * max(1.0, abs(omega)):
            converged = True
            break
    t[k] = tau
    v = v / np.linalg.norm(v)
    size = np.linalg.norm(A0, 2) + sum(np.linalg.norm(A, 2) for A in As)
    res = float(np.linalg.norm(characteristic_matrix(A0, As, t, 1j * omega) @ v)
                / (abs(omega) + size))
    return float(omega), float(tau), v, res, converged and res < 1e-12


def _crossing_speed(A0, As, taus, k, omega, v) -> float:
    """d Re(lambda) / d tau_k at the root i omega: -Re[p^H (dDelta/dtau_k) v] / p^H Delta' v
    with p the left null vector."""
    lam = 1j * omega
    Dl = characteristic_matrix(A0, As, taus, lam)
    padj = null_vector(Dl.conj().T)
    num = np.vdot(padj, lam * As[k] @ v * np.exp(-lam * taus[k]))
    den = np.vdot(padj, characteristic_derivative(A0, As, taus, lam) @ v)
    return float((-num / den).real)


def _match(za: np.ndarray, zb: np.ndarray) -> list[tuple[int, int]]:
    """Pairs (i, j) matching the candidates of two neighbouring frequencies (least total
    distance, in log|z| and arg z). One candidate on each side (model A: every frequency)
    is its own match, without the assignment solver (whose import, scipy.optimize, costs
    0.13 s of a process start)."""
    if za.size == 0 or zb.size == 0:
        return []
    la, lb = np.log(za), np.log(zb)  # log|z| + i arg z
    d = np.abs(la.real[:, None] - lb.real[None, :]) + np.abs(
        np.angle(np.exp(1j * (la.imag[:, None] - lb.imag[None, :]))))
    if d.shape == (1, 1) and np.isfinite(d[0, 0]):
        return [(0, 0)]
    from scipy.optimize import linear_sum_assignment

    rows, cols = linear_sum_assignment(d)
    return list(zip(rows.tolist(), cols.tolist(), strict=True))


def _intervals_to_search(zs: list[np.ndarray]) -> np.ndarray:
    """The grid intervals :func:`_crossing_brackets` has to look at: all of them, except
    those with one finite candidate at each end that stays on one side of |z| = 1 (which
    it would reject at once: model A has one candidate at every frequency, so this skips
    almost all of the 1,500 Python calls of an index)."""
    n = len(zs) - 1
    if n <= 0:
        return np.arange(0)
    single = np.array([z.size == 1 for z in zs])
    la = np.array([math.log(abs(z[0])) if z.size == 1 and np.isfinite(z[0]) and z[0] != 0
                   else math.nan for z in zs])
    return _same_side_skipped(single, la)


def _same_side_skipped(single: np.ndarray, la: np.ndarray) -> np.ndarray:
    """:func:`_intervals_to_search` from whether each frequency has one candidate and its
    log|z| (nan where it has none or it is not finite)."""
    both = single[:-1] & single[1:] & np.isfinite(la[:-1]) & np.isfinite(la[1:])
    same_side = both & (la[:-1] * la[1:] > 0.0)
    return np.flatnonzero(~same_side)


def _crossing_brackets(A0, As, taus, k, wa, wb, za, zb, depth: int, max_depth: int = 6,
                       split: int = 8) -> list[tuple[float, float, complex, complex]]:
    """Frequency intervals in which one matched candidate z passes |z| = 1, subdivided
    (``split`` parts, up to ``max_depth`` times) until each holds one crossing per
    candidate and is narrow against the frequency: near-equal roots (the six levitation
    points of a vehicle give clusters) cross within one coarse interval."""
    changes = [(za[a], zb[b]) for a, b in _match(za, zb)
               if math.log(abs(za[a])) * math.log(abs(zb[b])) <= 0.0]
    if not changes:
        return []
    if depth >= max_depth or wb - wa <= 1e-7 * wb:
        return [(wa, wb, x, y) for x, y in changes]
    ws = np.linspace(wa, wb, split + 1)
    zz = [za] + _candidates_on_grid(A0, As, taus, k, ws[1:-1]) + [zb]
    out = []
    for i in range(split):
        out += _crossing_brackets(A0, As, taus, k, ws[i], ws[i + 1], zz[i], zz[i + 1],
                                  depth + 1, max_depth, split)
    return out


def delay_crossings(dde: DelayDifferentialSystem, delay: str, x: np.ndarray | None = None,
                    p: np.ndarray | None = None, *, n_grid: int = 1500
                    ) -> list[DelayCrossing]:
    """Every pair of characteristic roots that can sit on the imaginary axis as the delay
    ``delay`` varies (the other delays fixed), at the equilibrium ``x``: their frequency
    and smallest delay (module docstring).

    The frequency axis (0, ||A_0|| + sum ||A_j||] is sampled on ``n_grid`` logarithmically
    spaced points; the candidates z of neighbouring points are matched (least distance),
    every candidate whose |z| passes 1 between two points is refined by Newton's method on
    (v, omega, tau) and the distinct solutions are kept."""
    pv = dde.p if p is None else np.asarray(p, float)
    xs = dde.x_guess if x is None else np.asarray(x, float)
    k = dde.delays.index(delay)
    taus = list(dde.delay_values(pv))
    A0, As = delay_jacobians(dde, xs, pv)
    if not np.any(As[k]):
        return []
    w_max = float(np.linalg.norm(A0, 2) + sum(np.linalg.norm(A, 2) for A in As))
    if not w_max > 0:
        return []
    grid = np.geomspace(w_max * 1e-8, w_max, n_grid)
    with _one_thread():
        z1 = _single_candidates(A0, As, taus, k, grid)
        if z1 is None:
            zs = _candidates_on_grid(A0, As, taus, k, grid)
            search = _intervals_to_search(zs)
        else:  # one candidate per frequency: the grid's tests as array operations
            ok = np.isfinite(z1) & (z1 != 0)
            with np.errstate(all="ignore"):
                la = np.where(ok, np.log(np.abs(z1)), np.nan)
            search = _same_side_skipped(np.isfinite(z1), la)
            zs = {int(i): z1[i:i + 1] if np.isfinite(z1[i]) else z1[:0]
                  for i in np.union1d(search, search + 1)}
        brackets = []
        for i in search:
            brackets += _crossing_brackets(A0, As, taus, k, grid[i], grid[i + 1], zs[i],
                                           zs[i + 1], depth=0)
    starts = []
    for wa, wb, za, zb in brackets:
        la, lb = math.log(abs(za)), math.log(abs(zb))
        f = la / (la - lb) if la != lb else 0.5
        w0 = wa + f * (wb - wa)
        z_guess = za * (zb / za) ** f
        z, V = scipy.linalg.eig(_rest_matrix(A0, As, taus, k, w0), As[k].astype(complex))
        ok = np.isfinite(z)
        z, V = z[ok], V[:, ok]
        if z.size == 0:
            continue
        j = int(np.argmin(np.abs(z - z_guess)))
        starts.append((w0, z[j] / abs(z[j]), V[:, j]))
    found: list[DelayCrossing] = []
    for w0, z0, v0 in starts:
        tau0 = (-np.angle(z0)) % (2 * math.pi) / w0
        om, tau, v, res, ok = _refine_crossing(A0, As, taus, k, w0, tau0, v0)
        if not (om > 0 and math.isfinite(tau)):
            continue
        period = 2 * math.pi / om
        tau = tau % period
        if any(abs(c.omega - om) <= 1e-8 * max(1.0, om) and abs(c.tau - tau) <= 1e-8 * period
               for c in found):
            continue
        t2 = list(taus)
        t2[k] = tau
        speed = _crossing_speed(A0, As, t2, k, om, v)
        found.append(DelayCrossing(tau=float(tau), omega=float(om), crossing_speed=speed,
                                   q=v, residual=res, converged=ok))
    found.sort(key=lambda c: c.tau)
    return found


@dataclass(frozen=True)
class CriticalDelay:
    """The smallest delay at which the equilibrium loses stability (the other parameters
    fixed), from the characteristic equation (no discretisation).

    delay : the delay parameter's name. value : the critical delay (s); 0 when the
        equilibrium is already unstable without delay; None when it stays stable for every
        delay up to ``tau_max`` (or for every delay, ``stable_for_all``).
    frequency : omega (rad/s) of the pair that crosses; crossing_speed : d Re / d tau.
    l1 : first Lyapunov coefficient there (1/s, |q| = 1 on the state): > 0 subcritical.
    stable_without_delay : stability at delay 0. unstable_roots_without_delay : count.
    crossings : every family of crossings (:class:`DelayCrossing`).
    """

    __repr__ = compact_repr

    delay: str
    value: float | None
    frequency: float | None
    crossing_speed: float | None
    l1: float | None
    stable_without_delay: bool
    unstable_roots_without_delay: int
    tau_max: float
    stable_for_all: bool
    crossings: tuple[DelayCrossing, ...]
    warnings: tuple[str, ...] = ()

    @property
    def kind(self) -> str:
        if self.l1 is None or not math.isfinite(self.l1):
            return "unknown"
        return "subcritical" if self.l1 > 0 else "supercritical" if self.l1 < 0 else \
            "degenerate"

    def as_json(self) -> dict[str, Any]:
        return {"delay": self.delay, "value": self.value, "frequency": self.frequency,
                "crossing_speed": self.crossing_speed, "l1": self.l1, "kind": self.kind,
                "stable_without_delay": self.stable_without_delay,
                "tau_max": self.tau_max, "stable_for_all": self.stable_for_all,
                "crossings": [{"tau": c.tau, "omega": c.omega,
                               "crossing_speed": c.crossing_speed, "converged": c.converged}
                              for c in self.crossings],
                "warnings": list(self.warnings)}


def critical_delay(dde: DelayDifferentialSystem, delay: str | None = None,
                   x: np.ndarray | None = None, p: np.ndarray | None = None, *,
                   tau_max: float = math.inf) -> CriticalDelay:
    """The smallest value of ``delay`` (default the first) at which the equilibrium ``x``
    loses stability, with the other delays at their values in ``p``.

    Stability at delay 0 comes from the roots with this delay removed (the delay-free
    eigenvalues for a single delay). Roots then cross only at the delays of
    :func:`delay_crossings`; walking through them in order and counting +-2 by the sign of
    each crossing speed gives the first delay at which a root enters the right half-plane.
    Its l1 is :func:`delay_first_lyapunov_coefficient`.
    """
    delay = delay or dde.delays[0]
    k = dde.delays.index(delay)
    pv = dde.p if p is None else np.asarray(p, float)
    xs = dde.x_guess if x is None else np.asarray(x, float)
    warnings: list[str] = []
    A0, As = delay_jacobians(dde, xs, pv)
    taus = dde.delay_values(pv)
    others = [j for j in range(len(taus)) if j != k]
    if not others or not np.any(taus[others] > 0):
        w0 = np.linalg.eigvals(A0 + sum(As))
        n_unst = int(np.sum(w0.real >= 0))
    else:
        # roots with this delay at 0: delay k folded into A_0, the others discretised
        _, R, G = signal_factors(dde, xs, pv)
        red_A0 = A0 + As[k]
        red_As = [As[j] for j in others]
        red_t = [float(taus[j]) for j in others]
        rate = max(1.0, float(np.max(np.abs(np.linalg.eigvals(red_A0 + sum(red_As))))))
        N = min(nodes_for(max(red_t), rate), NODES_MAX)
        M = discretised_matrix(red_A0, [R[j] for j in others], [G[j] for j in others],
                               red_t, N)
        w = np.array([refine_characteristic_root(red_A0, red_As, red_t, lam)[0]
                      for lam in rightmost_first(np.linalg.eigvals(M))[:12]])
        n_unst = int(np.sum(w.real >= 0))
    crossings = delay_crossings(dde, delay, xs, pv)
    events = []
    for c in crossings:
        for t in c.delays(tau_max if math.isfinite(tau_max) else c.tau + 20 * 2 * math.pi
                          / c.omega):
            events.append((t, c))
    events.sort(key=lambda e: e[0])
    value = frequency = speed = l1 = None
    if n_unst > 0:
        value = 0.0
    else:
        count = 0
        for t, c in events:
            if c.crossing_speed == 0.0:
                warnings.append(f"a pair of roots touches the imaginary axis at {delay} = "
                                f"{t:.6g} without crossing (crossing speed 0)")
                continue
            tp = list(taus)
            tp[k] = t
            sp = _crossing_speed(A0, As, tp, k, c.omega, c.q)
            count += 2 if sp > 0 else -2
            if count > 0:
                value, frequency, speed = float(t), float(c.omega), float(sp)
                pk = dde.params_with(pv, **{delay: t})
                l1 = delay_first_lyapunov_coefficient(dde, xs, pk, c.omega, c.q)
                break
    for c in crossings:
        if not c.converged:
            warnings.append(f"the crossing near omega = {c.omega:.6g} rad/s did not converge "
                            f"(residual {c.residual:.2e})")
    stable_for_all = n_unst == 0 and not crossings  # no root can reach the axis
    if value is not None and value > tau_max:
        value = frequency = speed = l1 = None
    return CriticalDelay(delay=delay, value=value, frequency=frequency, crossing_speed=speed,
                         l1=l1, stable_without_delay=n_unst == 0,
                         unstable_roots_without_delay=n_unst, tau_max=float(tau_max),
                         stable_for_all=stable_for_all, crossings=tuple(crossings),
                         warnings=tuple(warnings))


# ---------------------------------------------------------------------------------------
# Hopf points along a delay, for the discretised system
# ---------------------------------------------------------------------------------------
def delay_hopf_points(system: DiscretisedSystem, delay: str, start: float, stop: float,
                      p: np.ndarray | None = None, n_scan: int = 100):
    """Hopf points of the equilibrium as the delay ``delay`` runs over [start, stop] (s),
    as a :class:`~maglev_match.dynamics.hopf.HopfScan` of the discretised system.

    The points are the crossings of the characteristic equation (:func:`delay_crossings`:
    exact, and valid down to delay 0, where the discretised system is singular): delay,
    frequency, crossing speed d Re(lambda)/d tau and l1
    (:func:`delay_first_lyapunov_coefficient`) come from the characteristic matrix. The
    discretised system supplies the rest of the record: the equilibrium and eigenvectors in
    its coordinates (from which cycles are continued) and whether the other roots are
    stable. Its eigenvalue nearest i omega at the crossing measures the discretisation
    error; above 1e-8 relative it is a warning. ``scan_values`` and ``max_real_part``
    sample the rightmost root of the discretised system over [start, stop] (``n_scan``
    values; the delay-free eigenvalues at delay 0).
    """
    from maglev_match.dynamics.equilibria import find_equilibrium
    from maglev_match.dynamics.hopf import HopfPoint, HopfScan

    dde = system.dde
    pv = system.p if p is None else np.asarray(p, float)
    lo, hi = sorted((float(start), float(stop)))
    warnings: list[str] = []
    if lo < 0:
        raise DelayNodesError(delay, lo, "a delay must be >= 0 s")
    eq = find_equilibrium(dde.ode_system(), dde.ode_params(pv))
    if not eq.converged:
        warnings.append(f"equilibrium not converged: {eq.message}")
    xs = eq.x
    crossings = delay_crossings(dde, delay, xs, pv)
    A0, R, G = signal_factors(dde, xs, pv)
    As = [Rj @ Gj for Rj, Gj in zip(R, G, strict=True)]
    k = dde.delays.index(delay)

    def matrix(t: float) -> np.ndarray:
        taus = np.array(dde.delay_values(pv), float)
        taus[k] = t
        keep = [j for j in range(len(taus)) if taus[j] > 0]
        merged = A0 + sum(As[j] for j in range(len(taus)) if j not in keep)
        if not keep:
            return merged
        return discretised_matrix(merged, [R[j] for j in keep], [G[j] for j in keep],
                                  [taus[j] for j in keep], system.nodes)

    scan_values = np.linspace(lo, hi, max(int(n_scan), 2))
    with _one_thread():
        max_re = np.array([float(np.max(np.linalg.eigvals(matrix(t)).real))
                           for t in scan_values])
    X = system.lift(xs, pv)
    norm_dim = dde.dim
    points = []
    for c in crossings:
        for t in c.delays(hi):
            if t < lo - 1e-12 * max(1.0, hi):
                continue
            if t <= 0:
                warnings.append(f"a pair of roots sits on the imaginary axis at {delay} = 0 "
                                f"(omega = {c.omega:.6g} rad/s): the delay-free equilibrium is "
                                "itself at a Hopf point")
                continue
            pt = system.params_with(pv, **{delay: t})
            J = matrix(t)
            w = np.linalg.eigvals(J)
            near = int(np.argmin(np.abs(w - 1j * c.omega)))
            err = abs(w[near] - 1j * c.omega) / c.omega
            others = np.delete(w, [near, int(np.argmin(np.abs(w + 1j * c.omega)))])
            q = null_vector(J - 1j * c.omega * np.eye(J.shape[0]))
            q = q * np.exp(-1j * np.angle(q[int(np.argmax(np.abs(q[:norm_dim])))]))
            q = q / np.linalg.norm(q[:norm_dim])
            padj = null_vector(J.T + 1j * c.omega * np.eye(J.shape[0]))
            padj = padj / np.conj(np.vdot(padj, q))
            l1 = delay_first_lyapunov_coefficient(dde, xs, pt, c.omega, c.q)
            sp = _crossing_speed(A0, As, list(dde.delay_values(pt)), k, c.omega, c.q)
            hw: list[str] = []
            if err > 1e-8:
                hw.append(f"the discretised system (N = {system.nodes}) has its eigenvalue "
                          f"nearest i omega {err:.1e} (relative) away: the discretisation "
                          "does not resolve this root well")
            if not c.converged:
                hw.append(f"Newton on the characteristic equation did not converge "
                          f"(residual {c.residual:.1e})")
            points.append(HopfPoint(
                param=delay, value=float(t), x=X, p=pt, frequency=float(c.omega), q=q,
                p_adj=padj, crossing_speed=float(sp), l1=float(l1),
                others_stable=bool(np.all(others.real < 0)), converged=bool(c.converged),
                residual=float(c.residual), warnings=tuple(hw),
                message="" if c.converged else "the crossing did not converge"))
    points.sort(key=lambda h: h.value)
    return HopfScan(param=delay, start=float(start), stop=float(stop), points=points,
                    scan_values=scan_values, max_real_part=max_re,
                    warnings=tuple(warnings), special_points=())

