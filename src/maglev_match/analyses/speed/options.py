"""The settings of a computation at speed and its checks before any work: the numerical
settings (:class:`SpeedOptions`), the validation of the model, the parameters, the speeds
and the number of spans (:func:`check_speed_setup`), and the static deflection w0 of the
standstill index of the same model (:func:`w0_of`), the scale of chi(v) = h(v) / w0."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from maglev_match.analyses.speed.grid import KMH, SPEED_MAX, SPEED_MIN
from maglev_match.core.params import ParameterError, Params
from maglev_match.dynamics.integrate.passage import PassageOptions
from maglev_match.maglev import moving as mv
from maglev_match.maglev import moving_delay as md
from maglev_match.maglev.moving import MovingModel

__all__ = ["SpeedOptions", "check_speed_setup", "w0_of"]


@dataclass(frozen=True)
class SpeedOptions:
    """Numerical settings at speed (checked on construction; errors name the option).

    rtol, atol : tolerances of the periodic solve's runs (atol per state scale).
    tangent_rtol : tolerance of the variational solves. 1e-6 moves the multipliers by less
        than 2e-8 against 1e-10 on the turnout beams (unit and vehicle, 5 and 60 km/h,
        measured 2026-12-02) at about half the cost of 1e-8.
    newton_tol : scaled residual of the periodic response.
    samples_per_period : read-out samples per period of the fastest beam mode (>= 8).
    min_samples : read-out samples per passage at least.
    critical : compute the critical disturbance at speed.
    critical_sizes : disturbance sizes per direction and round; critical_rounds : rounds;
    critical_tol : bracket width reached (m); critical_rtol : tolerance of those runs.
    return_tol : a disturbed run has returned when the state at a span hand-over is within
        this (scaled: 1 mm, 1 cm/s, 1 A) of the periodic response.
    spans : spans a disturbed run may take to return (the guideway's length in spans).
    critical_delay : compute the critical delay of the outer loop at every speed
        (:mod:`maglev_match.analyses.speed.delay`).
    """

    rtol: float = 1e-10
    atol: float = 1e-10
    tangent_rtol: float = 1e-6
    newton_tol: float = 1e-9
    samples_per_period: int = 16
    min_samples: int = 512
    critical: bool = True
    critical_sizes: int = 8
    critical_rounds: int = 3
    critical_tol: float = 2e-5
    critical_rtol: float = 1e-8
    return_tol: float = 0.05
    spans: int = 40
    critical_delay: bool = False

    def __post_init__(self) -> None:
        for name in ("rtol", "atol", "tangent_rtol", "newton_tol", "critical_rtol",
                     "return_tol"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | float) or not 0 < v <= 0.1:
                raise ParameterError(name, v, "must be a number in (0, 0.1]")
        if not (isinstance(self.critical_tol, int | float) and 0 < self.critical_tol <= 1e-2):
            raise ParameterError("critical_tol", self.critical_tol, "must lie in (0, 0.01] m")
        for name, lo, hi in (("samples_per_period", 8, 1000), ("min_samples", 64, 10**6),
                             ("critical_sizes", 2, 64), ("critical_rounds", 1, 12),
                             ("spans", 1, 10_000)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or not lo <= v <= hi:
                raise ParameterError(name if name != "spans" else "--spans", v,
                                     f"must be a whole number in [{lo}, {hi}]")

        if not isinstance(self.critical_delay, bool):
            raise ParameterError("critical_delay", self.critical_delay, "must be true or false")

    def passage(self) -> PassageOptions:
        return PassageOptions(rtol=self.rtol, atol=self.atol, tangent_rtol=self.tangent_rtol,
                              tangent_atol=self.tangent_rtol, newton_tol=self.newton_tol)

    def key(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


def check_speed_setup(params: Params, model: str, speeds: Sequence[float] = (),
                      spans: int | None = None, *, delay: bool = True,
                      refuse_delay: str = "") -> MovingModel:
    """Validate a computation at speed before any work: the model name, the parameters the
    models at speed need, the speeds (m/s; finite, >= 0 and at most 900 km/h), the number
    of spans and the delay tau (one the discretisation resolves at every speed; with
    ``delay`` False any tau > 0 is refused, ``refuse_delay`` saying for what). Raises
    :class:`~maglev_match.core.params.ParameterError` naming the field, the value and the
    rule."""
    try:
        kind = MovingModel(model)
    except ValueError:
        raise ParameterError("--model", model, "must be 'unit', 'vehicle' or 'force' at "
                             "speed") from None
    if params.tau > 0 and not delay:
        raise ParameterError("tau", params.tau, f"{refuse_delay}: set tau = 0 (the delay at "
                             "speed is analysed on the periodic response over identical "
                             "spans: speed --set tau=...)")
    if kind is not MovingModel.VEHICLE and "sigma" in params.explicit:
        raise ParameterError(
            "sigma", params.sigma, "is set directly, but at speed the unit's coupling to the "
            "spans follows from the guideway and the vehicle (L, mbar, l, k): set those "
            "instead")
    lay = mv.layout_of(params, kind)
    if not lay.extent < params.L:
        what = "l" if kind is MovingModel.UNIT else "s0"
        value = params.l if kind is MovingModel.UNIT else params.s0
        raise ParameterError(what, value, f"the vehicle's layout ({lay.extent:g} m from the "
                             f"first to the last load) must be shorter than a span "
                             f"(L = {params.L:g} m): at most two spans may carry it")
    if spans is not None:
        if isinstance(spans, bool) or not isinstance(spans, int) or spans < 1:
            raise ParameterError("--spans", spans, "must be a whole number >= 1")
        if spans * params.L < lay.extent:
            raise ParameterError("--spans", spans, f"the guideway ({spans} x {params.L:g} m) "
                                 f"is shorter than the vehicle's layout ({lay.extent:g} m)")
    for v in speeds:
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
            raise ParameterError("speed", v, "must be a finite number")
        if v < 0:
            raise ParameterError("speed", v, "must be >= 0 (the direction of travel does not "
                                 "matter on identical spans)")
        if v > SPEED_MAX:
            raise ParameterError("speed", v, f"must be at most {SPEED_MAX:g} m/s "
                                 f"({SPEED_MAX / KMH:g} km/h)")
        if 0 < v < SPEED_MIN:
            raise ParameterError("speed", float(v), f"must be 0 (standstill) or at least "
                                 f"{SPEED_MIN:g} m/s ({SPEED_MIN / KMH:g} km/h): slower, one "
                                 "span passage lasts longer than a run at speed can "
                                 "integrate, and the answer is the standstill one")
    if params.tau > 0:
        md.check_delay_at_speed(params, kind, speeds)
    return kind


def w0_of(params: Params, kind: MovingModel) -> float:
    """The static deflection w0 (m) of the standstill index of the same model: model A's
    sigma (m + M) g / omega1^2 for the unit and the force, model B's static mid-span
    deflection under the vehicle for the vehicle."""
    if MovingModel(kind) is MovingModel.VEHICLE:
        from maglev_match.maglev.models import VehicleModel

        return float(VehicleModel(params).w0)
    return float(params.w0)
