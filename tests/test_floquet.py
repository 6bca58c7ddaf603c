"""Floquet multipliers by periodic QZ: closed forms, long products, the old method, Lorenz."""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np
import pytest
from scipy.linalg import block_diag, expm

from maglev_match.dynamics import floquet as fq
from maglev_match.dynamics.collocation import collocation_tables

# ---------------------------------------------------------------------------------------
# helpers
# ---------------------------------------------------------------------------------------


def gauss_point_jacobians(jac, ntst: int, m: int, T: float, mesh=None):
    """d f/d x along a known orbit at the Gauss points of each mesh interval (the input the
    collocation code hands to the multiplier routine): (NTST, m, n, n) and the interval
    lengths. ``jac(t)`` is the Jacobian at time t (s)."""
    mesh = np.linspace(0.0, 1.0, ntst + 1) if mesh is None else np.asarray(mesh)
    _, z, _, _, _ = collocation_tables(m)
    h = np.diff(mesh)
    s = mesh[:-1, None] + z[None, :] * h[:, None]
    return np.array([[jac(si * T) for si in row] for row in s]), h


def rel_match(got: np.ndarray, want: np.ndarray) -> float:
    """Largest relative distance from each wanted value to the nearest computed one, with the
    two sets of the same size matched one to one."""
    got = list(np.asarray(got, complex))
    worst = 0.0
    for w in sorted(np.asarray(want, complex), key=abs, reverse=True):
        k = int(np.argmin([abs(g - w) for g in got]))
        worst = max(worst, abs(got[k] - w) / abs(w))
        got.pop(k)
    return worst


def product_eigenvalues(P: np.ndarray) -> np.ndarray:
    M = np.eye(P.shape[1])
    for p in P:
        M = p @ M
    return np.linalg.eigvals(M)


# Hopf normal form x' = (mu - r^2) x - omega y, y' = omega x + (mu - r^2) y: the cycle
# r = sqrt(mu) has period 2 pi / omega and multipliers {1, exp(-2 mu T)} (Kuznetsov 2004,
# sec. 3.4); two decoupled linear oscillators z' = [[a, -b], [b, a]] z add exp((a +- i b) T).
OMEGA = 1.0
T_HOPF = 2.0 * math.pi / OMEGA
MU = math.log(100.0) / (2.0 * T_HOPF)  # exp(-2 mu T) = 1e-2
A_S, B_S = math.log(1e-30) / T_HOPF, 3.3  # multipliers of modulus 1e-30
A_U, B_U = math.log(1e3) / T_HOPF, 0.7  # multipliers of modulus 1e3


def _hopf_block(t: float, mu: float = MU) -> np.ndarray:
    r = math.sqrt(mu)
    x, y = r * math.cos(OMEGA * t), r * math.sin(OMEGA * t)
    return np.array([[mu - 3 * x * x - y * y, -OMEGA - 2 * x * y],
                     [OMEGA - 2 * x * y, mu - x * x - 3 * y * y]])


def _coupling() -> np.ndarray:
    """A fixed, non-orthogonal change of coordinates that mixes all six states, so no
    method can profit from the block structure."""
    rng = np.random.default_rng(7)
    return np.eye(6) + 0.4 * rng.standard_normal((6, 6))


def spread_jacobian(t: float) -> np.ndarray:
    S = _coupling()
    A = block_diag(_hopf_block(t), [[A_S, -B_S], [B_S, A_S]], [[A_U, -B_U], [B_U, A_U]])
    return S @ A @ np.linalg.inv(S)


SPREAD_EXACT = np.array(
    [1.0, math.exp(-2 * MU * T_HOPF)]
    + [math.exp(A_S * T_HOPF) * np.exp(s * 1j * B_S * T_HOPF) for s in (1, -1)]
    + [math.exp(A_U * T_HOPF) * np.exp(s * 1j * B_U * T_HOPF) for s in (1, -1)])


