"""Hopf bifurcations of equilibria of x' = f(x, p): detection along one parameter, the
two-parameter Hopf curve, first and second Lyapunov coefficients, codimension-two points.

Model-agnostic: works on any :class:`~maglev_match.dynamics.system.System` (SPEC.md 6.2, 6.3).

Defining system (real form) of a Hopf point, unknowns (x, v1, v2, omega, free parameters):

    f(x, alpha) = 0,   J v1 + omega v2 = 0,   J v2 - omega v1 = 0,   <c, v1> = 1,   <c, v2> = 0

so that q = v1 + i v2 satisfies J q = i omega q. With one free parameter the system is
square and Newton's method refines a Hopf point to full precision; with two free parameters
it defines the Hopf curve, followed by pseudo-arclength continuation.

Normal-form coefficients (Kuznetsov, Elements of Applied Bifurcation Theory, 3rd ed., and
Kuznetsov 1999 SIAM J. Numer. Anal. 36:1104), with J q = i omega q, J^T p = -i omega p,
<q, q> = 1, <p, q> = 1 and <a, b> = sum conj(a) b:

    h20 = (2 i omega - J)^-1 B(q, q),   h11 = -J^-1 B(q, qbar)
    G21 = <p, C(q, q, qbar) + B(qbar, h20) + 2 B(q, h11)>
    l1  = Re G21 / (2 omega)                                   (paper eq. 24)
    l2  = Re G32 / (12 omega)                                  (at l1 = 0)

With this normalisation a planar block z' = (mu + i) z + b z |z|^2 + s z |z|^4 written in
x1 + i x2 = z gives l1 = 2 Re b and, at Re b = 0, l2 = 4 Re s (since <q, q> = 1 means
z = sqrt(2) w in the normal-form coordinate w); the signs are those of Re b and Re s.
Derivatives of orders 2 to 5 are exact (nested forward-mode autodiff), never finite
differences.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass
from functools import cache

import jax
import jax.numpy as jnp
import numpy as np
import scipy.linalg
import scipy.optimize

from maglev_match.dynamics.system import System

__all__ = [
    "HopfPoint",
    "HopfScan",
    "HopfCurvePoint",
    "CodimTwoPoint",
    "HopfCurve",
    "locate_hopf_points",
    "refine_hopf_point",
    "first_lyapunov_coefficient",
    "second_lyapunov_coefficient",
    "hopf_eigenvectors",
    "hopf_curve",
    "stability_grid",
]


# ----------------------------------------------------------------------------------------
# results
# ----------------------------------------------------------------------------------------
@dataclass(frozen=True)
class HopfPoint:
    """A Hopf point of the equilibrium along one parameter, refined on the defining system."""

    param: str  # the continuation parameter name
    value: float  # its value at the Hopf point (SI unit of that parameter)
    x: np.ndarray  # equilibrium state there
    p: np.ndarray  # full parameter vector there
    frequency: float  # omega (rad/s), eigenvalues +-i omega
    q: np.ndarray  # complex right eigenvector, J q = i omega q, <q,q> = 1
    p_adj: np.ndarray  # complex adjoint eigenvector, J^T p = -i omega p, <p,q> = 1
    crossing_speed: float  # d Re(lambda)/d param (1/s per unit of param)
    l1: float  # first Lyapunov coefficient (paper eq. 24), 1/s with <q,q> = 1
    others_stable: bool  # all other eigenvalues in the open left half-plane
    converged: bool
    residual: float  # max |defining system| at the solution (scaled)
    warnings: tuple[str, ...] = ()
    message: str = ""  # why the point is not converged ('' when it is)

    @property
    def kind(self) -> str:
        """'subcritical' (l1 > 0), 'supercritical' (l1 < 0) or 'degenerate' (l1 = 0)."""
        return _criticality(self.l1)


@dataclass(frozen=True)
class HopfScan:
    """Hopf points found along one parameter interval."""

    param: str
    start: float
    stop: float
    points: list[HopfPoint]
    scan_values: np.ndarray  # parameter along the equilibrium branch (branch order)
    max_real_part: np.ndarray  # max Re(lambda) there (1/s)
    warnings: tuple[str, ...] = ()
    special_points: tuple = ()  # LP, BP, H of the equilibrium branch (EquilibriumSpecialPoint)


@dataclass(frozen=True)
class HopfCurvePoint:
    """One point of a two-parameter Hopf curve."""

    values: tuple[float, float]  # the two parameter values
    x: np.ndarray
    frequency: float  # omega (rad/s)
    l1: float  # first Lyapunov coefficient (1/s, <q,q> = 1)
    others_stable: bool  # every other eigenvalue has Re < 0
    n_unstable_others: int  # number of other eigenvalues with Re > 0


@dataclass(frozen=True)
class CodimTwoPoint:
    """A codimension-two point on the Hopf curve.

    type: 'GH' (generalised Hopf / Bautin, l1 = 0), 'BT' (Bogdanov-Takens, omega -> 0),
    'ZH' (zero-Hopf, a real eigenvalue at 0), 'HH' (double Hopf, a second imaginary pair).
    """

    type: str
    values: tuple[float, float]
    frequency: float
    l2: float | None = None  # second Lyapunov coefficient (GH only)
    other_frequency: float | None = None  # the second frequency (HH only)
    converged: bool = True
    residual: float = 0.0
    note: str = ""


@dataclass(frozen=True)
class HopfCurve:
    """A branch of the Hopf curve in the plane of two parameters."""

    params: tuple[str, str]
    points: list[HopfCurvePoint]
    special_points: list[CodimTwoPoint]
    converged: bool
    message: str
    steps: int
    closed: bool = False  # the branch came back to its start
    warnings: tuple[str, ...] = ()

    def values(self) -> np.ndarray:
        """(n, 2) array of the two parameter values along the branch."""
        return np.array([pt.values for pt in self.points]).reshape(-1, 2)

    def l1(self) -> np.ndarray:
        return np.array([pt.l1 for pt in self.points])

    def frequency(self) -> np.ndarray:
        return np.array([pt.frequency for pt in self.points])


def _criticality(l1: float) -> str:
    if not math.isfinite(l1):
        return "unknown"
    if l1 > 0:
        return "subcritical"
    if l1 < 0:
        return "supercritical"
    return "degenerate"


# ----------------------------------------------------------------------------------------
# compiled kernels (cached per right-hand side, so nothing recompiles per call)
# ----------------------------------------------------------------------------------------
def _real_form(rhs, order: int):
    """The real symmetric k-linear form d^k f / dx^k [u1, ..., uk] by nested jvp."""

    def form(x, p, *us):
        def g(y, k):
            if k == 0:
                return rhs(y, p)
            return jax.jvp(lambda z: g(z, k - 1), (y,), (us[k - 1],))[1]

        return g(x, order)

    return form


@cache
def _real_forms(rhs) -> dict[int, Callable]:
    """Jitted real multilinear forms of orders 2..5 for ``rhs``, vmapped over batches of
    directions (one trace each; complex directions are expanded outside, which keeps the
    compile time small even at order 5)."""
    out = {}
    for k in (2, 3, 4, 5):
        axes = (None, None) + (0,) * k
        out[k] = jax.jit(jax.vmap(_real_form(rhs, k), in_axes=axes))
    return out


def _complex_form_eval(real_form, x, p, us) -> np.ndarray:
    """A real k-linear form at complex directions: all 2^k real/imag combinations in one
    batched call."""
    parts = [(np.real(u), np.imag(u)) for u in us]
    order = len(us)
    masks = [m for m in range(2**order)
             if all(parts[j][(m >> j) & 1].any() for j in range(order))]
    if not masks:
        return np.zeros(np.shape(us[0]), complex)
    args = [np.asarray(np.stack([parts[j][(m >> j) & 1] for m in masks]))
            for j in range(order)]
    vals = np.asarray(real_form(x, p, *args))
    coef = np.array([1j ** bin(m).count("1") for m in masks])
    return coef @ vals


def _l1_from_forms(rhs, x, p, J, omega, q, padj) -> float:
    """Kuznetsov's l1 (paper eq. 24) from batched real forms B and C (4 calls)."""
    F = _real_forms(rhs)
    xj, pj = np.asarray(x, np.float64), np.asarray(p, np.float64)
    a, b = np.real(q), np.imag(q)
    Baa, Bbb, Bab = np.asarray(F[2](xj, pj, np.asarray(np.stack([a, b, a])),
                                    np.asarray(np.stack([a, b, b]))))
    Caaa, Cabb, Caab, Cbbb = np.asarray(F[3](
        xj, pj, np.asarray(np.stack([a, a, a, b])), np.asarray(np.stack([a, b, a, b])),
        np.asarray(np.stack([a, b, b, b]))))
    n = len(a)
    h11 = -np.linalg.solve(J, Baa + Bbb)  # real
    h20 = np.linalg.solve(2j * omega * np.eye(n) - J, Baa - Bbb + 2j * Bab)
    hr, hi = h20.real, h20.imag
    Bs = np.asarray(F[2](xj, pj, np.asarray(np.stack([a, b, a, b, a, b])),
                         np.asarray(np.stack([h11, h11, hr, hi, hi, hr]))))
    Bq_h11 = Bs[0] + 1j * Bs[1]
    Bqb_h20 = Bs[2] + Bs[3] + 1j * (Bs[4] - Bs[5])
    Cqqqb = Caaa + Cabb + 1j * (Caab + Cbbb)
    g21 = np.vdot(padj, Cqqqb + 2.0 * Bq_h11 + Bqb_h20)
    return float(g21.real / (2.0 * omega))


