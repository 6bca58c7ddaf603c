"""Curves of cycle bifurcations in two parameters (``dynamics.cycle_curves``) against
normal forms whose curves are known in closed form:

* the Bautin normal form r' = r (mu + l1 r^2 - r^4), theta' = omega: a cycle of radius r
  exists where g(s) = mu + l1 s - s^2 = 0 (s = r^2) and folds where also g'(s) = l1 - 2 s
  = 0, so the fold of cycles (LPC) is s = l1 / 2, mu = -l1^2 / 4: l1^2 + 4 mu = 0, l1 > 0;
* :func:`systems.pd_system_2p`: the period doubling nu = alpha^2 (derivation there);
* :func:`systems.bautin_flip_system`: the same LPC curve, with a transverse multiplier
  -exp(-alpha + r) that passes -1 on it at r = alpha, i.e. a fold-flip point (LPPD) at
  l1 = 2 alpha^2, mu = -alpha^4 (alpha = 0.5: (-1/16, 1/2)).

Each curve is started from the special point located on an independent one-parameter
cycle branch (``cycle_branch``), as a user does.
"""

from __future__ import annotations

import math

import matplotlib
import numpy as np
import pytest
from systems import (
    BAUTIN_NF,
    CYCLE_OMEGA,
    PD_OMEGA,
    Q_CRIT,
    bautin_flip_system,
    embedded,
    pd_system_2p,
)

from maglev_match.dynamics.cycle_curves import CurveStop, cycle_curve, start_from
from maglev_match.dynamics.cycles import cycle_branch, hopf_start

matplotlib.use("Agg")

Q_PLANE = np.array([1.0, -1.0j, 0.0, 0.0]) / math.sqrt(2.0)


def _fold_orbit(system, l1, label="LPC1", **kw):
    p = system.params_with(mu=0.0, l1=l1)
    x0 = np.zeros(system.dim)
    q = Q_CRIT if system.dim == 5 else Q_PLANE
    om = CYCLE_OMEGA if system.dim == 5 else PD_OMEGA
    br = cycle_branch(system, hopf_start(system, x0, p, "mu", om, q, l1), "mu",
                      stop_at=0.5, max_steps=200, **kw)
    return br, start_from(br, label)


@pytest.fixture(scope="module")
def bautin_fold():
    return _fold_orbit(BAUTIN_NF, 1.0, ntst=20, ncol=4)


@pytest.mark.parametrize("direction, end", [(1, 1.6), (-1, 0.4)])
def test_bautin_lpc_curve_is_the_closed_form(bautin_fold, direction, end):
    br, orbit = bautin_fold
    assert orbit.p[0] == pytest.approx(-0.25, abs=1e-9)  # the branch's fold at l1 = 1
    cv = cycle_curve(BAUTIN_NF, orbit, "LPC", ("mu", "l1"), ranges={"l1": (0.4, 1.6)},
                     direction=direction, ds_max=1.0, max_steps=300)
    assert cv.ok and cv.stopped_reason == CurveStop.BOUND, cv.warnings
    assert not cv.warnings
    mu, l1 = cv.p1, cv.p2
    assert np.max(np.abs(l1 ** 2 + 4.0 * mu)) < 1e-8
    assert l1[-1] == pytest.approx(end, abs=1e-12) and cv.points[-1].kind == "bound"
    assert np.all(np.diff(l1) * direction > 0)  # followed in the asked direction
    # radius^2 = l1 / 2 on the curve, the period 2 pi / omega
    r = np.array([c.extrema["radius"][0] for c in cv.points])
    np.testing.assert_allclose(r ** 2, l1 / 2.0, rtol=1e-7)
    np.testing.assert_allclose(cv.periods, 2 * math.pi / CYCLE_OMEGA, rtol=1e-9)
    # the exact Jacobian: Newton converges quadratically (a wrong derivative of the test
    # function would need many more iterations, or fail)
    assert max(c.iterations for c in cv.points[1:]) <= 4
    # at a fold the critical multiplier is 1 too; the stable 3-block's are inside
    for c in cv.points:
        assert c.reliable
        assert np.min(np.abs(c.multipliers - 1.0)) < 1e-5
        assert abs(c.test) < 1e-9


def test_both_ways_with_mesh_adaptation(bautin_fold):
    """direction=0 follows both halves from the start (one curve, from the decreasing
    end); the mesh adapted every 3 steps (profile, tangent and borders remapped) keeps the
    closed form."""
    _, orbit = bautin_fold
    cv = cycle_curve(BAUTIN_NF, orbit, "LPC", ("mu", "l1"), ranges={"l1": (0.4, 1.6)},
                     direction=0, adapt_every=3, ds_max=1.0, max_steps=300)
    assert cv.ok and not cv.warnings
    assert [c.kind for c in cv.points].count("start") == 1
    assert cv.points[0].kind == cv.points[-1].kind == "bound"
    assert cv.p2[0] == pytest.approx(0.4, abs=1e-12) and cv.p2[-1] == pytest.approx(1.6)
    assert np.all(np.diff(cv.p2) > 0)
    assert np.max(np.abs(cv.p2 ** 2 + 4.0 * cv.p1)) < 1e-8
    assert max(c.iterations for c in cv.points) <= 4


