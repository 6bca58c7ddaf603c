"""Eigenvalues of a formal matrix product E_{K-1}^{-1} F_{K-1} ... E_0^{-1} F_0 by the
periodic QZ algorithm (periodic Schur decomposition), without forming the product or any
inverse of a factor.

The periodic QZ algorithm (Bojanczyk, Golub & Van Dooren 1992; Hench & Laub 1994; Kressner
2006, ch. 3) reduces the pairs (F_j, E_j) by unitary transformations, each factor
separately, to periodic Schur form::

    Q_j^H F_j Z_j = R_j,   Q_j^H E_j Z_{j+1} = S_j    (Z_K = Z_0; R_j, S_j upper triangular)

so that mu_i = prod_j R_j[i, i] / S_j[i, i]: first to Hessenberg-triangular form (Kressner
2006, Alg. 3.9 in the pair form), then by implicitly shifted sweeps with single (Wilkinson)
shifts in complex arithmetic, optionally replaced by the nearest of given estimates. The
products are accumulated as log-magnitude and phase, so eigenvalues spanning 1e-30 .. 1e3
(and far beyond) keep full relative accuracy. The algorithm is backward stable for each
factor; it costs O(K n^3) per shift sweep. The Floquet multipliers of a collocation orbit
(:mod:`maglev_match.dynamics.floquet`) are computed with it.
"""

from __future__ import annotations

import cmath
import math
from dataclasses import dataclass

import numpy as np
import scipy.linalg

__all__ = ["PeriodicEigenvalues", "periodic_eigenvalues", "wrap_angle"]

_EPS = np.finfo(float).eps


@dataclass(frozen=True)
class PeriodicEigenvalues:
    """Eigenvalues of a formal product, as log-magnitude and phase.

    log_abs : natural log of |mu| (-inf for an exact zero).
    phase : argument of mu (rad).
    sweeps : shifted QZ sweeps used.
    converged : False if some eigenvalue did not deflate within the sweep budget.
    """

    log_abs: np.ndarray
    phase: np.ndarray
    sweeps: int
    converged: bool

    @property
    def values(self) -> np.ndarray:
        """The eigenvalues as complex numbers (under/overflow only outside double range)."""
        with np.errstate(over="ignore", under="ignore"):
            return np.exp(self.log_abs) * np.exp(1j * self.phase)


def _rot_zero_below(a: complex, b: complex) -> np.ndarray:
    """Unitary G (2x2) with G [a; b] = [r; 0]."""
    a, b = complex(a), complex(b)
    nrm = math.hypot(abs(a), abs(b))
    if nrm == 0.0:
        return np.eye(2, dtype=complex)
    return np.array([[a.conjugate(), b.conjugate()], [-b, a]]) / nrm


def _rot_zero_left(a: complex, b: complex) -> np.ndarray:
    """Unitary Z (2x2) with [a, b] Z = [0, r]."""
    a, b = complex(a), complex(b)
    nrm = math.hypot(abs(a), abs(b))
    if nrm == 0.0:
        return np.eye(2, dtype=complex)
    return np.array([[b, a.conjugate()], [-a, b.conjugate()]]) / nrm


def _hessenberg_triangular(F: np.ndarray, E: np.ndarray) -> None:
    """Reduce (in place) F_0 to upper Hessenberg and every other F_j and every E_j to upper
    triangular form by unitary transformations Q_j^H F_j Z_j, Q_j^H E_j Z_{j+1} (Kressner 2006,
    Alg. 3.9 in the pair form)."""
    K, n, _ = F.shape
    # E_j = Q R: the left transformation of pair j
    Q, R = np.linalg.qr(E)
    E[:] = R
    F[:] = np.conj(Q.transpose(0, 2, 1)) @ F
    # F_j (j >= 1) triangular by QR; E_j's triangularity restored by RQ, which changes the
    # basis at node j+1 (columns of F_{j+1}, or of F_0 for the last pair)
    for j in range(1, K):
        q, r = np.linalg.qr(F[j])
        F[j] = r
        e = np.conj(q.T) @ E[j]
        r2, q2 = scipy.linalg.rq(e)
        E[j] = r2
        F[(j + 1) % K] = F[(j + 1) % K] @ np.conj(q2.T)
    # F_0 to Hessenberg: zero F_0[i, k] by rotations on rows (i-1, i); the fill this makes
    # in E_0, F_1, E_1, ... is chased around the period back to the columns of F_0
    for k in range(n - 2):
        for i in range(n - 1, k + 1, -1):
            r = slice(i - 1, i + 1)
            G = _rot_zero_below(F[0, i - 1, k], F[0, i, k])
            F[0, r, :] = G @ F[0, r, :]
            F[0, i, k] = 0.0
            E[0, r, :] = G @ E[0, r, :]
            _chase_fill(F, E, i - 1)


