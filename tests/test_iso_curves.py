"""Iso-chi curves (`iso-curve`, `api.iso_curve`): the level set chi(p1, p2) = target.

The continuation is checked on toy evaluators whose curve, switch point and mechanism
change are known in closed form, and on model A: every point re-evaluated independently by
`api.matching_index` gives the target, and a point agrees with a 1-D root of chi along
p1 solved by brentq on independent index evaluations."""

from __future__ import annotations

import math

import numpy as np
import pytest

from maglev_match.analyses.iso import Sample, TraceSettings, trace_iso
from maglev_match.core.params import ParameterError

R2 = 0.5  # the paper part of the toy: chi_paper = 10 (p1^2 + p2^2), = 5 on p1^2 + p2^2 = R2
SWITCH = (1.0 / 3.0, math.sqrt(R2 - 1.0 / 9.0))  # chi_paper = chi_sim = 5 there


def toy(p1: float, p2: float, bracketed_below: float = -math.inf,
        rounded: bool = True) -> Sample:
    """chi_paper = 10 (p1^2 + p2^2), chi_simulation = 4 + 3 p1 (= 5 on p1 = 1/3), the
    headline their minimum; the simulated part's mechanism is grazing above p2 = 0.8 and a
    basin boundary below; below ``bracketed_below`` in p2 the simulated part is only a
    bisection bracket (its value rounded to 0.01, or, ``rounded`` False, exact but still
    marked as bracketed)."""
    cp, cs = 10.0 * (p1 * p1 + p2 * p2), 4.0 + 3.0 * p1
    status = "solved"
    if p2 < bracketed_below:
        cs, status = (round(cs, 2) + 0.003 if rounded else cs), "bracketed"
    basis = "simulation" if cs < cp else "paper"
    return Sample(min(cp, cs), cp, cs, basis, "grazing" if p2 > 0.8 else "basin_boundary",
                  "up", "cycle", status)


BOX = ((-1.0, 1.0), (-1.0, 1.0))


@pytest.mark.parametrize("n", [1, 2, 3, 4, 5])
def test_max_points_counts_both_directions_and_the_start(n):
    """--points N gives at most N points in all (start included); with room, exactly N."""
    tr = trace_iso(toy, BOX, 5.0, fixed=1, value=0.0,
                   settings=TraceSettings(max_points=n, ds=0.02))
    assert len(tr.points) == n
    assert tr.start == (n - 1) // 2  # backwards gets half, rounded down


def test_toy_curve_follows_both_parts_and_locates_the_switches():
    tr = trace_iso(toy, BOX, 5.0, fixed=1, value=0.0, settings=TraceSettings(max_points=40))
    assert tr.start is not None and len(tr.points) > 10
    for pt in tr.points:
        s = pt.sample
        assert pt.status == "solved"
        assert abs(s.chi - 5.0) <= 1e-7 * 5.0 + 1e-15
        if s.basis == "paper":  # on the circle
            assert abs(pt.p1 ** 2 + pt.p2 ** 2 - R2) < 1e-7
        else:  # on the line p1 = 1/3
            assert abs(pt.p1 - 1.0 / 3.0) < 1e-7
    # both directions end on the edge of the box: p2 = -1 and p2 = +1 on the line
    assert "end of the p2 range" in tr.ends[0] and "end of the p2 range" in tr.ends[1]
    assert tr.points[0].p2 == pytest.approx(-1.0) and tr.points[-1].p2 == pytest.approx(1.0)
    switches = [s for s in tr.specials if s.kind == "basis switch"]
    assert len(switches) == 2
    for s, sign in zip(switches, (-1, 1), strict=True):
        assert s.located
        assert s.p1 == pytest.approx(SWITCH[0], abs=1e-7)
        assert s.p2 == pytest.approx(sign * SWITCH[1], abs=1e-7)
        assert abs(s.sample.chi_paper - s.sample.chi_simulation) <= 1e-6 * 5.0
    # the mechanism changes at p2 = 0.8 on the simulation-decided line: located within
    # 1/32 of the step that crossed it
    changes = [s for s in tr.specials if s.kind == "mechanism change"]
    assert len(changes) == 1 and changes[0].located
    assert {changes[0].before, changes[0].after} == {"grazing", "basin_boundary"}
    step = max(abs(b.p2 - a.p2) for a, b in zip(tr.points, tr.points[1:], strict=False))
    assert abs(changes[0].p2 - 0.8) <= step / 16


