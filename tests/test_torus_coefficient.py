"""The Neimark-Sacker normal-form coefficient on NS curves of cycles, the Chenciner point
(CH) and the fold-Neimark-Sacker point (LPNS) on them, against a system whose normal form
is known in closed form (:mod:`torus_system`).

The system: a cycle x = (cos 2 pi t, sin 2 pi t) (period T = 1, radial multiplier
e^{-2}), a transverse pair y rotating at omega_t = 0.6 pi with w = y1 + i y2,

    w' = (mu + s + a |w|^2 + i omega_t) w + b w^2 + i k |w|^2,    s' = nu - s^2 + c |w|^2,

so on the cycle (y = 0, s = s* = sqrt(nu)) the multipliers are e^{mu + s* +- i omega_t}
(theta = 0.6 pi) and e^{-2 s*}: the NS curve is mu = -sqrt(nu). Its normal form: s
relaxes at the rate 2 s* to the slow manifold s - s* = c |w|^2 / (2 s*) + O(|w|^4) (|w|^2
changes at O(|w|^4) on the NS curve), which adds c / (2 s*) to a; the quadratic terms
(g20 = 2 b, g11 = i k) add Re{i (g20 g11 - 2 |g11|^2) / (2 omega_t)} = -b k / omega_t
(the Hopf formula of c1, Kuznetsov 2004 sec. 3.5). So the flow's resonant coefficient is
Re c1 = a_e = a - b k / omega_t + c / (2 s*), and over one period (at mu + s* = 0) the
normal-form coordinate zeta -> e^{i theta} zeta (1 + c1 T |zeta|^2 + ...). With the
critical eigenvector of unit norm in the section, q = (e_y1 - i e_y2) / sqrt 2 (up to a
phase), w = sqrt 2 z: z -> e^{i theta} z (1 + 2 c1 T |z|^2): d = 2 T a_e. (a checks the
formula's C term, c its B(q, (I - A)^{-1} B(q, qbar)) term, b k the
B(qbar, (e^{2 i theta} I - A)^{-1} B(q, q)) term too: with b = 1, k = 0.5 the sign of that
term's conjugation or of its 2 theta, flipped, moves d by a factor 4 or more.)

CH: d = 0 on the NS curve at a = -c / (2 s*). LPNS: on the curve continued in (nu, mu)
it is nu = mu^2 (s* = -mu: past mu = 0 the cycle is the one with s* = -sqrt(nu) < 0), and
the multiplier e^{-2 s*} passes 1 at mu = nu = 0 while the pair stays on the circle.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from torus_system import OMEGA_T, torus_cycle, torus_system

from maglev_match.dynamics.cycle_curves import cycle_curve
from maglev_match.dynamics.cycle_curves.torus import torus_coefficient


@pytest.mark.parametrize("a, c, s, b, k", [(0.3, 0.1, 0.5, 0.0, 0.0),
                                           (-0.2, 0.3, 0.5, 0.0, 0.0),
                                           (0.05, -0.1, 0.8, 0.0, 0.0),
                                           (0.3, 0.1, 0.5, 1.0, 0.5),
                                           (-0.2, 0.3, 0.5, -0.7, 0.4),
                                           (0.1, 0.0, 0.5, 0.5, -1.0)])
def test_torus_coefficient_is_the_closed_form(a, c, s, b, k):
    tc = torus_coefficient(torus_system(), torus_cycle(s, mu=-s, a=a, c=c, b=b, k=k))
    assert tc.ok, tc.message
    assert tc.multiplier == pytest.approx(complex(math.cos(OMEGA_T), math.sin(OMEGA_T)),
                                          abs=1e-7)
    d = 2.0 * (a - b * k / OMEGA_T + c / (2.0 * s))
    assert tc.d == pytest.approx(d, rel=1e-6)
    assert np.sign(tc.d) == np.sign(d)
    assert tc.error < 1e-3 * abs(d)


def test_coefficient_along_the_ns_curve_and_the_ch_point():
    """Started off the curve (mu = -0.45 at a = 0.3; c = 0.1, b = 1, k = 0.5, s* = 0.5),
    corrected onto mu = -0.5 and followed down to a = -0.3: d = 2 (a - 0.5 / omega_t +
    0.1) at every point, one CH, solved, at a = 0.5 / omega_t - 0.1 (mu = -0.5)."""
    S = torus_system()
    cv = cycle_curve(S, torus_cycle(0.5, mu=-0.45, a=0.3, c=0.1, b=1.0, k=0.5), "NS",
                     ("mu", "a"), ranges={"a": (-0.3, 0.3)}, direction=-1, ds_max=0.5,
                     max_steps=100)
    assert cv.ok, cv.warnings
    mu, a = cv.p1, cv.p2
    assert a[0] == pytest.approx(0.3) and a[-1] == pytest.approx(-0.3, abs=1e-12)
    assert np.max(np.abs(mu + 0.5)) < 1e-8
    shift = 0.5 / OMEGA_T - 0.1
    d = np.array([pt.ns_coefficient for pt in cv.points])
    np.testing.assert_allclose(d, 2.0 * (a - shift), atol=1e-6)
    assert [s.type for s in cv.special_points] == ["CH"]
    sp = cv.special_points[0]
    assert sp.label == "CH1" and sp.located == "solved"
    assert sp.values[0] == pytest.approx(-0.5, abs=1e-8)
    assert sp.values[1] == pytest.approx(shift, abs=1e-8)
    assert abs(sp.point.ns_coefficient) < 1e-9  # the bracket below the tolerance 1e-10
    ds = cv.to_xarray()
    np.testing.assert_array_equal(ds["ns_coefficient"].values, d)
    assert ds["ns_error"].attrs["units"] == "1"
    assert list(ds["special_type"].values) == ["CH"]


def test_lpns_on_the_ns_curve():
    """The NS curve in (nu, mu) is nu = mu^2; the fold multiplier e^{-2 s*} = e^{2 mu}
    passes 1 at (0, 0): LPNS, solved there. d = 2 a (c = 0) stays 0.6: no CH."""
    S = torus_system()
    cv = cycle_curve(S, torus_cycle(0.5, mu=-0.5, a=0.3), "NS", ("nu", "mu"),
                     ranges={"mu": (-0.5, 0.5)}, direction=1, ds_max=0.5, max_steps=100,
                     scales=(0.05, 0.05))
    assert cv.ok, cv.warnings
    nu, mu = cv.p1, cv.p2
    assert mu[-1] == pytest.approx(0.5, abs=1e-12)
    assert np.max(np.abs(nu - mu ** 2)) < 1e-8
    assert [s.type for s in cv.special_points] == ["LPNS"]
    sp = cv.special_points[0]
    assert sp.located == "solved"
    assert sp.values[0] == pytest.approx(0.0, abs=1e-8)
    assert sp.values[1] == pytest.approx(0.0, abs=1e-8)
    # the multipliers there: the pair on the circle and the fold's at 1
    rest = np.sort_complex(sp.point.multipliers)
    assert np.min(np.abs(rest - 1.0)) < 1e-7
    assert np.min(np.abs(rest - np.exp(1j * OMEGA_T))) < 1e-7


def test_torus_coefficient_of_the_ns_system_from_a_branch():
    """systems.ns_system (6-D, rotated by a fixed orthogonal matrix, which keeps unit
    eigenvectors unit): its (u, w) block u' = a u - w / 2 - (u^2 + w^2) u, ... is the
    normal form above with a = -1, c = 0 and the period T = 2 pi / (1 + beta): d = -2 T =
    -4 pi / (1 + beta) at the NS point beta = 0.6 that a one-parameter branch locates
    (from its collocated cycle, ntst 20)."""
    from systems import ns_plane_vector, ns_system

    from maglev_match.dynamics.cycle_curves import start_from
    from maglev_match.dynamics.cycles import cycle_branch, hopf_start

    S = ns_system()
    p = S.params_with(beta=0.0, gamma=0.36)
    br = cycle_branch(S, hopf_start(S, np.zeros(6), p, "beta", 1.0, ns_plane_vector(), None),
                      "beta", stop_at=0.8, ntst=20, ncol=4, max_steps=200)
    orbit = start_from(br, "NS1")
    beta = float(orbit.p[S.param_index("beta")])
    tc = torus_coefficient(S, orbit)
    assert tc.ok, tc.message
    assert abs(tc.multiplier) == pytest.approx(1.0, abs=1e-6)
    assert tc.d == pytest.approx(-4.0 * math.pi / (1.0 + beta), rel=1e-6)


def test_ns_coefficient_in_the_command_answers(tmp_path, capsys):
    """`cycle-curve --kind NS` on the user model of tests/test_ns_curves.py (the (u, w)
    block of ns_system unrotated: d = -4 pi / (1 + beta) too): the column `ns coefficient`
    of the table, `ns_coefficient` / `ns_error` in the CSV, the netCDF (with units and
    long_name) and the JSON."""
    import csv
    import json

    import xarray as xr
    from test_ns_curves import NS_FILE

    from maglev_match.cli import main

    model = tmp_path / "ns.py"
    model.write_text(NS_FILE)
    out = tmp_path / "out"
    args = ["cycle-curve", "--model", str(model), "--kind", "NS", "--params", "beta,gamma",
            "--from", "-0.5", "--to", "0.5", "--ntst", "20", "--range", "gamma=0.3:0.45"]
    assert main(args + ["--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "ns coefficient" in text
    with open(next(p for p in out.glob("*.csv") if "special" not in p.name)) as f:
        rows = list(csv.DictReader(f))
    beta = np.array([float(r["beta"]) for r in rows])
    d = np.array([float(r["ns_coefficient"]) for r in rows])
    np.testing.assert_allclose(d, -4.0 * math.pi / (1.0 + beta), rtol=1e-6)
    # the estimate (the second-order differences' distance) is conservative: d is right
    # to 1e-6 relative, the estimate says a few 1e-4
    assert all(0 < float(r["ns_error"]) < 1e-3 * abs(float(r["ns_coefficient"]))
               for r in rows)
    ds = xr.load_dataset(next(out.glob("*.nc")), engine="h5netcdf")
    np.testing.assert_allclose(ds["ns_coefficient"].values, -4.0 * math.pi / (1.0 + beta),
                               rtol=1e-6)
    assert ds["ns_coefficient"].attrs["units"] == "1"
    assert "Neimark-Sacker" in ds["ns_coefficient"].attrs["long_name"]
    assert main(args + ["--json"]) == 0
    res = json.loads(capsys.readouterr().out)
    assert all(p["ns_coefficient"] == pytest.approx(-4.0 * math.pi / (1.0 + p["beta"]),
                                                    rel=1e-6) for p in res["points"])


def test_ch_needs_d_beyond_its_error_on_both_sides():
    """CH is bracketed where d has opposite signs at two points with |d| above its error
    (a point between them within its error does not hide it; the bracket is the step where
    d itself changes sign); a sign change of d within its error is none."""
    from types import SimpleNamespace

    from maglev_match.dynamics.cycle_curves import detect_codim2

    def pts(ds, err):
        return [SimpleNamespace(values=(0.0, float(i)), period=1.0, reliable=False,
                                multipliers=np.zeros(0, complex), angle=1.0,
                                ns_coefficient=d, ns_error=err) for i, d in enumerate(ds)]

    sps = detect_codim2("NS", pts([0.3, 0.1, -1e-5, -0.2], 1e-3), ("p", "q"))
    assert [s.type for s in sps] == ["CH"] and sps[0].step == 1
    assert sps[0].values[1] == pytest.approx(1.0 + 0.1 / (0.1 + 1e-5))
    assert detect_codim2("NS", pts([2e-4, -3e-4, 1e-4], 1e-3), ("p", "q")) == []
    assert detect_codim2("NS", pts([0.3, math.nan, -0.2], 1e-3), ("p", "q")) == []


def test_gpd_follows_the_same_rule_as_ch():
    """GPD on a PD curve is read from the flip coefficient c with the same rule: a point
    next to GPD whose |c| is within its error does not hide it (it did when only
    consecutive points with |c| beyond the error were compared)."""
    from types import SimpleNamespace

    from maglev_match.dynamics.cycle_curves import detect_codim2

    def pts(cs, err):
        return [SimpleNamespace(values=(0.0, float(i)), period=1.0, reliable=False,
                                multipliers=np.zeros(0, complex), flip=c, flip_error=err)
                for i, c in enumerate(cs)]

    sps = detect_codim2("PD", pts([0.3, 1e-5, -0.1, -0.2], 1e-3), ("p", "q"))
    assert [s.type for s in sps] == ["GPD"] and sps[0].step == 1
    assert sps[0].values[1] == pytest.approx(1.0 + 1e-5 / (1e-5 + 0.1))
    assert detect_codim2("PD", pts([2e-4, -3e-4, 1e-4], 1e-3), ("p", "q")) == []