def _chase_fill(F: np.ndarray, E: np.ndarray, i: int) -> None:
    """Rows (i, i+1) of pair 0 were rotated, leaving fill E_0[i+1, i]: remove it by a column
    rotation Z_1 (basis at node 1), which fills F_1[i+1, i], removed by a row rotation G_1
    of pair 1, ... until the column rotation Z_0 of the basis at node 0 reaches the columns
    of F_0 (where the caller deals with what it creates).

    Every factor but F_0 is upper triangular, so each rotation depends only on the 2x2
    diagonal blocks (i, i+1) of the factors: the rotations are found by a scalar pass over
    those blocks, then applied to all factors at once (a left and a right rotation of the
    same matrix commute)."""
    K = F.shape[0]
    c = slice(i, i + 2)
    Zs = np.empty((K, 2, 2), dtype=complex)
    Gs = np.empty((K, 2, 2), dtype=complex)
    Gs[0] = np.eye(2)
    eb = E[:, c, c].tolist()
    fb = F[:, c, c].tolist()
    e = eb[0]  # E_0 already carries its row rotation
    for j in range(K):
        Z = _rot_zero_left(e[1][0], e[1][1])
        Zs[j] = Z
        jn = (j + 1) % K
        if jn == 0:
            break
        f = fb[jn]
        z00, z10 = Z[0, 0], Z[1, 0]
        # column rotation of F_jn's block, then the row rotation that zeroes its (1, 0)
        a0 = f[0][0] * z00 + f[0][1] * z10
        a1 = f[1][0] * z00 + f[1][1] * z10
        G = _rot_zero_below(a0, a1)
        Gs[jn] = G
        e = (G @ np.asarray(eb[jn])).tolist()
    E[:, :, c] = E[:, :, c] @ Zs
    F[1:, :, c] = F[1:, :, c] @ Zs[:-1]
    F[0, :, c] = F[0, :, c] @ Zs[K - 1]
    if K > 1:
        F[1:, c, :] = Gs[1:] @ F[1:, c, :]
        E[1:, c, :] = Gs[1:] @ E[1:, c, :]
        F[1:, i + 1, i] = 0.0
    E[:, i + 1, i] = 0.0  # only once both rotations of each factor are in


def _triangular_product_2x2(F: np.ndarray, E: np.ndarray, i: int
                            ) -> tuple[tuple[complex, complex, complex], float]:
    """Upper triangular 2x2 block (rows/columns i, i+1) of E_{K-1}^{-1} F_{K-1} ... E_1^{-1}
    F_1 E_0^{-1} (every factor upper triangular), scaled: ((a, b, d) / s, ln s) for the block
    [[a, b], [0, d]]. Scalar arithmetic: the blocks are 2x2 and K can be large."""
    K = F.shape[0]
    fa = F[:, i, i].tolist()
    fb = F[:, i, i + 1].tolist()
    fd = F[:, i + 1, i + 1].tolist()
    ea = E[:, i, i].tolist()
    eb = E[:, i, i + 1].tolist()
    ed = E[:, i + 1, i + 1].tolist()
    # inverse of E_0's block
    a, d = 1.0 / ea[0], 1.0 / ed[0]
    b = -eb[0] * a * d
    logs = 0.0
    for j in range(1, K):
        # X = F_j [[a, b], [0, d]], then E_j^{-1} X (back substitution)
        xa, xb, xd = fa[j] * a, fa[j] * b + fb[j] * d, fd[j] * d
        d = xd / ed[j]
        a = xa / ea[j]
        b = (xb - eb[j] * d) / ea[j]
        s = max(abs(a), abs(b), abs(d))
        if s > 1e100 or s < 1e-100:
            a, b, d = a / s, b / s, d / s
            logs += math.log(s)
    return (a, b, d), logs


