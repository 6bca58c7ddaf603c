"""The map's Hopf scan along a row (stacked eigenvalues at the known equilibrium x = 0)
against the general scan by equilibrium continuation (two independent detections, the same
refinement): the same Hopf points, and the eigenvalues at the nodes are those of the nodes."""

import numpy as np
import pytest

from maglev_match.analyses.maps import (
    SCAN_PER_NODE,
    Axis,
    MapSpec,
    hopf_test_sign,
    path_eigenvalues,
    row_extension,
    scan_hopf_points,
)
from maglev_match.core.params import load_preset

SPEC = MapSpec(base=load_preset("turnout-soft").as_input_dict(),
               x=Axis("omega1", 40.0, 190.0, 12), y=Axis("sigma", 2e-4, 6e-4, 3), ntst=30)


def _row_path(spec, row):
    from maglev_match.dynamics.paths import path_system
    from maglev_match.maglev.unit import param_vector, unit_system

    yv = spec.y.values[row]
    lo, hi = row_extension(spec, spec.x.values, yv)
    pts = [q for _, q in lo[::-1]] + [spec.point(x, yv) for x in spec.x.values] + [
        q for _, q in hi]
    system = unit_system(pts[0])
    nodes = np.array([param_vector(q) for q in pts])
    return system, nodes, path_system(system, nodes)


@pytest.mark.parametrize("row", [0, 2])
def test_eigenvalue_scan_finds_the_hopf_points_of_the_continuation_scan(row):
    from maglev_match.dynamics.hopf import locate_hopf_points
    from maglev_match.dynamics.paths import PATH_PARAM

    system, nodes, path = _row_path(SPEC, row)
    t_end = len(nodes) - 1.0
    w = path_eigenvalues(system, nodes)
    assert w.shape == (SCAN_PER_NODE * (len(nodes) - 1) + 1, system.dim)
    # the node samples are the Jacobians' eigenvalues at the nodes themselves
    for k in (0, len(nodes) // 2, len(nodes) - 1):
        ref = np.linalg.eigvals(np.asarray(system.jacobian(np.zeros(system.dim), nodes[k])))
        assert np.sort_complex(w[SCAN_PER_NODE * k]) == pytest.approx(np.sort_complex(ref),
                                                                       rel=1e-12, abs=1e-12)
    mine = scan_hopf_points(path, w, t_end, system, nodes)
    ref = [hp for hp in locate_hopf_points(path, PATH_PARAM, 0.0, t_end,
                                           n_scan=3 * len(nodes)).points if hp.converged]
    assert len(mine) >= 1  # each row of this grid crosses the Hopf curve
    assert [hp.value for hp in mine] == pytest.approx([hp.value for hp in ref], rel=1e-10)
    assert [hp.frequency for hp in mine] == pytest.approx([hp.frequency for hp in ref],
                                                          rel=1e-10)
    # every Hopf point lies where the test's sign flips between neighbouring samples
    sign = hopf_test_sign(w)
    for hp in mine:
        i = int(hp.value * SCAN_PER_NODE)
        assert sign[i] != sign[min(i + 1, len(sign) - 1)]


def test_hopf_test_sign_is_the_sign_of_the_bialternate_product():
    rng = np.random.default_rng(3)
    for _ in range(20):
        A = rng.normal(size=(5, 5))
        w = np.linalg.eigvals(A)
        i, j = np.triu_indices(5, 1)
        prod = np.prod(w[i] + w[j])
        assert abs(prod.imag) <= 1e-9 * abs(prod)
        assert hopf_test_sign(w[None, :])[0] == np.sign(prod.real)


def test_intervals_that_are_not_one_simple_crossing_are_rescanned_by_continuation(
        monkeypatch):
    """Two complex pairs crossing the imaginary axis in opposite directions within one
    sample interval leave the Hopf test's sign unchanged: that interval (and only that one)
    goes to the continuation scan, which splits the step until each crossing has its own."""
    import maglev_match.dynamics.hopf as hopf

    calls = []

    def record(system, param, start, stop, p=None, n_scan=200, progress=None):
        calls.append((start, stop, n_scan))
        return hopf.HopfScan(param, start, stop, [], np.linspace(start, stop, 2),
                             np.zeros(2), ())

    monkeypatch.setattr(hopf, "locate_hopf_points", record)
    stay = [-1.0 + 0j, -2.0 + 0j]
    w = np.array([
        [-0.1 + 5j, -0.1 - 5j, 0.2 + 9j, 0.2 - 9j, *stay],
        [-0.1 + 5j, -0.1 - 5j, 0.2 + 9j, 0.2 - 9j, *stay],
        [0.1 + 5j, 0.1 - 5j, -0.2 + 9j, -0.2 - 9j, *stay],  # both pairs cross here
        [0.1 + 5j, 0.1 - 5j, -0.2 + 9j, -0.2 - 9j, *stay],
    ])
    sign = hopf_test_sign(w)
    assert sign[1] == sign[2]  # the two crossings cancel in the test
    out = scan_hopf_points(None, w, 1.0, None, None)
    assert out == []
    assert calls == [(1 / SCAN_PER_NODE, 2 / SCAN_PER_NODE, 17)]
