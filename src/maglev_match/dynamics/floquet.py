"""Floquet multipliers of a periodic orbit from its collocation blocks, by a periodic Schur
decomposition (periodic QZ) that never forms the monodromy matrix.

The variational equation v' = T A(t) v along a collocation orbit is discretised by the same
collocation as the orbit. On mesh interval j the collocation equations tie the values at the
interval's end points, v_j = v(t_j) and v_{j+1} = v(t_{j+1}), to the interior nodes::

    [ A0_j | Aint_j | Aend_j ] [v_j; v_interior; v_{j+1}] = 0      (m n rows)

An orthogonal factorisation of ``Aint_j`` eliminates the interior nodes without inverting
anything and leaves n equations ``E_j v_{j+1} = F_j v_j`` (the condensation of Doedel, Keller &
Kernevez 1991, done with Householder reflections as in AUTO). The multipliers are the
eigenvalues of the *formal* product::

    M = E_{K-1}^{-1} F_{K-1} ... E_1^{-1} F_1 E_0^{-1} F_0,      K = NTST.

Forming M loses everything at long periods: near a homoclinic orbit the partial products grow
like exp(lambda_u t) and the rounding error of the product swamps the trivial multiplier 1
(Fairgrieve & Jepson 1991, "O.K. Floquet multipliers"). Instead the periodic QZ algorithm
(Bojanczyk, Golub & Van Dooren 1992; Hench & Laub 1994; Kressner 2006, ch. 3) reduces the pairs
(F_j, E_j) by unitary transformations, each factor separately, to periodic Schur form::

    Q_j^H F_j Z_j = R_j,   Q_j^H E_j Z_{j+1} = S_j    (Z_K = Z_0; R_j, S_j upper triangular)

so that mu_i = prod_j R_j[i, i] / S_j[i, i]. The products are accumulated as log-magnitude and
phase, so multipliers spanning 1e-30 .. 1e3 (and far beyond) keep full relative accuracy. The
algorithm is backward stable for each factor, which is what the collocation blocks are accurate
to; it costs O(K n^3) per shift sweep. Complex arithmetic with single (Wilkinson) shifts is
used; conjugate pairs of the real problem are re-paired at the end. The periodic QZ
algorithm itself is in :mod:`maglev_match.dynamics.periodic_schur`; this module builds the
factors from the collocation blocks and reads the multipliers off.

Three economies keep the cost per orbit small (all on by default; ``group_cond = 1`` turns
them off and runs the periodic QZ on the K orthogonally condensed pairs):

- the Jacobians are balanced by one constant diagonal similarity (exact, powers of 2), so
  states in very different units do not make every transfer matrix look ill-conditioned;
- runs of consecutive transfer matrices P_j (one LU solve per interval) are multiplied
  together only while the run's condition number stays below ``group_cond`` (default 1e4, so
  at most 4 of the 16 digits are spent there): on the 9-state maglev model with NTST 80 the
  80 intervals collapse to about 4 factors;
- LAPACK's QR on the block cyclic matrix of the factors (its eigenvalues are the K-th roots
  of the multipliers) gives estimates that serve as shifts, so the periodic QZ deflates about
  one eigenvalue per sweep and a half; the eigenvalues returned are the periodic QZ's.

The periodic QZ runs in Python loops (about 10-25 ms per orbit on model A). When the grouped
sequence is short, LAPACK's QR on its block cyclic matrix (whose eigenvalues are the K-th
roots of the multipliers) is used instead, but only when its first-order error bound, from
the eigenvalue condition numbers, proves every multiplier to 1e-10 relative
(:func:`_cyclic_multipliers`); otherwise, e.g. with multipliers 1e-30 and 1e3 in a short
sequence, the periodic QZ decides. ``method="periodic_qz"`` forces the periodic QZ.

Limits. The result is as accurate as the factors allow, which is the best any method working
on the collocation blocks can do; near a homoclinic orbit the trivial multiplier is itself
ill-conditioned (the flow vector almost vanishes near the saddle) and the discretisation of
the variational equation degrades on long intervals, so its distance from 1 is reported
(:class:`FloquetResult`) rather than assumed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import StrEnum

import numpy as np
import scipy.linalg

from maglev_match.core.reprs import compact_repr
from maglev_match.dynamics.collocation import collocation_tables
from maglev_match.dynamics.periodic_schur import (
    PeriodicEigenvalues,
    periodic_eigenvalues,
    wrap_angle,
)

__all__ = [
    "FloquetMethod",
    "FloquetResult",
    "PeriodicEigenvalues",
    "condensed_pairs",
    "floquet_analysis",
    "floquet_multipliers_from_blocks",
    "floquet_multipliers_product",
    "dominant_multipliers",
    "grouped_transfer_matrices",
    "transfer_matrices",
    "periodic_eigenvalues",
]

_EPS = np.finfo(float).eps

#: Default tolerance on |mu_trivial - 1| below which a point's multipliers are trusted.
DEFAULT_TRIVIAL_TOL = 1e-4
#: Largest condition number of a run of transfer matrices multiplied together before the
#: periodic QZ (see :func:`grouped_transfer_matrices`): costs at most 4 digits of the 16.
DEFAULT_GROUP_COND = 1e4


class FloquetMethod(StrEnum):
    """How the multipliers were computed."""

    PERIODIC_QZ = "periodic_qz"  # periodic Schur form of the condensed pairs
    DOMINANT = "dominant"  # orthogonal iteration for the largest ones, the rest below 1e-12
    CYCLIC_QR = "cyclic_qr"  # LAPACK QR on the block cyclic matrix, accepted by its bound
    PRODUCT = "product"  # eigenvalues of the explicit monodromy product (old method)


# ---------------------------------------------------------------------------------------
# condensation of the collocation blocks
# ---------------------------------------------------------------------------------------
def _interval_blocks(J: np.ndarray, T: float, h: np.ndarray, m: int) -> np.ndarray:
    """Collocation matrix of v' = T A(t) v on each interval: (NTST, m n, (m+1) n).

    Row block l is the equation at Gauss point z_l, column block k the node c_k = k/m of the
    interval (k = 0 the left end, k = m the right end): sum_k [D_lk I - T h_j L_lk A(z_l)] v_k.
    """
    ntst, _, n, _ = J.shape
    _, _, _, L, D = collocation_tables(m)
    blk = (D[None, :, :, None, None] * np.eye(n)[None, None, None]
           - (T * np.asarray(h, float))[:, None, None, None, None]
           * L[None, :, :, None, None] * J[:, :, None, :, :])  # (ntst, m, m+1, n, n)
    return blk.transpose(0, 1, 3, 2, 4).reshape(ntst, m * n, (m + 1) * n)


def condensed_pairs(J: np.ndarray, T: float, h: np.ndarray, m: int
                    ) -> tuple[np.ndarray, np.ndarray]:
    """End-point relations E_j v(t_{j+1}) = F_j v(t_j) of each mesh interval.

    Parameters
    ----------
    J : Jacobian of the right-hand side at the Gauss points, shape (NTST, m, n, n).
    T : period (s).
    h : mesh interval lengths on [0, 1], shape (NTST,).
    m : collocation points per interval (NCOL).

    Returns
    -------
    (F, E), each (NTST, n, n): the interior nodes are eliminated by a complete QR factorisation
    of their columns (orthogonal, no inverse), and the last n rows of Q^T applied to the
    end-point columns give the relation. The transfer matrix is E_j^{-1} F_j.
    """
    J = np.asarray(J, float)
    ntst, _, n, _ = J.shape
    blk = _interval_blocks(J, T, h, m)
    A0 = blk[:, :, :n]
    Aend = blk[:, :, m * n:]
    if m == 1:
        return -A0, Aend
    Aint = blk[:, :, n:m * n]
    Q = np.linalg.qr(Aint, mode="complete")[0]  # (ntst, mn, mn)
    rows = Q[:, :, (m - 1) * n:].transpose(0, 2, 1)  # last n rows of Q^T
    return -(rows @ A0), rows @ Aend



def _pair_conjugates(log_abs: np.ndarray, phase: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eigenvalues of a real problem computed in complex arithmetic, as (ln|mu|, arg mu):
    make each conjugate pair exact and each real eigenvalue real. The distance between mu_i
    and conj(mu_k) is measured relatively, |ln|mu_i| - ln|mu_k|| + |arg mu_i + arg mu_k|,
    so that it means the same for 1e-30 and 1e3. An eigenvalue whose nearest conjugate is its
    own is real; otherwise it is paired with the eigenvalue nearest its conjugate."""
    la = np.array(log_abs, float)
    ph = np.array(phase, float)
    left = [int(i) for i in np.argsort(-np.abs(np.sin(ph)))]
    while left:
        i = left.pop(0)
        cands = [i, *left]
        d = [abs(la[k] - la[i]) + abs(wrap_angle(ph[k] + ph[i])) if np.isfinite(la[k] - la[i])
             else (0.0 if k == i else math.inf) for k in cands]
        k = cands[int(np.argmin(d))]
        if k == i:
            ph[i] = 0.0 if abs(ph[i]) < 0.5 * math.pi else math.pi
        else:
            dph = wrap_angle(ph[i] + ph[k])
            ph[i] = wrap_angle(ph[i] - 0.5 * dph)
            ph[k] = -ph[i]
            la[i] = la[k] = 0.5 * (la[i] + la[k]) if np.isfinite(la[i] + la[k]) else la[i]
            left.remove(k)
    return la, ph


