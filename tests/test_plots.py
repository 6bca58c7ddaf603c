"""Structure of the figures: panels, markers, legends, zoom and what the titles say."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
import pytest  # noqa: E402
import xarray as xr  # noqa: E402
from matplotlib.collections import PolyCollection  # noqa: E402

import maglev_match as mm  # noqa: E402
from maglev_match.dynamics.hopf_curve import HopfCurve, HopfCurvePoint  # noqa: E402
from maglev_match.plots.cycles import branch_label, cycle_diagram  # noqa: E402
from maglev_match.plots.hopf import hopf_curve_figure  # noqa: E402
from maglev_match.plots.maps import map_figure  # noqa: E402
from maglev_match.plots.rootlocus import root_locus_figure, zoom_window  # noqa: E402
from maglev_match.plots.simulate import (  # noqa: E402
    describe_initial,
    fitted_time_window,
    simulation_figure,
)


def _legend_texts(ax) -> list[str]:
    leg = ax.get_legend()
    return [t.get_text() for t in leg.get_texts()] if leg is not None else []


def _has_marker(ax, marker: str) -> bool:
    return any(line.get_marker() == marker and len(line.get_xdata()) > 0
               for line in ax.get_lines())


# ---------------------------------------------------------------------------------------
# simulation
# ---------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def runs():
    p = mm.load_preset("turnout-soft")
    return (mm.simulate(p, x5=-3e-3, t_end=3.0, n_save=3001),
            mm.simulate(p, x5=-7e-3, t_end=3.0, n_save=3001))


def test_simulation_figure_has_gap_current_beam_and_phase_panels(runs):
    small, large = runs
    fig, axes = simulation_figure([small, large])
    assert axes.shape == (2, 2)
    labels = [ax.get_ylabel() for ax in axes.ravel()]
    assert "gap deviation" in labels[0] and "current" in labels[1]
    assert "beam deflection" in labels[2] and "gap rate" in labels[3]
    title = fig._suptitle.get_text()
    # what was simulated and what happened
    assert "Model A" in title and "x5(0) = -3 mm" in title and "x5(0) = -7 mm" in title
    assert f"collision at t = {large.collision_time:.3f} s" in title
    texts = _legend_texts(axes[0, 0])
    assert any("gap limits" in t for t in texts) and "collision" in texts
    assert any("zero current" in t for t in _legend_texts(axes[0, 1]))
    assert _has_marker(axes[0, 0], "x") and _has_marker(axes[1, 1], "x")


def test_simulation_time_axis_is_fitted_to_the_event(runs):
    small, large = runs
    fig, axes = simulation_figure([large])
    t_end = axes[0, 0].get_xlim()[1]
    assert t_end == pytest.approx(max(0.1, 1.25 * large.collision_time))
    assert t_end < 0.2 * large.t_end
    # the small disturbance dies out well before the horizon: the axis stops there too
    assert fitted_time_window([small]) < 0.5 * small.t_end
    assert describe_initial(small) == "x5(0) = -3 mm"


def test_phase_portrait_is_smooth(runs):
    """Successive points of the phase portrait turn by a small angle (no polygon)."""
    small, _ = runs
    fig, axes = simulation_figure([small])
    line = axes[1, 1].get_lines()[0]
    x, y = np.asarray(line.get_xdata()), np.asarray(line.get_ydata())
    d = np.diff(np.column_stack([x / np.ptp(x), y / np.ptp(y)]), axis=0)
    d = d[np.linalg.norm(d, axis=1) > 1e-9]
    turn = np.arccos(np.clip(np.sum(d[1:] * d[:-1], axis=1)
                             / (np.linalg.norm(d[1:], axis=1) * np.linalg.norm(d[:-1], axis=1)),
                             -1, 1))
    assert np.degrees(turn).max() < 20.0


# ---------------------------------------------------------------------------------------
# root locus
# ---------------------------------------------------------------------------------------
def test_root_locus_zooms_on_the_axis_and_notes_far_eigenvalues():
    values = np.linspace(1.0, 2.0, 11)
    near = np.column_stack([-1 + values + 10j, -1 + values - 10j, -2 + 0 * values,
                            -3 + 5j + 0 * values, -3 - 5j + 0 * values, -4 + 0 * values])
    eig = np.column_stack([near, -480.0 + 0 * values])
    (x0, x1), (y0, y1) = zoom_window(eig)
    assert -6 < x0 < -4 and 1 < x1 < 2 and 10 < y1 < 12
    design = (1.5, eig[5])
    fig = root_locus_figure(values, eig, "kD", "A s/m", design=design)
    ax1, ax2 = fig.axes[0], fig.axes[1]
    assert ax1.get_xlim()[0] > -10
    notes = [t.get_text() for t in ax1.texts]
    assert any("not shown: 1 eigenvalue" in t and "-480" in t for t in notes)
    assert _has_marker(ax1, "x")  # the design point's eigenvalues
    assert any("design point kD = 1.5" in t for t in _legend_texts(ax2))
    assert "kD (A s/m)" == ax2.get_xlabel()


# ---------------------------------------------------------------------------------------
# Hopf curve
# ---------------------------------------------------------------------------------------
def test_hopf_curve_marks_the_design_point():
    pts = [HopfCurvePoint(values=(100.0 + k, 3e-4 + 1e-5 * k), x=np.zeros(2), frequency=100.0,
                          l1=1e-4 if k < 5 else -1e-4, others_stable=True,
                          n_unstable_others=0) for k in range(10)]
    curve = HopfCurve(params=("omega1", "sigma"), points=pts, special_points=[],
                      converged=True, message="", steps=10)
    fig = hopf_curve_figure([curve], ("omega1", "sigma"), ("rad/s", "1/kg"),
                            design_point=(97.3, 4.7e-4))
    ax = fig.axes[0]
    texts = _legend_texts(ax)
    assert any(t.startswith("design point (omega1 = 97.3") for t in texts)
    assert any("subcritical" in t for t in texts) and any("supercritical" in t for t in texts)
    assert _has_marker(ax, "*")


# ---------------------------------------------------------------------------------------
# map
# ---------------------------------------------------------------------------------------
def _toy_map():
    x = np.linspace(60.0, 180.0, 7)
    y = np.linspace(2e-4, 6e-4, 5)
    X, _ = np.meshgrid(x, y)
    stable = (X < 130).astype(np.int8)
    chi = np.where(stable == 1, 0.02 * (140 - X), np.nan)  # small chi next to the boundary
    resolved = np.ones_like(stable)
    resolved[0, 0] = 0
    return xr.Dataset(
        {"chi": (("sigma", "omega1"), chi), "stable": (("sigma", "omega1"), stable),
         "max_real_part": (("sigma", "omega1"), (X - 130.0) / 100.0),
         "resolved": (("sigma", "omega1"), resolved),
         "hopf_x": (("sigma", "hopf"), np.full((len(y), 1), 130.0))},
        coords={"omega1": ("omega1", x, {"units": "rad/s"}),
                "sigma": ("sigma", y, {"units": "1/kg"})})


def test_map_draws_unstable_points_grey_hatched_apart_from_small_chi():
    ds = _toy_map()
    fig = map_figure(ds, design_point=(97.3, 4.7e-4))
    fig.canvas.draw()  # colours are mapped at draw time
    ax = fig.axes[0]
    hatched = [c for c in ax.collections if isinstance(c, PolyCollection) and c.get_hatch()]
    assert hatched, "unstable cells must be hatched"
    grey = hatched[0].get_facecolor()[0][:3]
    assert np.allclose(grey, grey[0]), "unstable cells are grey"
    # the colour mesh of chi leaves every unstable cell out (masked), so chi = 0 never
    # takes the colour of small chi
    meshes = [c for c in ax.collections if c.get_array() is not None
              and np.ma.isMaskedArray(c.get_array()) and c.get_cmap().name == "viridis"]
    assert meshes
    mask = np.ma.getmaskarray(meshes[0].get_array()).reshape(ds["chi"].shape)
    assert np.array_equal(mask, ds["stable"].values == 0)
    texts = _legend_texts(ax)
    assert any(t.startswith("unstable equilibrium: no index") for t in texts)
    assert any(t.startswith("design point") for t in texts)
    assert any(t.startswith("unresolved: 1 point") for t in texts)
    assert any("stability boundary" in t for t in texts)


# ---------------------------------------------------------------------------------------
# cycle diagram
# ---------------------------------------------------------------------------------------
def test_cycle_diagram_legend_is_complete_and_labels_branches():
    from test_cycles import _Q, FOLD_NF, _start

    from maglev_match.dynamics.cycles import cycle_branch

    def limits(system, orbit):
        r = np.sqrt(np.sum((orbit.states @ _Q)[:, :2] ** 2, axis=1))
        return {"radius 1.3": 1.3 - float(np.max(r))}

    br = cycle_branch(FOLD_NF, _start(FOLD_NF, 2.0), "mu", ntst=12, ncol=4, max_steps=200,
                      ds_max=0.5, limits=limits)
    eq = np.linspace(-1.5, 0.5, 21)
    fig, ax = cycle_diagram([br], "mu", eq, eq < 0, observable="radius", scale=1.0, unit="1",
                            limits=(-1.3, 1.3), design_value=-0.5)
    texts = _legend_texts(ax)
    for expected in ("equilibrium, stable", "equilibrium, unstable", "stable cycle (max/min)",
                     "unstable cycle (max/min)", "Hopf point", "fold of cycles (LPC)",
                     "cycle touches a physical limit", "design point mu = -0.5"):
        assert expected in texts, expected
    assert any(t.startswith("physical limits") for t in texts)
    assert any(t.startswith(f"{branch_label(0)}: cycles from the Hopf point") for t in texts)
    # the branch label, and the limit the cycle touched named beside its mark
    assert [t.get_text() for t in ax.texts] == ["b1", "touches: radius 1.3"]
    # line-style entries are neutral grey, not a branch colour
    styles = {t.get_text(): h for t, h in zip(ax.get_legend().get_texts(),
                                               ax.get_legend().legend_handles, strict=True)}
    assert matplotlib.colors.to_hex(styles["stable cycle (max/min)"].get_color()) == "#595959"


def test_root_locus_marks_the_hopf_crossing_at_its_interpolated_value_and_frequency():
    """A pair a(p) +- i w(p) with a = p - 1, w = 2 + p and a real eigenvalue -3 crosses the
    axis at p = 1 with omega = 3 (linear data: interpolation is exact); the figure marks it
    on both panels."""
    from maglev_match.plots.rootlocus import axis_crossings, root_locus_figure

    p = np.linspace(0.0, 2.0, 9)
    a, w = p - 1.0, 2.0 + p
    ev = np.column_stack([a + 1j * w, a - 1j * w, np.full_like(p, -3.0)])
    ((value, omega, hopf),) = axis_crossings(p, ev)
    assert value == pytest.approx(1.0) and omega == pytest.approx(3.0) and hopf
    fig = root_locus_figure(p, ev, "p")
    labels = [t.get_text() for ax in fig.axes if ax.get_legend() for t in
              ax.get_legend().get_texts()]
    assert any(t.startswith("Hopf crossing p = 1,") and "omega = 3 rad/s" in t
               for t in labels), labels
    # a real eigenvalue crossing is not called a Hopf point
    ev_real = np.column_stack([p - 1.0, np.full_like(p, -3.0)])
    assert [h for *_, h in axis_crossings(p, ev_real)] == [False]