# ---------------------------------------------------------------------------------------
# (1) closed forms
# ---------------------------------------------------------------------------------------
def test_product_of_matrix_exponentials_matches_expm_of_the_sum():
    """prod_j expm(A h_j) = expm(A T) for any split of T: multipliers exp(lambda_i T) spanning
    1e-30 .. 1e3 to 1e-8 relative, through both the plain and the pair (E^-1 F) forms."""
    rng = np.random.default_rng(3)
    lam = np.array([math.log(1e3), 0.0, -5.0 + 2.0j, -5.0 - 2.0j, math.log(1e-30)]) / 1.0
    Lr = np.zeros((5, 5))
    Lr[0, 0], Lr[1, 1], Lr[4, 4] = lam[0].real, 0.0, lam[4].real
    Lr[2:4, 2:4] = [[-5.0, -2.0], [2.0, -5.0]]
    Lr[0, 1] = 3.0  # non-normal
    S = np.eye(5) + 0.5 * rng.standard_normal((5, 5))
    A = S @ Lr @ np.linalg.inv(S)
    T = 1.0
    h = rng.uniform(0.5, 1.5, 120)
    h *= T / h.sum()
    exact = np.exp(lam * T)
    F = np.array([expm(A * hj) for hj in h])
    pe = fq.periodic_eigenvalues(F)
    assert pe.converged
    assert rel_match(pe.values, exact) < 1e-8
    # the same product written as pairs E_j^-1 F_j with E_j = expm(-A h_j / 2)
    Fp = np.array([expm(A * hj / 2) for hj in h])
    Ep = np.array([expm(-A * hj / 2) for hj in h])
    assert rel_match(fq.periodic_eigenvalues(Fp, Ep).values, exact) < 1e-8
    # log|mu| is exact too, including the 1e-30 one
    assert np.allclose(np.sort(pe.log_abs), np.sort(np.log(np.abs(exact))), atol=1e-8)
    # the explicit product cannot see 1e-30 next to 1e3
    assert rel_match(product_eigenvalues(F), exact) > 1e-3


@pytest.mark.parametrize("method", ["periodic_qz", "cyclic_qr"])
@pytest.mark.parametrize(("ntst", "ncol"), [(80, 6), (200, 4)])
def test_collocated_hopf_cycle_times_oscillators_has_closed_form_multipliers(ntst, ncol,
                                                                             method):
    """Collocation of the variational equation along the Hopf normal-form cycle, coupled
    (by a change of coordinates) to a stable and an unstable oscillator: the six
    multipliers {1, e^-2muT, 1e-30 e^(+-i b_s T), 1e3 e^(+-i b_u T)} to 1e-8 relative,
    by the periodic QZ and by the block cyclic QR (accepted by its error bound here)."""
    J, h = gauss_point_jacobians(spread_jacobian, ntst, ncol, T_HOPF)
    res = fq.floquet_analysis(J, T_HOPF, h, ncol, method=method)
    assert res.converged and res.reliable
    assert rel_match(res.multipliers, SPREAD_EXACT) < 1e-8
    assert res.trivial_error < 1e-10
    assert np.all(np.diff(res.log_abs) <= 0.0)  # sorted by |mu| descending
    assert res.method == method
    # conjugate pairs exact; nontrivial = everything but the one nearest 1
    mu = res.multipliers
    assert np.allclose(np.sort_complex(mu), np.sort_complex(np.conj(mu)), rtol=0, atol=0)
    assert len(res.nontrivial) == 5 and not np.any(np.isclose(res.nontrivial, 1.0))
    # the function the cycles package calls returns the same n multipliers
    assert rel_match(fq.floquet_multipliers_from_blocks(J, T_HOPF, h, ncol, method=method),
                     SPREAD_EXACT) < 1e-8
    # the old explicit product loses the 1e-30 pair
    assert rel_match(fq.floquet_multipliers_product(J, T_HOPF, h, ncol), SPREAD_EXACT) > 1e-3


def test_grouping_changes_nothing_but_the_cost():
    J, h = gauss_point_jacobians(spread_jacobian, 80, 4, T_HOPF)
    a = fq.floquet_analysis(J, T_HOPF, h, 4, group_cond=1.0)
    b = fq.floquet_analysis(J, T_HOPF, h, 4)
    assert a.factors == 80 and b.factors < 80
    assert np.allclose(a.log_abs, b.log_abs, rtol=0, atol=1e-9)


# ---------------------------------------------------------------------------------------
# (2) long products where the explicit product fails
# ---------------------------------------------------------------------------------------
def _rotating_frame_sequence(K: int, rates: tuple[float, ...]) -> np.ndarray:
    """P_j = S_{j+1} D S_j^{-1} with S_j a rotating, sheared frame (S_K = S_0) and D =
    diag(exp(rate / K)): the product is S_0 diag(exp(rates)) S_0^{-1} exactly, while the
    partial products grow like exp(max rate * j / K)."""
    W = np.array([[0, -1, 0.5], [1, 0, -0.3], [-0.5, 0.3, 0]])
    shear = np.array([[1, 0.5, 0], [0, 1, 0.5], [0, 0, 1.0]])
    S = [expm(2 * math.pi * j / K * W) @ shear for j in range(K)]
    S.append(S[0])
    D = np.diag(np.exp(np.asarray(rates) / K))
    return np.array([S[j + 1] @ D @ np.linalg.inv(S[j]) for j in range(K)])


