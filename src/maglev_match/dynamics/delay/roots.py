"""Characteristic roots of a delay system at an equilibrium: the characteristic matrix, the
Jacobian of the discretised system built from the linearisation, and the rightmost roots,
corrected by Newton's method and checked against a finer discretisation.

**Characteristic roots** (:func:`characteristic_roots`). Linearised at an equilibrium,
x' = A_0 x(t) + sum_k A_k x(t - tau_k), with A_0 = df/dx and A_k = (df/dy_k)(dg_k/dx); the
characteristic matrix is Delta(lambda) = lambda I - A_0 - sum_k A_k exp(-lambda tau_k).
The eigenvalues of the discretised system's Jacobian approximate the rightmost roots of
det Delta = 0 with an error that falls exponentially in N (the eigenfunction
exp(lambda theta) on the interval is resolved when N >> |lambda| tau / 2; Breda, Maset &
Vermiglio 2005, SIAM J. Sci. Comput. 27:482); each approximation is then corrected by
Newton's method on the exact equations Delta(lambda) v = 0, c^H v = 1 (as DDE-BIFTOOL does;
Engelborghs, Luzyanina & Roose 2002, ACM TOMS 28:1). A root is *trusted* when Newton's
method, started from its approximations with N and with a larger N (both within
``APPROX_TOL``), converges to the same root (to ``TRUST_TOL``), and the larger N shows no
further root to its right; the trusted roots are the leading ones (by real part) up to the
first one that fails. (For tiny delays, tau |lambda| < 1e-5 or so, the discretised matrix
has entries ~ N^2 / tau and its eigenvalues carry round-off far above the spectral error;
the Newton correction removes it.)
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import cache

import jax
import jax.numpy as jnp
import numpy as np

from maglev_match.core import jax_setup  # noqa: F401  (float64 on)
from maglev_match.core.reprs import compact_repr
from maglev_match.dynamics.delay.discretisation import NODES_MAX, chebyshev_nodes, nodes_for
from maglev_match.dynamics.delay.system import DelayDifferentialSystem
from maglev_match.dynamics.normal_forms import null_vector

__all__ = [
    "TRUST_TOL",
    "APPROX_TOL",
    "CharacteristicRoots",
    "characteristic_matrix",
    "characteristic_derivative",
    "signal_factors",
    "discretised_matrix",
    "characteristic_roots",
    "refine_characteristic_root",
    "rightmost_first",
]

#: a characteristic root is trusted when Newton's method on the exact characteristic
#: equation, started from its approximations with N and with a larger N, converges from both
#: to the same root, to this relative to max(1, |lambda|) ...
TRUST_TOL = 1e-10
#: ... from approximations no further than this (relative) from it
APPROX_TOL = 1e-2


# ---------------------------------------------------------------------------------------
# characteristic roots
# ---------------------------------------------------------------------------------------
def characteristic_matrix(A0: np.ndarray, As: Sequence[np.ndarray], taus: Sequence[float],
                          lam: complex) -> np.ndarray:
    """Delta(lambda) = lambda I - A_0 - sum_k A_k exp(-lambda tau_k)."""
    M = lam * np.eye(A0.shape[0]) - A0
    for A, t in zip(As, taus, strict=True):
        M = M - A * np.exp(-lam * t)
    return M


def characteristic_derivative(A0, As, taus, lam) -> np.ndarray:
    """Delta'(lambda) = I + sum_k tau_k A_k exp(-lambda tau_k)."""
    M = np.eye(A0.shape[0], dtype=complex)
    for A, t in zip(As, taus, strict=True):
        M = M + t * A * np.exp(-lam * t)
    return M


@cache
def _factor_kernel(rhs: Callable, signals: tuple[Callable, ...]) -> Callable:
    """Jitted (A0, (R_k), (G_k)) at (x, p) for one delay model (compiled once)."""

    def factors(x, p):
        ys = tuple(jnp.reshape(g(x, p), (-1,)) for g in signals)
        A0 = jax.jacfwd(lambda z: rhs(z, ys, p))(x)
        R = jax.jacfwd(lambda yy: rhs(x, yy, p))(ys)
        G = tuple(jax.jacfwd(lambda z, g=g: jnp.reshape(g(z, p), (-1,)))(x) for g in signals)
        return A0, tuple(R), G

    return jax.jit(factors)