@cache
def _defining_kernels(rhs, idx: tuple[int, ...]):
    """Hopf defining system G(z, p, c) and its Jacobian, with z = (x, v1, v2, omega,
    alpha[idx]); G has 3n + 2 components and z has 3n + 1 + len(idx)."""

    def G(z, p, c):
        n = c.shape[0]
        x, v1, v2 = z[:n], z[n : 2 * n], z[2 * n : 3 * n]
        om = z[3 * n]
        pp = p.at[jnp.array(idx)].set(z[3 * n + 1 :])

        def fp(y):
            return rhs(y, pp)

        fx, jv1 = jax.jvp(fp, (x,), (v1,))
        jv2 = jax.jvp(fp, (x,), (v2,))[1]
        return jnp.concatenate([
            fx, jv1 + om * v2, jv2 - om * v1, jnp.stack([c @ v1 - 1.0, c @ v2])
        ])

    DG = jax.jacfwd(G, argnums=0)
    return jax.jit(G), jax.jit(DG), jax.jit(lambda z, p, c: (G(z, p, c), DG(z, p, c)))


@cache
def _crossing_kernel(rhs):
    """d/ds [J(x + s dx, p + s dp) v] at s = 0 (real v)."""

    def dJv(x, p, v, dx, dp):
        def Jv(y, pp):
            return jax.jvp(lambda z: rhs(z, pp), (y,), (v,))[1]

        return jax.jvp(Jv, (x, p), (dx, dp))[1]

    return jax.jit(dJv)


# ----------------------------------------------------------------------------------------
# eigenvectors and Lyapunov coefficients
# ----------------------------------------------------------------------------------------
def _null_vector(M: np.ndarray) -> np.ndarray:
    """Unit vector spanning the (numerical) null space of a square matrix."""
    _, _, vh = scipy.linalg.svd(M)
    return np.conj(vh[-1])


def hopf_eigenvectors(J: np.ndarray, omega: float) -> tuple[np.ndarray, np.ndarray]:
    """Right and adjoint eigenvectors at a Hopf point.

    Returns (q, p) with J q = i omega q, J^T p = -i omega p, <q, q> = 1, <p, q> = 1
    (<a, b> = sum conj(a) b). The phase of q is fixed so that its largest component is real
    and positive.
    """
    n = J.shape[0]
    eye = np.eye(n)
    q = _null_vector(J - 1j * omega * eye)
    k = int(np.argmax(np.abs(q)))
    q = q * np.exp(-1j * np.angle(q[k]))
    q = q / np.linalg.norm(q)
    p = _null_vector(J.T + 1j * omega * eye)
    s = np.vdot(p, q)
    p = p / np.conj(s)
    return q, p


