"""Every result object of the public API draws itself (``.plot()``: a matplotlib figure, or
PNG and SVG files at a path) and has an xarray form (``.to_xarray()``) that survives a
netCDF round trip with the object's own numbers. The instances are the cheapest real ones
the API builds (model A at turnout-soft without simulation, a two-state user model)."""

from __future__ import annotations

import dataclasses
import math

import matplotlib
import numpy as np
import pytest

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import xarray as xr  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from maglev_match import api  # noqa: E402
from maglev_match.analyses.design import DesignResult  # noqa: E402
from maglev_match.analyses.iso import IsoChiCurve  # noqa: E402
from maglev_match.analyses.matching import MatchingIndex  # noqa: E402
from maglev_match.analyses.sensitivity import IndexSensitivity  # noqa: E402
from maglev_match.analyses.simulation import MaglevSimulation  # noqa: E402
from maglev_match.analyses.speed.irregular import IrregularSweep  # noqa: E402
from maglev_match.analyses.speed.spans import SpanRun  # noqa: E402
from maglev_match.analyses.speed.sweep import SpeedSweep  # noqa: E402
from maglev_match.api.cycle_curves import CycleCurveStudy  # noqa: E402
from maglev_match.api.cycles import CycleStudy  # noqa: E402
from maglev_match.api.hopf import HopfCurveStudy  # noqa: E402
from maglev_match.api.index import IndexSpread  # noqa: E402
from maglev_match.api.simulation import UserSimulation  # noqa: E402
from maglev_match.dynamics.equilibria import RootLocusResult, StabilityResult  # noqa: E402
from maglev_match.dynamics.hopf import HopfPoint, HopfScan  # noqa: E402

PRESET = "turnout-soft"

# a damped oscillator y'' + c y' + k y = 0: two states, cheap to load and integrate
OSCILLATOR = '''\
import jax.numpy as jnp

STATES = ["y", "v"]
PARAMS = {"k": 4.0, "c": 0.8}
X0 = [0.0, 0.0]


def rhs(x, p):
    return jnp.array([x[1], -p["k"] * x[0] - p["c"] * x[1]])
'''

RESULT_TYPES = [StabilityResult, RootLocusResult, HopfScan, HopfCurveStudy, CycleStudy,
                CycleCurveStudy,
                MaglevSimulation, UserSimulation, SpanRun, SpeedSweep, MatchingIndex,
                IndexSensitivity, IndexSpread, DesignResult, IrregularSweep,
                IsoChiCurve]


@pytest.mark.parametrize("cls", RESULT_TYPES, ids=lambda c: c.__name__)
def test_every_api_result_type_has_plot_and_to_xarray(cls):
    assert callable(getattr(cls, "plot", None)), cls
    assert callable(getattr(cls, "to_xarray", None)), cls


def test_a_hopf_point_has_an_xarray_form():
    # (no figure of its own: a single point is drawn in its scan's figure)
    assert callable(getattr(HopfPoint, "to_xarray", None))