def _to_values(log_abs: np.ndarray, phase: np.ndarray) -> np.ndarray:
    """exp(log_abs + i phase); a real array when every phase is 0 or pi."""
    with np.errstate(over="ignore", under="ignore"):
        mag = np.exp(log_abs)
    if np.all((phase == 0.0) | (phase == math.pi)):
        return np.where(phase == 0.0, mag, -mag)
    return mag * np.exp(1j * phase)


# ---------------------------------------------------------------------------------------
# public entry points
# ---------------------------------------------------------------------------------------
def floquet_multipliers_product(J: np.ndarray, T: float, h: np.ndarray, m: int) -> np.ndarray:
    """The old method, kept for comparison: transfer matrices P_j = -A1_j^{-1} A0_j (last n
    rows), explicit product P_{K-1} ... P_0 and its eigenvalues. Accurate for short,
    well-conditioned orbits only (its error is eps times the largest partial product)."""
    J = np.asarray(J, float)
    ntst, _, n, _ = J.shape
    blk = _interval_blocks(J, T, h, m)
    P = np.linalg.solve(blk[:, :, n:], -blk[:, :, :n])[:, -n:, :]
    M = np.eye(n)
    for j in range(ntst):
        M = P[j] @ M
    return np.linalg.eigvals(M)


