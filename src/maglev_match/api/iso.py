"""Iso-chi design curves (`maglev-match iso-curve`): where in two parameters the headline
index equals a target."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from maglev_match.api.inputs import resolve_params
from maglev_match.api.progress import reported
from maglev_match.core.params import ParameterError, Params, valid_range
from maglev_match.maglev.catalog import model_info

if TYPE_CHECKING:  # pragma: no cover
    from maglev_match.analyses.iso import IsoChiCurve

__all__ = ["iso_curve", "iso_inputs", "restart_iso_curve"]

#: a parameter without a range is followed from its base value / this factor to x this
DEFAULT_FACTOR = 2.0


def _names(names: Sequence[str] | str) -> tuple[str, str]:
    from maglev_match.analyses.design import check_varied_name

    parts = [n.strip() for n in names.split(",")] if isinstance(names, str) else list(names)
    if len(parts) != 2:
        raise ParameterError("names", ",".join(map(str, parts)), "give exactly two "
                             "parameters P1,P2, e.g. EI,kD")
    if parts[0] == parts[1]:
        raise ParameterError("names", ",".join(parts), "the same parameter twice: an "
                             "iso-chi curve needs two different parameters")
    for n in parts:
        check_varied_name("names", n)
    return parts[0], parts[1]


def _ranges(base: Params, names: tuple[str, str],
            ranges: Mapping[str, tuple[float, float]] | None
            ) -> dict[str, tuple[float, float]]:
    ranges = dict(ranges or {})
    for key in ranges:
        if key not in names:
            raise ParameterError("ranges", key, f"is not one of the curve's parameters "
                                 f"({', '.join(names)})")
    out = {}
    for n in names:
        valid = valid_range(n) or (-math.inf, math.inf)
        if n in ranges:
            try:
                lo, hi = (float(v) for v in ranges[n])
            except (TypeError, ValueError):
                raise ParameterError("ranges", f"{n}={ranges[n]}", "expected (low, high) "
                                     "numbers") from None
            if not (math.isfinite(lo) and math.isfinite(hi)):
                raise ParameterError("ranges", f"{n}={lo:g}:{hi:g}", "LOW and HIGH must "
                                     "be finite numbers")
            if not lo < hi:
                raise ParameterError("ranges", f"{n}={lo:g}:{hi:g}", "LOW must be below "
                                     "HIGH")
            if lo < valid[0] or hi > valid[1]:
                raise ParameterError("ranges", f"{n}={lo:g}:{hi:g}", f"must lie inside "
                                     f"the valid range of {n}, [{valid[0]:g}, {valid[1]:g}]")
        else:
            v = float(getattr(base, n))
            if not v > 0:
                raise ParameterError("ranges", n, f"give a range for {n} (its base value "
                                     f"{v:g} has no default range around it)")
            lo, hi = max(v / DEFAULT_FACTOR, valid[0]), min(v * DEFAULT_FACTOR, valid[1])
        out[n] = (lo, hi)
    return out


def _at(at: Any, names: tuple[str, str], ranges: Mapping[str, tuple[float, float]]
        ) -> tuple[str, float]:
    if at is None:
        lo, hi = ranges[names[1]]
        return names[1], 0.5 * (lo + hi)
    if isinstance(at, str):
        if "=" not in at:
            raise ParameterError("at", at, "expected NAME=VALUE, e.g. kD=150")
        name, text = (s.strip() for s in at.split("=", 1))
        try:
            value = float(text)
        except ValueError:
            raise ParameterError("at", at, "the value must be a number") from None
    elif isinstance(at, Mapping):
        if len(at) != 1:
            raise ParameterError("at", dict(at), "fix exactly one of the two parameters")
        ((name, value),) = at.items()
    else:
        name, value = at
    if name not in names:
        raise ParameterError("at", name, f"is not one of the curve's parameters "
                             f"({', '.join(names)})")
    value = float(value)
    lo, hi = ranges[name]
    if not (math.isfinite(value) and lo <= value <= hi):
        raise ParameterError("at", f"{name}={value:g}", f"must lie inside the range of "
                             f"{name}, [{lo:g}, {hi:g}]")
    return name, value


def iso_inputs(params: Params | str | None = None, target: float = 5.0, *,
               names: Sequence[str] | str = ("EI", "kD"),
               ranges: Mapping[str, tuple[float, float]] | None = None,
               at: Any = None, model: str = "unit", config: str | Path | None = None,
               **overrides: Any) -> tuple[Params, tuple[str, str], dict, tuple[str, float]]:
    """The inputs of an iso-chi curve, checked before any index is computed (what
    :func:`iso_curve` does first): (base parameter set, the two names, both ranges, the
    start (name, value))."""
    from maglev_match.analyses.design import Variable, check_vary_ranges
    from maglev_match.analyses.engineering import engineering_nodes
    from maglev_match.analyses.iso import finite_target

    if not finite_target(target):
        raise ParameterError("target", target, "must be a finite number > 0 (chi = h / w0 "
                             "of a stable design is positive)")
    pair = _names(names)
    info = model_info(model)
    if info.name not in ("unit", "vehicle"):
        raise ParameterError("model", model, "iso-chi curves are computed for the maglev "
                             "models unit and vehicle")
    base = resolve_params(params, config=config, **overrides)
    box = _ranges(base, pair, ranges)
    start = _at(at, pair, box)
    try:
        check_vary_ranges(base, [Variable(n, *box[n]) for n in pair], "ranges")
    except ParameterError as exc:  # named by the option that gives the ranges
        raise ParameterError("ranges", exc.value, exc.rule) from None
    for n in pair:
        engineering_nodes(base, info.name, n, box[n], option="names")
    if not base.w0 > 0:
        raise ParameterError("sigma", base.sigma, "must be > 0 for the index: chi = h / w0 "
                             f"needs a beam deflection w0 > 0 (w0 = {base.w0:g} m)")
    return base, pair, box, start


@reported("iso-curve", units=False)
def iso_curve(params: Params | str | None = None, target: float = 5.0, *,
              names: Sequence[str] | str = ("EI", "kD"),
              ranges: Mapping[str, tuple[float, float]] | None = None, at: Any = None,
              model: str = "unit", simulate: bool = True, points: int = 30,
              step: float = 0.05, tol: float = 1e-7, config: str | Path | None = None,
              stage: Callable[[str], None] | None = None,
              **overrides: Any) -> IsoChiCurve:
    """The iso-chi curve: where the headline chi(P1, P2) equals ``target``
    (`maglev-match iso-curve chi=5 --params EI,kD`).

    The level set is continued by pseudo-arclength (predictor along the tangent, corrector
    along the gradient of chi: the exact one of the deciding part from the index's analytic
    sensitivities, a forward difference where that part is only bracketed; index evaluations
    warm-started from the previous point), both ways from the start, inside the ranges. At
    every point: chi, its two parts, the deciding part, the simulated part's mechanism and
    direction, whether each part was solved or only bracketed (status per point) and how
    the gradient was obtained. Where the deciding
    part switches (paper <-> simulation) the switch is located (both parts equal the
    target there); a change of the simulated part's mechanism is located by bisection.

    Parameters
    ----------
    params : Params | str | None
        The base parameter set (see [`resolve_params`][maglev_match.api.inputs.resolve_params]).
    target : float
        The value of chi on the curve (finite, > 0).
    names : (str, str) or "P1,P2"
        The two parameters, e.g. ``("EI", "kD")`` (beam data L, EI, mbar derive omega1 and
        sigma).
    ranges : mapping, optional
        ``{name: (low, high)}``: the curve ends on these; a parameter without a range
        runs from half to twice its base value.
    at : "NAME=VALUE", (name, value) or {name: value}, optional
        The start: that parameter fixed, the other solved over its range (default: P2 at
        the middle of its range).
    model : str
        ``"unit"`` (model A) or ``"vehicle"``.
    simulate : bool
        The headline chi (default); False: the paper's chi alone (``--no-simulation``).
    points : int
        At most this many points (both directions together); 1: the start alone (chi =
        target solved along the free parameter).
    step : float
        The first step, as a fraction of the ranges.
    tol : float
        |chi - target| <= tol * target at every solved point.
    config : str or Path, optional
        A TOML file applied on top of the preset.
    stage : callable, optional
        Called with a line of text as each stage starts.
    **overrides : float
        Parameter values applied on top.

    Returns
    -------
    IsoChiCurve
        See [`IsoChiCurve`][maglev_match.analyses.iso.curve.IsoChiCurve]: ``rows()``,
        ``special_rows()``, ``to_xarray()``, ``.plot()``.
    """
    from maglev_match.analyses.iso import iso_chi_curve

    settings = _settings(points, step, tol)
    base, pair, box, start = iso_inputs(params, target, names=names, ranges=ranges, at=at,
                                        model=model, config=config, **overrides)
    return iso_chi_curve(base, pair, box, float(target), at=start,
                         model=model_info(model).name, simulate=simulate,
                         settings=settings, stage=stage)


def _settings(points: Any, step: Any, tol: Any) -> Any:
    """The tracer's settings from the options, checked (naming the option)."""
    from maglev_match.analyses.iso import TraceSettings

    if isinstance(points, bool) or not isinstance(points, int) or points < 1:
        raise ParameterError("points", points, "must be a whole number >= 1 (1: the start "
                             "alone, chi = target solved along one parameter)")
    if not (math.isfinite(step) and 0 < step <= 0.5):
        raise ParameterError("step", step, "must be a fraction of the ranges in (0, 0.5]")
    if not (math.isfinite(tol) and 1e-12 <= tol <= 1e-3):
        raise ParameterError("tol", tol, "must lie in [1e-12, 1e-3]")
    return TraceSettings(tol=tol, ds=step, ds_max=max(0.2, step), max_points=points,
                         ds_min=min(2e-3, step / 4))