def test_trivial_multiplier_survives_a_long_product_that_the_explicit_product_loses():
    P = _rotating_frame_sequence(500, (50.0, 0.0, -70.0))  # multipliers e^50, 1, e^-70
    naive = product_eigenvalues(P)
    assert np.min(np.abs(naive - 1.0)) > 0.5  # the explicit product has no multiplier near 1
    pe = fq.periodic_eigenvalues(P)
    assert np.allclose(np.sort(pe.log_abs), [-70.0, 0.0, 50.0], rtol=0, atol=1e-9)
    G = fq.grouped_transfer_matrices(P, np.broadcast_to(np.eye(3), P.shape), 1e3)
    assert len(G) < len(P)
    assert np.allclose(np.sort(fq.periodic_eigenvalues(G).log_abs), [-70.0, 0.0, 50.0],
                       rtol=0, atol=1e-9)


# ---------------------------------------------------------------------------------------
# (3) agreement with the old method where it works
# ---------------------------------------------------------------------------------------
def test_agrees_with_the_explicit_product_on_a_short_well_conditioned_cycle():
    def jac(t):
        return block_diag(_hopf_block(t, 0.05), [[-0.2, -1.3], [1.3, -0.2]], [[0.1]])

    J, h = gauss_point_jacobians(jac, 40, 4, T_HOPF)
    new = fq.floquet_multipliers_from_blocks(J, T_HOPF, h, 4)
    old = fq.floquet_multipliers_product(J, T_HOPF, h, 4)
    assert new.shape == old.shape == (5,)
    assert rel_match(new, old) < 1e-10
    assert rel_match(old, new) < 1e-10


def test_real_multipliers_come_back_as_a_real_array():
    def jac(t):
        return block_diag(_hopf_block(t, 0.05), [[-0.3]], [[0.2]])

    J, h = gauss_point_jacobians(jac, 30, 4, T_HOPF)
    mu = fq.floquet_multipliers_from_blocks(J, T_HOPF, h, 4)
    assert mu.dtype == np.float64
    assert rel_match(mu, [1.0, math.exp(-0.1 * T_HOPF), math.exp(-0.3 * T_HOPF),
                          math.exp(0.2 * T_HOPF)]) < 1e-9


def test_tolerance_must_be_positive():
    J, h = gauss_point_jacobians(lambda t: _hopf_block(t), 10, 3, T_HOPF)
    with pytest.raises(ValueError, match="tol"):
        fq.floquet_analysis(J, T_HOPF, h, 3, tol=0.0)


def test_reliability_follows_the_trivial_multiplier():
    """A coarse mesh on a cycle with a fast transverse rate: the trivial multiplier drifts
    and the verdict says so; the same cycle on a fine mesh is reliable."""
    J, h = gauss_point_jacobians(lambda t: _hopf_block(t, 4.0), 3, 2, T_HOPF)
    coarse = fq.floquet_analysis(J, T_HOPF, h, 2, tol=1e-4)
    assert coarse.trivial_error > 1e-4 and not coarse.reliable
    J, h = gauss_point_jacobians(lambda t: _hopf_block(t, 4.0), 60, 4, T_HOPF)
    assert fq.floquet_analysis(J, T_HOPF, h, 4, tol=1e-4).reliable


# ---------------------------------------------------------------------------------------
# Lorenz: the cycles of the subcritical Hopf of C+ towards the homoclinic orbit
# ---------------------------------------------------------------------------------------
SIGMA, BETA = 10.0, 8.0 / 3.0
RHO_HOPF = SIGMA * (SIGMA + BETA + 3.0) / (SIGMA - BETA - 1.0)


def _lorenz(x, p):
    s, r, b = p[0], p[1], p[2]
    return jnp.array([s * (x[1] - x[0]), r * x[0] - x[1] - x[0] * x[2], x[0] * x[1] - b * x[2]])


def _orbit_gauss_jacobians(system, orbit):
    """Jacobian at the Gauss points of a collocation orbit (its node values interpolated)."""
    m, ntst = orbit.ncol, orbit.ntst
    _, _, _, L, _ = collocation_tables(m)
    U = np.asarray(orbit.states).reshape(-1, system.dim)
    J = np.empty((ntst, m, system.dim, system.dim))
    for j in range(ntst):
        nodes = U[j * m: j * m + m + 1]
        for k, x in enumerate(L @ nodes):
            J[j, k] = system.jacobian(x, orbit.p)
    return J, np.diff(orbit.mesh)