def test_a_curve_continued_beyond_its_ends_is_the_whole_curve():
    # followed in p2 in [-0.5, 0.5] (both directions end on that range, before either
    # switch), then continued from its saved points in p2 in [-1, 1]: the saved points
    # stay as they are, the new ones lie on the closed-form curve, go on away from the
    # saved ones (p2 monotone along the whole curve), and the switches beyond the old ends
    # are located as in one go
    from maglev_match.analyses.iso.trace import extend_iso

    small = ((-1.0, 1.0), (-0.5, 0.5))
    part = trace_iso(toy, small, 5.0, fixed=1, value=0.0, settings=TraceSettings(max_points=40))
    assert all("end of the p2 range" in e for e in part.ends) and not part.specials
    whole = extend_iso(toy, BOX, 5.0, part.points, part.start, part.ends,
                       settings=TraceSettings(max_points=40))
    n_back = whole.start - part.start
    assert n_back > 0 and whole.points[n_back:n_back + len(part.points)] == part.points
    p2 = [pt.p2 for pt in whole.points]
    assert all(b > a for a, b in zip(p2, p2[1:], strict=False))
    assert p2[0] == pytest.approx(-1.0) and p2[-1] == pytest.approx(1.0)
    for pt in whole.points:
        assert pt.status == "solved" and abs(pt.sample.chi - 5.0) <= 1e-7 * 5.0 + 1e-15
    assert [pt.branch for pt in whole.points[:n_back]] == [-1] * n_back
    assert "end of the p2 range" in whole.ends[0] and "end of the p2 range" in whole.ends[1]
    switches = [s for s in whole.specials if s.kind == "basis switch"]
    assert [s.located for s in switches] == [True, True]
    for s, sign in zip(switches, (-1, 1), strict=True):
        assert (s.p1, s.p2) == pytest.approx((SWITCH[0], sign * SWITCH[1]), abs=1e-7)
    assert whole.points[-1].sample.mechanism == "grazing"  # (beyond p2 = 0.8)
    # continued again, both ends on the box: nothing to add, the saved special points kept
    again = extend_iso(toy, BOX, 5.0, whole.points, whole.start, whole.ends,
                       specials=whole.specials, settings=TraceSettings(max_points=4))
    assert again.points == whole.points and again.specials == whole.specials
    assert again.ends == ("reached the edge of the ranges",) * 2


def test_toy_curve_says_where_the_deciding_part_is_only_bracketed():
    # below p2 = -0.85 the simulated part is a bracket (a step function): the corrector
    # cannot converge on it; the curve ends there, says why, and marks that point
    def ev(p1, p2):
        return toy(p1, p2, bracketed_below=-0.85)

    tr = trace_iso(ev, BOX, 5.0, fixed=1, value=0.0, settings=TraceSettings(max_points=40))
    first = tr.points[0]
    assert first.status == "not converged"
    assert first.sample.simulation_status == "bracketed"
    assert "only bracketed" in tr.ends[0]
    assert any("only bracketed" in w for w in tr.warnings)
    assert all(p.status == "solved" for p in tr.points[1:])


def test_toy_curve_that_cannot_start_says_why():
    tr = trace_iso(toy, BOX, 50.0, fixed=1, value=0.0)
    assert not tr.points and tr.start is None
    assert "no sign change" in tr.warnings[0] and "chi from" in tr.warnings[0]


class _Quadratic:
    """chi = 5 + (p1 - a)(p1 - b), the same along p2: chi = 5 at p1 = a and p1 = b;
    ``seen`` the p1 values evaluated, in order."""

    def __init__(self, a: float, b: float) -> None:
        self.a, self.b, self.seen = a, b, []

    def __call__(self, p1: float, p2: float) -> Sample:
        self.seen.append(p1)
        return Sample(5.0 + (p1 - self.a) * (p1 - self.b), 10.0)


@pytest.mark.parametrize("a, b, fewest, most", [
    (0.1, -0.9, 2, 3),  # a root next to the middle: the middle and one or two neighbours
    (-0.9, 0.95, 7, 7),  # roots near both ends: the whole scan
    (-0.9, 5.0, 6, 7),  # one root near an end: the far end only if its pair ties
])
def test_the_start_scans_from_the_middle_until_the_nearest_sign_change_is_known(
        a, b, fewest, most):
    # the full scan's rule (7 points over p1 in [-1, 1], the sign change whose midpoint
    # is nearest the middle) applied to the same function, against the scan from the
    # middle outwards: the same root, and only the grid points nearest the middle
    grid = np.linspace(-1.0, 1.0, 7)
    f = [(x - a) * (x - b) for x in grid]
    pairs = [j for j in range(6) if (f[j] > 0) != (f[j + 1] > 0)]
    j = min(pairs, key=lambda j: abs(0.5 - 0.5 * ((grid[j] + 1) / 2 + (grid[j + 1] + 1) / 2)))
    root = a if grid[j] <= a <= grid[j + 1] else b
    ev = _Quadratic(a, b)
    tr = trace_iso(ev, BOX, 5.0, fixed=1, value=0.0, settings=TraceSettings(max_points=1))
    (pt,) = tr.points
    assert pt.p1 == pytest.approx(root, abs=1e-6)
    on_grid = [x for x in ev.seen if np.min(np.abs(grid - x)) < 1e-12]
    n = len(on_grid)
    assert fewest <= n <= most and ev.seen[:n] == on_grid  # the scan, then regula falsi
    middle_out = sorted(grid, key=abs)
    assert sorted(np.abs(on_grid)) == pytest.approx(np.abs(middle_out[:n]))


