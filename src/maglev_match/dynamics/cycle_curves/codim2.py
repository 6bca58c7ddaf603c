"""Codimension-two points on a curve of cycle bifurcations, with AUTO / MatCont labels.

Test functions, evaluated at every point of the curve whose Floquet data are reliable
(|trivial multiplier - 1| within tolerance; the NS curve's angle tests at every point); a
point is reported only where the test changes sign between two consecutive points where
it is evaluated. The critical multiplier of the curve
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
  in the parameter plane (a cusp; then solved where the curve's tangent in the parameter
  plane vanishes, :mod:`~maglev_match.dynamics.cycle_curves.cusp`);
* on PD: LPPD, prod (mu_i - 1) / (1 + |mu_i|) (a second multiplier at +1); PDNS, the NS
  test above on the remaining multipliers; R2 (1:2 resonance), prod (mu_i + 1) / (1 +
  |mu_i|) (a second multiplier at -1; there the PD system's test function g vanishes to
  second order, (mu_1 + 1)(mu_2 + 1) with the Jordan block of the pair, so the system is
  singular and the point stays bracketed, the curve passing it); GPD (generalised period
  doubling), the critical coefficient c of the flip's normal form eta -> -eta + c eta^3
  (:mod:`~maglev_match.dynamics.cycle_curves.flip`), reported where c changes sign
  between two points at which |c| exceeds its estimated error, the points between them
  within their error not counting (as for CH below; a c that is zero within its accuracy
  all along, as for a flip that is linear in the critical direction, reports no GPD).
* on NS (the critical pair e^{+-i theta} removed, theta an unknown of the augmented system,
  :mod:`~maglev_match.dynamics.cycle_curves.ns`, kappa = cos theta): the strong resonances
  R3, kappa + 1/2 (theta = 2 pi / 3), and R4, kappa (theta = pi / 2); R2, cos(theta / 2),
  and R1, sin(theta / 2), which change sign where theta passes pi or 0, where kappa + 1 and
  kappa - 1 touch zero (the driver ends the curve there: R2 solved at theta = pi, R1
  bracketed, :func:`~maglev_match.dynamics.cycle_curves.curve.cycle_curve`); these four read
  the solved angle, so they are evaluated at every point; LPNS (fold-NS), prod (mu_i - 1) /
  (1 + |mu_i|), and PDNS (flip-NS), prod (mu_i + 1) / (1 + |mu_i|), of the remaining
  multipliers, only where the Floquet data are reliable; CH (Chenciner), the critical
  coefficient d of the NS normal form z -> e^{i theta} z (1 + d |z|^2)
  (:mod:`~maglev_match.dynamics.cycle_curves.torus`), computed only where the Floquet
  data are reliable: CH where d has opposite signs at two points where |d| exceeds its
  estimated error, d computed at every point between them (these need not be
  consecutive: a point near CH has |d| within its error), bracketed on the step where d
  itself changes sign.

The driver solves the multiplier points, GPD and CH on the curve (``located`` "solved");
where it cannot, and for R1 on NS and R2 on PD, the point stays bracketed: the linear
interpolation of the test function's zero between the two points, CPC (if its solve
fails) the point where the direction reverses (``located`` says so).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from maglev_match.dynamics.continuation import SpecialPoint, label_points
from maglev_match.dynamics.cycle_curves.augmented import CurveKind

__all__ = ["detect_codim2", "codim2_rest", "codim2_tests", "torus_pair"]


def codim2_tests(kind: str, mult: np.ndarray, angle: float = float("nan")
                 ) -> dict[str, float]:
    """The test functions of the module docstring at one point (nontrivial multipliers
    ``mult``, the critical one still among them, empty where unreliable; ``angle`` theta of
    an NS curve's point). Plain products (smooth along the curve, so their zeros are
    solved by secant iterations). GPD and CH, read from the normal-form coefficients with
    their error estimates, are detected over the whole curve (`detect_codim2`)."""
    mult = np.asarray(mult, complex)
    if CurveKind(kind) == CurveKind.NS:
        return _ns_tests(mult, angle)
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
    return {"LPPD": fold, "PDNS": ns, "R2": flip}


def torus_pair(mult: np.ndarray, tol: float) -> bool:
    """Whether a complex-conjugate pair of multipliers lies within ``tol`` of the unit
    circle (what a zero of the NS product must have to be a torus bifurcation, and not a
    neutral saddle mu_i mu_j = 1 of two real or unrelated multipliers)."""
    mult = np.asarray(mult, complex)
    cplx = mult[np.abs(mult.imag) > 1e-8 * np.maximum(1.0, np.abs(mult))]
    return bool(cplx.size and np.min(np.abs(np.abs(cplx) - 1.0)) <= tol)


def _ns_tests(mult: np.ndarray, angle: float) -> dict[str, float]:
    out = {}
    if np.isfinite(angle):
        kappa = float(np.cos(angle))
        out = {"R1": float(np.sin(angle / 2.0)), "R2": float(np.cos(angle / 2.0)),
               "R3": kappa + 0.5, "R4": kappa}
    if mult.size >= 2 and np.isfinite(angle):
        rest = codim2_rest(CurveKind.NS, mult, angle)
        if rest.size:
            out["LPNS"] = float(np.real(np.prod((rest - 1.0) / (1.0 + np.abs(rest)))))
            out["PDNS"] = float(np.real(np.prod((rest + 1.0) / (1.0 + np.abs(rest)))))
    return out


def codim2_rest(kind: str, mult: np.ndarray, angle: float = float("nan")) -> np.ndarray:
    """The nontrivial multipliers without the curve's critical one (+1 on LPC, -1 on
    PD; on NS the pair nearest e^{+-i angle})."""
    if CurveKind(kind) == CurveKind.NS:
        e = complex(np.exp(1j * angle))
        rest = np.delete(mult, int(np.argmin(np.abs(mult - e))))
        return np.delete(rest, int(np.argmin(np.abs(rest - e.conjugate()))))
    crit = 1.0 if CurveKind(kind) == CurveKind.LPC else -1.0
    return np.delete(mult, int(np.argmin(np.abs(mult - crit))))


def detect_codim2(kind: str, points: Sequence, params: tuple[str, str]
                  ) -> list[SpecialPoint]:
    """The codimension-two points between consecutive reliable points of a curve."""
    out: list[SpecialPoint] = []
    ns = CurveKind(kind) == CurveKind.NS
    # unreliable points carry no multipliers: only the NS curve's angle tests remain there
    tests = [codim2_tests(kind, c.multipliers if c.reliable else np.zeros(0, complex),
                          getattr(c, "angle", np.nan)) for c in points]
    for ka in range(len(points) - 1):
        a, b = points[ka], points[ka + 1]
        ta, tb = tests[ka], tests[ka + 1]
        for name in ta:
            fa, fb = ta.get(name, np.nan), tb.get(name, np.nan)
            if not (np.isfinite(fa) and np.isfinite(fb)) or fa * fb >= 0:
                continue
            near = a if abs(fa) <= abs(fb) else b
            if not ns and name in ("LPNS", "PDNS") and not torus_pair(codim2_rest(
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
    if ns:
        out.extend(_coefficient_sign_changes(points, "CH", "ns_coefficient", "ns_error",
                                             "NS coefficient"))
    if CurveKind(kind) == CurveKind.PD:
        out.extend(_coefficient_sign_changes(points, "GPD", "flip", "flip_error",
                                             "flip coefficient"))
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


def _coefficient_sign_changes(points: Sequence, name: str, coef: str, error: str,
                              what: str) -> list[SpecialPoint]:
    """CH on an NS curve (the NS coefficient d, attribute ``ns_coefficient``) and GPD on a
    PD curve (the flip coefficient c, ``flip``): the coefficient changes sign between two
    points where its modulus exceeds its estimated error (``ns_error``, ``flip_error``),
    with it computed (finite) at every point between them (where it is within its error
    the sign is not trusted, so the two points need not be consecutive); the bracket is the
    step between them over which the coefficient itself changes sign (the first, if noise
    near zero makes several)."""
    d = np.array([getattr(c, coef, np.nan) for c in points], float)
    err = np.array([getattr(c, error, np.nan) for c in points], float)
    sure = np.flatnonzero(np.abs(d) > err)  # nan compares False: not evaluated there
    out = []
    for i, j in zip(sure[:-1], sure[1:], strict=True):
        if d[i] * d[j] >= 0 or not np.all(np.isfinite(d[i:j + 1])):
            continue
        k = i + int(np.flatnonzero(d[i:j] * d[i + 1:j + 1] <= 0)[0])
        a, b = points[k], points[k + 1]
        fa, fb = d[k], d[k + 1]
        f = fa / (fa - fb) if fa != fb else 0.5
        vals = tuple(float(x + f * (y - x)) for x, y in zip(a.values, b.values, strict=True))
        out.append(SpecialPoint(
            type=name, value=vals[0], values=vals, step=int(k),
            located="bracketed between two consecutive points of the curve (linear "
            f"interpolation of the {what}, not solved)",
            detail=f"{what} {d[i]:.3g} and {d[j]:.3g} (beyond their estimated errors "
            f"{err[i]:.2g}, {err[j]:.2g})",
            period=float(a.period + f * (b.period - a.period)),
            point=a if abs(fa) <= abs(fb) else b))
    return out
