"""Models A and B and the equilibrium/stability layer."""

import numpy as np
import pytest

from maglev_match.core.params import load_preset
from maglev_match.dynamics.equilibria import eigenvalue_analysis, find_equilibrium, stability
from maglev_match.dynamics.system import System
from maglev_match.maglev.models import build_system
from maglev_match.maglev.unit import unit_system
from maglev_match.maglev.vehicle import layout, pressed_initial_state, vehicle_system

RNG = np.random.default_rng(20191118)


def central_difference_jacobian(system, x, h_rel=1e-6):
    n = system.dim
    J = np.zeros((n, n))
    for j in range(n):
        h = h_rel * system.state_scale[j]
        e = np.zeros(n)
        e[j] = h
        J[:, j] = (system.f(x + e) - system.f(x - e)) / (2 * h)
    return J


@pytest.mark.parametrize("model", ["unit", "vehicle"])
def test_autodiff_jacobian_matches_central_difference(model):
    params = load_preset("turnout-soft")
    system = build_system(params, model)
    eq = find_equilibrium(system)
    for _ in range(3):
        x = eq.x + 0.05 * system.state_scale * RNG.standard_normal(system.dim)
        J_ad = system.jacobian(x)
        J_fd = central_difference_jacobian(system, x)
        # column-wise relative agreement, scaled by the column's size
        err = np.abs(J_ad - J_fd).max(axis=0) / np.maximum(np.abs(J_ad).max(axis=0), 1e-300)
        assert err.max() < 1e-6, err.max()


def test_model_a_equilibrium_is_origin():
    system = unit_system(load_preset("alpha1"))
    assert np.all(system.f(np.zeros(9)) == 0.0)
    eq = find_equilibrium(system, x0=1e-4 * system.state_scale)
    assert eq.converged
    assert np.abs(eq.x / system.state_scale).max() < 1e-9


def test_model_a_equation_by_hand():
    """One evaluation of the vector field against the model equations written out in NumPy."""
    p = load_preset("alpha1")
    x = np.array([1e-4, 2e-3, -5e-5, 1e-3, 2e-4, -3e-3, 0.7, 5e-5, 1e-3])
    K = p.mu0 * p.N**2 * p.A
    c = x[0] - x[4] + p.c0
    r = (x[6] + p.i0) / c
    F2 = K * r**2 / 2
    ref = np.array([
        x[1],
        -F2 / p.m + (p.M + p.m) * p.g / p.m
        - p.cs / p.m * (x[1] - x[3]) - p.ks / p.m * (x[0] - x[2]),
        x[3],
        p.cs / p.M * (x[1] - x[3]) + p.ks / p.M * (x[0] - x[2]),
        x[5],
        -p.omega1**2 * x[4] - 2 * p.xi1 * p.omega1 * x[5] + p.sigma * (F2 - (p.m + p.M) * p.g),
        r * (x[1] - x[5]) + p.ke * c / K * (p.kP * x[7] + p.kD * (x[8] + x[1]) - x[6]),
        x[8] + x[1] + 2 * p.xi0 * p.omega0 * (x[0] - x[4] - x[7]),
        p.omega0**2 * (x[0] - x[4] - x[7]),
    ])
    got = unit_system(p).f(x)
    np.testing.assert_allclose(got, ref, rtol=1e-9, atol=1e-12)


def test_current_clamp_layer():
    p = load_preset("alpha1")
    smooth, limited = unit_system(p), unit_system(p, limited=True)
    x = np.zeros(9)
    x[6] = -p.i0 - 1.0  # current -1 A
    x[7] = 1e-3  # controller asks for more current (di/dt > 0): allowed to rise
    f_lim = limited.f(x)
    # no force at all: the magnet falls freely apart from the suspension, beam unloaded
    assert f_lim[1] == pytest.approx((p.m + p.M) * p.g / p.m, rel=1e-12)
    assert f_lim[6] > 0
    x[7] = -0.02  # controller asks to decrease further (kP y1 < i - i0): held
    assert limited.f(x)[6] == 0.0
    assert smooth.f(x)[6] < 0


def _mirror(params, x):
    """Mirror map x -> L - x of model B's state: frames 1 <-> 3, pitch angles change sign,
    even beam modes change sign, levitation points j <-> 7 - j."""
    n = params.n_modes
    L = layout(n)
    y = np.array(x, dtype=float)
    for blk in ("body", "body_dot"):
        b = x[L[blk]]
        z = np.array([b[4], -b[5], b[2], -b[3], b[0], -b[1], b[6], -b[7]])
        y[L[blk]] = z
    sign = np.array([(-1.0) ** (k + 1) for k in range(1, n + 1)])
    y[L["q"]] = sign * x[L["q"]]
    y[L["q_dot"]] = sign * x[L["q_dot"]]
    for blk in ("i", "y1", "v"):
        y[L[blk]] = x[L[blk]][::-1]
    return y


def test_model_b_equilibrium_residual_gaps_and_symmetry():
    params = load_preset("turnout-soft")
    system = vehicle_system(params)
    eq = find_equilibrium(system, x0=pressed_initial_state(params))  # start off-equilibrium
    assert eq.converged
    assert eq.scaled_residual < 1e-10
    gaps = system.observe("gap_deviation", eq.x)
    np.testing.assert_allclose(gaps, 0.0, atol=1e-12)
    L = layout(params.n_modes)
    assert np.all(eq.x[L["q"]][[0, 2]] > 0)  # beam deflected downwards by the weight
    assert abs(eq.x[L["q"]][1]) < 1e-15  # the antisymmetric mode carries no static load
    np.testing.assert_allclose(_mirror(params, eq.x), eq.x, atol=1e-14)


