"""Normal-form coefficients of a Hopf point: the first and second Lyapunov coefficients.

Kuznetsov, Elements of Applied Bifurcation Theory (3rd ed., 2004, sec. 3.5 and 8.7) and
Kuznetsov 1999 (SIAM J. Numer. Anal. 36:1104), with J q = i omega q, J^T p = -i omega p,
<q, q> = 1, <p, q> = 1 and <a, b> = sum conj(a) b:

    h20 = (2 i omega - J)^-1 B(q, q),   h11 = -J^-1 B(q, qbar)
    G21 = <p, C(q, q, qbar) + B(qbar, h20) + 2 B(q, h11)>
    l1  = Re G21 / (2 omega)
    l2  = Re G32 / (12 omega)                                  (at l1 = 0)

With this normalisation a planar block z' = (mu + i) z + b z |z|^2 + s z |z|^4 written in
x1 + i x2 = z gives l1 = 2 Re b and, at Re b = 0, l2 = 4 Re s (since <q, q> = 1 means
z = sqrt(2) w in the normal-form coordinate w); the signs are those of Re b and Re s.
Derivatives of orders 2 to 5 are exact (nested forward-mode autodiff), never finite
differences.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import cache

import jax
import numpy as np
import scipy.linalg

from maglev_match.core.aot import cached_kernel
from maglev_match.dynamics.system import System

__all__ = [
    "eigenvector_norm",
    "hopf_eigenvectors",
    "first_lyapunov_coefficient",
    "second_lyapunov_coefficient",
]


def _real_form(rhs, order: int):
    """The real symmetric k-linear form d^k f / dx^k [u1, ..., uk] by nested jvp."""

    def form(x, p, *us):
        def g(y, k):
            if k == 0:
                return rhs(y, p)
            return jax.jvp(lambda z: g(z, k - 1), (y,), (us[k - 1],))[1]

        return g(x, order)

    return form


#: the directions of every call of a form of order k are padded (with zeros) to a multiple
#: of FORM_BATCH[k]: one compiled kernel per order instead of one per batch size (the
#: Lyapunov coefficients call them with 1 to 32 directions; every kernel costs ~30 ms to
#: load in a new process)
FORM_BATCH = {2: 8, 3: 8, 4: 16, 5: 32}


class _PaddedForm:
    """A batched real form called with its directions padded to a multiple of ``size``;
    returns the rows of the directions given (a NumPy array)."""

    def __init__(self, kernel: Callable, size: int) -> None:
        self.kernel, self.size = kernel, size

    def __call__(self, x, p, *us):
        us = [np.asarray(u, np.float64) for u in us]
        n = us[0].shape[0]
        pad = -n % self.size
        if pad:
            us = [np.concatenate([u, np.zeros((pad,) + u.shape[1:])]) for u in us]
        return np.asarray(self.kernel(x, p, *us))[:n]


@cache
def real_forms(rhs) -> dict[int, Callable]:
    """Real multilinear forms of orders 2..5 for ``rhs``, jitted and vmapped over batches
    of directions (one trace each; complex directions are expanded outside, which keeps
    the compile time small even at order 5), each batch padded to a multiple of
    :data:`FORM_BATCH`."""
    out = {}
    for k in (2, 3, 4, 5):
        axes = (None, None) + (0,) * k
        out[k] = _PaddedForm(cached_kernel(jax.vmap(_real_form(rhs, k), in_axes=axes), rhs,
                                           k, name="normal_forms.form"), FORM_BATCH[k])
    return out


def complex_form_eval(real_form, x, p, us) -> np.ndarray:
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


def l1_from_forms(rhs, x, p, J, omega, q, padj) -> float:
    """Kuznetsov's l1 (paper eq. 24) from batched real forms B and C (4 calls)."""
    F = real_forms(rhs)
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


def null_vector(M: np.ndarray) -> np.ndarray:
    """Unit vector spanning the (numerical) null space of a square matrix."""
    _, _, vh = scipy.linalg.svd(M)
    return np.conj(vh[-1])


def eigenvector_norm(q: np.ndarray, norm_dim: int | None = None) -> float:
    """The norm in <q, q> = 1: over all entries, or over the first ``norm_dim`` (a system
    whose leading states are the physical ones, e.g. a discretised delay system whose other
    states sample the past: its coefficients then do not depend on the discretisation)."""
    q = np.asarray(q)
    return float(np.linalg.norm(q if norm_dim is None else q[:norm_dim]))


def hopf_eigenvectors(J: np.ndarray, omega: float, norm_dim: int | None = None
                      ) -> tuple[np.ndarray, np.ndarray]:
    """Right and adjoint eigenvectors at a Hopf point.

    Returns (q, p) with J q = i omega q, J^T p = -i omega p, <q, q> = 1, <p, q> = 1
    (<a, b> = sum conj(a) b; <q, q> over the first ``norm_dim`` entries when given, see
    :func:`eigenvector_norm`). The phase of q is fixed so that its largest component is
    real and positive.
    """
    n = J.shape[0]
    eye = np.eye(n)
    q = null_vector(J - 1j * omega * eye)
    k = int(np.argmax(np.abs(q)))
    q = q * np.exp(-1j * np.angle(q[k]))
    q = q / eigenvector_norm(q, norm_dim)
    p = null_vector(J.T + 1j * omega * eye)
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
    with <q, q> = 1 and <p, q> = 1; B and C exact by autodiff. <q, q> is taken over the
    system's first ``normal_form_dim`` states when it has that attribute (a discretised
    delay system: the current state).

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
    norm_dim = getattr(system, "normal_form_dim", None)
    if q is None or p_adj is None:
        q, p_adj = hopf_eigenvectors(J, omega, norm_dim)
    else:
        q = np.asarray(q, complex) / eigenvector_norm(q, norm_dim)
        p_adj = np.asarray(p_adj, complex)
        p_adj = p_adj / np.conj(np.vdot(p_adj, q))
    return l1_from_forms(system.rhs, x, pv, J, float(omega), q, p_adj)


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
        q, p_adj = hopf_eigenvectors(J, omega, getattr(system, "normal_form_dim", None))
    F = real_forms(system.rhs)
    xj, pj = np.asarray(x), np.asarray(pv)

    def form(k, *us):
        return complex_form_eval(F[k], xj, pj, [np.asarray(u, complex) for u in us])

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

