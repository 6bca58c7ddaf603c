"""Result reprs are short and informative: key scalars shown, arrays and functions
summarised (a notebook or a log must not drown in array elements)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

import maglev_match as mm
from maglev_match.core.reprs import compact_repr
from maglev_match.dynamics.hopf import locate_hopf_points


@dataclass(frozen=True)
class _Result:
    value: float
    states: np.ndarray
    one: np.ndarray
    rhs: object
    names: tuple
    label: str

    __repr__ = compact_repr


def test_compact_repr_summarises_arrays_sequences_and_functions():
    r = _Result(value=1.23456789, states=np.zeros((3, 4)), one=np.array([2.5]), rhs=np.sin,
                names=tuple("abcdefg"), label="x" * 200)
    text = repr(r)
    assert text.startswith("_Result(value=1.23457, states=<array 3x4 float64>, one=2.5, ")
    assert "rhs=sin" in text and "names=<7 items>" in text
    assert "x" * 61 not in text and len(text) < 200


def test_library_results_have_short_reprs():
    system = mm.build_system("alpha1", "unit")
    scan = locate_hopf_points(system, "omega1", 100.0, 200.0, n_scan=50)
    for obj in (mm.stability("alpha1"), system, scan, scan.points[0]):
        text = repr(obj)
        assert len(text) < 700, text
        assert "array([" not in text and "<function" not in text, text
    assert f"value={scan.points[0].value:.6g}" in repr(scan.points[0])