def test_lorenz_cycle_branch_keeps_the_trivial_multiplier_at_one():
    from maglev_match.dynamics.cycles import cycle_branch, hopf_start
    from maglev_match.dynamics.system import System

    system = System(rhs=_lorenz, p=np.array([SIGMA, RHO_HOPF, BETA]),
                    param_names=("sigma", "rho", "beta"), state_names=("x", "y", "z"),
                    state_scale=np.array([8.0, 8.0, 20.0]), name="lorenz")
    xe = math.sqrt(BETA * (RHO_HOPF - 1.0))
    x = np.array([xe, xe, RHO_HOPF - 1.0])
    w, V = np.linalg.eig(system.jacobian(x))
    k = int(np.argmax(w.imag))
    assert abs(w[k].real) < 1e-12  # the closed-form Hopf value
    start = hopf_start(system, x, system.p, "rho", float(w[k].imag), V[:, k])
    T0 = 2 * math.pi / w[k].imag
    br = cycle_branch(system, start, "rho", ntst=80, ncol=4, max_steps=150,
                      max_period_factor=8.0, ds_max=0.5)
    periods = br.periods
    assert periods[-1] > 7.0 * T0  # well into the approach to the homoclinic orbit
    assert br.values[-1] < 13.93  # the homoclinic value is rho = 13.926...
    triv_err = np.array([abs(pt.trivial_multiplier - 1.0) for pt in br.points])
    assert np.all(triv_err <= fq.DEFAULT_TRIVIAL_TOL), triv_err.max()
    # saddle cycles: one real multiplier > 1, one real in (0, 1); never a PD or NS pattern
    for pt in br.points:
        mu = np.asarray(pt.multipliers)
        assert np.all(np.abs(np.imag(mu)) == 0.0) and np.all(np.real(mu) > 0.0)
        assert pt.n_unstable == 1
    assert not [s for s in br.special_points if s.type in ("PD", "NS")]
    # at the long-period end the explicit product has lost the trivial multiplier
    J, h = _orbit_gauss_jacobians(system, br.points[-1].orbit)
    res = fq.floquet_analysis(J, br.points[-1].period, h, 4)
    assert res.reliable and res.trivial_error < 1e-5
    naive = fq.floquet_multipliers_product(J, br.points[-1].period, h, 4)
    assert np.min(np.abs(naive - 1.0)) > 1e-3


def test_non_finite_jacobian_is_an_error_not_a_result():
    J, h = gauss_point_jacobians(lambda t: _hopf_block(t), 10, 3, T_HOPF)
    J[3, 1, 0, 0] = np.nan
    with pytest.raises(ValueError, match="not finite"):
        fq.floquet_multipliers_from_blocks(J, T_HOPF, h, 3)


def test_block_cyclic_qr_is_refused_when_its_error_bound_fails():
    """Two factors whose product has multipliers 1e-32, 1 and 900: the square roots 1e-16
    next to 30 in the block cyclic matrix cannot be resolved to 1e-10 relative by an
    unstructured QR, so the bound refuses the cyclic result (None) and the periodic QZ is
    used; with a mild spread (multipliers 0.25 .. 4) the bound accepts it and the result
    equals the periodic QZ's to 1e-10."""
    S = np.array([[1.0, 0.4, 0.1], [0.2, 1.0, -0.3], [0.0, 0.5, 1.0]])
    Si = np.linalg.inv(S)
    # upper triangular factors: the multipliers are exactly the products of the diagonals
    wide = np.array([[[1e-16, 0.3, 0.2], [0.0, 1.0, 0.5], [0.0, 0.0, 30.0]],
                     [[1e-16, -0.7, 0.1], [0.0, 1.0, 0.9], [0.0, 0.0, 30.0]]])
    assert fq._cyclic_multipliers(wide) is None
    pe = fq.periodic_eigenvalues(wide)
    assert np.allclose(np.sort(pe.log_abs), np.log([1e-32, 1.0, 900.0]), rtol=0, atol=1e-9)
    mild = np.array([S @ np.diag([0.5, 1.0, 2.0]) @ Si, S @ np.diag([0.5, -1.0, 2.0]) @ Si])
    la, ph, bound = fq._cyclic_multipliers(mild)
    assert bound <= fq.CYCLIC_RTOL
    exact = np.array([0.25, -1.0, 4.0])
    got = np.exp(la) * np.exp(1j * ph)
    assert rel_match(got, exact) < 1e-10
    assert rel_match(fq.periodic_eigenvalues(mild).values, got) < 1e-10


def test_floquet_method_must_be_known():
    J, h = gauss_point_jacobians(spread_jacobian, 20, 4, T_HOPF)
    with pytest.raises(ValueError, match="method"):
        fq.floquet_analysis(J, T_HOPF, h, 4, method="product")
