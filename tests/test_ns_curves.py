"""Neimark-Sacker (torus) curves of cycles in two parameters (``cycle_curve(kind="NS")``)
against :func:`systems.ns_system`, whose Floquet multipliers are known in closed form along
its cycles (derivation there): 1, exp(-2 beta T), exp((gamma - beta^2) T) e^{+-i T / 2} and
-exp((-ALPHA +- sqrt(beta)) T), T = 2 pi / (1 + beta). So

* the NS curve is gamma = beta^2, with the critical angle theta = pi / (1 + beta);
* on it the strong resonances R3 (kappa = cos theta = -1/2) at beta = 1/2 and R4
  (kappa = 0) at beta = 1 (gamma = beta^2);
* a real multiplier passes -1 at beta = ALPHA^2 = 1.21: a flip-NS point (PDNS).

The curve starts from the NS point that an independent one-parameter cycle branch locates
(at gamma = 0.36: beta = 0.6).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from systems import NS_ALPHA, ns_plane_vector, ns_system

from maglev_match.dynamics.cycle_curves import CurveStop, cycle_curve, start_from
from maglev_match.dynamics.cycles import cycle_branch, hopf_start


@pytest.fixture(scope="module")
def ns_start():
    S = ns_system()
    p = S.params_with(beta=0.0, gamma=0.36)
    br = cycle_branch(S, hopf_start(S, np.zeros(6), p, "beta", 1.0, ns_plane_vector(), None),
                      "beta", stop_at=0.8, ntst=20, ncol=4, max_steps=200)
    return S, br


@pytest.fixture(scope="module")
def ns_curve(ns_start):
    S, br = ns_start
    return cycle_curve(S, start_from(br, "NS1"), "NS", ("beta", "gamma"),
                       ranges={"beta": (0.3, 1.3)}, direction=0, ds_max=1.0, max_steps=300)


def test_the_branch_locates_the_start(ns_start):
    _, br = ns_start
    ns = [sp for sp in br.special_points if sp.type == "NS"]
    assert len(ns) == 1 and ns[0].value == pytest.approx(0.6, abs=1e-7)


def test_ns_curve_is_the_closed_form(ns_curve):
    cv = ns_curve
    assert cv.ok and cv.stopped_reason == CurveStop.BOUND and not cv.warnings
    beta, gamma = cv.p1, cv.p2
    assert beta[0] == pytest.approx(0.3, abs=1e-12) and beta[-1] == pytest.approx(1.3)
    assert np.all(np.diff(beta) > 0)
    assert np.max(np.abs(gamma - beta ** 2)) < 1e-7
    theta = np.array([c.angle for c in cv.points])
    assert np.max(np.abs(theta - math.pi / (1.0 + beta))) < 1e-7
    kappa = np.array([c.kappa for c in cv.points])
    assert np.max(np.abs(kappa - np.cos(math.pi / (1.0 + beta)))) < 1e-7
    np.testing.assert_allclose(cv.periods, 2 * math.pi / (1.0 + beta), rtol=1e-9)
    # the exact Jacobian (complex test function and its theta derivative): quadratic
    # convergence; a wrong derivative needs many more iterations or fails
    assert max(c.iterations for c in cv.points[1:]) <= 4
    for c in cv.points:  # the Floquet multipliers have the pair e^{+-i theta}
        assert c.reliable and c.test < 1e-9
        assert np.min(np.abs(c.multipliers - np.exp(1j * c.angle))) < 1e-7
        assert np.min(np.abs(c.multipliers - np.exp(-1j * c.angle))) < 1e-7


def test_resonances_and_flip_ns_on_the_ns_curve(ns_curve):
    sps = ns_curve.special_points
    assert [s.type for s in sps] == ["R3", "R4", "PDNS"]
    assert all(s.located == "solved" for s in sps)
    want = {"R3": 0.5, "R4": 1.0, "PDNS": NS_ALPHA ** 2}
    for s in sps:
        b = want[s.type]
        assert s.values[0] == pytest.approx(b, abs=1e-7), s.type
        assert s.values[1] == pytest.approx(b * b, abs=1e-7), s.type
    r3, r4, pdns = sps
    assert r3.point.kappa == pytest.approx(-0.5, abs=1e-9)
    assert r4.point.kappa == pytest.approx(0.0, abs=1e-9)
    assert np.min(np.abs(pdns.point.multipliers + 1.0)) < 1e-7


def test_ns_curve_xarray(ns_curve):
    ds = ns_curve.to_xarray()
    assert ds.attrs["kind"] == "NS"
    np.testing.assert_allclose(ds["kappa"].values, [c.kappa for c in ns_curve.points])
    assert list(ds["special_type"].values) == ["R3", "R4", "PDNS"]


def test_no_complex_pair_is_reported_not_raised():
    """A cycle with only real multipliers (the period-doubling system's) cannot start an
    NS curve: the curve says so."""
    from systems import PD_OMEGA, pd_system_2p

    S = pd_system_2p()
    p = S.params_with(nu=0.0)
    q = np.array([1.0, -1.0j, 0.0, 0.0]) / math.sqrt(2.0)
    br = cycle_branch(S, hopf_start(S, np.zeros(4), p, "nu", PD_OMEGA, q, -1.0), "nu",
                      ntst=20, ncol=4, stop_at=0.1, max_steps=50)
    cv = cycle_curve(S, br.points[-1].orbit, "NS", ("nu", "alpha"))
    assert cv.stopped_reason == CurveStop.START_FAILED and not cv.ok
    assert not cv.points and "no complex pair" in cv.warnings[0]


NS_FILE = '''import jax.numpy as jnp

STATES = ["x", "y", "u", "w"]
PARAMS = {"beta": 0.1, "gamma": 0.36}
X0 = [0.0, 0.0, 0.0, 0.0]


def rhs(x, p):
    r2 = x[0] ** 2 + x[1] ** 2
    om = 1.0 + r2
    a = p["gamma"] - r2 * r2
    q2 = x[2] ** 2 + x[3] ** 2
    return jnp.array([p["beta"] * x[0] - om * x[1] - x[0] * r2,
                      om * x[0] + p["beta"] * x[1] - x[1] * r2,
                      a * x[2] - 0.5 * x[3] - q2 * x[2],
                      0.5 * x[2] + a * x[3] - q2 * x[3]])
'''


def test_ns_command_for_a_user_model(tmp_path, capsys):
    """`cycle-curve --kind NS` on a user model file (ns_system without the rotation and
    the Moebius block): started directly (the branch along beta at gamma = 0.36, NS1 at
    beta = 0.6) and from a saved branch (--restart FILE --label NS1); the closed form
    gamma = beta^2 and R3, R4 at beta = 1/2, 1 in the text, JSON and netCDF answers."""
    import json

    import xarray as xr

    from maglev_match.cli import main

    model = tmp_path / "ns.py"
    model.write_text(NS_FILE)
    out = tmp_path / "out"
    code = main(["cycle-curve", "--model", str(model), "--kind", "NS", "--params",
                 "beta,gamma", "--from", "-0.5", "--to", "0.5", "--ntst", "20", "--range",
                 "gamma=0.2:1.2", "--out", str(out)])
    text = capsys.readouterr().out
    assert code == 0, text
    assert "NS curve of cycles in (beta, gamma)" in text and "kappa" in text
    assert "R31: R3 at beta = 0.5, gamma = 0.25 (solved)" in text
    assert "R41: R4 at beta = 1, gamma = 1 (solved)" in text
    ds = xr.load_dataset(next(out.glob("*.nc")), engine="h5netcdf")
    beta, gamma = ds["beta"].values, ds["gamma"].values
    assert gamma.min() == pytest.approx(0.2) and gamma.max() == pytest.approx(1.2)
    assert np.max(np.abs(gamma - beta ** 2)) < 1e-7
    np.testing.assert_allclose(ds["kappa"].values, np.cos(math.pi / (1 + beta)), atol=1e-7)
    saved = tmp_path / "branch"
    assert main(["cycles", "--model", str(model), "--param", "beta", "--from", "-0.5",
                 "--to", "0.5", "--ntst", "20", "--max-steps", "60", "--out",
                 str(saved)]) == 0
    capsys.readouterr()
    code = main(["cycle-curve", "--model", str(model), "--kind", "NS", "--params",
                 "beta,gamma", "--restart", str(next(saved.glob("*.nc"))), "--label", "NS1",
                 "--range", "gamma=0.3:0.5", "--json"])
    res = json.loads(capsys.readouterr().out)
    assert code == 0 and res["ok"] and res["kind"] == "NS"
    assert res["restart_of"].startswith("NS1 of")
    assert max(abs(p["gamma"] - p["beta"] ** 2) for p in res["points"]) < 1e-7
    assert max(abs(p["kappa"] - math.cos(math.pi / (1 + p["beta"])))
               for p in res["points"]) < 1e-7


def test_ns_curve_with_mesh_adaptation(ns_start):
    """The mesh adapted every 3 steps (profile, tangent and the complex border remapped,
    the borders refreshed) keeps the closed form and the quadratic convergence. (The cycle
    is a circle, so the adapted mesh stays uniform: this exercises the remapping and the
    refreshed complex borders, not a moved mesh.)"""
    S, br = ns_start
    cv = cycle_curve(S, start_from(br, "NS1"), "NS", ("beta", "gamma"),
                     ranges={"beta": (0.3, 0.9)}, direction=1, adapt_every=3, ds_max=1.0)
    assert cv.ok and cv.stopped_reason == CurveStop.BOUND and not cv.warnings
    assert np.max(np.abs(cv.p2 - cv.p1 ** 2)) < 1e-7
    theta = np.array([c.angle for c in cv.points])
    assert np.max(np.abs(theta - math.pi / (1.0 + cv.p1))) < 1e-7
    assert max(c.iterations for c in cv.points[1:]) <= 4