class ToyWithGradient:
    """:func:`toy` with the exact gradient of both parts (the tracer uses it instead of a
    forward difference); ``calls`` counts the evaluations."""

    def __init__(self, bracketed_below: float = -math.inf, rounded: bool = True) -> None:
        self.below, self.rounded, self.calls = bracketed_below, rounded, 0

    def __call__(self, p1: float, p2: float) -> Sample:
        self.calls += 1
        return toy(p1, p2, self.below, self.rounded)

    def gradient(self, p1: float, p2: float, sample: Sample):
        parts = {"paper": np.array([20.0 * p1, 20.0 * p2])}
        if sample.simulation_status == "solved":
            parts["simulation"] = np.array([3.0, 0.0])
        return parts, "" if "simulation" in parts else "simulated part bracketed"


def test_toy_curve_with_the_exact_gradient_is_the_same_curve_with_fewer_evaluations():
    fd = trace_iso(toy, BOX, 5.0, fixed=1, value=0.0, settings=TraceSettings(max_points=40))
    ev = ToyWithGradient()
    tr = trace_iso(ev, BOX, 5.0, fixed=1, value=0.0, settings=TraceSettings(max_points=40))
    assert tr.evaluations == ev.calls < fd.evaluations
    assert {p.gradient for p in tr.points} == {"exact"}
    assert {p.gradient for p in fd.points} == {"difference: the evaluator gives no "
                                               "derivative"}
    for pt in tr.points:  # on the same closed-form curve
        assert pt.status == "solved" and abs(pt.sample.chi - 5.0) <= 1e-7 * 5.0
        if pt.sample.basis == "paper":
            assert abs(pt.p1 ** 2 + pt.p2 ** 2 - R2) < 1e-7
        else:
            assert abs(pt.p1 - 1.0 / 3.0) < 1e-7
    assert tr.ends == fd.ends
    switches = [s for s in tr.specials if s.kind == "basis switch"]
    assert len(switches) == 2 and all(s.located for s in switches)
    for s, sign in zip(switches, (-1, 1), strict=True):  # located with the exact Jacobian
        assert s.p1 == pytest.approx(SWITCH[0], abs=1e-7)
        assert s.p2 == pytest.approx(sign * SWITCH[1], abs=1e-7)


def test_toy_gradient_falls_back_to_a_difference_only_where_the_part_is_bracketed():
    # the simulated part is marked bracketed below p2 = -0.2 (its values exact, so the
    # corrector converges there): the points there that the simulation decides have no
    # derivative and say so; all others use the exact gradient
    ev = ToyWithGradient(bracketed_below=-0.2, rounded=False)
    tr = trace_iso(ev, BOX, 5.0, fixed=1, value=0.0, settings=TraceSettings(max_points=40))
    fallbacks = 0
    for pt in tr.points:
        s = pt.sample
        assert pt.status in ("solved", "bracketed")
        if s.basis == "simulation" and s.simulation_status == "bracketed":
            fallbacks += 1
            assert pt.status == "bracketed" and abs(pt.p1 - 1.0 / 3.0) < 1e-7
            assert pt.gradient == ("difference: the deciding simulated part is only "
                                   "bracketed: no derivative"), pt
        else:
            assert pt.gradient == "exact", pt
    assert fallbacks >= 2 and sum(p.gradient == "exact" for p in tr.points) > 10


def test_the_corrector_gives_up_when_it_moves_away_from_the_root_twice():
    """On a line without a root (F = chi - 5 >= 1 along p1, its smallest value off the
    line's start), the corrector stops after two steps that each move further from the root,
    instead of spending all of max_iter (12) iterations; where F has a root, it finds it."""
    from maglev_match.analyses.iso.trace import _Tracer

    def bowl(p1, p2):  # chi = 6 + (p1 - 0.3)^2 + p2^2: never 5; its slope misleads Newton
        c = 6.0 + (p1 - 0.3) ** 2 + p2 ** 2
        return Sample(c, c)

    tr = _Tracer(bowl, BOX, 5.0, TraceSettings(), None)
    u0 = np.array([0.5, 0.5])
    _, f, its = tr.line_solve(u0, np.array([1.0, 0.0]), 0.8)
    assert f >= 1.0 and its <= 4 and tr.evaluations <= 5
    tr = _Tracer(toy, BOX, 5.0, TraceSettings(), None)  # with a root: solved
    u, f, _ = tr.line_solve(np.array([0.75, 0.7]), np.array([0.0, 1.0]), 16.0)
    assert tr.converged(f)