def transfer_matrices(J: np.ndarray, T: float, h: np.ndarray, m: int) -> np.ndarray:
    """P_j with v(t_{j+1}) = P_j v(t_j): the end-node rows of the solution of each interval's
    collocation system (one LU solve per interval, no explicit inverse)."""
    n = J.shape[-1]
    blk = _interval_blocks(J, T, h, m)
    return np.linalg.solve(blk[:, :, n:], -blk[:, :, :n])[:, -n:, :]


def _group(P: np.ndarray, max_cond: float, chunk: int = 16) -> np.ndarray:
    """Runs of consecutive factors multiplied together while the run's 2-norm condition
    number stays <= max_cond (the same products, in the same order, as one at a time: the
    running products of a run are formed ``chunk`` at a time and their condition numbers
    computed in one batched SVD)."""
    groups = []
    K = P.shape[0]
    start = 0
    while start < K:
        G = P[start]
        k = 1  # factors start .. start + k - 1 are in the run, G is their product
        while start + k < K:
            run = []
            H = G
            for j in range(start + k, min(K, start + k + chunk)):
                H = P[j] @ H
                run.append(H)
            R = np.stack(run)
            with np.errstate(all="ignore"):
                ok = np.all(np.isfinite(R), axis=(1, 2))
                cond = np.full(len(run), np.inf)
                if np.any(ok):
                    sv = np.linalg.svd(R[ok], compute_uv=False)
                    cond[ok] = sv[:, 0] / sv[:, -1]
            bad = np.nonzero(~(cond <= max_cond))[0]
            if bad.size:
                if bad[0] > 0:
                    G, k = R[bad[0] - 1], k + int(bad[0])
                break
            G, k = R[-1], k + len(run)
        groups.append(G)
        start += k
    return np.stack(groups)