def signal_factors(dde: DelayDifferentialSystem, x: np.ndarray, p: np.ndarray):
    """(A0, R_k, G_k): df/dx, df/dy_k (n x m_k) and dg_k/dx (m_k x n) at the equilibrium."""
    n = dde.dim
    A0, R, G = _factor_kernel(dde.rhs, dde.signals)(jnp.asarray(x, jnp.float64),
                                                    jnp.asarray(p, jnp.float64))
    return (np.asarray(A0), [np.asarray(r).reshape(n, -1) for r in R],
            [np.asarray(g).reshape(-1, n) for g in G])


def discretised_matrix(A0: np.ndarray, R: Sequence[np.ndarray], G: Sequence[np.ndarray],
                       taus: Sequence[float], nodes: int) -> np.ndarray:
    """The Jacobian of the discretised system at an equilibrium, built from the
    linearisation x' = A_0 x + sum_k R_k y_k(t - tau_k), y_k = G_k x (equal to the
    autodiff Jacobian of :func:`discretise`'s right-hand side; no compilation per N)."""
    n = A0.shape[0]
    sizes = [Gk.shape[0] for Gk in G]
    dim = n + nodes * sum(sizes)
    M = np.zeros((dim, dim))
    M[:n, :n] = A0
    _, D = chebyshev_nodes(nodes)
    off = n
    for Rk, Gk, t, m in zip(R, G, taus, sizes, strict=True):
        M[:n, off + (nodes - 1) * m: off + nodes * m] += Rk
        Dt = D / t
        block = np.kron(Dt[1:, 1:], np.eye(m))
        M[off: off + nodes * m, off: off + nodes * m] = block
        M[off: off + nodes * m, :n] = np.kron(Dt[1:, :1], Gk)
        off += nodes * m
    return M


@dataclass(frozen=True)
class CharacteristicRoots:
    """The rightmost characteristic roots of a delay system at an equilibrium.

    roots : the Newton-corrected roots (1/s), largest real part first; entries after
        ``trusted`` are the discretisation's approximations (not trusted).
    approximations : eigenvalues of the discretised Jacobian with ``nodes`` intervals
        (same order); check : the matching ones with ``check_nodes`` intervals.
    trusted : how many leading roots are trusted (module docstring, TRUST_TOL).
    residuals : |Delta(lambda) v| / (|lambda| + ||A||) of each corrected root.
    """

    __repr__ = compact_repr

    roots: np.ndarray
    approximations: np.ndarray
    check: np.ndarray
    nodes: int
    check_nodes: int
    trusted: int
    residuals: np.ndarray
    max_real_part: float

    @property
    def stable(self) -> bool | None:
        """True/False when the rightmost root is trusted; None otherwise."""
        if self.trusted == 0:
            return None
        return bool(self.max_real_part < 0)


def refine_characteristic_root(A0: np.ndarray, As: Sequence[np.ndarray],
                               taus: Sequence[float], lam: complex,
                               v: np.ndarray | None = None, tol: float = 1e-14,
                               max_iter: int = 30) -> tuple[complex, np.ndarray, float, bool]:
    """Newton's method on Delta(lambda) v = 0, c^H v = 1 from ``lam`` (and ``v``).

    Returns (lambda, v with |v| = 1, residual |Delta(lambda) v| / (|lambda| + ||A||),
    converged)."""
    n = A0.shape[0]
    lam = complex(lam)
    if v is None:
        v = null_vector(characteristic_matrix(A0, As, taus, lam))
    v = np.asarray(v, complex)
    v = v / np.linalg.norm(v)
    c = v.copy()
    size = np.linalg.norm(A0, 2) + sum(np.linalg.norm(A, 2) for A in As)
    converged = False
    for _ in range(max_iter):
        Dl = characteristic_matrix(A0, As, taus, lam)
        F = np.concatenate([Dl @ v, [np.vdot(c, v) - 1.0]])
        Jm = np.zeros((n + 1, n + 1), complex)
        Jm[:n, :n] = Dl
        Jm[:n, n] = characteristic_derivative(A0, As, taus, lam) @ v
        Jm[n, :n] = np.conj(c)
        try:
            d = np.linalg.solve(Jm, -F)
        except np.linalg.LinAlgError:
            break
        if not np.all(np.isfinite(d)):
            break
        v = v + d[:n]
        lam = lam + d[n]
        if abs(d[n]) <= tol * max(1.0, abs(lam)) and np.linalg.norm(d[:n]) <= 1e-12 * \
                np.linalg.norm(v):
            converged = True
            break
    v = v / np.linalg.norm(v)
    res = float(np.linalg.norm(characteristic_matrix(A0, As, taus, lam) @ v)
                / (abs(lam) + size + 1e-300))
    return lam, v, res, converged and res < 1e-12