def test_lpc_curve_from_the_generalised_hopf_point():
    """Branch switching at GH: the Hopf curve of the Bautin normal form (mu = 0) has its GH
    point at l1 = 0 (with l2 = -1 in r' = r (mu + l1 r^2 - r^4), -2 in the package's
    scaling <q, q> = 1); a step to l1 > 0 (l1 l2 < 0), the fold of the small cycles there
    (mu = -l1^2 / 4), and its curve down towards GH and up: the closed form again."""
    from maglev_match.dynamics.cycle_curves import lpc_from_generalised_hopf
    from maglev_match.dynamics.hopf import locate_hopf_points
    from maglev_match.dynamics.hopf_curve import hopf_curve

    p = BAUTIN_NF.params_with(l1=-0.5)
    hopf = locate_hopf_points(BAUTIN_NF, "mu", -1.0, 1.0, p=p, n_scan=20).points[0]
    hc = hopf_curve(BAUTIN_NF, ("mu", "l1"), hopf, {"mu": (-1.0, 1.0), "l1": (-0.5, 0.5)},
                    p=p)
    gh = [sp for sp in hc.special_points if sp.type == "GH"]
    assert len(gh) == 1 and gh[0].values[1] == pytest.approx(0.0, abs=1e-9)
    assert gh[0].l2 < 0
    g = gh[0]
    x = min(hc.points, key=lambda c: abs(c.values[1] - g.values[1])).x
    pg = BAUTIN_NF.params_with(p, mu=g.values[0], l1=g.values[1])
    with pytest.raises(ValueError, match="no fold of cycles"):  # l1 l2 > 0 there
        lpc_from_generalised_hopf(BAUTIN_NF, x, pg, g.frequency, ("mu", "l1"), offset=-0.02,
                                  l2=g.l2)
    cv, br = lpc_from_generalised_hopf(
        BAUTIN_NF, x, pg, g.frequency, ("mu", "l1"), offset=0.02, l2=g.l2,
        ranges={"l1": (0.002, 0.5)}, direction=0, ds_max=1.0, max_steps=300,
        scales=(0.01, 0.05))
    assert [s.type for s in br.special_points][:1] == ["LPC"]
    assert cv.ok and cv.p2[0] == pytest.approx(0.002) and cv.p2[-1] == pytest.approx(0.5)
    assert np.max(np.abs(cv.p2 ** 2 + 4.0 * cv.p1)) < 1e-8


def test_pd_curve_is_the_closed_form():
    S = pd_system_2p()
    p = S.params_with(nu=0.0)
    br = cycle_branch(S, hopf_start(S, np.zeros(4), p, "nu", PD_OMEGA, Q_PLANE, -1.0), "nu",
                      ntst=20, ncol=4, stop_at=0.5, max_steps=200)
    orbit = start_from(br, "PD1")
    cv = cycle_curve(S, orbit, "PD", ("nu", "alpha"), ranges={"alpha": (0.3, 0.8)},
                     ds_max=1.0, max_steps=300)
    assert cv.ok and cv.stopped_reason == CurveStop.BOUND, cv.warnings
    nu, alpha = cv.p1, cv.p2
    assert alpha[-1] == pytest.approx(0.8, abs=1e-12)
    assert np.max(np.abs(nu - alpha ** 2)) < 1e-7
    for c in cv.points:
        assert np.min(np.abs(c.multipliers + 1.0)) < 1e-7
    assert not cv.special_points  # no second multiplier reaches +1 or the circle


def test_fold_flip_point_on_the_lpc_curve():
    S = bautin_flip_system()
    br, orbit = _fold_orbit(S, 1.0, ntst=20, ncol=4)
    assert [s.type for s in br.special_points] == ["PD", "LPC"]
    cv = cycle_curve(S, orbit, "LPC", ("mu", "l1"), ranges={"l1": (0.3, 1.5)},
                     direction=-1, ds_max=1.0, max_steps=300)
    assert cv.ok
    assert np.max(np.abs(cv.p2 ** 2 + 4.0 * cv.p1)) < 1e-8
    assert [s.type for s in cv.special_points] == ["LPPD"]
    sp = cv.special_points[0]
    assert sp.label == "LPPD1" and sp.located == "solved"
    assert sp.values[0] == pytest.approx(-1.0 / 16.0, abs=1e-7)
    assert sp.values[1] == pytest.approx(0.5, abs=1e-7)
    assert np.min(np.abs(sp.point.multipliers + 1.0)) < 1e-7