def test_model_b_vector_field_commutes_with_mirror():
    params = load_preset("turnout-soft")
    system = vehicle_system(params)
    x = system.x_guess + 0.1 * system.state_scale * RNG.standard_normal(system.dim)
    np.testing.assert_allclose(system.f(_mirror(params, x)), _mirror(params, system.f(x)),
                               rtol=1e-10, atol=1e-10)


def assert_same_spectrum(a, b, rtol):
    """Equal multisets of eigenvalues: optimal one-to-one matching, then relative distance."""
    from scipy.optimize import linear_sum_assignment

    a, b = np.asarray(a), np.asarray(b)
    assert a.shape == b.shape
    dist = np.abs(a[:, None] - b[None, :])
    rows, cols = linear_sum_assignment(dist)
    rel = dist[rows, cols] / np.maximum(np.abs(b[cols]), 1e-300)
    assert rel.max() < rtol, rel.max()


def test_model_b_decouples_into_single_unit_loops():
    """Beam made rigid and car body frozen (their rows and columns removed from model B's
    Jacobian, i.e. infinite beam stiffness and body inertia) leaves three frames.

    Precisely: each frame's heave loop (the two points moving together) equals model A's
    magnet/controller loop (states z1, z1', i, y1, v with car body and beam held at rest)
    with m = m_s/4, ks = k2/4, cs = c2/4 and the same levitation current; each pitch loop
    equals the same model-A loop with m = j_s/(4 s^2) and ks = cs = 0. So the 30
    eigenvalues of model B's restricted Jacobian are those two sets of 5, three times each.
    """
    params = load_preset("turnout-soft")
    vs = vehicle_system(params)
    L = layout(params.n_modes)
    J = vs.jacobian(vs.x_guess)
    drop = set(range(6, 8)) | set(range(14, 16)) | set(range(L["q"].start, L["q_dot"].stop))
    keep = [k for k in range(vs.dim) if k not in drop]
    eig_b = np.linalg.eigvals(J[np.ix_(keep, keep)])

    loop = [0, 1, 6, 7, 8]  # z1, z1', i - i0, y1, v of model A
    total = params.m_s / 2 + params.m_b / 6  # load per point (kg) = 2 (m + M) in model A
    ua = unit_system(params)

    def loop_eigs(m, ks, cs):
        p = ua.params_with(m=m, M=total / 2 - m, ks=ks, cs=cs, sigma=0.0)
        Ja = ua.jacobian(np.zeros(9), p)
        return np.linalg.eigvals(Ja[np.ix_(loop, loop)])

    heave = loop_eigs(params.m_s / 4, params.k2 / 4, params.c2 / 4)
    pitch = loop_eigs(params.j_s / (4 * params.s**2), 0.0, 0.0)
    expected = np.concatenate([heave] * 3 + [pitch] * 3)
    assert_same_spectrum(eig_b, expected, rtol=1e-8)
    # and with the printed defaults the heave loop IS model A's own loop (m=550, ks=12000, cs=900)
    assert_same_spectrum(heave, loop_eigs(params.m, params.ks, params.cs), rtol=1e-12)


def test_eigenvalues_of_linear_oscillator():
    """Damped oscillator x'' + 2 z w x' + w^2 x = 0: eigenvalues -z w +- i w sqrt(1 - z^2)."""
    import jax.numpy as jnp

    def rhs(x, p):
        return jnp.stack([x[1], -p[0] ** 2 * x[0] - 2 * p[1] * p[0] * x[1]])

    s = System(rhs=rhs, p=np.array([3.0, 0.1]), param_names=("w", "zeta"),
               state_names=("x", "v"))
    res = stability(s)
    w, z = 3.0, 0.1
    assert res.stable
    np.testing.assert_allclose(res.eigenvalues[0], complex(-z * w, w * np.sqrt(1 - z**2)),
                               rtol=1e-13)
    assert res.max_real_part == pytest.approx(-z * w, rel=1e-13)
    unstable = stability(s, p=np.array([3.0, -0.1]))
    assert not unstable.stable and unstable.max_real_part == pytest.approx(0.3)


def test_ill_conditioned_eigenproblem_is_reported():
    J = np.array([[-1.0, 1e9], [0.0, -1.0 - 1e-9]])
    _, cond = eigenvalue_analysis(J)
    assert cond.max() > 1e8


def test_root_locus_follows_analytic_eigenvalues():
    import jax.numpy as jnp

    from maglev_match.dynamics.equilibria import root_locus

    def rhs(x, p):
        return jnp.stack([x[1], -p[0] ** 2 * x[0] - 2 * p[1] * p[0] * x[1]])

    s = System(rhs=rhs, p=np.array([3.0, 0.1]), param_names=("w", "zeta"),
               state_names=("x", "v"))
    zetas = np.linspace(-0.5, 0.5, 11)
    rl = root_locus(s, "zeta", zetas)
    np.testing.assert_allclose(rl.max_real_part, -zetas * 3.0, atol=1e-12)
    assert rl.converged.all()


def test_turnout_beams_stability_both_models():
    """Both models give a verdict with a converged equilibrium on both turnout beams."""
    for name in ("turnout-soft", "turnout-stiff"):
        for model in ("unit", "vehicle"):
            res = stability(build_system(load_preset(name), model))
            assert res.equilibrium.converged
            assert np.isfinite(res.max_real_part)