def _cyclic_estimates(G: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Estimates (ln|mu|, arg mu) of the eigenvalues of G_{K-1} ... G_0 from the block
    cyclic matrix [[0, ..., G_{K-1}], [G_0, 0, ...], ..., [..., G_{K-2}, 0]], whose
    eigenvalues are the K-th roots of the multipliers (Kressner 2006, "The periodic QR
    algorithm is a disguised QR algorithm"): LAPACK's QR on it is fast, and the K-th root
    compresses the range of magnitudes. The K roots of each multiplier are grouped back."""
    K, n, _ = G.shape
    C = np.zeros((K * n, K * n))
    for j in range(K):
        jn = (j + 1) % K
        C[jn * n:(jn + 1) * n, j * n:(j + 1) * n] = G[j]
    lam = np.linalg.eigvals(C)
    with np.errstate(divide="ignore"):
        la = K * np.log(np.abs(lam))
    ph = np.angle(lam ** K) if K > 1 else np.angle(lam)
    left = list(np.argsort(-la))
    out_l, out_p = [], []
    while left and len(out_l) < n:
        i = left[0]
        d = np.abs(la[left] - la[i]) + np.abs(np.angle(np.exp(1j * (ph[left] - ph[i]))))
        d = np.where(np.isfinite(d), d, np.inf)
        take = [left[k] for k in np.argsort(d, kind="stable")[:K]]
        out_l.append(la[i])
        out_p.append(ph[i])
        left = [k for k in left if k not in take]
    return np.array(out_l), np.array(out_p)


#: Largest first-order error bound (relative, on every multiplier) with which the block
#: cyclic QR result is accepted instead of running the periodic QZ.
CYCLIC_RTOL = 1e-10
#: Largest order K n of the block cyclic matrix tried (beyond it the dense QR costs more
#: than the periodic QZ).
CYCLIC_MAX_ORDER = 160


def _cyclic_multipliers(G: np.ndarray, rtol: float = CYCLIC_RTOL
                        ) -> tuple[np.ndarray, np.ndarray, float] | None:
    """Multipliers of G_{K-1} ... G_0 from LAPACK's QR algorithm on the block cyclic matrix
    C (see :func:`_cyclic_estimates`) when a first-order error bound proves them accurate;
    None otherwise (the caller then runs the periodic QZ).

    The computed eigenvalues of C are exact for C + dC with ||dC|| <= p(Kn) u ||C||
    (backward stability of the Hessenberg QR algorithm), so an eigenvalue lambda_i of C with
    reciprocal condition number s_i = |y_i^H x_i| / (||x_i|| ||y_i||) (left and right
    eigenvectors) moves by at most e_i = u ||C||_1 / s_i to first order, with the modest
    growth factor p taken as 1 as in LAPACK's own error bound EERRBD = EPSMCH * ABNRM /
    RCONDE (LAPACK Users' Guide, 3rd ed., sec. 4.8.1; Wilkinson 1965; Golub & Van Loan
    2013, sec. 7.2.2). A multiplier is mu = lambda^K, so its relative error is at most
    K e_i / |lambda_i|. The result is accepted only when this bound is <= ``rtol`` for every
    one of the K n eigenvalues, and when the K roots lambda^K of each multiplier agree to
    the same bound; this holds for the well-conditioned factors of the grouped sequence
    (condition numbers <= 1e4) unless multipliers of very different size (e.g. 1e-30 next
    to 1e3) make some lambda small against ||C||, where the periodic QZ is needed. Returns
    (ln|mu|, arg mu, largest bound) for the n multipliers."""
    K, n, _ = G.shape
    if K * n > CYCLIC_MAX_ORDER:
        return None
    C = np.zeros((K * n, K * n))
    for j in range(K):
        jn = (j + 1) % K
        C[jn * n:(jn + 1) * n, j * n:(j + 1) * n] = G[j]
    if not np.all(np.isfinite(C)):
        return None
    lam, vl, vr = scipy.linalg.eig(C, left=True, right=True)
    sc = np.abs(np.sum(np.conj(vl) * vr, axis=0)) / (
        np.linalg.norm(vl, axis=0) * np.linalg.norm(vr, axis=0))
    absl = np.abs(lam)
    with np.errstate(divide="ignore", invalid="ignore"):
        bound = K * (_EPS * np.linalg.norm(C, 1) / sc) / absl
    if not (np.all(np.isfinite(bound)) and float(np.max(bound)) <= rtol):
        return None
    la = K * np.log(absl)
    ph = np.angle(lam ** K) if K > 1 else np.angle(lam)
    left = list(np.argsort(-la, kind="stable"))
    out_l, out_p = [], []
    worst = float(np.max(bound))
    while left:
        i = left[0]
        d = np.abs(la[left] - la[i]) + np.abs(np.angle(np.exp(1j * (ph[left] - ph[i]))))
        take = [left[k] for k in np.argsort(d, kind="stable")[:K]]
        if len(take) < K or float(np.max(d[np.argsort(d, kind="stable")[:K]])) > \
                4.0 * float(np.max(bound[take])) + 4.0 * rtol:
            return None  # the K roots of one multiplier do not agree: not trusted
        z = np.mean(np.exp(1j * (ph[take] - ph[i]))) * np.exp(1j * ph[i])
        out_l.append(float(np.mean(la[take])))
        out_p.append(float(np.angle(z)))
        left = [k for k in left if k not in take]
    if len(out_l) != n:
        return None
    return np.array(out_l), np.array(out_p), worst


def grouped_transfer_matrices(F: np.ndarray, E: np.ndarray, max_cond: float) -> np.ndarray:
    """Collapse runs of consecutive transfer matrices E_j^{-1} F_j into their products while
    the 2-norm condition number of a run's product stays <= ``max_cond``.

    A product whose condition number is bounded by C carries a relative rounding error of at
    most about C times that of its factors, so the periodic QZ on the grouped sequence is
    backward stable to C eps per factor (the "collapsing" of short products discussed by
    Kressner 2006, sec. 3.5); the cost falls with the number of groups. ``max_cond`` = 1
    keeps every interval separate. E_j is the condensed end-node block, whose conditioning is
    that of the collocation matrix of a single short interval (close to 1 for small T h).
    """
    P = np.linalg.solve(E, F)
    return P if max_cond <= 1.0 else _group(P, max_cond)


def _balance_scale(J: np.ndarray) -> np.ndarray:
    """The diagonal D of :func:`_balanced` (n,)."""
    if J.shape[-1] < 2:
        return np.ones(J.shape[-1])
    _, (s, _) = scipy.linalg.matrix_balance(np.abs(J).mean(axis=(0, 1)), permute=False,
                                            separate=True)
    return s


def _balanced(J: np.ndarray) -> np.ndarray:
    """D^-1 J(t) D with one diagonal D (powers of 2, so exact) for the whole orbit, chosen by
    balancing the mean |J| (Parlett & Reinsch 1969). The transfer matrices become D^-1 P_j D:
    the same multipliers, but states of very different units (a gap in m, a current in A) no
    longer make every P_j look ill-conditioned, which would defeat the grouping."""
    if J.shape[-1] < 2:
        return J
    s = _balance_scale(J)
    return J * s[None, None, None, :] / s[None, None, :, None]


def _multipliers(J, T, h, m, group_cond: float = DEFAULT_GROUP_COND, method: str = "auto",
                 transfer: np.ndarray | None = None
                 ) -> tuple[np.ndarray, np.ndarray, PeriodicEigenvalues, int, FloquetMethod]:
    """(multipliers, ln|multipliers|, raw result, number of factors, method), by |mu|
    descending. ``method``: "auto" (the block cyclic QR when its error bound proves it
    accurate, else the periodic QZ), "periodic_qz" or "cyclic_qr" (falls back to the
    periodic QZ when the bound fails). ``transfer``: the interval transfer matrices P_j if
    already known (e.g. from the condensation of the Newton step), else computed from J."""
    J = np.asarray(J, float)
    if not (np.all(np.isfinite(J)) and math.isfinite(T)):
        raise ValueError("Floquet multipliers: the Jacobian along the orbit (or the period) "
                         "is not finite")
    if method not in ("auto", *tuple(FloquetMethod)) or method == FloquetMethod.PRODUCT:
        raise ValueError(f"method = {method!r}: must be auto, periodic_qz, cyclic_qr or "
                         "dominant")
    if method == FloquetMethod.DOMINANT:
        P = transfer_matrices(J, T, h, m) if transfer is None else np.asarray(transfer, float)
        mu, _, ok = dominant_multipliers(P, min(P.shape[1], 16))
        with np.errstate(divide="ignore"):
            la = np.log(np.abs(mu))
        pe = PeriodicEigenvalues(log_abs=la, phase=np.angle(mu), sweeps=0, converged=ok)
        return (mu.real if np.all(mu.imag == 0) else mu), la, pe, int(P.shape[0]), \
            FloquetMethod.DOMINANT
    if transfer is not None and group_cond > 1.0:
        d = _balance_scale(J)  # the same balancing, applied to the given P_j: D^-1 P_j D
        P = np.asarray(transfer, float) * (d[None, None, :] / d[None, :, None])
    else:
        J = _balanced(J)
        P = None
    if group_cond > 1.0:
        if P is None:
            P = transfer_matrices(J, T, h, m)
        F, E = _group(P, group_cond), None
        cyc = None if method == FloquetMethod.PERIODIC_QZ else _cyclic_multipliers(F)
        if cyc is not None:
            la, ph = _pair_conjugates(cyc[0], cyc[1])
            order = np.argsort(-la, kind="stable")
            la, ph = la[order], ph[order]
            pe = PeriodicEigenvalues(log_abs=la, phase=ph, sweeps=0, converged=True)
            return _to_values(la, ph), la, pe, int(F.shape[0]), FloquetMethod.CYCLIC_QR
        pe = periodic_eigenvalues(F, shifts=_cyclic_estimates(F))
    else:
        F, E = condensed_pairs(J, T, h, m)
        pe = periodic_eigenvalues(F, E)
    la, ph = _pair_conjugates(pe.log_abs, pe.phase)
    order = np.argsort(-la, kind="stable")
    la, ph = la[order], ph[order]
    return _to_values(la, ph), la, pe, int(F.shape[0]), FloquetMethod.PERIODIC_QZ


#: With method "dominant", the multipliers left out are below this in modulus.
DOMINANT_FLOOR = 1e-12


def dominant_multipliers(P: np.ndarray, p: int, *, floor: float = DOMINANT_FLOOR,
                         max_sweeps: int = 12, tol: float = 1e-13, seed: int = 0
                         ) -> tuple[np.ndarray, int, bool]:
    """The multipliers of largest modulus of the formal product M = P_{K-1} ... P_0, by
    orthogonal iteration on the periodic sequence (subspace iteration carried through the
    factors with a QR factorisation after each, so the product is never formed; Golub &
    Van Loan 2013, sec. 7.3.2 for one matrix, Kressner 2006, sec. 3.1 for products).

    For a stiff system, such as the discretised past of a delay equation (modes decaying
    like exp(-N^2 t / tau)), each P_j is ill-conditioned beyond any grouping and the periodic
    QZ on NTST factors of full size is slow; but all multipliers except a few are far below
    round-off. Starting with a subspace of dimension ``p``, the iteration runs until the
    subspace is invariant to ``tol`` (a sweep costs K QR factorisations of n x p matrices),
    then the multipliers are the eigenvalues of the p x p restriction Q_0^T M Q_0. When the
    smallest of them is not below ``floor``, ``p`` is doubled (up to n): the multipliers
    left out are then all smaller than ``floor`` and are returned as 0.

    Returns (n multipliers by modulus, largest first; the dimension used; converged).
    """
    P = np.asarray(P, float)
    K, n, _ = P.shape
    rng = np.random.default_rng(seed)
    p = max(1, min(int(p), n))
    while True:
        Q0 = np.linalg.qr(rng.standard_normal((n, p)))[0]
        converged = False
        for _ in range(max_sweeps):
            Q = Q0
            Rs = []
            for j in range(K):
                Q, R = np.linalg.qr(P[j] @ Q)
                Rs.append(R)
            moved = float(np.linalg.norm(Q - Q0 @ (Q0.T @ Q)))
            Qstart = Q0
            Q0 = Q
            if moved <= tol * max(1.0, math.sqrt(p)):
                converged = True
                break
        # M Qstart = Q R_{K-1} ... R_0, so M restricted to span(Qstart) is Qstart^T Q R_tot
        Rtot = np.eye(p)
        with np.errstate(under="ignore"):
            for R in Rs:
                Rtot = R @ Rtot
        mu = np.linalg.eigvals(Qstart.T @ Q @ Rtot)
        mu = mu[np.argsort(-np.abs(mu), kind="stable")]
        if p >= n or (converged and abs(mu[-1]) < floor):
            out = np.zeros(n, complex)
            out[:p] = mu
            return out, p, converged
        p = min(n, 2 * p)


def floquet_multipliers_from_blocks(J: np.ndarray, T: float, h: np.ndarray, m: int,
                                    method: str = "auto",
                                    transfer: np.ndarray | None = None) -> np.ndarray:
    """Floquet multipliers (all n, by |mu| descending) of a collocation orbit from the
    Jacobian at its Gauss points, by periodic QZ on the grouped transfer matrices (see the
    module docstring); the monodromy matrix is never formed.

    Parameters
    ----------
    J : d f / d x at the Gauss points, shape (NTST, NCOL, n, n).
    T : period (s).
    h : mesh interval lengths on [0, 1], shape (NTST,).
    m : NCOL.
    method : "auto", "periodic_qz" or "cyclic_qr" (see :func:`floquet_analysis`).
    transfer : the interval transfer matrices P_j (NTST, n, n) when they are already known
        (:meth:`~maglev_match.dynamics.collocation.CondensedLU.transfer_matrices`, a
        by-product of the Newton step's condensation at this orbit): they replace the
        batched interval solve; J is still used for the balancing.

    Returns
    -------
    The n multipliers; a real array when all are real, else complex with exact conjugate
    pairs. If the periodic QZ exhausts its sweep budget (never seen in practice) the
    explicit product is used instead; :func:`floquet_analysis` reports that case.
    """
    mu, _, pe, _, _ = _multipliers(J, T, h, m, method=method, transfer=transfer)
    if not pe.converged:
        return floquet_multipliers_product(J, T, h, m)
    return mu


@dataclass(frozen=True)
class FloquetResult:
    """Floquet multipliers of one periodic orbit with their accuracy check.

    multipliers : all n multipliers, sorted by |mu| descending.
    log_abs : ln|mu| of each (same order): usable where |mu| under/overflows.
    trivial : the multiplier nearest 1 (exactly 1 for the exact orbit: f(x(t)) solves the
        variational equation).
    trivial_error : |trivial - 1|.
    reliable : trivial_error <= tol and the algorithm converged.
    tol : the tolerance used.
    method : how they were computed.
    sweeps : periodic QZ sweeps used.
    converged : the periodic QZ deflated every eigenvalue.
    factors : length of the periodic sequence the QZ worked on (after grouping).
    """

    __repr__ = compact_repr

    multipliers: np.ndarray
    log_abs: np.ndarray
    trivial: complex
    trivial_error: float
    reliable: bool
    tol: float
    method: FloquetMethod
    sweeps: int
    converged: bool
    factors: int

    @property
    def nontrivial(self) -> np.ndarray:
        """The multipliers without the trivial one (sorted by |mu| descending)."""
        k = int(np.argmin(np.abs(self.multipliers - 1.0)))
        return np.delete(self.multipliers, k)


def floquet_analysis(J: np.ndarray, T: float, h: np.ndarray, m: int, *,
                     tol: float = DEFAULT_TRIVIAL_TOL,
                     group_cond: float = DEFAULT_GROUP_COND,
                     method: str = "auto") -> FloquetResult:
    """Floquet multipliers with a reliability verdict.

    Parameters
    ----------
    J, T, h, m : as for :func:`floquet_multipliers_from_blocks`.
    group_cond : bound on the condition number of the runs of transfer matrices multiplied
        together before the periodic QZ (1: none; see :func:`grouped_transfer_matrices`).
    tol : largest accepted |mu_trivial - 1|. The trivial multiplier is exactly 1 for the
        exact orbit, so its error measures the accuracy of the multipliers near the unit
        circle, which decide stability and the bifurcations of cycles. The default 1e-4
        (a) passes converged orbits on the default mesh with a wide margin: NTST 80, NCOL 4
        gives 1e-13 .. 1e-9 on the maglev model-A branches and <= 1e-6 on the Lorenz cycles
        up to 8 Hopf periods (where the explicit product is off by 0.1); (b) flags an error
        that could move a multiplier across the unit circle at the resolution of a
        continuation step (|mu| changes by 1e-3 .. 1e-2 per step near a crossing), as on
        the strongly unstable part of the model-A branch with xi0 = 0.7 near omega1 = 79
        rad/s (|mu| ~ 600 .. 2000), where the trivial error grows to 0.25 with this method
        and the explicit product alike (a property of the discretised problem, not of the
        linear algebra). A bound this strict is affordable because the linear algebra
        here does not degrade with the period.

    Returns
    -------
    FloquetResult (multipliers sorted by |mu| descending).
    """
    if not tol > 0.0:
        raise ValueError(f"tol = {tol!r}: must be > 0")
    mu_sorted, log_abs, pe, nfac, used = _multipliers(J, T, h, m, group_cond, method)
    k = int(np.argmin(np.abs(mu_sorted - 1.0)))
    triv = complex(mu_sorted[k])
    err = abs(triv - 1.0)
    return FloquetResult(multipliers=mu_sorted, log_abs=log_abs, trivial=triv,
                         trivial_error=err, reliable=bool(pe.converged and err <= tol), tol=tol,
                         method=used, sweeps=pe.sweeps,
                         converged=pe.converged, factors=nfac)