def _sweep(F: np.ndarray, E: np.ndarray, exceptional: bool, rng: np.random.Generator,
           guesses: tuple[np.ndarray, np.ndarray] | None = None) -> None:
    """One implicitly shifted periodic QZ sweep on the active window (views, in place).

    The shift is the Wilkinson shift of the product, or, when estimates of the eigenvalues
    are given as (ln|mu|, arg mu), the estimate nearest to it: an accurate shift deflates an
    eigenvalue in one or two sweeps instead of about three."""
    K, w, _ = F.shape
    # Wilkinson shift: eigenvalue of the trailing 2x2 of the product nearer its (2,2) entry
    t = slice(w - 2, w)
    (a, b, d), lt = _triangular_product_2x2(F, E, w - 2)
    Mt = np.array([[a, b], [0.0, d]]) @ F[0, t, t]
    st = float(np.max(np.abs(Mt)))
    if st > 0.0:
        Mt = Mt / st
        lt += math.log(st)
    tr = Mt[0, 0] + Mt[1, 1]
    det = Mt[0, 0] * Mt[1, 1] - Mt[0, 1] * Mt[1, 0]
    disc = cmath.sqrt(tr * tr / 4.0 - det)
    ev = (tr / 2.0 + disc, tr / 2.0 - disc)
    sig = min(ev, key=lambda z: abs(z - Mt[1, 1]))
    if exceptional:
        sig = abs(Mt[1, 1]) * (0.75 + 0.5 * rng.random()) * cmath.exp(2j * math.pi * rng.random())
    elif guesses is not None and abs(sig) > 0.0:
        gl, gp = guesses
        dist = np.abs(gl - (math.log(abs(sig)) + lt)) + np.abs(
            np.angle(np.exp(1j * (gp - cmath.phase(sig)))))
        k = int(np.argmin(dist))
        if math.isfinite(gl[k]) and gl[k] - lt < 700.0:
            sig = math.exp(gl[k] - lt) * cmath.exp(1j * gp[k])
    # first column of (M - sigma I): only its first two entries are non-zero
    (a, b, d), ll = _triangular_product_2x2(F, E, 0)
    h0, h1 = complex(F[0, 0, 0]), complex(F[0, 1, 0])
    v = (a * h0 + b * h1, d * h1)
    cmax = max(ll, lt)
    x0 = v[0] * math.exp(ll - cmax) - sig * math.exp(lt - cmax)
    x1 = v[1] * math.exp(ll - cmax)
    nrm = math.hypot(abs(x0), abs(x1))
    if nrm == 0.0:
        x0, x1, nrm = 1.0 + 0j, 1.0 + 0j, math.sqrt(2.0)
    Z = np.array([[x0, -np.conj(x1)], [x1, np.conj(x0)]]) / nrm  # Z e_1 ~ x
    c = slice(0, 2)
    F[0, :, c] = F[0, :, c] @ Z
    E[K - 1, :, c] = E[K - 1, :, c] @ Z
    # backward: the fill E_{K-1}[1, 0] -> rows of pair K-1 -> columns of node K-1 -> ...
    for j in range(K - 1, -1, -1):
        G = _rot_zero_below(E[j, 0, 0], E[j, 1, 0])
        E[j, c, :] = G @ E[j, c, :]
        E[j, 1, 0] = 0.0
        F[j, c, :] = G @ F[j, c, :]
        if j == 0:
            break
        Zj = _rot_zero_left(F[j, 1, 0], F[j, 1, 1])
        F[j, :, c] = F[j, :, c] @ Zj
        F[j, 1, 0] = 0.0
        E[j - 1, :, c] = E[j - 1, :, c] @ Zj
    # forward: chase the bulge F_0[k+2, k] down and off the matrix
    for k in range(w - 2):
        r = slice(k + 1, k + 3)
        G = _rot_zero_below(F[0, k + 1, k], F[0, k + 2, k])
        F[0, r, :] = G @ F[0, r, :]
        F[0, k + 2, k] = 0.0
        E[0, r, :] = G @ E[0, r, :]
        _chase_fill(F, E, k + 1)