def test_maglev_evaluator_warm_starts_from_the_nearest_design(monkeypatch):
    """Each index continues from the nearest design evaluated so far (the backward
    direction of a curve starts next to the first point, far from the forward end)."""
    from types import SimpleNamespace

    import maglev_match.analyses.iso.maglev as mod
    from maglev_match.analyses.iso import MaglevChi
    from maglev_match.api.inputs import resolve_params

    seen = []

    def fake_index(p, *, model, simulate, near=None):
        seen.append(None if near is None else near.at)
        return SimpleNamespace(at=(p.EI, p.kD), critical_up=object())

    monkeypatch.setattr(mod, "matching_index", fake_index)
    monkeypatch.setattr(mod, "sample_of", lambda idx: Sample(5.0, 5.0))
    ev = MaglevChi(resolve_params("turnout-soft"), ("EI", "kD"))
    for v in ((2.0e10, 150.0), (3.0e10, 200.0), (2.02e10, 151.0), (2.9e10, 199.0)):
        ev(*v)
    assert seen == [None, (2.0e10, 150.0), (2.0e10, 150.0), (3.0e10, 200.0)]


def test_maglev_gradient_equals_a_central_difference_of_chi():
    # the tracer's gradient on model A: the analytic sensitivities of the deciding part,
    # against a central difference of independent index evaluations (no warm start), where
    # the paper decides (no simulation) and where the simulation (grazing) does (kD = 150)
    from maglev_match.analyses.iso import MaglevChi
    from maglev_match.api.inputs import resolve_params

    base = resolve_params("turnout-soft")
    for simulate, kd, basis in ((False, 150.0, "paper"), (True, 150.0, "simulation")):
        ev = MaglevChi(base, ("EI", "kD"), simulate=simulate, warm=False)
        v = np.array([2.0e10, kd])
        smp = ev(*v)
        assert smp.basis == basis and smp.exact
        parts, why = ev.gradient(*v, smp)
        g = parts[basis]
        for i in range(2):
            h = np.zeros(2)
            h[i] = 1e-5 * v[i]
            cd = (ev(*(v + h)).chi - ev(*(v - h)).chi) / (2 * h[i])
            assert g[i] == pytest.approx(cd, rel=2e-6), (simulate, kd, i, g[i], cd)
        if simulate:  # both parts differentiated where both were solved
            assert set(parts) == {"paper", "simulation"} and why == ""


# ---------------------------------------------------------------------------------------
# model A (the paper's chi alone, turnout-soft)
# ---------------------------------------------------------------------------------------
PAPER = dict(names=("EI", "kD"), ranges={"EI": (1.5e10, 3e10), "kD": (120.0, 180.0)},
             simulate=False, stage=False)


@pytest.fixture(scope="module")
def paper_curve():
    from maglev_match import api

    return api.iso_curve("turnout-soft", 9.0, points=5, **PAPER)


def test_paper_curve_points_give_the_target_when_evaluated_again(paper_curve):
    from maglev_match import api

    assert len(paper_curve.points) == 5 and paper_curve.ok
    assert {r["paper_part"] for r in paper_curve.rows()} == {"cycle"}
    for pt in paper_curve.points:
        idx = api.matching_index("turnout-soft", simulate=False, stage=False, EI=pt.p1,
                                 kD=pt.p2)
        assert abs(idx.chi - 9.0) <= 1e-6 * 9.0, (pt, idx.chi)
    # the curve goes somewhere: its points are not all the start
    kd = [p.p2 for p in paper_curve.points]
    assert max(kd) - min(kd) > 5.0


def test_paper_curve_point_equals_a_brentq_root_along_p1(paper_curve):
    from scipy.optimize import brentq

    from maglev_match import api

    pt = paper_curve.points[-1]

    def f(ei):
        return api.matching_index("turnout-soft", simulate=False, stage=False, EI=ei,
                                  kD=pt.p2).chi - 9.0

    root = brentq(f, 0.97 * pt.p1, 1.03 * pt.p1, xtol=1.0, rtol=1e-10)
    assert root == pytest.approx(pt.p1, rel=1e-6)


def test_curve_xarray_round_trip_and_figure(paper_curve, tmp_path):
    import xarray as xr

    ds = paper_curve.to_xarray()
    path = tmp_path / "iso.nc"
    ds.to_netcdf(path)
    back = xr.load_dataset(path)
    np.testing.assert_array_equal(back["EI"].values, [p.p1 for p in paper_curve.points])
    np.testing.assert_array_equal(back["chi"].values,
                                  [p.sample.chi for p in paper_curve.points])
    assert list(back["status"].values) == [p.status for p in paper_curve.points]
    assert back.attrs["target"] == 9.0 and back["EI"].attrs["units"] == "N m^2"
    files = paper_curve.plot(tmp_path / "iso")
    assert sorted(f.suffix for f in files) == [".png", ".svg"]