def rightmost_first(w: np.ndarray) -> np.ndarray:
    """The roots ``w`` by real part, largest first (equal real parts: by imaginary part,
    largest first)."""
    return w[np.lexsort((-w.imag, -w.real))]


def characteristic_roots(dde: DelayDifferentialSystem, x: np.ndarray | None = None,
                         p: np.ndarray | None = None, *, count: int = 10,
                         nodes: int | None = None, check_nodes: int | None = None
                         ) -> CharacteristicRoots:
    """The ``count`` rightmost characteristic roots at the equilibrium ``x`` (the delay
    system's state, default x_guess) with their trust (module docstring).

    ``nodes`` (default :func:`nodes_for` the largest delay) and ``check_nodes`` (default
    nodes + max(8, nodes // 2)) are the two discretisations compared. With every delay 0 the
    roots are the eigenvalues of the delay-free Jacobian (all trusted).
    """
    pv = dde.p if p is None else np.asarray(p, float)
    xs = dde.x_guess if x is None else np.asarray(x, float)
    taus = dde.delay_values(pv)
    A0, R, G = signal_factors(dde, xs, pv)
    As = [Rk @ Gk for Rk, Gk in zip(R, G, strict=True)]
    if not np.any(taus > 0):
        w = rightmost_first(np.linalg.eigvals(A0 + sum(As)))[:count]
        return CharacteristicRoots(roots=w, approximations=w, check=w, nodes=0, check_nodes=0,
                                   trusted=int(w.size), residuals=np.zeros(w.size),
                                   max_real_part=float(np.max(w.real)))
    if np.any(taus <= 0):
        raise ValueError("characteristic_roots: delays must be all positive or all zero")
    rate = max(float(np.max(np.abs(np.linalg.eigvals(A0 + sum(As))))), 1e-300)
    N = nodes or min(nodes_for(float(np.max(taus)), rate), NODES_MAX)
    N2 = check_nodes or N + max(8, N // 2)
    w1 = rightmost_first(np.linalg.eigvals(discretised_matrix(A0, R, G, taus, N)))[:count]
    w2 = rightmost_first(np.linalg.eigvals(discretised_matrix(A0, R, G, taus, N2)))
    roots, check, res = [], [], []
    trusted, broken = 0, False
    for lam in w1:
        k = int(np.argmin(np.abs(w2 - lam)))
        check.append(w2[k])
        lr, _, r, ok = refine_characteristic_root(A0, As, taus, lam)
        lr2, _, _, ok2 = refine_characteristic_root(A0, As, taus, w2[k])
        scale = max(1.0, abs(lr))
        # both discretisations lead Newton to the same exact root, from nearby
        good = (ok and ok2 and abs(lr - lr2) <= TRUST_TOL * scale
                and abs(lr - lam) <= APPROX_TOL * scale
                and abs(lr - w2[k]) <= APPROX_TOL * scale)
        # and the finer discretisation has no root right of it that the coarse one lacks
        missed = np.any((w2.real > lr.real + APPROX_TOL * scale)
                        & (np.min(np.abs(w2[:, None] - np.asarray(w1)[None, :]), axis=1)
                           > APPROX_TOL * np.maximum(1.0, np.abs(w2))))
        if good and not missed and not broken:
            trusted += 1
            roots.append(lr)
        else:
            broken = True
            roots.append(lam)
        res.append(r)
    roots_a = np.asarray(roots)
    return CharacteristicRoots(roots=roots_a, approximations=w1, check=np.asarray(check),
                               nodes=N, check_nodes=N2, trusted=trusted,
                               residuals=np.asarray(res),
                               max_real_part=float(np.max(roots_a.real)))