def periodic_eigenvalues(F: np.ndarray, E: np.ndarray | None = None, *,
                         max_sweeps_per_eigenvalue: int = 40,
                         seed: int = 0,
                         shifts: tuple[np.ndarray, np.ndarray] | None = None
                         ) -> PeriodicEigenvalues:
    """Eigenvalues of the formal product E_{K-1}^{-1} F_{K-1} ... E_0^{-1} F_0 by the periodic
    QZ algorithm, without forming the product or any inverse of a factor.

    Parameters
    ----------
    F, E : (K, n, n) real or complex; E = None means every E_j = I (plain product
        F_{K-1} ... F_0).
    max_sweeps_per_eigenvalue : sweep budget (n times this in all).
    seed : seed of the random exceptional shifts (after 10 and 20 sweeps without deflation).
    shifts : optional estimates of the eigenvalues as (ln|mu|, arg mu) arrays, used as
        shifts (the one nearest each Wilkinson shift); they speed up convergence only, the
        result is that of the periodic QZ.

    Returns
    -------
    PeriodicEigenvalues with log|mu| and arg(mu) accumulated factor by factor from the
    diagonals of the periodic Schur form (Bojanczyk, Golub & Van Dooren 1992, eq. (2.2)):
    mu_i = prod_j R_j[i,i] / S_j[i,i].
    """
    F = np.array(F, dtype=complex, copy=True)
    if F.ndim == 2:
        F = F[None]
    K, n, _ = F.shape
    E = (np.broadcast_to(np.eye(n, dtype=complex), F.shape).copy() if E is None
         else np.array(E, dtype=complex, copy=True).reshape(F.shape))
    _hessenberg_triangular(F, E)
    rng = np.random.default_rng(seed)
    hi = n - 1
    sweeps = 0
    since = 0
    budget = max_sweeps_per_eigenvalue * max(n, 1)
    converged = True
    H = F[0]
    while hi > 0:
        # deflate negligible subdiagonals of the Hessenberg factor (relative to neighbours)
        lo = hi
        while lo > 0:
            if abs(H[lo, lo - 1]) <= _EPS * (abs(H[lo, lo]) + abs(H[lo - 1, lo - 1])):
                H[lo, lo - 1] = 0.0
                break
            lo -= 1
        if lo == hi:
            hi -= 1
            since = 0
            continue
        if sweeps >= budget:
            converged = False
            break
        win = slice(lo, hi + 1)
        _sweep(F[:, win, win], E[:, win, win], exceptional=since in (10, 20), rng=rng,
               guesses=shifts)
        sweeps += 1
        since += 1
    dF = np.diagonal(F, axis1=1, axis2=2)
    dE = np.diagonal(E, axis1=1, axis2=2)
    with np.errstate(divide="ignore"):
        log_abs = np.sum(np.log(np.abs(dF)), axis=0) - np.sum(np.log(np.abs(dE)), axis=0)
    phase = np.array([wrap_angle(float(v)) for v in
                      np.sum(np.angle(dF), axis=0) - np.sum(np.angle(dE), axis=0)])
    return PeriodicEigenvalues(log_abs=log_abs, phase=phase, sweeps=sweeps, converged=converged)


def wrap_angle(phi: float) -> float:
    """Angle in (-pi, pi]."""
    return math.pi - (math.pi - phi) % (2.0 * math.pi)

