"""Codimension-two points on a curve of cycle bifurcations, with AUTO / MatCont labels.

Test functions, evaluated at every point of the curve whose Floquet data are reliable
(|trivial multiplier - 1| within tolerance); a point is reported only where the test
changes sign between two consecutive reliable points. The critical multiplier of the curve
(the second +1 on an LPC curve, the -1 on a PD curve) is removed from the nontrivial
multipliers first; the remaining ones, mu_i, give (Kuznetsov 2004, sec. 10.3.2; the
products of :func:`~maglev_match.dynamics.cycles.multiplier_tests`, not their geometric
means, so that they are smooth where they vanish):

* on LPC: LPPD (fold-flip), prod (mu_i + 1) / (1 + |mu_i|): a real multiplier passes -1;
  LPNS (fold-Neimark-Sacker), prod_{i<j} (mu_i mu_j - 1) / (1 + |mu_i mu_j|), kept only
  where a complex-conjugate pair lies on the unit circle (within 0.1 at the bracket,
  1e-4 once solved): a neutral saddle mu_i mu_j = 1 of other multipliers is no
  bifurcation;
  CPC (cusp of cycles): the projection of the curve's direction in the scaled parameter
  plane on its direction one step before, which changes sign where the curve turns back
  in the parameter plane (a cusp);
* on PD: LPPD, prod (mu_i - 1) / (1 + |mu_i|) (a second multiplier at +1); PDNS, the NS
  test above on the remaining multipliers.

The driver solves the multiplier points on the curve (``located`` "solved"); where it
cannot, and for CPC, the point stays bracketed: the linear interpolation of the test
function's zero between the two points, CPC the point where the direction reverses
(``located`` says so).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from maglev_match.dynamics.continuation import SpecialPoint, label_points
from maglev_match.dynamics.cycle_curves.augmented import CurveKind

__all__ = ["detect_codim2", "codim2_rest", "codim2_tests", "torus_pair"]


def codim2_tests(kind: str, mult: np.ndarray) -> dict[str, float]:
    """The multiplier test functions of the module docstring at one point (nontrivial
    multipliers ``mult``, the critical one still among them). Plain products (smooth along
    the curve, so their zeros are solved by secant iterations)."""
    mult = np.asarray(mult, complex)
    if mult.size == 0:
        return {}
    rest = codim2_rest(kind, mult)
    if rest.size == 0:
        return {}
    i, j = np.triu_indices(rest.size, 1)
    pair = rest[i] * rest[j]
    flip = float(np.real(np.prod((rest + 1.0) / (1.0 + np.abs(rest)))))
    ns = float(np.real(np.prod((pair - 1.0) / (1.0 + np.abs(pair))))) if pair.size else np.nan
    if CurveKind(kind) == CurveKind.LPC:
        return {"LPPD": flip, "LPNS": ns}
    fold = float(np.real(np.prod((rest - 1.0) / (1.0 + np.abs(rest)))))
    return {"LPPD": fold, "PDNS": ns}


def torus_pair(mult: np.ndarray, tol: float) -> bool:
    """Whether a complex-conjugate pair of multipliers lies within ``tol`` of the unit
    circle (what a zero of the NS product must have to be a torus bifurcation, and not a
    neutral saddle mu_i mu_j = 1 of two real or unrelated multipliers)."""
    mult = np.asarray(mult, complex)
    cplx = mult[np.abs(mult.imag) > 1e-8 * np.maximum(1.0, np.abs(mult))]
    return bool(cplx.size and np.min(np.abs(np.abs(cplx) - 1.0)) <= tol)


def codim2_rest(kind: str, mult: np.ndarray) -> np.ndarray:
    """The nontrivial multipliers without the curve's critical one (+1 on LPC, -1 on
    PD)."""
    crit = 1.0 if CurveKind(kind) == CurveKind.LPC else -1.0
    return np.delete(mult, int(np.argmin(np.abs(mult - crit))))


def detect_codim2(kind: str, points: Sequence, params: tuple[str, str]
                  ) -> list[SpecialPoint]:
    """The codimension-two points between consecutive reliable points of a curve."""
    out: list[SpecialPoint] = []
    rel = [(k, c) for k, c in enumerate(points) if c.reliable]
    tests = {k: codim2_tests(kind, c.multipliers) for k, c in rel}
    for (ka, a), (kb, b) in zip(rel, rel[1:], strict=False):
        if kb != ka + 1:
            continue
        ta, tb = tests[ka], tests[kb]
        for name in ta:
            fa, fb = ta.get(name, np.nan), tb.get(name, np.nan)
            if not (np.isfinite(fa) and np.isfinite(fb)) or fa * fb >= 0:
                continue
            near = a if abs(fa) <= abs(fb) else b
            if name in ("LPNS", "PDNS") and not torus_pair(codim2_rest(
                    kind, near.multipliers), 0.1):
                continue
            f = fa / (fa - fb)
            vals = tuple(float(x + f * (y - x)) for x, y in zip(a.values, b.values,
                                                                  strict=True))
            out.append(SpecialPoint(
                type=name, value=vals[0], values=vals, step=ka,
                located="bracketed between two consecutive points of the curve (linear "
                "interpolation of the test function, not solved)",
                detail=f"test function {fa:.3g} and {fb:.3g} at the two points",
                period=float(a.period + f * (b.period - a.period)), point=near))
    if CurveKind(kind) == CurveKind.LPC:
        out.extend(_cusps(points))
    out.sort(key=lambda s: s.step)
    return label_points(out)


def _cusps(points: Sequence) -> list[SpecialPoint]:
    """CPC: the curve's direction in the parameter plane reverses at point k (scaled by
    the spread of each parameter along the curve)."""
    if len(points) < 3:
        return []
    P = np.array([c.values for c in points], float)
    span = np.ptp(P, axis=0)
    span[span == 0] = 1.0
    d = np.diff(P / span, axis=0)
    out = []
    for k in range(1, len(d)):
        c = points[k]
        if not c.reliable:
            continue
        if float(d[k - 1] @ d[k]) < 0:
            out.append(SpecialPoint(
                type="CPC", value=float(P[k, 0]), values=tuple(map(float, P[k])), step=k,
                located="bracketed at a point of the curve (it turns back in the "
                "parameter plane there; not solved)", period=c.period, point=c))
    return out
