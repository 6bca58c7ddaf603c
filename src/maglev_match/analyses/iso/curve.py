"""The iso-chi curve of a maglev model (`maglev-match iso-curve`): where in two parameters
the headline index chi equals a target, with, at every point, the part that decides it and
whether that part was solved; the switches of the deciding part and the changes of the
simulated part's mechanism as special points. The continuation itself is
:mod:`maglev_match.analyses.iso.trace`."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from maglev_match.analyses.iso.maglev import MaglevChi
from maglev_match.analyses.iso.trace import (
    DEFAULT_SETTINGS,
    ENDED,
    IsoPoint,
    IsoSpecial,
    Sample,
    TraceSettings,
    extend_iso,
    trace_iso,
)
from maglev_match.core.params import Params
from maglev_match.core.reprs import compact_repr
from maglev_match.core.results import Plottable

__all__ = ["IsoChiCurve", "iso_chi_curve", "continue_iso_curve", "read_iso_curve",
           "POINT_STATUSES"]

#: the title of an iso-chi curve file (its attribute ``title`` starts with it)
TITLE = "maglev-match iso-chi curve"

#: the status of a curve point, and what it means
POINT_STATUSES = {
    "solved": "chi = target to the corrector's tolerance, the deciding part solved",
    "bracketed": "the corrector converged, but the deciding simulated part is only the "
                 "bisection's bracket (chi known to the bisection's tolerance)",
    "not converged": "the corrector's last iterate where the curve ends (see the end "
                     "reason)",
}


def _none(v: Any) -> float:
    return float("nan") if v is None else float(v)


@dataclass(frozen=True)
class IsoChiCurve(Plottable):
    """The curve headline chi(p1, p2) = ``target`` of ``model`` at the base parameter set.

    ``names`` the two parameters (SI units, ``units``), ``ranges`` the box the curve was
    followed in, ``points`` in order along the curve (``start`` the index of the start
    point), ``specials`` the located switches of the deciding part ("basis switch", where
    chi_paper = chi_simulation = target) and changes of the simulated part's mechanism,
    ``ends`` why each direction ended (backwards, forwards), ``warnings`` (a corrector
    failure, a start that did not converge), ``simulate`` whether chi is the headline
    (False: the paper's chi alone), ``evaluations`` the index evaluations and
    ``cpu_seconds`` the process CPU time spent."""

    __repr__ = compact_repr

    target: float
    names: tuple[str, str]
    units: tuple[str, str]
    model: str
    simulate: bool
    ranges: tuple[tuple[float, float], tuple[float, float]]
    points: tuple[IsoPoint, ...]
    start: int | None
    specials: tuple[IsoSpecial, ...]
    ends: tuple[str, str]
    warnings: tuple[str, ...]
    evaluations: int = 0
    cpu_seconds: float = 0.0
    tolerance: float = 1e-7
    base: Params | None = field(default=None, repr=False, compare=False)

    @property
    def ok(self) -> bool:
        """The curve started and every point is solved."""
        return bool(self.points) and all(p.status == "solved" for p in self.points)

    def rows(self) -> list[dict[str, Any]]:
        """One dict per point (SI units): the two parameters, chi, chi_paper,
        chi_simulation, the deciding part, the simulated part's mechanism and direction,
        the status of each part and of the point, the residual chi - target, and how the
        gradient of chi there was obtained ("exact", or "difference: " and why not)."""
        a, b = self.names
        out = []
        for k, pt in enumerate(self.points):
            s = pt.sample
            out.append({a: pt.p1, b: pt.p2, "chi": s.chi, "chi_paper": s.chi_paper,
                        "chi_simulation": _none(s.chi_simulation), "basis": s.basis,
                        "mechanism": s.mechanism or "", "direction": s.direction or "",
                        "paper_part": s.paper_status, "simulation_part": s.simulation_status,
                        "status": pt.status, "residual": pt.residual,
                        "iterations": pt.iterations,
                        "start": int(k == self.start), "gradient": pt.gradient})
        return out

    def special_rows(self) -> list[dict[str, Any]]:
        """One dict per special point: kind, the two parameters, chi_paper,
        chi_simulation, what changes (before -> after), located, residual, message."""
        a, b = self.names
        return [{"kind": s.kind, a: s.p1, b: s.p2, "chi_paper": s.sample.chi_paper,
                 "chi_simulation": _none(s.sample.chi_simulation), "before": s.before,
                 "after": s.after, "located": s.located, "residual": s.residual,
                 "message": s.message} for s in self.specials]

    def as_json(self) -> dict[str, Any]:
        """The machine-readable form (SI units)."""
        return {"target": self.target, "params": list(self.names), "units": list(self.units),
                "model": self.model, "simulate": self.simulate,
                "ranges": {n: list(r) for n, r in zip(self.names, self.ranges, strict=True)},
                "points": self.rows(), "special_points": self.special_rows(),
                "start": self.start, "ends": {"backwards": self.ends[0],
                                              "forwards": self.ends[1]},
                "ok": self.ok, "warnings": list(self.warnings),
                "evaluations": self.evaluations, "cpu_seconds": self.cpu_seconds,
                "tolerance": self.tolerance, "point_statuses": POINT_STATUSES}

    def to_xarray(self) -> Any:
        """The curve as an :class:`xarray.Dataset` over ``point`` (the two parameters,
        chi, chi_paper, chi_simulation, residual, iterations as numbers; basis, mechanism,
        direction, paper_part, simulation_part, status and gradient as strings) and over ``special``
        (kind, position, parts, before/after, located); the target, names, ends and
        warnings as attributes, the base parameter set and the version as well."""
        import json

        import xarray as xr

        from maglev_match.core.datasets import annotate

        a, b = self.names
        rows, sp = self.rows(), self.special_rows()

        def col(key: str, kind: Any = float) -> np.ndarray:
            return np.array([r[key] for r in rows], dtype=kind)

        def scol(key: str, kind: Any = float) -> np.ndarray:
            return np.array([r[key] for r in sp], dtype=kind)

        data = {
            a: ("point", col(a)), b: ("point", col(b)), "chi": ("point", col("chi")),
            "chi_paper": ("point", col("chi_paper")),
            "chi_simulation": ("point", col("chi_simulation")),
            "residual": ("point", col("residual")),
            "iterations": ("point", col("iterations", np.int64)),
            "basis": ("point", col("basis", str)), "mechanism": ("point", col("mechanism", str)),
            "direction": ("point", col("direction", str)),
            "paper_part": ("point", col("paper_part", str)),
            "simulation_part": ("point", col("simulation_part", str)),
            "status": ("point", col("status", str)),
            "gradient": ("point", col("gradient", str)),
            "special_kind": ("special", scol("kind", str)),
            f"special_{a}": ("special", scol(a)), f"special_{b}": ("special", scol(b)),
            "special_chi_paper": ("special", scol("chi_paper")),
            "special_chi_simulation": ("special", scol("chi_simulation")),
            "special_before": ("special", scol("before", str)),
            "special_after": ("special", scol("after", str)),
            "special_located": ("special", scol("located", np.int8)),
        }
        ua, ub = self.units
        units = {a: ua, b: ub, "chi": "1", "chi_paper": "1", "chi_simulation": "1",
                 "residual": "1", "iterations": "1", "basis": "1", "mechanism": "1",
                 "direction": "1", "paper_part": "1", "simulation_part": "1",
                 "status": "1", "gradient": "1", "special_kind": "1", f"special_{a}": ua,
                 f"special_{b}": ub,
                 "special_chi_paper": "1", "special_chi_simulation": "1",
                 "special_before": "1", "special_after": "1", "special_located": "1",
                 "point": "1", "special": "1"}
        longs = {
            a: f"{a} on the curve", b: f"{b} on the curve",
            "chi": "headline matching index at the point" if self.simulate
            else "matching index by the paper's definition (no simulation)",
            "chi_paper": "matching index by the paper's definition, h / w0",
            "chi_simulation": "h_simulation / w0 (NaN: not simulated or inconclusive)",
            "residual": "chi - target at the point", "iterations": "corrector iterations",
            "basis": "the part deciding the headline (paper or simulation)",
            "mechanism": "what decided the simulated critical disturbance",
            "direction": "the direction of the simulated critical disturbance (up/down)",
            "paper_part": "the paper part: cycle, rule (no cycle within the limits), "
                          "unstable or failed",
            "simulation_part": "the simulated part: solved, bracketed, inconclusive, "
                               "skipped or off",
            "status": "the point: solved, bracketed or not converged",
            "gradient": "how the gradient of chi was obtained: exact (analytic "
                        "sensitivities) or difference (and why)",
            "special_kind": "basis switch or mechanism change",
            f"special_{a}": f"{a} at the special point",
            f"special_{b}": f"{b} at the special point",
            "special_chi_paper": "chi_paper at the special point",
            "special_chi_simulation": "chi_simulation at the special point",
            "special_before": "deciding part or mechanism before the special point",
            "special_after": "deciding part or mechanism after the special point",
            "special_located": "location converged (1) or not (0)",
            "point": "point number along the curve", "special": "special point number"}
        ds = xr.Dataset(data, coords={"point": np.arange(len(rows)),
                                      "special": np.arange(len(sp))}, attrs={
            "title": f"{TITLE} chi = {self.target:g} in ({a}, {b})",
            "target": self.target, "curve_params": f"{a},{b}", "model": self.model,
            "simulate": int(self.simulate), "start_point": -1 if self.start is None
            else int(self.start), "end_backwards": self.ends[0],
            "end_forwards": self.ends[1], "tolerance": self.tolerance,
            "range_" + a: json.dumps(list(self.ranges[0])),
            "range_" + b: json.dumps(list(self.ranges[1])),
            "warnings": json.dumps(list(self.warnings)),
            "evaluations": self.evaluations})
        if self.base is not None:  # the values as given (a restart derives the rest again)
            ds.attrs["base_inputs"] = json.dumps(_plain_inputs(self.base))
        return annotate(ds, self.base, units=units, long_names=longs)


def iso_chi_curve(base: Params, names: tuple[str, str],
                  ranges: Mapping[str, tuple[float, float]], target: float, *,
                  at: tuple[str, float], model: str = "unit", simulate: bool = True,
                  settings: TraceSettings = DEFAULT_SETTINGS,
                  stage: Callable[[str], None] | None = None) -> IsoChiCurve:
    """The iso-chi curve of ``model`` at ``base``: chi(names) = ``target`` inside
    ``ranges`` (both names), started where ``at`` = (name, value) holds (the other
    parameter solved over its range), followed both ways
    (:func:`~maglev_match.analyses.iso.trace.trace_iso`). Inputs are checked by the API."""
    from maglev_match.core.params import PARAMETER_DOCS

    box = (tuple(map(float, ranges[names[0]])), tuple(map(float, ranges[names[1]])))
    fixed = names.index(at[0])
    evaluate = MaglevChi(base, names, model=model, simulate=simulate)
    traced = trace_iso(evaluate, box, target, fixed=fixed, value=float(at[1]),
                       settings=settings, stage=stage)
    warnings = list(traced.warnings) + _summary(traced.points, traced.specials, names)
    units = tuple(PARAMETER_DOCS.get(n, ("1",))[0] for n in names)
    return IsoChiCurve(float(target), names, units, model, simulate, box,  # type: ignore[arg-type]
                       traced.points, traced.start, traced.specials, traced.ends,
                       tuple(warnings), traced.evaluations, traced.cpu_seconds,
                       settings.tol, base)


_BRACKETED = "point(s) of the curve rest on a simulated part that is only bracketed"


def _plain_inputs(params: Params) -> dict[str, Any]:
    """The values a parameter set was given (derived ones left out unless set), as plain
    JSON numbers."""
    return {k: (v.item() if isinstance(v, np.generic) else v)
            for k, v in params.as_input_dict().items()}


def _summary(points: Sequence[IsoPoint], specials: Sequence[IsoSpecial],
             names: tuple[str, str]) -> list[str]:
    """The warnings a whole curve carries: its bracketed points, its special points that
    were not located."""
    out = []
    brack = sum(p.status == "bracketed" for p in points)
    if brack:
        out.append(f"{brack} {_BRACKETED} (status 'bracketed'): chi there is known to the "
                   "bisection's tolerance only")
    for s in specials:
        if not s.located:
            out.append(f"a {s.kind} ({s.before} -> {s.after}) near {names[0]} = "
                       f"{s.p1:.6g}, {names[1]} = {s.p2:.6g}: {s.message}")
    return out


def continue_iso_curve(curve: IsoChiCurve,
                       ranges: Mapping[str, tuple[float, float]] | None = None, *,
                       settings: TraceSettings = DEFAULT_SETTINGS,
                       stage: Callable[[str], None] | None = None) -> IsoChiCurve:
    """``curve`` (computed here or read from its file by :func:`read_iso_curve`) continued
    beyond both of its ends (:func:`~maglev_match.analyses.iso.trace.extend_iso`) at its
    base parameter set, model, target and part (headline or paper), inside ``ranges``
    (default the curve's own; wider ones let a direction that ended on them go on), with
    ``settings.max_points`` new points. The saved points and special points are kept as
    they are; the ends, the counts and the warnings are those of the whole curve (the
    saved curve's warnings about how its ends ended are replaced by the new ones)."""
    if curve.base is None:
        raise ValueError("the curve has no base parameter set to continue at")
    box = (curve.ranges if ranges is None else
           tuple(tuple(map(float, ranges[n])) for n in curve.names))
    evaluate = MaglevChi(curve.base, curve.names, model=curve.model, simulate=curve.simulate)
    traced = extend_iso(evaluate, box, curve.target, curve.points, curve.start, curve.ends,
                        specials=curve.specials, settings=settings, stage=stage)
    def of_the_whole(w: str) -> bool:  # said again below, for the whole curve
        return (w.startswith((ENDED, "a basis switch", "a mechanism change"))
                or _BRACKETED in w)

    warnings = [w for w in curve.warnings if not of_the_whole(w)] + list(traced.warnings) + \
        _summary(traced.points, traced.specials, curve.names)
    return dataclasses.replace(
        curve, ranges=box, points=traced.points, start=traced.start,
        specials=traced.specials, ends=traced.ends, warnings=tuple(warnings),
        evaluations=curve.evaluations + traced.evaluations,
        cpu_seconds=curve.cpu_seconds + traced.cpu_seconds)


def read_iso_curve(source: Any) -> IsoChiCurve:
    """The iso-chi curve saved by ``iso-curve --out`` (a netCDF path or its xarray
    Dataset): its points (their evaluations' numbers and labels; not the indices
    themselves), special points, ends, warnings, target, parameters, ranges, model, part
    and base parameter set. A file that is not such a curve is a
    :class:`~maglev_match.analyses.restart.files.RestartFileError` naming what is wrong."""
    import json

    from maglev_match.analyses.restart.files import RestartFileError, open_saved
    from maglev_match.core.params import FIELD_NAMES, ParameterError, make_params

    ds, where = open_saved(source)
    if not str(ds.attrs.get("title", "")).startswith(TITLE):
        raise RestartFileError(where, "is not an iso-chi curve file (the netCDF file "
                               "written by `maglev-match iso-curve --out`)")
    if "base_inputs" not in ds.attrs:
        raise RestartFileError(where, "does not hold the parameter set as given (attribute "
                               "base_inputs; a file written before restarts of iso-chi "
                               "curves): compute the curve again")
    try:
        a, b = str(ds.attrs["curve_params"]).split(",")
        ranges = (tuple(json.loads(ds.attrs["range_" + a])),
                  tuple(json.loads(ds.attrs["range_" + b])))
        params = make_params({k: v for k, v in json.loads(ds.attrs["base_inputs"]).items()
                              if k in FIELD_NAMES})

        def num(key: str, i: int) -> float:
            return float(ds[key].values[i])

        def text(key: str, i: int) -> str:
            return str(ds[key].values[i])

        def opt(v: float) -> float | None:
            return None if math.isnan(v) else v

        start = int(ds.attrs["start_point"])
        points = []
        for i in range(ds.sizes["point"]):
            smp = Sample(num("chi", i), num("chi_paper", i), opt(num("chi_simulation", i)),
                         text("basis", i), text("mechanism", i) or None,
                         text("direction", i) or None, text("paper_part", i),
                         text("simulation_part", i))
            points.append(IsoPoint(num(a, i), num(b, i), smp, num("residual", i),
                                   int(ds["iterations"].values[i]), text("status", i),
                                   (i > start) - (i < start), text("gradient", i)))
        specials = []
        for i in range(ds.sizes.get("special", 0)):
            smp = Sample(float("nan"), num("special_chi_paper", i),
                         opt(num("special_chi_simulation", i)))
            located = bool(int(ds["special_located"].values[i]))
            specials.append(IsoSpecial(text("special_kind", i), num(f"special_{a}", i),
                                       num(f"special_{b}", i), text("special_before", i),
                                       text("special_after", i), smp, located,
                                       float("nan"), "" if located else "not located"))
        curve = IsoChiCurve(
            float(ds.attrs["target"]), (a, b),
            (str(ds[a].attrs.get("units", "1")), str(ds[b].attrs.get("units", "1"))),
            str(ds.attrs["model"]), bool(int(ds.attrs["simulate"])), ranges,  # type: ignore[arg-type]
            tuple(points), None if start < 0 else start, tuple(specials),
            (str(ds.attrs["end_backwards"]), str(ds.attrs["end_forwards"])),
            tuple(json.loads(ds.attrs["warnings"])), int(ds.attrs["evaluations"]), 0.0,
            float(ds.attrs["tolerance"]), params)
    except (KeyError, ValueError, TypeError, IndexError, ParameterError) as exc:
        raise RestartFileError(where, "is not a complete iso-chi curve file: "
                               f"{' '.join(str(exc).split())[:160]}") from None
    return curve


def finite_target(target: Any) -> bool:
    """A target chi is a finite number > 0."""
    try:
        return math.isfinite(float(target)) and float(target) > 0
    except (TypeError, ValueError):
        return False