@reported("iso-curve", units=False)
def restart_iso_curve(source: Any, *, ranges: Mapping[str, tuple[float, float]] | None = None,
                      points: int = 30, step: float = 0.05, tol: float | None = None,
                      stage: Callable[[str], None] | None = None) -> IsoChiCurve:
    """An iso-chi curve saved by `iso-curve --out` continued beyond both of its ends
    (`maglev-match iso-curve --restart FILE`).

    The saved file gives the base parameter set, the model, the target, the two
    parameters, whether chi is the headline or the paper's, the ranges and the tolerance;
    each end is evaluated again (one index from scratch per end) and followed on, away
    from its neighbour, by the same continuation as :func:`iso_curve`. The saved points
    and special points are kept unchanged; the new ones are added before and after them.
    A last point that did not converge is dropped and its direction goes on from the
    point before it; a curve that closed on its start is not continued.

    Parameters
    ----------
    source : str, Path or xarray.Dataset
        The netCDF file written by `iso-curve --out` (or the dataset of
        ``IsoChiCurve.to_xarray()``).
    ranges : mapping, optional
        ``{name: (low, high)}`` for either parameter: the new ranges (each must contain
        the saved curve); a direction that ended on the saved range goes on in a wider
        one. Default: the saved ranges.
    points : int
        At most this many new points (both ends together: backwards gets half, rounded
        down).
    step : float
        The first step from each end, as a fraction of the ranges.
    tol : float, optional
        Default: the saved curve's tolerance.
    stage : callable, optional
        Called with a line of text as each stage starts.

    Returns
    -------
    IsoChiCurve
        The whole curve; ``evaluations`` counts the saved and the new evaluations.
    """
    from maglev_match.analyses.iso import continue_iso_curve, read_iso_curve

    curve = read_iso_curve(source)
    settings = _settings(points, step, curve.tolerance if tol is None else tol)
    box = dict(zip(curve.names, curve.ranges, strict=True))
    if ranges:
        new = _ranges(curve.base, curve.names, ranges)  # (checked as iso_curve's)
        for n in ranges:
            lo, hi = new[n]
            vals = [pt.p1 if n == curve.names[0] else pt.p2 for pt in curve.points]
            if vals and (min(vals) < lo or max(vals) > hi):
                raise ParameterError("ranges", f"{n}={lo:g}:{hi:g}", "must contain the "
                                     f"saved curve ({n} from {min(vals):g} to "
                                     f"{max(vals):g})")
            box[n] = (lo, hi)
    return continue_iso_curve(curve, box, settings=settings, stage=stage)