def first_lyapunov_coefficient(
    system: System,
    x: np.ndarray,
    p: np.ndarray | None,
    omega: float,
    q: np.ndarray | None = None,
    p_adj: np.ndarray | None = None,
) -> float:
    """First Lyapunov coefficient l1 at a Hopf point (paper eq. 24, Kuznetsov's projection).

    l1 = 1/(2 omega) Re[<p, C(q,q,qbar)> - 2 <p, B(q, J^-1 B(q,qbar))>
                        + <p, B(qbar, (2 i omega I - J)^-1 B(q,q))>]
    with <q, q> = 1 and <p, q> = 1; B and C exact by autodiff.

    Parameters
    ----------
    system : the ODE system.
    x : equilibrium state at the Hopf point.
    p : parameter vector (None: the system's).
    omega : the Hopf frequency (rad/s), eigenvalues +-i omega of J.
    q, p_adj : eigenvectors (computed when not given; they are renormalised here).

    Returns
    -------
    l1 (1/s with the normalisation above): > 0 subcritical, < 0 supercritical.
    """
    pv = system.p if p is None else np.asarray(p, float)
    x = np.asarray(x, float)
    J = np.asarray(system.derivatives.jacobian(x, pv))
    if q is None or p_adj is None:
        q, p_adj = hopf_eigenvectors(J, omega)
    else:
        q = np.asarray(q, complex) / np.linalg.norm(q)
        p_adj = np.asarray(p_adj, complex)
        p_adj = p_adj / np.conj(np.vdot(p_adj, q))
    return _l1_from_forms(system.rhs, x, pv, J, float(omega), q, p_adj)


def second_lyapunov_coefficient(
    system: System,
    x: np.ndarray,
    p: np.ndarray | None,
    omega: float,
    q: np.ndarray | None = None,
    p_adj: np.ndarray | None = None,
) -> tuple[float, float]:
    """Second Lyapunov coefficient l2 = Re G32 / (12 omega) at a generalised Hopf point.

    Kuznetsov 1999 (Numerical normalization techniques, eq. for the Bautin point), with
    derivatives of orders 2..5 exact by nested autodiff and the normalisation
    <q, q> = 1, <p, q> = 1. Only meaningful where l1 = 0.

    Returns (l1, l2) (both 1/s in the normalisation above).
    """
    pv = system.p if p is None else np.asarray(p, float)
    x = np.asarray(x, float)
    J = system.jacobian(x, pv)
    if q is None or p_adj is None:
        q, p_adj = hopf_eigenvectors(J, omega)
    F = _real_forms(system.rhs)
    xj, pj = np.asarray(x), np.asarray(pv)

    def form(k, *us):
        return _complex_form_eval(F[k], xj, pj, [np.asarray(u, complex) for u in us])

    def B(a, b):
        return form(2, a, b)

    def C(a, b, c):
        return form(3, a, b, c)

    def D(a, b, c, d):
        return form(4, a, b, c, d)

    def E(a, b, c, d, e):
        return form(5, a, b, c, d, e)

    n = J.shape[0]
    eye = np.eye(n)
    iw = 1j * omega
    qb = np.conj(q)
    h20 = np.linalg.solve(2 * iw * eye - J, B(q, q))
    h11 = -np.linalg.solve(J, B(q, qb))
    r21 = C(q, q, qb) + B(qb, h20) + 2 * B(q, h11)
    g21 = np.vdot(p_adj, r21)
    h30 = np.linalg.solve(3 * iw * eye - J, C(q, q, q) + 3 * B(q, h20))
    # h21: (i omega - J) h21 = r21 - G21 q, <p, h21> = 0 (bordered system)
    bord = np.zeros((n + 1, n + 1), complex)
    bord[:n, :n] = iw * eye - J
    bord[:n, n] = q
    bord[n, :n] = np.conj(p_adj)
    sol = np.linalg.solve(bord, np.concatenate([r21 - g21 * q, [0.0]]))
    h21 = sol[:n]
    h02, h12 = np.conj(h20), np.conj(h21)
    h31 = np.linalg.solve(
        2 * iw * eye - J,
        D(q, q, q, qb) + 3 * C(q, q, h11) + 3 * C(q, qb, h20) + 3 * B(h20, h11)
        + B(qb, h30) + 3 * B(q, h21) - 3 * g21 * h20,
    )
    h22 = -np.linalg.solve(
        J,
        D(q, q, qb, qb) + 4 * C(q, qb, h11) + C(qb, qb, h20) + C(q, q, h02)
        + 2 * B(h11, h11) + 2 * B(q, h12) + 2 * B(qb, h21) + B(h20, h02)
        - 2 * (g21 + np.conj(g21)) * h11,
    )
    r32 = (
        E(q, q, q, qb, qb) + D(q, q, q, h02) + 3 * D(q, qb, qb, h20) + 6 * D(q, q, qb, h11)
        + C(qb, qb, h30) + 3 * C(q, q, h12) + 6 * C(q, qb, h21) + 3 * C(q, h02, h20)
        + 6 * C(q, h11, h11) + 6 * C(qb, h20, h11) + 2 * B(qb, h31) + 3 * B(q, h22)
        + B(h02, h30) + 3 * B(h12, h20) + 6 * B(h11, h21)
    )
    g32 = np.vdot(p_adj, r32)
    return float(g21.real / (2 * omega)), float(g32.real / (12 * omega))


# ----------------------------------------------------------------------------------------
# Hopf points along one parameter
# ----------------------------------------------------------------------------------------
def _pack(x, v1, v2, omega, alphas) -> np.ndarray:
    return np.concatenate([x, v1, v2, [omega], np.atleast_1d(alphas)])


def _unpack(z: np.ndarray, n: int):
    return z[:n], z[n : 2 * n], z[2 * n : 3 * n], float(z[3 * n]), z[3 * n + 1 :]


