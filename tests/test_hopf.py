"""Hopf points, Hopf curve, Lyapunov coefficients.

Known answers: the Hopf and Bautin normal forms embedded in a larger stable system,
rotated by a random orthogonal matrix and deformed by a nonlinear change of coordinates;
on model A, the Hopf curve against an independent eigenvalue scan and l1 by autodiff against
l1 by finite differences.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest
import scipy.optimize
from systems import DIM, OMEGA, bautin_system

from maglev_match.dynamics.hopf import (
    first_lyapunov_coefficient,
    hopf_eigenvectors,
    locate_hopf_points,
    second_lyapunov_coefficient,
)
from maglev_match.dynamics.hopf_curve import hopf_curve, stability_grid
from maglev_match.dynamics.system import System


@pytest.fixture(scope="module")
def bautin_pos():
    return bautin_system()


def test_hopf_point_of_rotated_normal_form_is_exact(bautin_pos):
    beta2 = -0.3
    p = bautin_pos.params_with(beta2=beta2)
    scan = locate_hopf_points(bautin_pos, "beta1", -0.7, 0.9, p, n_scan=23)
    assert len(scan.points) == 1
    hp = scan.points[0]
    assert hp.converged
    assert abs(hp.value) < 1e-10
    assert hp.frequency == pytest.approx(OMEGA, rel=1e-10)
    assert hp.l1 == pytest.approx(2 * beta2 / OMEGA, rel=1e-8)
    assert hp.crossing_speed == pytest.approx(1.0, rel=1e-8)
    assert hp.others_stable
    assert hp.kind == "supercritical"
    J = bautin_pos.jacobian(hp.x, hp.p)
    np.testing.assert_allclose(J @ hp.q, 1j * OMEGA * hp.q, atol=1e-10)
    np.testing.assert_allclose(J.T @ hp.p_adj, -1j * OMEGA * hp.p_adj, atol=1e-10)
    assert np.vdot(hp.q, hp.q) == pytest.approx(1.0)
    assert np.vdot(hp.p_adj, hp.q) == pytest.approx(1.0)


@pytest.mark.parametrize("beta2", [0.25, -0.6])
def test_first_lyapunov_coefficient_sign_and_value(bautin_pos, beta2):
    p = bautin_pos.params_with(beta2=beta2)
    l1 = first_lyapunov_coefficient(bautin_pos, np.zeros(DIM), p, OMEGA)
    assert l1 == pytest.approx(2 * beta2 / OMEGA, rel=1e-8)


@pytest.mark.parametrize("s", [0.45, -0.7])
def test_second_lyapunov_coefficient_at_bautin_point(bautin_pos, s):
    p = np.array([0.0, 0.0, s])
    l1, l2 = second_lyapunov_coefficient(bautin_pos, np.zeros(DIM), p, OMEGA)
    assert abs(l1) < 1e-12
    assert l2 == pytest.approx(4 * s / OMEGA, rel=1e-8)


def test_hopf_curve_finds_bautin_point(bautin_pos):
    start = locate_hopf_points(bautin_pos, "beta1", -0.7, 0.9,
                               bautin_pos.params_with(beta2=-0.5), n_scan=12).points[0]
    curve = hopf_curve(bautin_pos, ("beta1", "beta2"), start,
                       {"beta1": (-1.0, 1.0), "beta2": (-1.0, 0.8)}, max_step=0.05)
    assert curve.converged, curve.message
    vals = curve.values()
    assert np.max(np.abs(vals[:, 0])) < 1e-9  # the Hopf curve is beta1 = 0
    assert vals[:, 1].min() == pytest.approx(-1.0) and vals[:, 1].max() == pytest.approx(0.8)
    gh = [sp for sp in curve.special_points if sp.type == "GH"]
    assert len(gh) == 1 and len(curve.special_points) == 1
    assert abs(gh[0].values[1]) < 1e-10
    assert gh[0].l2 == pytest.approx(4 * 0.45 / OMEGA, rel=1e-7)
    l1 = curve.l1()
    np.testing.assert_allclose(l1, 2 * vals[:, 1] / OMEGA, rtol=1e-7, atol=1e-12)


def test_hopf_curve_passes_turning_point():
    """A circle of Hopf points: mu = a^2 + b^2 - 1 turns in both parameters."""

    def rhs(x, p):
        a, b = p[0], p[1]
        mu = 1.0 - a**2 - b**2
        r2 = x[0] ** 2 + x[1] ** 2
        return jnp.stack([mu * x[0] - 2.0 * x[1] - x[0] * r2,
                          2.0 * x[0] + mu * x[1] - x[1] * r2,
                          -x[2] + x[0] ** 2])

    system = System(rhs=rhs, p=np.array([0.0, 0.0]), param_names=("a", "b"),
                    state_names=("x", "y", "z"))
    start = locate_hopf_points(system, "a", 0.1, 1.6, n_scan=8).points[0]
    assert start.value == pytest.approx(1.0, rel=1e-10)
    curve = hopf_curve(system, ("a", "b"), start, {"a": (-2, 2), "b": (-2, 2)},
                       max_step=0.02)
    assert curve.converged and curve.closed, curve.message
    vals = curve.values()
    np.testing.assert_allclose(np.hypot(vals[:, 0], vals[:, 1]), 1.0, rtol=1e-9)
    assert vals[:, 0].min() < -0.99 and vals[:, 1].min() < -0.99 and vals[:, 1].max() > 0.99


# ----- model A ---------------------------------------------------------------------------
@pytest.fixture(scope="module")
def unit():
    from maglev_match.core.params import load_preset
    from maglev_match.maglev.models import build_system

    return build_system(load_preset("turnout-soft"), "unit")


@pytest.fixture(scope="module")
def unit_scan(unit):
    return locate_hopf_points(unit, "omega1", 30.0, 400.0, unit.params_with(sigma=4e-4),
                              n_scan=60)


def _max_real_part(system, p):
    return float(np.max(np.linalg.eigvals(system.jacobian(np.zeros(system.dim), p)).real))


def test_model_a_hopf_points_match_eigenvalue_bisection(unit, unit_scan):
    assert len(unit_scan.points) >= 1
    for hp in unit_scan.points:
        assert hp.converged
        root = scipy.optimize.brentq(
            lambda w, hp=hp: _max_real_part(unit, unit.params_with(hp.p, omega1=w)),
            hp.value - 2.0, hp.value + 2.0, xtol=1e-12)
        assert hp.value == pytest.approx(root, rel=1e-8)
        d = 1e-4 * hp.value
        # crossing speed against a central difference of the crossing eigenvalue

        def re_lambda(w, hp=hp):
            ev = np.linalg.eigvals(unit.jacobian(hp.x, unit.params_with(hp.p, omega1=w)))
            return ev[np.argmin(np.abs(ev - 1j * hp.frequency))].real

        fd = (re_lambda(hp.value + d) - re_lambda(hp.value - d)) / (2 * d)
        assert hp.crossing_speed == pytest.approx(fd, rel=1e-5)


def test_model_a_hopf_curve_agrees_with_grid_scan(unit, unit_scan):
    hp = unit_scan.points[0]
    bounds = {"omega1": (30.0, 400.0), "sigma": (2e-4, 6e-4)}
    curve = hopf_curve(unit, ("omega1", "sigma"), hp, bounds)
    assert curve.converged, curve.message
    vals = curve.values()
    # every point on the curve: the largest real part vanishes there (independent eig)
    for w1, sg in vals[:: max(1, len(vals) // 8)]:
        p = unit.params_with(omega1=w1, sigma=sg)
        assert abs(_max_real_part(unit, p)) < 1e-8 * w1
    # and the sign changes of max Re(lambda) on a coarse grid bracket the curve
    w_grid = np.linspace(30.0, 400.0, 75)
    s_grid = np.array([2.5e-4, 3.5e-4, 4.5e-4, 5.5e-4])
    mr, ok = stability_grid(unit, ("omega1", "sigma"), w_grid, s_grid)
    assert ok.all()
    for row, sg in zip(mr, s_grid, strict=True):
        k = np.where(np.diff(np.sign(vals[:, 1] - sg)) != 0)[0]
        assert len(k) == 1  # this branch crosses each sigma once
        j = k[0]
        w_curve = vals[j, 0] + (sg - vals[j, 1]) * (vals[j + 1, 0] - vals[j, 0]) / (
            vals[j + 1, 1] - vals[j, 1])
        i = np.searchsorted(w_grid, w_curve)
        assert np.sign(row[i - 1]) != np.sign(row[i])


def _fd_l1(system, x, p, omega, h=1e-2):
    """l1 with B and C from central finite differences (real polarisation) of f.

    The unit eigenvector is dominated by the current component (A), so h = 1e-2 is a small
    perturbation; the differences are then accurate to about 1e-7 relative."""
    J = system.jacobian(x, p)
    q, pa = hopf_eigenvectors(J, omega)

    def f(y):
        return system.f(y, p)

    def B_real(u, v):
        return (f(x + h * u + h * v) - f(x + h * u - h * v) - f(x - h * u + h * v)
                + f(x - h * u - h * v)) / (4 * h * h)

    def C_real(u, v, w):
        tot = 0.0
        for a in (1, -1):
            for b in (1, -1):
                for c in (1, -1):
                    tot = tot + a * b * c * f(x + h * (a * u + b * v + c * w))
        return tot / (8 * h**3)

    def cplx(form, *us):
        parts = [(np.real(u), np.imag(u)) for u in us]
        out = 0j
        for mask in range(2 ** len(us)):
            args = [parts[j][(mask >> j) & 1] for j in range(len(us))]
            out = out + 1j ** bin(mask).count("1") * form(*args)
        return out

    qb = np.conj(q)
    h11 = -np.linalg.solve(J, cplx(B_real, q, qb))
    h20 = np.linalg.solve(2j * omega * np.eye(len(x)) - J, cplx(B_real, q, q))
    g = np.vdot(pa, cplx(C_real, q, q, qb) + 2 * cplx(B_real, q, h11) + cplx(B_real, qb, h20))
    return g.real / (2 * omega)


def test_model_a_l1_autodiff_matches_finite_differences(unit, unit_scan):
    for hp in unit_scan.points:
        l1_fd = _fd_l1(unit, hp.x, hp.p, hp.frequency)
        assert hp.l1 == pytest.approx(l1_fd, rel=1e-5)


# ----- command line ----------------------------------------------------------------------
def _run(capsys, *args):
    from maglev_match.cli import main

    code = main(list(args))
    out = capsys.readouterr()
    return code, out.out, out.err


def test_cli_hopf_json(capsys, unit_scan):
    import json

    code, out, _ = _run(capsys, "hopf", "--param", "omega1", "--from", "100", "--to", "160",
                        "--steps", "25", "--set", "sigma=4e-4", "--json")
    assert code == 0
    doc = json.loads(out)
    assert len(doc["points"]) == 1
    rec = doc["points"][0]
    for key in ("omega1", "sigma", "frequency", "crossing_speed", "l1"):
        assert key in rec
    assert rec["sigma"] == pytest.approx(4e-4)
    ref = unit_scan.points[0]  # same Hopf point found from a different scan
    assert rec["omega1"] == pytest.approx(ref.value, rel=1e-9)
    assert rec["l1"] == pytest.approx(ref.l1, rel=1e-6)
    hs = [sp for sp in doc["special_points"] if sp["type"] == "H"]
    assert len(hs) == 1 and hs[0]["label"] == "H1" and hs[0]["located"] == "solved"
    assert hs[0]["omega1"] == pytest.approx(rec["omega1"], rel=1e-8)  # before refinement


def test_cli_hopf_curve_json_and_figure(capsys, tmp_path):
    import json

    code, out, _ = _run(capsys, "hopf-curve", "--params", "omega1,sigma", "--range",
                        "sigma=3e-4:5e-4", "--range", "omega1=100:160", "--grid", "12",
                        "--scan-steps", "20", "--out", str(tmp_path), "--json")
    assert code == 0
    doc = json.loads(out)
    pts = doc["points"]
    assert len(pts) > 5
    for key in ("omega1", "sigma", "frequency", "l1"):
        assert key in pts[0]
    s = np.array([p["sigma"] for p in pts])
    assert s.min() == pytest.approx(3e-4) and s.max() == pytest.approx(5e-4)
    assert doc["special_points"] == []
    for f in doc["figures"]:
        assert (tmp_path / f.split("/")[-1]).exists()
    import xarray as xr

    saved = xr.load_dataset(doc["netcdf"][0], engine="h5netcdf")
    n0 = sum(p["branch"] == 0 for p in pts)
    np.testing.assert_allclose(saved["sigma"].values, s[:n0])
    assert saved["sigma"].attrs["units"] == "1/kg" and saved["l1"].attrs["units"] == "1/s"
    assert all("long_name" in v.attrs for v in saved.data_vars.values())


def test_cli_hopf_curve_rejects_unknown_parameter(capsys):
    code, _, err = _run(capsys, "hopf-curve", "--params", "omega1,nonsense")
    assert code == 2
    assert "nonsense" in err


def test_hopf_curve_module_imports_first():
    """hopf_curve imports hopf (and hopf does not import hopf_curve): either module can be
    imported first in a fresh interpreter."""
    import subprocess
    import sys

    code = ("import maglev_match.dynamics.hopf_curve as hc\n"
            "from maglev_match.dynamics.hopf_curve import HopfCurve, hopf_curve\n"
            "assert HopfCurve is hc.HopfCurve and hopf_curve is hc.hopf_curve\n")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr


def test_hopf_curve_reports_a_generalised_hopf_point_at_its_start():
    """A curve started exactly on the GH point (l1 = 0 there, as when a scan starts at the
    middle of a symmetric range) reports it: the start point is the zero, and no step of
    either direction sees a sign change inside it. Bautin normal form: l2 = -2 (<q, q> = 1)."""
    from systems import BAUTIN_NF

    p = BAUTIN_NF.params_with(l1=0.0)
    start = locate_hopf_points(BAUTIN_NF, "mu", -1.0, 1.0, p=p, n_scan=20).points[0]
    assert start.l1 == 0.0  # the case: exactly on the GH point
    curve = hopf_curve(BAUTIN_NF, ("mu", "l1"), start, {"mu": (-1.0, 1.0), "l1": (-0.5, 0.5)},
                       p=p)
    assert curve.converged, curve.message
    gh = [sp for sp in curve.special_points if sp.type == "GH"]
    assert len(gh) == 1 and len(curve.special_points) == 1
    assert gh[0].values[1] == 0.0 and abs(gh[0].values[0]) < 1e-12
    assert gh[0].l2 == pytest.approx(-2.0, rel=1e-8)
    assert gh[0].located == "solved"


def test_a_form_padded_to_its_batch_is_the_form_of_the_directions_given():
    # the forms of the Lyapunov coefficients pad their directions to a multiple of the
    # order's batch (one compiled kernel per order): the rows given are the form at those
    # directions (against the bilinear form's closed form for a quadratic field), and any
    # number of directions up to the batch uses the one kernel signature
    from maglev_match.dynamics.normal_forms import FORM_BATCH, real_forms

    A = np.array([[0.3, -1.2, 0.5], [0.7, 0.1, -0.4], [-0.2, 0.9, 0.6]])

    def rhs(x, p):  # f(x) = p0 (x . A x) e0 + p1 x1 x2 e2: B(u, v) in closed form
        return jnp.array([p[0] * (x @ A @ x), 0.0 * x[1], p[1] * x[1] * x[2]])

    p = np.array([1.5, -2.0])
    x = np.array([0.1, 0.2, -0.3])
    F2 = real_forms(rhs)[2]
    rng = np.random.default_rng(3)
    for n in (1, 3, 6, FORM_BATCH[2], FORM_BATCH[2] + 2):
        u, v = rng.normal(size=(n, 3)), rng.normal(size=(n, 3))
        got = F2(x, p, u, v)
        want = np.stack([[p[0] * (ui @ (A + A.T) @ vi), 0.0,
                          p[1] * (ui[1] * vi[2] + ui[2] * vi[1])]
                         for ui, vi in zip(u, v, strict=True)])
        assert got.shape == (n, 3)
        np.testing.assert_allclose(got, want, rtol=1e-13, atol=1e-15)
    # (a local field has no stable identity: its kernel is a plain jit, which counts the
    # signatures it compiled) 1 to 8 directions: one; 10: a second
    assert F2.kernel._cache_size() == 2
