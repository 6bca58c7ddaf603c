"""What a two-parameter curve of cycle bifurcations returns: its points
(:class:`CycleCurvePoint`: both parameters, the cycle, its Floquet multipliers where they
are reliable, the test function's value), the curve (:class:`CycleCurve`: the points, the
special points, why it stopped and its warnings) and its :class:`xarray.Dataset` form.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any

import numpy as np

from maglev_match.core.reprs import compact_repr
from maglev_match.core.results import Plottable
from maglev_match.dynamics.continuation import SpecialPoint
from maglev_match.dynamics.cycles.orbits import PeriodicOrbit

__all__ = ["CurveStop", "CycleCurvePoint", "CycleCurve"]


class CurveStop(StrEnum):
    """Why a curve of cycle bifurcations stopped (the strings of JSON and files)."""

    BOUND = "reached the end of the range"
    MAX_STEPS = "max_steps"
    STEP_TOO_SMALL = "step too small"
    START_FAILED = "the start could not be corrected onto the curve"
    RESONANCE = "reached a strong resonance (R1 or R2)"
    CONTACT = "reached a physical limit"


@dataclass(frozen=True)
class CycleCurvePoint:
    """One point of the curve: a cycle at its bifurcation (LPC or PD) at (p1, p2).

    ``amplitude`` is the largest distance of the orbit's nodes from their mean, each state
    in units of ``system.state_scale`` (Euclidean norm, dimensionless); ``multipliers``
    the nontrivial Floquet multipliers (the one nearest 1 removed; on an LPC curve a
    second one lies at 1, the critical one), reported only where ``reliable`` (|trivial -
    1| <= trivial_tol), else empty; ``test`` the value of the bordered test function g at
    the last Newton iterate (0 to the tolerance);
    ``residual`` the largest residual there; ``angle`` (NS curves only, else nan) the
    angle theta (rad) of the critical multipliers e^{+-i theta}, an unknown of the
    augmented system (``kappa`` = cos theta), where ``test`` is |g| of the complex test
    function; ``flip`` (PD curves only, else nan) the critical coefficient c of the period
    doubling's normal form eta -> -eta + c eta^3 (:mod:`~maglev_match.dynamics.
    cycle_curves.flip`; c > 0 supercritical, c < 0 subcritical; nan also where the
    Floquet data are unreliable or it could not be computed), ``flip_error`` its
    estimated error; ``ns_coefficient`` (NS curves only, else nan) the critical
    coefficient d of the Neimark-Sacker normal form z -> e^{i theta} z (1 + d |z|^2)
    (:mod:`~maglev_match.dynamics.cycle_curves.torus`; d < 0 supercritical, d > 0
    subcritical; nan also where the Floquet data are unreliable), ``ns_error`` its
    estimated error."""

    __repr__ = compact_repr

    values: tuple[float, float]
    period: float
    amplitude: float
    orbit: PeriodicOrbit
    multipliers: np.ndarray
    trivial_multiplier: complex
    reliable: bool
    test: float
    iterations: int
    residual: float
    extrema: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    kind: str = "step"
    angle: float = float("nan")
    flip: float = float("nan")
    flip_error: float = float("nan")
    ns_coefficient: float = float("nan")
    ns_error: float = float("nan")

    @property
    def kappa(self) -> float:
        """cos theta of the critical pair e^{+-i theta} on an NS curve (nan on others)."""
        return float(np.cos(self.angle))


@dataclass(frozen=True)
class CycleCurve(Plottable):
    """A curve of cycle bifurcations (``kind`` LPC or PD) in the parameters ``params``."""

    __repr__ = compact_repr

    kind: str
    params: tuple[str, str]
    points: tuple[CycleCurvePoint, ...]
    special_points: tuple[SpecialPoint, ...] = ()
    stopped_reason: str = ""
    warnings: tuple[str, ...] = ()
    message: str = ""
    ntst: int = 0
    ncol: int = 0
    steps: int = 0
    rejected_steps: int = 0
    newton_iterations: int = 0

    @property
    def ok(self) -> bool:
        """Whether the curve ended where it was asked to (the range's end or max_steps) or
        where an NS curve ends (R1, R2) or at a physical limit, not on a numerical
        failure."""
        return self.stopped_reason in (CurveStop.BOUND, CurveStop.MAX_STEPS,
                                       CurveStop.RESONANCE, CurveStop.CONTACT)

    @property
    def p1(self) -> np.ndarray:
        return np.array([c.values[0] for c in self.points])

    @property
    def p2(self) -> np.ndarray:
        return np.array([c.values[1] for c in self.points])

    @property
    def periods(self) -> np.ndarray:
        return np.array([c.period for c in self.points])

    @property
    def amplitudes(self) -> np.ndarray:
        return np.array([c.amplitude for c in self.points])

    def to_xarray(self, units: Mapping[str, str] | None = None) -> Any:
        return curve_to_xarray(self, units)


def curve_to_xarray(curve: CycleCurve, units: Mapping[str, str] | None = None) -> Any:
    """The curve as an :class:`xarray.Dataset` (dimension ``point``; the special points on
    ``special``); every variable has ``units`` and ``long_name``."""
    import xarray as xr

    units = dict(units or {})
    a, b = curve.params
    pts = list(curve.points)
    k = len(pts)
    nm = max([c.multipliers.size for c in pts] + [0])
    mult = np.full((k, nm), np.nan, complex)
    for i, c in enumerate(pts):
        mult[i, :c.multipliers.size] = c.multipliers
    triv = np.array([complex(c.trivial_multiplier) for c in pts], complex)
    data: dict[str, Any] = {
        a: (("point",), curve.p1, {"units": units.get(a, ""), "long_name": f"{a} on the "
                                   f"{curve.kind} curve"}),
        b: (("point",), curve.p2, {"units": units.get(b, ""), "long_name": f"{b} on the "
                                   f"{curve.kind} curve"}),
        "period": (("point",), curve.periods, {"units": "s", "long_name": "period of the "
                                               "cycle"}),
        "amplitude": (("point",), curve.amplitudes, {"units": "1", "long_name":
                      "largest distance of the orbit from its mean (states in units of the "
                      "system's state scale)"}),
        "test": (("point",), np.array([c.test for c in pts]), {"units": "1", "long_name":
                 "bordered test function g at the point"}),
        "reliable": (("point",), np.array([c.reliable for c in pts], np.int8),
                     {"units": "1", "long_name": "1 if the trivial multiplier is within "
                      "tolerance of 1 (multipliers reported)"}),
        "mult_re": (("point", "multiplier"), mult.real, {"units": "1", "long_name":
                    "nontrivial Floquet multipliers, real part"}),
        "mult_im": (("point", "multiplier"), mult.imag, {"units": "1", "long_name":
                    "nontrivial Floquet multipliers, imaginary part"}),
        "triv_re": (("point",), triv.real, {"units": "1", "long_name":
                    "trivial Floquet multiplier, real part"}),
        "triv_im": (("point",), triv.imag, {"units": "1", "long_name":
                    "trivial Floquet multiplier, imaginary part"}),
        "kind": (("point",), np.array([c.kind for c in pts], object), {"units": "1",
                 "long_name": "kind of point (start, step, bound)"}),
    }
    if curve.kind == "NS":
        data["kappa"] = (("point",), np.array([c.kappa for c in pts]), {"units": "1",
                         "long_name": "cos theta of the critical multipliers e^(+-i theta)"})
        data["ns_coefficient"] = (("point",), np.array([c.ns_coefficient for c in pts]), {
            "units": "1", "long_name": "critical coefficient d of the Neimark-Sacker normal "
            "form z -> e^(i theta) z (1 + d |z|^2) (d < 0 supercritical; states in units of "
            "the system's state scale)"})
        data["ns_error"] = (("point",), np.array([c.ns_error for c in pts]), {
            "units": "1", "long_name": "estimated error of the NS coefficient"})
    if curve.kind == "PD":
        data["flip_coefficient"] = (("point",), np.array([c.flip for c in pts]), {
            "units": "1", "long_name": "critical coefficient c of the period doubling's "
            "normal form eta -> -eta + c eta^3 (c > 0 supercritical; states in units of the "
            "system's state scale)"})
        data["flip_error"] = (("point",), np.array([c.flip_error for c in pts]), {
            "units": "1", "long_name": "estimated error of the flip coefficient"})
    names = sorted({n for c in pts for n in c.extrema})
    for n in names:
        for j, w in ((0, "max"), (1, "min")):
            data[f"{n}_{w}"] = (("point",), np.array([c.extrema.get(n, (np.nan,) * 2)[j]
                                                      for c in pts]),
                                {"units": units.get(n, ""), "long_name": f"{w} of {n} over "
                                 "the cycle"})
    coords: dict[str, Any] = {"label": ("point", [f"P{i}" for i in range(k)],
                                        {"units": "1", "long_name": "point label"})}
    sps = list(curve.special_points)
    if sps:
        coords["special_label"] = ("special", [s.label for s in sps],
                                   {"units": "1", "long_name": "special point label"})
        data["special_type"] = (("special",), np.array([s.type for s in sps], object),
                                {"units": "1", "long_name": "codimension-two point type"})
        data["special_" + a] = (("special",), np.array([s.values[0] for s in sps]),
                                {"units": units.get(a, ""), "long_name": f"{a} there"})
        data["special_" + b] = (("special",), np.array([s.values[1] for s in sps]),
                                {"units": units.get(b, ""), "long_name": f"{b} there"})
        data["special_located"] = (("special",), np.array([s.located for s in sps], object),
                                   {"units": "1", "long_name": "solved, or why not"})
        data["special_detail"] = (("special",), np.array([s.detail for s in sps], object),
                                  {"units": "1", "long_name": "detail"})
    attrs = {"kind": curve.kind, "param1": a, "param2": b, "ntst": curve.ntst,
             "ncol": curve.ncol, "stopped_reason": str(curve.stopped_reason),
             "message": curve.message, "warnings": "\n".join(curve.warnings),
             "title": f"curve of {curve.kind} of cycles in ({a}, {b})"}
    return xr.Dataset(data, coords=coords, attrs=attrs)