@pytest.mark.parametrize("kw, field, text", [
    (dict(target=0.0), "target", "finite number > 0"),
    (dict(target=float("nan")), "target", "finite number > 0"),
    (dict(names=("EI", "EI")), "names", "the same parameter twice"),
    (dict(names=("EI", "kQ")), "names", "unknown parameter"),
    (dict(names=("EI", "w0")), "names", "derived"),
    (dict(ranges={"kD": (-5.0, 10.0)}), "ranges", "valid range of kD"),
    (dict(ranges={"kP": (1.0, 10.0)}), "ranges", "not one of the curve's parameters"),
    (dict(at="kD=500"), "at", "inside the range of kD"),
    (dict(at="kP=5"), "at", "not one of the curve's parameters"),
])
def test_bad_inputs_are_refused_naming_the_field(kw, field, text):
    from maglev_match import api

    args = dict(names=("EI", "kD"), ranges={"kD": (120.0, 180.0)})
    args.update(kw)
    target = args.pop("target", 5.0)
    with pytest.raises(ParameterError) as exc:
        api.iso_inputs("turnout-soft", target, **args)
    assert exc.value.args and field in str(exc.value) and text in str(exc.value)


def test_headline_curve_points_and_its_switch_evaluated_again():
    # the one headline case (turnout-soft, chi = 5 in (EI, kD) near kD = 222): the curve
    # is decided by the simulation (grazing) below the switch and by the paper part above
    # it, each point computed warm-started from its neighbour. Re-evaluated from scratch,
    # every point gives the target, and at the located switch both parts equal it.
    from maglev_match import api

    c = api.iso_curve("turnout-soft", 5.0, names=("EI", "kD"), points=3, step=0.1,
                      at="kD=222.2", stage=False,
                      ranges={"EI": (2.0e10, 2.4e10), "kD": (218.0, 226.0)})
    assert len(c.points) == 3 and c.ok
    rows = c.rows()
    assert [r["basis"] for r in rows] == ["simulation", "paper", "paper"]
    for r in rows:
        assert r["simulation_part"] == "solved" and r["mechanism"] == "grazing"
        assert r["direction"] in ("up", "down")
        idx = api.matching_index("turnout-soft", stage=False, EI=r["EI"], kD=r["kD"])
        assert abs(idx.chi - 5.0) <= 1e-6 * 5.0, (r, idx.chi)
        assert idx.reading_basis == r["basis"]
    (sw,) = c.specials
    assert sw.kind == "basis switch" and sw.located
    assert rows[0]["kD"] < sw.p2 < rows[1]["kD"]
    idx = api.matching_index("turnout-soft", stage=False, EI=sw.p1, kD=sw.p2)
    assert abs(idx.chi_paper - 5.0) <= 1e-6 * 5.0
    assert abs(idx.chi_simulation - 5.0) <= 1e-6 * 5.0


def test_the_docs_example_runs_as_written_and_prints_its_table(tmp_path, monkeypatch):
    import contextlib
    import io
    import re
    import shlex
    from pathlib import Path

    from maglev_match.cli import main

    page = (Path(__file__).resolve().parents[1] / "docs" / "iso.md").read_text()
    line = next(ln for ln in page.splitlines() if ln.startswith("maglev-match iso-curve"))
    shown = re.search(r"```text\n(.*?)```", page, re.S).group(1).splitlines()
    monkeypatch.chdir(tmp_path)
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(shlex.split(line)[1:])
    assert code == 0, err.getvalue()
    printed = out.getvalue()
    for row in shown[1:]:  # every table row and the ends as printed (the first line has
        assert row in printed, row  # the CPU time)
    folder = tmp_path / "maglev-match-out" / "iso-curve"
    assert {p.name for p in folder.iterdir()} >= {
        "iso_chi_unit_EI_kD.csv", "iso_chi_unit_EI_kD_special_points.csv",
        "iso_chi_unit_EI_kD.nc", "iso_chi_unit_EI_kD.png", "iso_chi_unit_EI_kD.svg"}
    # the restart of the page, as written: the saved rows unchanged, two new points beyond
    # each end, each of which gives the target when the index is computed there afresh
    import xarray as xr

    from maglev_match import api

    again = next(ln for ln in page.splitlines()
                 if ln.startswith("maglev-match iso-curve --restart"))
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
        assert main(shlex.split(again)[1:]) == 0, err.getvalue()
    with xr.open_dataset(folder / "iso_chi_unit_EI_kD.nc") as old, \
            xr.open_dataset(tmp_path / "longer" / "iso_chi_unit_EI_kD.nc") as new:
        assert new.sizes["point"] == old.sizes["point"] + 4
        assert int(new.attrs["start_point"]) == int(old.attrs["start_point"]) + 2
        for name in ("EI", "kD", "chi", "status"):
            assert list(new[name].values[2:-2]) == list(old[name].values)
        kd = new["kD"].values
        assert np.all(np.diff(kd) > 0)  # on along the curve, away from the saved points
        for i in (0, 1, -2, -1):
            idx = api.matching_index("turnout-soft", simulate=False, stage=False,
                                     EI=float(new["EI"].values[i]), kD=float(kd[i]))
            assert abs(idx.chi - 9.0) <= 1e-7 * 9.0, (i, idx.chi)