# ---------------------------------------------------------------------------------------
# helpers
# ---------------------------------------------------------------------------------------
def drawn(result, tmp_path) -> Figure:
    """The figure of ``result`` (checked to hold data), after checking that ``.plot(path)``
    writes a PNG and an SVG file."""
    files = result.plot(tmp_path / "f")
    assert sorted(p.suffix for p in files) == [".png", ".svg"]
    for p in files:
        assert p.exists() and p.stat().st_size > 0
    assert (tmp_path / "f.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert b"<svg" in (tmp_path / "f.svg").read_bytes()[:2000]
    fig = result.plot()
    assert isinstance(fig, Figure)
    assert any(ax.has_data() for ax in fig.axes)
    return fig


def round_trip(ds: xr.Dataset, tmp_path) -> xr.Dataset:
    """``ds`` written to netCDF and read back (every variable documented)."""
    assert isinstance(ds, xr.Dataset)
    for name in list(ds.data_vars) + list(ds.coords):
        assert ds[name].attrs.get("units"), name
        assert ds[name].attrs.get("long_name"), name
    path = tmp_path / "result.nc"
    ds.to_netcdf(path, engine="h5netcdf")
    return xr.load_dataset(path, engine="h5netcdf")


def close(fig) -> None:
    plt.close(fig)


# ---------------------------------------------------------------------------------------
# instances (module-scoped: each is computed once)
# ---------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def stability():
    return api.stability(PRESET)


@pytest.fixture(scope="module")
def index():
    return api.matching_index(PRESET, simulate=False)


@pytest.fixture(scope="module")
def scan():
    return api.hopf_points(PRESET, "omega1", 30.0, 300.0, n_scan=40)


@pytest.fixture(scope="module")
def user_run(tmp_path_factory):
    path = tmp_path_factory.mktemp("model") / "oscillator.py"
    path.write_text(OSCILLATOR)
    return api.simulate(model=str(path), x0=[1.0, 0.0], t_end=2.0, n_save=21)


@pytest.fixture(scope="module")
def sensitivity(index):
    return api.index_sensitivity(PRESET, simulate=False, boundaries=False, index=index)


class ClosedFormBeam:
    """Model A's index against the beam stiffness EI where no cycle bounds the basin
    within the gap range (the case that decides the cheapest soft beam of turnout-soft,
    tests/test_design.py): h = gap_max - c0 and w0 = sigma (m + M) g mbar L^4 / (pi^4 EI),
    so chi = h / w0 grows linearly with EI. The design search through the API
    (``api.design_search``) costs ~45 s of compilation on a fresh cache (its start grid
    runs the design map's kernels, tests/test_design.py runs it); the optimiser on this
    evaluator takes milliseconds and returns a real :class:`DesignResult`."""

    names = ("EI",)

    def __init__(self, index: MatchingIndex):
        from maglev_match.core.params import load_preset

        b = load_preset(PRESET)
        self.index = index
        self.h = b.gap_max - b.c0
        self.w0_times_ei = b.sigma * (b.m + b.M) * b.g * b.mbar * b.L**4 / math.pi**4

    def evaluate(self, values, gradient):
        from maglev_match.analyses.design import Evaluation
        from maglev_match.analyses.matching import Case
        from maglev_match.analyses.sensitivity import DerivativeStatus

        ei = float(values[0])
        w0 = self.w0_times_ei / ei
        chi = self.h / w0
        idx = dataclasses.replace(self.index, chi=chi, chi_paper=chi, h=self.h, w0=w0,
                                  case=Case.NO_CYCLE_WITHIN_LIMITS)
        return Evaluation(np.asarray(values, float), chi, -idx.max_real_part,
                          np.array([chi / ei]) if gradient else None,
                          np.zeros(1) if gradient else None,
                          DerivativeStatus.RULE if gradient else None, idx, chi_paper=chi)

    def recheck(self, values, simulate):
        return self.evaluate(values, gradient=False).index


@pytest.fixture(scope="module")
def design(index):
    from maglev_match.analyses.design import (
        DesignProblem,
        Goal,
        Quantity,
        Requirement,
        Variable,
        optimise_design,
    )

    problem = DesignProblem((Variable("EI", 5e9, 4e10),), Goal.MINIMIZE, "EI",
                            (Requirement(Quantity.CHI, 5.0),))
    return optimise_design(problem, ClosedFormBeam(index), grid=5, starts=1)


# ---------------------------------------------------------------------------------------
# the round trips
# ---------------------------------------------------------------------------------------
def test_stability_result(stability, tmp_path):
    fig = drawn(stability, tmp_path)
    eig = np.asarray(stability.eigenvalues)
    # the left panel shows every eigenvalue once, at its place in the complex plane
    pts = np.concatenate([c.get_offsets() for c in fig.axes[0].collections])
    assert len(pts) == eig.size
    assert np.allclose(np.sort_complex(pts[:, 0] + 1j * pts[:, 1]), np.sort_complex(eig))
    assert "stable" in fig.texts[0].get_text()
    close(fig)
    ds = round_trip(stability.to_xarray(), tmp_path)
    assert np.array_equal(ds["eigenvalue_real"].values, eig.real)
    assert np.array_equal(ds["eigenvalue_imag"].values, eig.imag)
    assert np.array_equal(ds["condition_number"].values, stability.condition_numbers)
    assert float(ds["margin"]) == stability.margin
    assert float(ds["max_real_part"]) == stability.max_real_part
    assert bool(ds["stable"]) is stability.stable is True
    assert list(ds["state"].values) == list(stability.system.state_names)
    assert np.array_equal(ds["equilibrium"].values, stability.equilibrium.x)
    assert ds.attrs["verdict"] == "stable"
    assert ds["eigenvalue_real"].attrs["units"] == "1/s"


def test_matching_index(index, tmp_path):
    fig = drawn(index, tmp_path)
    bars = fig.axes[0].containers[0]
    # without the simulation: the paper's chi and the headline, nothing else
    assert [b.get_height() for b in bars] == pytest.approx([index.chi_paper, index.chi])
    close(fig)
    ds = round_trip(index.to_xarray(), tmp_path)
    for name in ("chi", "chi_paper", "h", "w0", "max_real_part", "omega1", "sigma",
                 "hopf_value", "l1", "cycle_period", "cycle_gap_max"):
        assert float(ds[name]) == getattr(index, name), name
    assert math.isnan(float(ds["chi_simulation"])) and index.chi_simulation is None
    assert float(ds["chi"]) == pytest.approx(9.5622, rel=1e-4)  # turnout-soft
    assert ds.attrs["case"] == index.case == "unstable_cycle"
    assert ds.attrs["reading"] == index.reading
    assert ds.attrs["reading_basis"] == "paper"
    assert ds["h"].attrs["units"] == "m" and ds["omega1"].attrs["units"] == "rad/s"


def test_hopf_scan_and_point(scan, tmp_path):
    fig = drawn(scan, tmp_path)
    close(fig)
    ds = round_trip(scan.to_xarray(), tmp_path)
    assert len(scan.points) == 1
    hp = scan.points[0]
    assert np.array_equal(ds["scan"].values, scan.scan_values)
    assert np.array_equal(ds["max_real_part"].values, scan.max_real_part)
    assert list(ds["hopf"].values) == ["H1"]
    for name in ("value", "frequency", "crossing_speed", "l1", "residual"):
        assert float(ds[name][0]) == getattr(hp, name), name
    assert ds["value"].attrs["units"] == "rad/s"  # omega1
    assert np.array_equal(ds["equilibrium"].values[0], hp.x)
    assert [str(t) for t in ds["special_type"].values] == [str(sp.type) for sp in
                                                           scan.special_points]
    pt = round_trip(hp.to_xarray("rad/s", scan.system.state_names), tmp_path)
    assert float(pt["value"]) == hp.value and float(pt["frequency"]) == hp.frequency
    assert float(pt["l1"]) == hp.l1 and bool(pt["converged"]) is hp.converged
    assert np.array_equal(pt["q_real"].values + 1j * pt["q_imag"].values, hp.q)
    assert np.array_equal(pt["p"].values, hp.p)
    assert pt.attrs["kind"] == hp.kind == "subcritical"


def test_user_simulation(user_run, tmp_path):
    assert isinstance(user_run, UserSimulation)
    t, x = user_run.history()
    fig = drawn(user_run, tmp_path)
    lines = [ln for ax in fig.axes for ln in ax.lines]
    assert len(lines) == len(user_run.state_names) == 2  # one history per state
    for k, ln in enumerate(lines):
        assert np.array_equal(ln.get_ydata(), x[:, k])
    close(fig)
    ds = round_trip(user_run.to_xarray(), tmp_path)
    assert list(ds["state"].values) == ["y", "v"]
    assert np.array_equal(ds["time"].values, t)
    assert np.array_equal(ds["x"].values, x)
    assert float(ds["final_time"]) == user_run.result.final_time == 2.0
    assert np.array_equal(ds["final_state"].values, user_run.result.final_state)
    assert ds.attrs["outcome"] == user_run.outcome


def test_index_sensitivity(sensitivity, tmp_path):
    close(drawn(sensitivity, tmp_path))
    ds = round_trip(sensitivity.to_xarray(), tmp_path)
    assert list(ds["parameter"].values) == [r.name for r in sensitivity.rows]
    for r in sensitivity.rows:
        row = ds.sel(parameter=r.name)
        assert float(row["value"]) == r.value
        assert float(row["dchi"]) == pytest.approx(r.dchi, nan_ok=True)
        assert float(row["dmargin"]) == pytest.approx(r.dmargin, nan_ok=True)
        assert float(row["elasticity"]) == pytest.approx(r.elasticity, nan_ok=True)
        assert str(row["parameter_unit"].values) == r.unit
    assert float(ds.sel(parameter="kD")["dchi"]) == sensitivity.dchi("kD") != 0.0
    assert float(ds["chi"]) == sensitivity.index.chi
    assert ds.attrs["status"] == str(sensitivity.status)


def test_index_spread_linearised(sensitivity, tmp_path):
    spread = api.index_spread(PRESET, {"kD": 5.0, "EI": 3.0}, sensitivity=sensitivity)
    assert spread.sampled is None
    fig = drawn(spread, tmp_path)
    widths = [b.get_width() for b in fig.axes[-1].containers[0]]
    assert widths == pytest.approx(list(spread.linearised["contributions"].values()))
    close(fig)
    ds = round_trip(spread.to_xarray(), tmp_path)
    assert float(ds["chi"]) == spread.linearised["chi"] == sensitivity.index.chi
    assert float(ds["sd_linearised"]) == spread.linearised["sd"]
    for name, part in spread.linearised["contributions"].items():
        assert float(ds["contribution"].sel(parameter=name)) == part
    assert "chi_sample" not in ds


def test_index_spread_without_scatter_is_empty_but_drawable(tmp_path):
    spread = api.index_spread(PRESET)  # nothing scattered: nothing computed
    fig = spread.plot()
    assert isinstance(fig, Figure) and "no scatter" in fig.axes[0].texts[0].get_text()
    close(fig)
    ds = round_trip(spread.to_xarray(), tmp_path)
    assert not ds.data_vars and ds.attrs["linearised"] == 0


def test_index_spread_sampled(sensitivity, tmp_path):
    spread = api.index_spread(PRESET, {"kD": 5.0}, sensitivity=sensitivity, monte_carlo=3,
                              checkpoint=tmp_path / "mc", workers=0)
    mc = spread.sampled
    fig = drawn(spread, tmp_path)
    counts = [b.get_height() for b in fig.axes[0].containers[0]]
    assert sum(counts) == np.isfinite(mc.chi).sum() == 3  # the histogram of the samples
    close(fig)
    ds = round_trip(spread.to_xarray(), tmp_path)
    assert np.array_equal(ds["chi_sample"].values, mc.chi)
    assert np.array_equal(ds["parameter_sample"].values, mc.samples)
    assert float(ds["chi_mean"]) == mc.mean and float(ds["chi_sd"]) == mc.sd
    assert float(ds["chi_q50"]) == mc.quantiles["50%"]
    assert int(ds["samples"]) == 3 and list(ds["parameter"].values) == ["kD"]


def test_design_result(design, tmp_path):
    close(drawn(design, tmp_path))
    ds = round_trip(design.to_xarray(), tmp_path)
    assert list(ds["variable"].values) == ["EI"]
    assert float(ds["design"].sel(variable="EI")) == design.values["EI"]
    assert float(ds["objective"]) == design.objective
    assert float(ds["chi"]) == design.index.chi >= 5.0
    assert np.array_equal(ds["grid_chi"].values, design.grid_chi)
    for j, c in enumerate(design.candidates):
        k = int(ds["path_length"][j])
        assert k == len(c.path)
        assert np.array_equal(ds["path"].values[j, :k], c.path)
        assert np.array_equal(ds["path_chi"].values[j, :k], c.path_chi)
        assert np.all(np.isnan(ds["path"].values[j, k:]))
        assert float(ds["candidate_chi"][j]) == c.chi
    assert ds.attrs["status"] == str(design.status) == "feasible"
    # the cheapest EI meeting chi >= 5: chi = h EI / (w0 EI) = 5
    beam = ClosedFormBeam(design.index)
    assert float(ds["design"][0]) == pytest.approx(5.0 * beam.w0_times_ei / beam.h, rel=1e-6)
    assert ds["variable_unit"].values[0] == "N m^2"


# ---------------------------------------------------------------------------------------
# .plot(ax=...): into the user's own axes
# ---------------------------------------------------------------------------------------
def test_plot_into_given_axes_draws_the_same_panels(stability, user_run):
    own = stability.plot()
    fig, axes = plt.subplots(1, 2)
    got = stability.plot(ax=axes)
    assert got is fig  # the user's figure, no new one
    for mine, theirs in zip(own.axes[:2], axes, strict=True):
        assert len(theirs.collections) == len(mine.collections) > 0
        for a, b in zip(mine.collections, theirs.collections, strict=True):
            assert np.array_equal(a.get_offsets(), b.get_offsets())
    close(own)
    # a one-panel-per-state figure into a column of axes the user made
    fig2, col = plt.subplots(2, 1)
    assert user_run.plot(ax=col) is fig2
    t, x = user_run.history()
    assert [np.array_equal(ax.lines[0].get_ydata(), x[:, k]) for k, ax in enumerate(col)] \
        == [True, True]
    plt.close(fig2)
    # the wrong number of axes is refused by name, and nothing is left half-drawn
    fig3, one = plt.subplots()
    with pytest.raises(ValueError, match=r"ax: 1 axes given; this figure has 2 panel"):
        stability.plot(ax=one)
    assert not one.has_data()
    with pytest.raises(ValueError, match=r"^ax: "):
        stability.plot(ax="not axes")
    plt.close(fig3)
    plt.close(fig)
    # and the next plot without ax= makes its own figure again
    again = stability.plot()
    assert again is not fig and len(again.axes) >= 2
    close(again)