def _normalise_pair(v1: np.ndarray, v2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotate q = v1 + i v2 by a phase so that v1 is orthogonal to v2, scale |v1| = 1."""
    q = v1 + 1j * v2
    # phase theta maximising |Re(e^{i theta} q)|: principal axis of the ellipse
    theta = -0.5 * np.angle(np.sum(q * q))
    q = q * np.exp(1j * theta)
    scale = np.linalg.norm(q.real)
    if scale == 0:
        scale = 1.0
    q = q / scale
    return q.real.copy(), q.imag.copy()


def _other_eigenvalues(w: np.ndarray, omega: float) -> np.ndarray:
    """The eigenvalues other than the pair closest to +-i omega."""
    if w.size < 2:
        return w[:0]
    k1 = int(np.argmin(np.abs(w - 1j * omega)))
    rest = np.delete(w, k1)
    k2 = int(np.argmin(np.abs(rest + 1j * omega)))
    return np.delete(rest, k2)


def refine_hopf_point(
    system: System,
    param: str,
    value: float,
    x: np.ndarray,
    omega: float,
    q: np.ndarray | None = None,
    p: np.ndarray | None = None,
    tol: float = 1e-11,
    max_iter: int = 30,
    value_scale: float | None = None,
    bounds: tuple[float, float] | None = None,
) -> HopfPoint:
    """Refine an approximate Hopf point by Newton's method on the defining system
    (x, v1, v2, omega, param), then compute eigenvectors, crossing speed and l1.

    A converged Newton iteration is validated before the point is called converged
    (Kuznetsov 2004, sec. 10.2.2: the defining system also has spurious solutions, e.g.
    neutral saddles, and Newton may run to a Hopf point of another, unphysical region):
    omega > 0, +-i omega is an eigenvalue pair of the Jacobian there (to 1e-6 relative),
    and the parameter lies inside ``bounds``. Otherwise ``converged`` is False and the
    reason is the point's ``message`` (and a warning).

    Parameters
    ----------
    value, x, omega : initial guesses (parameter value, equilibrium state, frequency rad/s).
    q : guess of the complex eigenvector (computed from J when not given).
    value_scale : typical size of ``param`` for the convergence test (default |value|).
    bounds : (lo, hi) of ``param``, the search interval (None: not checked); the
        system's ``param_ranges`` (valid range) is checked too.
    """
    base = system.p if p is None else np.asarray(p, float)
    k = system.param_index(param)
    n = system.dim
    pk = system.params_with(base, **{param: value})
    warnings: list[str] = []
    if q is None:
        w, V = np.linalg.eig(system.jacobian(x, pk))
        j = int(np.argmin(np.abs(w - 1j * omega)))
        q = V[:, j]
    v1, v2 = _normalise_pair(np.real(q), np.imag(q))
    c = v1.copy()
    z = _pack(np.asarray(x, float), v1, v2, omega, [value])
    G, DG, _ = _defining_kernels(system.rhs, (k,))
    pj = np.asarray(base)
    cj = np.asarray(c)
    scale = _z_scale(system, omega, [value_scale or abs(value) or 1.0])
    converged = False
    res = np.inf
    n_iter = 0
    for n_iter in range(1, max_iter + 1):  # noqa: B007 (n_iter reported below)
        g = np.asarray(G(np.asarray(z), pj, cj))
        A = np.asarray(DG(np.asarray(z), pj, cj))
        try:
            dz = -np.linalg.solve(A, g)
        except np.linalg.LinAlgError:
            warnings.append("singular Hopf defining system (degenerate Hopf point?)")
            break
        if not np.all(np.isfinite(dz)):
            warnings.append("non-finite Newton step")
            break
        z = z + dz
        step = float(np.max(np.abs(dz) / scale))
        # converged on a small step, or on a residual at round-off level after a small step
        # (the step may stall slightly above tol when the unknowns are far from unit scale)
        if step < tol:
            converged = True
            break
        if step < 1e-6:
            g_new = np.asarray(G(np.asarray(z), pj, cj))
            if np.max(np.abs(g_new[n:])) < 1e-13 * max(1.0, abs(omega)) and np.max(
                    np.abs(g_new[:n]) / (np.abs(A[:n, :n]) @ system.state_scale + 1e-300)
            ) < 1e-13:
                converged = True
                break
    g = np.asarray(G(np.asarray(z), pj, cj))
    res = float(np.max(np.abs(g[:n]) / (np.abs(np.asarray(system.jacobian(z[:n],
                system.params_with(base, **{param: float(z[-1])}))))
                @ system.state_scale + 1e-300)))
    res = max(res, float(np.max(np.abs(g[n:]) / (abs(z[3 * n]) + 1.0))))
    if not converged:
        warnings.append(f"Newton on the Hopf defining system did not converge in {n_iter} steps")
    xs, v1, v2, om, al = _unpack(z, n)
    if om < 0:
        om, v2 = -om, -v2
    val = float(al[0])
    pv = system.params_with(base, **{param: val})
    message = ""
    if converged:
        message = _hopf_validation(system, param, val, xs, pv, om, omega, bounds)
        if message:
            converged = False
            warnings.append(f"not a valid Hopf point: {message}")
    else:
        message = f"Newton on the Hopf defining system did not converge in {n_iter} steps"
    hp = _hopf_point_at(system, param, val, xs, pv, om, converged, res, warnings)
    return dataclasses.replace(hp, message=message) if message else hp


def _hopf_validation(system, param, val, xs, pv, om, omega_guess, bounds) -> str:
    """Why a solution of the defining system is not an acceptable Hopf point ('' if it is)."""
    if not (np.all(np.isfinite(xs)) and math.isfinite(val) and math.isfinite(om)):
        return "non-finite solution"
    if not om > 1e-8 * max(1.0, abs(omega_guess)):
        return f"frequency omega = {om:.3g} rad/s is not positive (Bogdanov-Takens?)"
    w = np.linalg.eigvals(system.jacobian(xs, pv))
    dist = float(np.min(np.abs(w - 1j * om)))
    if dist > 1e-6 * max(1.0, om):
        return (f"+-i {om:.6g} is not an eigenvalue pair of the Jacobian (nearest "
                f"eigenvalue {dist:.2e} away)")
    for rng, what in ((bounds, "the search bounds"),
                      (system.param_ranges.get(param), "its valid range")):
        if rng is None:
            continue
        lo, hi = sorted(map(float, rng))
        slack = 1e-12 * max(1.0, abs(lo) if math.isfinite(lo) else 1.0,
                            abs(hi) if math.isfinite(hi) else 1.0)
        if not lo - slack <= val <= hi + slack:
            return f"{param} = {val:.8g} lies outside [{lo:g}, {hi:g}] ({what})"
    return ""


def _hopf_point_at(system, param, val, xs, pv, om, converged, res, warnings) -> HopfPoint:
    J = system.jacobian(xs, pv)
    q, padj = hopf_eigenvectors(J, om)
    # crossing speed: d lambda / d alpha = <p, (dJ/dalpha along the equilibrium branch) q>
    fa = system.param_derivative(xs, pv, param)
    try:
        dx = -np.linalg.solve(J, fa)
    except np.linalg.LinAlgError:
        dx = np.zeros_like(xs)
        warnings.append("singular Jacobian: crossing speed ignores the equilibrium's drift")
    dp = np.zeros_like(pv)
    dp[system.param_index(param)] = 1.0
    kern = _crossing_kernel(system.rhs)
    args = (np.asarray(xs), np.asarray(pv))
    dJq = (np.asarray(kern(*args, np.asarray(q.real), np.asarray(dx), np.asarray(dp)))
           + 1j * np.asarray(kern(*args, np.asarray(q.imag), np.asarray(dx),
                                  np.asarray(dp))))
    speed = float(np.real(np.vdot(padj, dJq)))
    l1 = first_lyapunov_coefficient(system, xs, pv, om, q, padj)
    w = np.linalg.eigvals(J)
    others = _other_eigenvalues(w, om)
    others_stable = bool(np.all(others.real < 0))
    if abs(speed) < 1e-12 * max(1.0, om):
        warnings.append("crossing speed is zero: the transversality condition fails")
    return HopfPoint(
        param=param, value=val, x=np.asarray(xs), p=np.asarray(pv), frequency=float(om),
        q=q, p_adj=padj, crossing_speed=speed, l1=float(l1), others_stable=others_stable,
        converged=bool(converged), residual=float(res), warnings=tuple(warnings),
    )


def _z_scale(system: System, omega: float, alpha_scales) -> np.ndarray:
    n = system.dim
    return np.concatenate([
        system.state_scale, np.ones(2 * n), [max(abs(omega), 1.0)], np.asarray(alpha_scales)
    ])


def locate_hopf_points(
    system: System,
    param: str,
    start: float,
    stop: float,
    p: np.ndarray | None = None,
    n_scan: int = 200,
    progress: Callable[[int, int], None] | None = None,
) -> HopfScan:
    """Hopf points of the equilibrium as ``param`` runs from ``start`` to ``stop``.

    The equilibrium is followed by pseudo-arclength continuation
    (:func:`~maglev_match.dynamics.equilibria.equilibrium_branch`, through folds, so every
    part of an S-shaped equilibrium curve is visited), sampled at least as finely as
    ``n_scan`` values; the Hopf test function (bialternate product) is located by solving
    inside its step, then each point is refined to full precision by Newton's method on
    the Hopf defining system (x, v1, v2, omega, param) and validated
    (:func:`refine_hopf_point`). ``scan_values`` and ``max_real_part`` are the branch's
    parameter values and largest real parts, in branch order.
    """
    from maglev_match.dynamics.continuation import SpecialPointKind
    from maglev_match.dynamics.equilibria import equilibrium_branch

    base = system.p if p is None else np.asarray(p, float)
    branch = equilibrium_branch(system, param, start, stop, p=base, n_points=int(n_scan),
                                progress=progress)
    warnings = list(branch.warnings)
    lo, hi = sorted((float(start), float(stop)))
    points: list[HopfPoint] = []
    for sp in branch.special_points:
        if sp.type != SpecialPointKind.HOPF:
            continue
        hp = refine_hopf_point(system, param, sp.value, sp.x, sp.frequency, p=base,
                               value_scale=max(abs(sp.value), hi - lo), bounds=(lo, hi))
        if sp.located != "solved":
            hp = _with_warning(hp, f"Hopf test function {sp.located}")
        if any(abs(hp.value - o.value) <= 1e-9 * max(1.0, abs(o.value))
               and abs(hp.frequency - o.frequency) <= 1e-6 * o.frequency for o in points):
            continue
        points.append(hp)
    points.sort(key=lambda h: h.value)
    return HopfScan(param=param, start=float(start), stop=float(stop), points=points,
                    scan_values=branch.values, max_real_part=branch.max_real_part,
                    warnings=tuple(warnings), special_points=branch.special_points)


def _with_warning(hp: HopfPoint, msg: str) -> HopfPoint:
    return dataclasses.replace(hp, warnings=hp.warnings + (msg,))


# ----------------------------------------------------------------------------------------
# the two-parameter Hopf curve
# ----------------------------------------------------------------------------------------
@dataclass
class _Branch:
    """Working state of one direction of the continuation."""

    zs: list  # accepted points (unscaled z, each with its own normalisation vector)
    cs: list  # normalisation vectors c
    info: list  # (l1, n_pos_real_others, n_pos_complex_others, others_stable)
    message: str = ""
    ok: bool = True
    closed: bool = False
    bt: bool = False


def _reference_c(v1: np.ndarray) -> np.ndarray:
    return v1 / float(v1 @ v1)


def _renormalise(z: np.ndarray, n: int, c: np.ndarray) -> np.ndarray:
    """Re-express the eigenvector part of z for the normalisation <c, v1> = 1, <c, v2> = 0."""
    x, v1, v2, om, al = _unpack(z, n)
    q = v1 + 1j * v2
    q = q / (c @ q)
    return _pack(x, q.real, q.imag, om, al)


class _HopfCurveSolver:
    """Pseudo-arclength continuation of the standard Hopf defining system."""

    def __init__(self, system: System, params: tuple[str, str], base: np.ndarray,
                 bounds: dict[str, tuple[float, float]], omega0: float, tol: float):
        self.system = system
        self.n = system.dim
        self.idx = tuple(system.param_index(k) for k in params)
        self.params = params
        self.base = base
        self.bounds = [tuple(map(float, bounds[k])) for k in params]
        ranges = [abs(b - a) for a, b in self.bounds]
        self.S = _z_scale(system, omega0, ranges)
        self.G, self.DG, self.GDG = _defining_kernels(system.rhs, self.idx)
        self.pj = np.asarray(base)
        self.jac = system.derivatives.jacobian
        self.tol = tol

    # --- basic pieces ---
    def residual_and_jac(self, u: np.ndarray, c: np.ndarray):
        z = u * self.S
        g, A = self.GDG(z, self.pj, np.asarray(c))
        return np.asarray(g), np.asarray(A) * self.S[None, :]

    def tangent(self, u: np.ndarray, c: np.ndarray, orient: np.ndarray | None,
                A: np.ndarray | None = None) -> np.ndarray:
        """Unit tangent of the curve in scaled variables (oriented along ``orient``);
        ``A`` is the scaled Jacobian of the defining system if already known."""
        if A is None:
            _, A = self.residual_and_jac(u, c)
        if orient is None:
            _, _, vh = np.linalg.svd(A)
            t = vh[-1]
        else:
            M = np.vstack([A, orient[None, :]])
            rhs = np.zeros(A.shape[0] + 1)
            rhs[-1] = 1.0
            try:
                t = np.linalg.solve(M, rhs)
            except np.linalg.LinAlgError:
                _, _, vh = np.linalg.svd(A)
                t = vh[-1]
                if t @ orient < 0:
                    t = -t
        return t / np.linalg.norm(t)

    def correct(self, u_pred: np.ndarray, c: np.ndarray, row: np.ndarray, target: float,
                max_iter: int = 10) -> tuple[np.ndarray | None, int]:
        """Newton on [G(u) = 0; row . u = target]; returns (u, iterations) or (None, k)."""
        u = u_pred.copy()
        for k in range(1, max_iter + 1):
            g, A = self.residual_and_jac(u, c)
            self.last_jacobian = A
            H = np.concatenate([g, [row @ u - target]])
            M = np.vstack([A, row[None, :]])
            try:
                du = -np.linalg.solve(M, H)
            except np.linalg.LinAlgError:
                return None, k
            if not np.all(np.isfinite(du)):
                return None, k
            u = u + du
            if np.max(np.abs(du)) < self.tol:
                return u, k
        return None, max_iter

    def point_info(self, z: np.ndarray) -> tuple[float, int, int, bool, np.ndarray]:
        """l1, the numbers of other real / complex eigenvalues with Re > 0, others_stable,
        and the sorted other eigenvalues."""
        n = self.n
        x, _, _, om, al = _unpack(z, n)
        pv = self.full_p(al)
        J = np.asarray(self.jac(x, pv))
        w = np.linalg.eigvals(J)
        others = _other_eigenvalues(w, abs(om))
        others = others[np.lexsort((-np.abs(others.imag), -others.real))]
        if om > 0:
            q = z[n : 2 * n] + 1j * z[2 * n : 3 * n]
            q = q / np.linalg.norm(q)
            padj = _null_vector(J.T + 1j * om * np.eye(n))
            padj = padj / np.conj(np.vdot(padj, q))
            l1 = _l1_from_forms(self.system.rhs, x, pv, J, om, q, padj)
        else:
            l1 = float("nan")
        imag_tol = 1e-7 * max(1.0, abs(om))
        pos = others.real > 0
        n_real = int(np.sum(pos & (np.abs(others.imag) <= imag_tol)))
        n_cplx = int(np.sum(pos & (np.abs(others.imag) > imag_tol)))
        return l1, n_real, n_cplx, bool(np.all(others.real < 0)), others

    def full_p(self, al) -> np.ndarray:
        pv = self.base.copy()
        pv[list(self.idx)] = al
        return pv

    def in_bounds(self, z: np.ndarray) -> int:
        """-1 if inside the bounds, else the index of a violated parameter."""
        al = z[3 * self.n + 1 :]
        for k, (a, b) in enumerate(self.bounds):
            lo, hi = min(a, b), max(a, b)
            if not lo <= al[k] <= hi:
                return k
        return -1

    # --- one direction ---
    def run(self, z0: np.ndarray, c0: np.ndarray, t0: np.ndarray, h0: float, h_max: float,
            h_min: float, max_steps: int, progress) -> _Branch:
        n = self.n
        br = _Branch(zs=[z0], cs=[c0], info=[self.point_info(z0)[:4]])
        u, c, t, h = z0 / self.S, c0, t0, h0
        u_start = u.copy()
        inv = np.ones_like(t)
        inv[n : 3 * n] = 0.0  # orientation uses only the normalisation-free components
        for step in range(max_steps):
            u_pred = u + h * t
            u_new, its = self.correct(u_pred, c, t, t @ u_pred)
            if u_new is not None:
                jump = np.linalg.norm((u_new - u) * inv)
                if jump > 3.0 * h:  # jumped to another branch
                    u_new = None
            if u_new is None:
                h *= 0.5
                if h < h_min:
                    br.ok = False
                    br.message = (f"step size fell below {h_min:g} at "
                                  f"{self._where(u * self.S)} (corrector failed)")
                    break
                continue
            z_new = u_new * self.S
            k_out = self.in_bounds(z_new)
            if k_out >= 0:
                z_b = self.land_on_bound(u, u_new, c, k_out)
                if z_b is not None:
                    self.accept(br, z_b, c)
                br.message = f"reached the bound of {self.params[k_out]}"
                break
            om = z_new[3 * n]
            if om <= 1e-6 * abs(self.S[3 * n]):
                br.bt = True
                br.message = "frequency fell to zero (Bogdanov-Takens or neutral saddle)"
                self.accept(br, z_new, c)
                break
            A_last = self.last_jacobian
            c_new = self.accept(br, z_new, c)
            u_prev, u = u, br.zs[-1] / self.S
            # the corrector's last Jacobian serves for the tangent unless the eigenvector
            # normalisation was renewed
            t = self.tangent(u, c_new, t * inv, None if c_new is not c else A_last)
            c = c_new
            if its <= 3:
                h = min(h * 1.5, h_max)
            elif its >= 6:
                h = max(h * 0.6, h_min)
            if step > 10 and np.linalg.norm((u - u_start) * inv) < 0.5 * h and \
                    np.linalg.norm((u_prev - u_start) * inv) >= np.linalg.norm(
                        (u - u_start) * inv):
                br.closed = True
                br.message = "the curve closed on itself"
                break
            if progress is not None:
                progress(len(br.zs))
        else:
            br.ok = False
            br.message = f"stopped after max_steps = {max_steps}"
        return br

    def accept(self, br: _Branch, z: np.ndarray, c: np.ndarray) -> np.ndarray:
        """Store a point; renew the normalisation <c, v1> = 1, <c, v2> = 0 when the
        eigenvector has drifted far from c (returns the c in force, ``c`` itself if kept)."""
        n = self.n
        x, v1, v2, om, al = _unpack(z, n)
        c_new = c
        if max(np.linalg.norm(v1), np.linalg.norm(v2)) > 2.0 / np.linalg.norm(c):
            v1, v2 = _normalise_pair(v1, v2)
            c_new = v1.copy()
        br.zs.append(_pack(x, v1, v2, om, al))
        br.cs.append(c_new)
        br.info.append(self.point_info(br.zs[-1])[:4])
        return c_new

    def land_on_bound(self, u_a, u_b, c, k) -> np.ndarray | None:
        n = self.n
        j = 3 * n + 1 + k
        a, b = self.bounds[k]
        za, zb = u_a * self.S, u_b * self.S
        bound = a if abs(zb[j] - a) < abs(zb[j] - b) else b
        frac = (bound - za[j]) / (zb[j] - za[j])
        u_pred = u_a + frac * (u_b - u_a)
        row = np.zeros_like(u_a)
        row[j] = 1.0
        u, _ = self.correct(u_pred, c, row, bound / self.S[j])
        return None if u is None else u * self.S

    def _where(self, z: np.ndarray) -> str:
        al = z[3 * self.n + 1 :]
        return ", ".join(f"{k} = {v:.6g}" for k, v in zip(self.params, al, strict=True))

    # --- codimension-two points between two accepted points ---
    def locate(self, za, ca, zb, fn) -> tuple[np.ndarray | None, float]:
        """Solve fn(z(theta)) = 0 on the curve between za and zb (theta in [0, 1])."""
        n = self.n
        zb = _renormalise(zb, n, ca)
        ua, ub = za / self.S, zb / self.S
        d = ub - ua
        dn = d / np.linalg.norm(d)
        cache: dict[float, np.ndarray] = {}

        def point(theta: float) -> np.ndarray | None:
            if theta in cache:
                return cache[theta]
            u_pred = ua + theta * d
            u, _ = self.correct(u_pred, ca, dn, dn @ u_pred, max_iter=20)
            z = None if u is None else u * self.S
            cache[theta] = z
            return z

        def g(theta: float) -> float:
            z = point(theta)
            if z is None:
                raise RuntimeError("corrector failed")
            return fn(z)

        try:
            ga, gb = g(0.0), g(1.0)
            if not (np.isfinite(ga) and np.isfinite(gb)) or ga * gb > 0:
                return None, np.nan
            theta = scipy.optimize.brentq(g, 0.0, 1.0, xtol=1e-14, rtol=1e-14, maxiter=200)
        except (RuntimeError, ValueError):
            return None, np.nan
        z = point(theta)
        return z, abs(g(theta))


def hopf_curve(
    system: System,
    params: tuple[str, str],
    start: HopfPoint,
    bounds: dict[str, tuple[float, float]],
    p: np.ndarray | None = None,
    initial_step: float = 2e-3,
    max_step: float = 1e-2,
    min_step: float = 1e-9,
    max_steps: int = 5000,
    tol: float = 1e-10,
    both_directions: bool = True,
    detect_special_points: bool = True,
    progress: Callable[[int], None] | None = None,
) -> HopfCurve:
    """Continue a Hopf point in two parameters: the Hopf curve (SPEC.md 6.2, paper Fig. 4).

    Pseudo-arclength continuation of the standard defining system
    f(x, alpha) = 0, J v1 + omega v2 = 0, J v2 - omega v1 = 0, <c, v1> = 1, <c, v2> = 0
    in scaled variables (states by ``system.state_scale``, parameters by the width of their
    bounds), so turning points in either parameter are passed. Along the curve: l1 at every
    point; generalised Hopf points (l1 = 0) located by solving l1(s) = 0 along the curve
    with l2 there; zero-Hopf (a real eigenvalue crosses 0) and double-Hopf (a second pair
    crosses the imaginary axis) points located by solving for the crossing eigenvalue's real
    part = 0; Bogdanov-Takens when the frequency falls to zero.

    Parameters
    ----------
    params : the two free parameter names; ``start.param`` must be one of them.
    start : a Hopf point (from :func:`locate_hopf_points`).
    bounds : {name: (lo, hi)} for both parameters; the branch stops on them.
    initial_step, max_step, min_step : arclength steps in scaled units (1 = the width of
        the bounds of a parameter).
    both_directions : continue both ways from ``start``.

    Returns
    -------
    :class:`HopfCurve`: points ordered along the branch, special points, diagnostics.
    A stalled continuation is reported (``converged`` False, ``message``), never raised.
    """
    if start.param not in params:
        raise ValueError(f"start point is along '{start.param}', not one of {params}")
    for k in params:
        if k not in bounds:
            raise ValueError(f"no bounds given for parameter '{k}'")
    base = np.array(start.p if p is None else p, float)
    base[system.param_index(start.param)] = start.value
    n = system.dim
    solver = _HopfCurveSolver(system, tuple(params), base, bounds, start.frequency, tol)
    v1, v2 = _normalise_pair(start.q.real, start.q.imag)
    c0 = v1.copy()
    al0 = base[list(solver.idx)]
    z0 = _pack(start.x, v1, v2, start.frequency, al0)
    warnings: list[str] = []
    # make the start point exact for this normalisation
    u0, _ = solver.correct(z0 / solver.S, c0, np.zeros_like(z0), 0.0)
    if u0 is not None:
        z0 = u0 * solver.S
    if solver.in_bounds(z0) >= 0:
        return HopfCurve(params=tuple(params), points=[], special_points=[], converged=False,
                         message="the start point lies outside the bounds", steps=0)
    t0 = solver.tangent(z0 / solver.S, c0, None)
    branches = [solver.run(z0, c0, t0, initial_step, max_step, min_step, max_steps,
                           progress)]
    if both_directions and not branches[0].closed:
        branches.append(solver.run(z0, c0, -t0, initial_step, max_step, min_step,
                                   max_steps, progress))
    # assemble in order: reversed second direction, then the first
    zs, cs, info = list(branches[0].zs), list(branches[0].cs), list(branches[0].info)
    if len(branches) > 1:
        b = branches[1]
        zs = b.zs[:0:-1] + zs
        cs = b.cs[:0:-1] + cs
        info = b.info[:0:-1] + info
    special: list[CodimTwoPoint] = []
    if detect_special_points:
        special = _special_points(solver, zs, cs, info, warnings)
    for br in branches:
        if br.bt:
            z = br.zs[-1]
            al = z[3 * n + 1 :]
            special.append(CodimTwoPoint(
                type="BT", values=(float(al[0]), float(al[1])), frequency=float(z[3 * n]),
                converged=False, note="frequency fell to zero; located to the last step"))
    pts = []
    for z, inf in zip(zs, info, strict=True):
        x, _, _, om, al = _unpack(z, n)
        pts.append(HopfCurvePoint(values=(float(al[0]), float(al[1])), x=x, frequency=om,
                                  l1=inf[0], others_stable=inf[3],
                                  n_unstable_others=inf[1] + inf[2]))
    ok = all(br.ok for br in branches)
    message = "; ".join(f"direction {k + 1}: {br.message}" for k, br in enumerate(branches))
    return HopfCurve(params=tuple(params), points=pts, special_points=special, converged=ok,
                     message=message, steps=len(pts) - 1,
                     closed=any(br.closed for br in branches), warnings=tuple(warnings))


def _special_points(solver: _HopfCurveSolver, zs, cs, info, warnings) -> list[CodimTwoPoint]:
    n = solver.n
    out: list[CodimTwoPoint] = []
    for j in range(len(zs) - 1):
        (la, ra, ca_, _), (lb, rb, cb, _) = info[j], info[j + 1]
        za, zb = zs[j], zs[j + 1]
        if np.isfinite(la) and np.isfinite(lb) and la * lb < 0:
            z, res = solver.locate(za, cs[j], zb, lambda z: solver.point_info(z)[0])
            if z is None:
                warnings.append(f"could not locate the l1 = 0 point between steps {j} and "
                                f"{j + 1}")
                z, res = za if abs(la) < abs(lb) else zb, np.nan
                conv = False
            else:
                conv = True
            x, _, _, om, al = _unpack(z, n)
            try:
                _, l2 = second_lyapunov_coefficient(solver.system, x, solver.full_p(al), om)
            except np.linalg.LinAlgError:
                l2 = float("nan")
            out.append(CodimTwoPoint(type="GH", values=(float(al[0]), float(al[1])),
                                     frequency=om, l2=l2, converged=conv,
                                     residual=float(res)))
        ka, kb = ra + ca_, rb + cb
        if ka != kb:
            k = min(ka, kb)

            def crossing(z, k=k):
                return float(solver.point_info(z)[4][k].real)

            z, res = solver.locate(za, cs[j], zb, crossing)
            conv = z is not None
            if z is None:
                warnings.append(f"could not locate the eigenvalue crossing between steps {j}"
                                f" and {j + 1}")
                z = za
            x, _, _, om, al = _unpack(z, n)
            ev = solver.point_info(z)[4][k]
            imag_tol = 1e-6 * max(1.0, om)
            kind = "ZH" if abs(ev.imag) <= imag_tol or (ra != rb and ca_ == cb) else "HH"
            out.append(CodimTwoPoint(
                type=kind, values=(float(al[0]), float(al[1])), frequency=om,
                other_frequency=float(abs(ev.imag)) if kind == "HH" else None,
                converged=conv, residual=float(res) if conv else float("nan")))
    return out


# ----------------------------------------------------------------------------------------
# stability on a grid (independent check of the Hopf curve, shading of regions S/U)
# ----------------------------------------------------------------------------------------
@cache
def _newton_batch(rhs, n_iter: int = 12):
    jac = jax.jacfwd(rhs, argnums=0)

    def solve(x0, p):
        def body(x, _):
            return x - jnp.linalg.solve(jac(x, p), rhs(x, p)), None

        x, _ = jax.lax.scan(body, x0, None, length=n_iter)
        return x, rhs(x, p), jac(x, p)

    return jax.jit(jax.vmap(solve, in_axes=(None, 0)))


def stability_grid(
    system: System,
    params: tuple[str, str],
    values1: np.ndarray,
    values2: np.ndarray,
    p: np.ndarray | None = None,
    x0: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Largest real part of the Jacobian's eigenvalues at the equilibrium on a grid.

    Equilibria by a batched (vmapped) Newton iteration from ``x0`` (default the system's
    guess). Returns (max_real_part, converged), both shaped (len(values2), len(values1));
    max_real_part in 1/s, NaN where Newton did not converge.
    """
    base = system.p if p is None else np.asarray(p, float)
    i1, i2 = system.param_index(params[0]), system.param_index(params[1])
    V1, V2 = np.meshgrid(np.asarray(values1, float), np.asarray(values2, float))
    P = np.repeat(base[None, :], V1.size, axis=0)
    P[:, i1] = V1.ravel()
    P[:, i2] = V2.ravel()
    x_start = system.x_guess if x0 is None else np.asarray(x0, float)
    xs, fs, Js = _newton_batch(system.rhs)(jnp.asarray(x_start), jnp.asarray(P))
    xs, fs, Js = np.asarray(xs), np.asarray(fs), np.asarray(Js)
    denom = np.abs(Js) @ system.state_scale
    scaled = np.max(np.abs(fs) / np.where(denom > 0, denom, 1.0), axis=1)
    ok = np.isfinite(scaled) & (scaled < 1e-8)
    mr = np.full(V1.size, np.nan)
    good = np.where(ok)[0]
    if good.size:
        mr[good] = np.linalg.eigvals(Js[good]).real.max(axis=1)
    return mr.reshape(V1.shape), ok.reshape(V1.shape)