def _fake_map(x, y, chi):
    import xarray as xr

    shape = (len(y), len(x))
    return xr.Dataset({"chi": (("kD", "EI"), chi), "chi_paper": (("kD", "EI"), chi),
                       "chi_simulation": (("kD", "EI"), np.full(shape, np.nan)),
                       "stable": (("kD", "EI"), np.ones(shape, np.int8)),
                       "resolved": (("kD", "EI"), np.ones(shape, np.int8))},
                      coords={"EI": x, "kD": y})


def test_map_overlay_is_the_level_set_of_the_grid_labelled_interpolated(paper_curve):
    # chi linear over the grid: the marching-squares level set is exact, kD = 150 + 4 (EI/1e9 - 20)
    import matplotlib

    matplotlib.use("Agg")
    from maglev_match.plots.maps import map_figure

    x, y = np.linspace(1.5e10, 3e10, 7), np.linspace(120.0, 180.0, 9)
    chi = 5.0 + (y[:, None] - 150.0) / 4.0 - (x[None, :] / 1e9 - 20.0)
    fig = map_figure(_fake_map(x, y, chi), iso=5.0)
    ax = fig.axes[0]
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert "chi = 5, interpolated from the map grid" in labels
    verts = np.concatenate([p.vertices for c in ax.collections
                            for p in getattr(c, "get_paths", list)()
                            if type(c).__name__ in ("QuadContourSet", "PathCollection",
                                                    "LineCollection") and len(p.vertices)])
    assert len(verts) > 2
    np.testing.assert_allclose(verts[:, 1], 150.0 + 4.0 * (verts[:, 0] / 1e9 - 20.0),
                               atol=1e-9)
    # an iso-curve file is drawn as solved, point for point
    fig = map_figure(_fake_map(x, y, chi), iso_curve=paper_curve.to_xarray(),
                     iso_source="c.nc")
    ax = fig.axes[0]
    line = next(ln for ln in ax.get_lines() if "(solved)" in str(ln.get_label()))
    np.testing.assert_array_equal(line.get_xdata(), [p.p1 for p in paper_curve.points])
    assert "from c.nc" in line.get_label()


def test_map_iso_options_are_checked_before_the_map(tmp_path, paper_curve):
    from maglev_match.cli.common import UserError
    from maglev_match.cli.iso_curve import iso_overlay

    path = tmp_path / "c.nc"
    paper_curve.to_xarray().to_netcdf(path)
    assert iso_overlay(None, path, ["kD", "EI"])["iso_curve"].attrs["target"] == 9.0
    with pytest.raises(UserError, match=r"a curve in \(EI, kD\), the map is in"):
        iso_overlay(None, path, ["EI", "omega0"])
    with pytest.raises(UserError, match="name different levels"):
        iso_overlay(5.0, path, ["EI", "kD"])
    with pytest.raises(ParameterError, match="--iso"):
        iso_overlay(float("nan"), None, ["EI", "kD"])


def test_a_saved_curve_reads_back_as_it_was_written(tmp_path, paper_curve):
    from maglev_match.analyses.iso import read_iso_curve

    path = tmp_path / "c.nc"
    paper_curve.to_xarray().to_netcdf(path)
    import json

    back = read_iso_curve(path)
    for rows in ("rows", "special_rows"):  # (as text: NaN == NaN there)
        assert json.dumps(getattr(back, rows)()) == json.dumps(getattr(paper_curve, rows)())
    assert (back.target, back.names, back.model, back.simulate, back.ranges, back.ends,
            back.warnings, back.tolerance) == (
        paper_curve.target, paper_curve.names, paper_curve.model, paper_curve.simulate,
        paper_curve.ranges, paper_curve.ends, paper_curve.warnings, paper_curve.tolerance)
    # the parameter set as given: EI and kD still derive omega1 and sigma (a set read
    # from the resolved values would hold them fixed, and chi would not move with EI)
    assert back.base == paper_curve.base and "omega1" not in back.base.explicit


@pytest.mark.parametrize("args, where, text", [
    (["chi=9"], "TARGET", "leave TARGET out"),
    (["--model", "vehicle"], "--model", "the saved curve at its own"),
    (["--params", "EI,L"], "--params", "the saved curve at its own"),
    (["--range", "kD=149:151"], "--range", "must contain the saved curve"),
    (["--points", "0"], "points", "must be a whole number >= 1"),
])
def test_restart_options_that_do_not_apply_are_refused(tmp_path, paper_curve, capsys,
                                                       args, where, text):
    from maglev_match.cli import main

    path = tmp_path / "c.nc"
    paper_curve.to_xarray().to_netcdf(path)
    code = main(["iso-curve", "--restart", str(path), *args, "--out", str(tmp_path / "o")])
    err = " ".join(capsys.readouterr().err.split())
    assert code == 2 and where in err and text in err, err
    assert not (tmp_path / "o").exists()