def test_cusp_of_cycles_is_solved():
    """g(s) = mu + l1 s + 0.3 s^2 - s^3: folds where g = g' = 0, a cusp where also g'' = 0:
    s = 0.1, l1 = -0.03, mu = 0.001. The LPC curve (mu, l1) = (0.3 s^2 - 2 s^3,
    -0.6 s + 3 s^2) turns back there (s the squared radius); the CPC is solved where its
    tangent in the parameter plane vanishes (dynamics/cycle_curves/cusp.py)."""
    S = embedded(lambda mu, l1, r2: mu + l1 * r2 + 0.3 * r2 ** 2 - r2 ** 3)
    br, orbit = _fold_orbit(S, 0.2, ntst=20, ncol=4)
    cv = cycle_curve(S, orbit, "LPC", ("mu", "l1"), ranges={"l1": (-0.2, 0.2)},
                     direction=-1, ds_max=0.5, max_steps=400, scales=(0.01, 0.01))
    s = np.array([c.extrema["radius"][0] for c in cv.points]) ** 2
    np.testing.assert_allclose(cv.p1, 0.3 * s ** 2 - 2 * s ** 3, atol=1e-7)
    np.testing.assert_allclose(cv.p2, -0.6 * s + 3 * s ** 2, atol=1e-7)
    cpc = [sp for sp in cv.special_points if sp.type == "CPC"]
    assert len(cpc) == 1 and cpc[0].located == "solved"
    assert cpc[0].values[0] == pytest.approx(0.001, abs=1e-9)
    assert cpc[0].values[1] == pytest.approx(-0.03, abs=1e-8)
    assert cpc[0].point.extrema["radius"][0] ** 2 == pytest.approx(0.1, abs=1e-7)


def test_a_stall_at_the_generalised_hopf_end_is_reported():
    """Followed down towards GH (l1 -> 0) the fold's cycle shrinks to the equilibrium and
    the collocation problem degenerates: the curve stops with the reason and the place in
    its warning, and every point it kept is on the closed form."""
    br, orbit = _fold_orbit(BAUTIN_NF, 0.2, ntst=20, ncol=4)
    cv = cycle_curve(BAUTIN_NF, orbit, "LPC", ("mu", "l1"), ranges={"l1": (-0.5, 1.0)},
                     direction=-1, ds_max=1.0, max_steps=300, scales=(0.01, 0.05))
    assert cv.stopped_reason == CurveStop.STEP_TOO_SMALL and not cv.ok
    assert len(cv.warnings) == 1 and "the LPC curve stopped at (mu, l1)" in cv.warnings[0]
    assert 0 < cv.p2[-1] < 1e-3 and cv.amplitudes[-1] < 0.05
    assert np.max(np.abs(cv.p2 ** 2 + 4.0 * cv.p1)) < 1e-8


def test_no_fold_is_reported_not_raised():
    """A supercritical Hopf family (l1 < 0 in r' = r (mu + l1 r^2)) has no fold of cycles:
    the start cannot be corrected onto an LPC curve, and the curve says so."""
    S = embedded(lambda mu, l1, r2: mu + l1 * r2)
    p = S.params_with(mu=0.0, l1=-1.0)
    br = cycle_branch(S, hopf_start(S, np.zeros(5), p, "mu", CYCLE_OMEGA, Q_CRIT, -1.0),
                      "mu", stop_at=0.3, ntst=20, ncol=4)
    cv = cycle_curve(S, br.points[-1].orbit, "LPC", ("mu", "l1"))
    assert cv.stopped_reason == CurveStop.START_FAILED and not cv.ok
    assert not cv.points and "could not be corrected" in cv.warnings[0]


def test_curve_result_xarray_and_figure(bautin_fold, tmp_path):
    _, orbit = bautin_fold
    cv = cycle_curve(BAUTIN_NF, orbit, "LPC", ("mu", "l1"), ranges={"l1": (0.9, 1.1)})
    ds = cv.to_xarray()
    for name, var in ds.data_vars.items():
        assert "units" in var.attrs and var.attrs.get("long_name"), name
    path = tmp_path / "curve.nc"
    ds.to_netcdf(path, engine="h5netcdf")
    import xarray as xr

    back = xr.load_dataset(path, engine="h5netcdf")
    np.testing.assert_array_equal(back["mu"].values, cv.p1)
    np.testing.assert_array_equal(back["l1"].values, cv.p2)
    assert back.attrs["kind"] == "LPC" and back.attrs["stopped_reason"] == cv.stopped_reason
    from matplotlib.figure import Figure

    assert isinstance(cv.plot(), Figure)
    files = cv.plot(tmp_path / "curve.png")
    assert all(f.exists() for f in files)
