"""The map figure's stability boundary is the computed Hopf curve: on a coarse grid it lies on
the curve that `hopf-curve` computes (within the continuation's tolerance), where a contour
of max Re(lambda) interpolated on the grid misses it by rad/s."""

import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
import pytest  # noqa: E402

from maglev_match.analyses.maps import Axis, MapSpec, compute_tile, map_dataset  # noqa: E402
from maglev_match.core.params import load_preset  # noqa: E402
from maglev_match.plots.maps import BOUNDARY_LABEL, ROW_HOPF_LABEL, map_figure  # noqa: E402

BASE = load_preset("turnout-soft")
# a coarse grid: 8 x 5 over the whole plane of the README's map
SPEC = MapSpec(base=BASE.as_input_dict(), x=Axis("omega1", 40.0, 190.0, 8),
               y=Axis("sigma", 2e-4, 6e-4, 5), rows_per_tile=5, simulate=False)


def _distance_to_polyline(points: np.ndarray, line: np.ndarray) -> np.ndarray:
    """Distance of each point (n, 2) to the polyline (m, 2), NaN rows split branches."""
    out = np.full(len(points), np.inf)
    for a, b in zip(line[:-1], line[1:], strict=True):
        if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
            continue
        ab = b - a
        t = np.clip(((points - a) @ ab) / max(ab @ ab, 1e-300), 0.0, 1.0)
        out = np.minimum(out, np.linalg.norm(points - (a + t[:, None] * ab), axis=1))
    return out


@pytest.fixture(scope="module")
def coarse_map():
    return map_dataset(SPEC, compute_tile(SPEC, (0, 5)), check=False)


def test_figure_boundary_lies_on_the_hopf_curve_of_hopf_curve(coarse_map):
    import maglev_match as mm

    ds = coarse_map
    fig = map_figure(ds)
    ax = fig.axes[0]
    lines = [ln for ln in ax.get_lines() if ln.get_label() == BOUNDARY_LABEL]
    assert len(lines) == 1, "the boundary must be the continued Hopf curve"
    drawn = np.column_stack(lines[0].get_data())
    drawn = drawn[np.all(np.isfinite(drawn), axis=1)]
    assert len(drawn) > 20
    # the `hopf-curve` command's curve inside the same ranges
    curves = mm.hopf_curve(BASE, names=("omega1", "sigma"),
                           bounds={"omega1": (40.0, 190.0), "sigma": (2e-4, 6e-4)})
    assert curves
    ref = np.concatenate([np.vstack([c.values(), [np.nan, np.nan]]) for c in curves])
    span = np.array([150.0, 4e-4])
    d = _distance_to_polyline(drawn / span, ref / span)
    # the two continuations step differently along the same curve: their vertices lie on
    # each other's polylines to the chord error of a step of at most 1 % of the ranges
    assert d.max() < 1e-4
    # every drawn vertex is a Hopf point: a pair of eigenvalues on the imaginary axis
    from maglev_match.maglev.unit import unit_system

    system = unit_system(BASE)
    for w, s in drawn[:: max(1, len(drawn) // 12)]:
        p = system.params_with(omega1=w, sigma=s)
        lam = np.linalg.eigvals(np.asarray(system.jacobian(np.zeros(system.dim), p)))
        crossing = lam[np.argmin(np.abs(lam.real))]
        assert abs(crossing.real) < 1e-6 * abs(crossing.imag)
    # the grid contour that the figure no longer draws misses the curve by rad/s here
    import matplotlib.pyplot as plt

    x, y = ds["omega1"].values, ds["sigma"].values
    cs = plt.figure().add_subplot().contour(x, y, ds["max_real_part"].values, levels=[0.0])
    contour = np.concatenate([seg for seg in cs.allsegs[0]])
    assert _distance_to_polyline(contour / span, ref / span).max() * 150.0 > 1.0
    plt.close("all")


def test_figure_draws_each_rows_hopf_points_when_no_curve_was_continued(coarse_map):
    ds = coarse_map.drop_vars(["hopf_curve_x", "hopf_curve_y", "hopf_curve_l1"])
    ax = map_figure(ds).axes[0]
    pts = [ln for ln in ax.get_lines() if ln.get_label() == ROW_HOPF_LABEL]
    assert len(pts) == 1
    xs, ys = pts[0].get_data()
    hx = coarse_map["hopf_x"].values
    assert len(xs) == np.isfinite(hx).sum() >= 4
    # each row's Hopf point is the continued curve's crossing of that row
    ref = np.column_stack([coarse_map["hopf_curve_x"].values,
                           coarse_map["hopf_curve_y"].values])
    span = np.array([150.0, 4e-4])
    pts_xy = np.column_stack([xs, ys])
    assert _distance_to_polyline(pts_xy / span, ref / span).max() < 1e-4


def test_unstable_points_are_drawn_apart_and_chi_is_nan_there(coarse_map):
    ds = coarse_map
    stable = ds["stable"].values == 1
    assert stable.any() and (~stable).any()
    assert np.all(np.isnan(ds["chi"].values[~stable]))
    ax = map_figure(ds, design_point=(97.3, 4.7e-4)).axes[0]
    texts = [t.get_text() for t in ax.get_legend().get_texts()]
    assert any(t.startswith("unstable equilibrium: no index") for t in texts)
    assert BOUNDARY_LABEL in texts