def test_restart_files_that_are_not_a_curve_are_refused(tmp_path, paper_curve, capsys):
    import xarray as xr

    from maglev_match.cli import main

    ds = paper_curve.to_xarray()
    other = xr.Dataset({"x": ("i", np.zeros(2))}, attrs={"title": "maglev-match cycles"})
    old = ds.copy()
    del old.attrs["base_inputs"]
    csv = tmp_path / "c.csv"
    csv.write_text("EI,kD\n1,2\n")
    cases = {"not a netCDF file": csv, "is not an iso-chi curve file": tmp_path / "o.nc",
             "compute the curve again": tmp_path / "old.nc", "no such file": tmp_path / "x.nc"}
    other.to_netcdf(tmp_path / "o.nc")
    old.to_netcdf(tmp_path / "old.nc")
    for text, path in cases.items():
        code = main(["iso-curve", "--restart", str(path)])
        err = " ".join(capsys.readouterr().err.split())
        assert code == 2 and "--restart" in err and text in err, (text, err)


def test_a_delayed_controller_moves_the_curve_and_its_point_gives_the_target_again():
    # the outer loop delayed by tau = 0.5 ms (the discretised delay system is the engine's
    # ODE): the curve's start at kD = 150, solved along EI, is where `index` with the same
    # delay gives chi = 9 again, and it is not the delay-free curve's EI (1.90027e10, the
    # documented example): the delay moves the curve. The index has no analytic derivative
    # with a delay: a step takes differences (the start alone takes none)
    from maglev_match import api
    from maglev_match.analyses.iso import iso_chi_curve
    from maglev_match.api.inputs import resolve_params

    base = resolve_params("turnout-soft", tau=5e-4)
    c = iso_chi_curve(base, ("EI", "kD"), {"EI": (1.8e10, 1.95e10), "kD": (140.0, 160.0)},
                      9.0, at=("kD", 150.0), simulate=False,
                      settings=TraceSettings(max_points=1, scan=2))
    (pt,) = c.points
    assert pt.status == "solved" and pt.p2 == 150.0
    assert abs(pt.p1 / 1.90027e10 - 1.0) > 0.01
    idx = api.matching_index("turnout-soft", simulate=False, stage=False, tau=5e-4,
                             EI=pt.p1, kD=150.0)
    assert abs(idx.chi - 9.0) <= 1e-7 * 9.0, idx.chi
    assert pt.sample.basis == "paper" and pt.sample.paper_status == "cycle"
    from maglev_match.analyses.iso import MaglevChi

    parts, why = MaglevChi(base, ("EI", "kD"), simulate=False).gradient(pt.p1, pt.p2,
                                                                          pt.sample)
    assert parts == {} and "with a delay" in why  # a step takes differences, and says so


def test_the_curve_crosses_the_design_kd_at_the_design_ei():
    # independent methods: `design` (SLSQP on exact gradients, the cheapest EI with the
    # headline chi >= 5 at the base kD = 150) and the curve's point at kD = 150 (chi = 5
    # solved along EI by regula falsi on index evaluations). The curve's start scans EI
    # over +-15 % of the design at 3 points (the scan only brackets the root; the root is
    # solved to tol 1e-7 either way): 5 index evaluations instead of the 11 of the API's
    # default scan of 7 points over EI = 1.2e10..3.6e10 (the same root to 3e-8). The
    # design starts from one point of a 3-point grid: 4 index evaluations instead of the
    # 19 of the default 9-point grid and 2 starts (the same optimum to 1e-7; the README's
    # `design` runs the default)
    from maglev_match import api
    from maglev_match.analyses.iso import iso_chi_curve
    from maglev_match.api.inputs import resolve_params

    design = api.design_search("turnout-soft", vary={"EI": (5e9, 4e10)}, minimize="EI",
                               require={"chi": 5.0}, stage=False, grid=3, starts=1)
    assert "chi" in " ".join(design.active), design.active  # chi = 5 holds there
    ei = design.values["EI"]
    c = iso_chi_curve(resolve_params("turnout-soft"), ("EI", "kD"),
                      {"EI": (0.85 * ei, 1.15 * ei), "kD": (100.0, 200.0)}, 5.0,
                      at=("kD", 150.0), settings=TraceSettings(max_points=1, scan=3))
    (pt,) = c.points
    assert pt.p2 == 150.0 and pt.status == "solved"
    assert pt.p1 == pytest.approx(ei, rel=1e-4)


def _fake_design(names=("EI", "kD")):
    """What the design figure reads of a DesignResult: a 3 x 3 start grid, no optimiser
    path, the design point."""
    from types import SimpleNamespace

    x, y = np.linspace(1.5e10, 3e10, 3), np.linspace(120.0, 180.0, 3)
    gv = np.array([[a, b] for a in x for b in y])
    problem = SimpleNamespace(names=names, requirements=(), goal="minimize",
                              objective=names[0])
    return SimpleNamespace(problem=problem, grid_shape=(3, 3), grid_values=gv,
                           grid_chi=gv[:, 0] / 2e9 - gv[:, 1] / 40.0, candidates=(),
                           values=dict(zip(names, gv[4], strict=False)), status="optimal")


def test_design_figure_draws_the_iso_curve_as_given(paper_curve, tmp_path):
    # the curve drawn on the design figure is the curve's own data, point for point, from
    # the result object and from its netCDF file (names in either order)
    import matplotlib
    import xarray as xr

    matplotlib.use("Agg")
    from maglev_match.plots.design import design_path_figure

    path = tmp_path / "c.nc"
    paper_curve.to_xarray().to_netcdf(path)
    for iso, source in ((paper_curve, ""), (xr.load_dataset(path), "c.nc")):
        fig = design_path_figure(_fake_design(), iso=iso, iso_source=source)
        (line,) = [ln for ln in fig.axes[0].get_lines() if "(solved)" in str(ln.get_label())]
        np.testing.assert_array_equal(line.get_xdata(), [p.p1 for p in paper_curve.points])
        np.testing.assert_array_equal(line.get_ydata(), [p.p2 for p in paper_curve.points])
        assert line.get_label().endswith(f"from {source}") == bool(source)
    fig = design_path_figure(_fake_design(("kD", "EI")), iso=paper_curve)  # axes swapped
    (line,) = [ln for ln in fig.axes[0].get_lines() if "(solved)" in str(ln.get_label())]
    np.testing.assert_array_equal(line.get_xdata(), [p.p2 for p in paper_curve.points])
    for names in (("EI", "omega0"), ("EI",)):
        with pytest.raises(ParameterError, match=r"iso.*design's two varied parameters"):
            design_path_figure(_fake_design(names), iso=paper_curve)


def test_design_iso_curve_option_is_checked_before_the_search(paper_curve, tmp_path):
    import contextlib
    import io

    from maglev_match.cli import main

    path = tmp_path / "c.nc"
    paper_curve.to_xarray().to_netcdf(path)
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        code = main(["design", "--vary", "EI=5e9:4e10", "--minimize", "EI", "--require",
                     "chi>=5", "--iso-curve", str(path), "--out", str(tmp_path / "o")])
    assert code == 2
    assert "a curve in (EI, kD), the design is in (EI)" in " ".join(err.getvalue().split())


@pytest.mark.slow  # vehicle indices (88 s with 3 points, a 3-point scan and 3 modes)

def test_vehicle_paper_curve_is_the_closed_form_of_the_case_rule():
    # model B (the vehicle), the paper's chi alone (its headline needs the simulated part,
    # minutes per point): at turnout-soft its bounding cycle does not fit the gap range
    # (case rule, h = gap_max - c0), so chi = h / w0(EI) does not depend on kD and the
    # curve chi = 9 is the line EI = EI* where the static mid-span deflection w0 of the
    # beam formulas (derived_map, no index) gives h / w0 = 9
    import jax.numpy as jnp
    from scipy.optimize import brentq

    from maglev_match.analyses.iso import iso_chi_curve
    from maglev_match.analyses.sensitivity import derived_map, engineering_names
    from maglev_match.api.inputs import resolve_params

    # one beam mode (the closed form's w0 then is that of one mode): the same case rule at
    # about half the cost of a vehicle index with the preset's three
    base = resolve_params("turnout-soft", n_modes=1)
    names = engineering_names(base, "vehicle")
    fmap = derived_map(base, "vehicle")

    def chi_rule(ei):
        q = jnp.asarray([ei if n == "EI" else float(getattr(base, n)) for n in names])
        _, w0, hmax = fmap(q)
        return float(hmax) / float(w0)

    ei_star = brentq(lambda e: chi_rule(e) - 9.0, 1.5e10, 3e10, xtol=1e-3, rtol=1e-14)
    c = iso_chi_curve(base, ("EI", "kD"), {"EI": (1.5e10, 3e10), "kD": (120.0, 180.0)}, 9.0,
                      at=("kD", 150.0), model="vehicle", simulate=False,
                      settings=TraceSettings(max_points=2, ds=0.2, scan=2))
    assert c.model == "vehicle" and len(c.points) == 2 and c.ok
    for r in c.rows():
        assert r["paper_part"] == "rule" and r["gradient"] == "exact"
        assert abs(r["chi"] - 9.0) <= 1e-7 * 9.0
        assert r["EI"] == pytest.approx(ei_star, rel=1e-7)
    kd = [p.p2 for p in c.points]
    assert kd == sorted(kd) and kd[-1] - kd[0] > 10.0  # one step of 0.2 x 60
