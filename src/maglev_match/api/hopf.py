"""Hopf points along one parameter (`maglev-match hopf`) and the Hopf curve in two
parameters (`hopf-curve`), for the maglev models and user model files.

The method is chosen here, once, for the command line and the Python API alike: along an
ordinary parameter the equilibrium branch is scanned and each crossing refined on the Hopf
defining system (:func:`~maglev_match.dynamics.hopf.locate_hopf_points`); along a beam or
vehicle quantity of the maglev models (L, EI, ...) on the path of the model's parameters
through it (:mod:`maglev_match.analyses.engineering`); along a delay, as the crossings of
the characteristic equation of the delay system
(:func:`~maglev_match.dynamics.delay.delay_hopf_points`, exact; a delay axis uses the
discretised delay system sized for the largest delay).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from maglev_match.api.compat import deprecated
from maglev_match.api.inputs import StudiedModel, names_a_preset, resolve_model
from maglev_match.api.progress import reported
from maglev_match.core.params import ParameterError, Params
from maglev_match.core.results import Plottable
from maglev_match.maglev.catalog import CATALOG

__all__ = ["hopf_points", "hopf_curve", "HopfCurveStudy", "HOPF_CURVE_RANGES",
           "DEFAULT_DELAY_RANGE", "DELAY_FLOOR", "delay_description"]

#: Default bounds of the Hopf curve's parameters (as on the command line).
HOPF_CURVE_RANGES = {"omega1": (30.0, 400.0), "sigma": (1e-4, 8e-4)}
#: The default range of a delay axis whose design value is 0 (s).
DEFAULT_DELAY_RANGE = 0.005
#: A delay axis of the Hopf curve starts at this fraction of its largest value: the
#: discretised delay system is singular at delay 0 (the delay-free model).
DELAY_FLOOR = 1e-3


def default_plane(studied: StudiedModel) -> tuple[str, ...]:
    """The default (x, y) plane of the model's Hopf curve; () for a user model."""
    return () if studied.is_user else CATALOG[studied.label].plane


def delay_description(system: Any, param: str, crossings: bool = True) -> dict | None:
    """How a delay model was analysed (its discretisation, and whether ``param`` is the
    delay axis whose Hopf points are the crossings of the characteristic equation); None
    for an ODE."""
    from maglev_match.dynamics.delay import DiscretisedSystem

    if not isinstance(system, DiscretisedSystem):
        return None
    axis = param in system.delays and crossings
    text = (f"  delay system: Chebyshev discretisation of the past with N = {system.nodes} "
            f"nodes per delay (dimension {system.dim} = {system.n_state} states + "
            f"{system.dim - system.n_state} history values); l1 with <q,q> = 1 over the "
            f"{system.n_state} states"
            + ("; Hopf points in the delay are the crossings of the characteristic equation "
               "(exact; delay 0 is the delay-free model)" if axis else ""))
    return {"nodes": system.nodes, "dimension": system.dim, "states": system.n_state,
            "delays": list(system.delays), "axis": axis, "text": text}


def hopf_points(params: Params | str | None = None, param: str = "omega1",
                start: float = 30.0, stop: float = 300.0, *, model: str = "unit",
                n_scan: int = 200, config: str | Path | None = None,
                stage: Callable[[str], None] | None = None, **overrides: Any) -> Any:
    """Hopf points of the equilibrium along one parameter (`maglev-match hopf`).

    A scan of `n_scan` eigenvalue computations brackets each crossing of a complex pair
    of eigenvalues; each bracket is refined by Newton's method on the Hopf defining system,
    and the first Lyapunov coefficient l1 is computed there by Kuznetsov's projection
    formula (Kuznetsov 2004, ch. 3 and 5): l1 > 0 subcritical, l1 < 0 supercritical. Along
    a delay the crossings of the characteristic equation; along beam or vehicle data the
    path of the model's parameters (module docstring).

    Parameters
    ----------
    params : Params | str | None
        The parameter set (see [`resolve_params`][maglev_match.api.inputs.resolve_params]).
    param : str
        The parameter to vary (a model parameter, a delay, or beam/vehicle data).
    start, stop : float
        The interval searched, in the parameter's SI unit (a delay: from 0 up).
    model : str
        `"unit"`, `"vehicle"` or a user model file `FILE.py`.
    n_scan : int
        Values of the bracketing scan (steps at most 1/n_scan of the range).
    config : str or Path, optional
        A TOML file applied on top of the preset.
    stage : callable, optional
        Called with a line of text once the inputs are checked and the search starts.
    **overrides : float
        Parameter values applied on top.

    Returns
    -------
    HopfScan
        `points`: the [`HopfPoint`][maglev_match.dynamics.hopf.HopfPoint]s (value,
        frequency, crossing speed, l1), the scan itself, `records()` (a table row per
        point with the model's plane parameters) and, for a delay model, `delay` (how it
        was discretised); `.plot()` draws it.
    """
    import dataclasses

    if isinstance(params, str) and not names_a_preset(params):  # (param, start, stop, p)
        deprecated("hopf_points(param, start, stop, params)",
                   "hopf_points(params, param, start, stop)")
        # old positions: (param, start, stop, params); a number in `stop` is the default
        old_params = None if isinstance(stop, int | float) else stop
        params, param, start, stop = old_params, params, param, start
    from maglev_match.analyses.engineering import engineering_hopf_points, is_engineering
    from maglev_match.dynamics.delay import delay_hopf_points, is_delay_parameter
    from maglev_match.dynamics.hopf import locate_hopf_points

    if n_scan < 2:
        raise ParameterError("n_scan", n_scan, "must be at least 2")
    if not start < stop:
        raise ParameterError("start", start, f"must be smaller than stop = {stop:g}")
    studied = resolve_model(params, model, config=config, **overrides)
    engineering = studied.params is not None and is_engineering(param)
    studied.check_param(param, "param", delays=True, engineering=True)
    for v in (start, stop):
        studied.validate_value(param, v)
    if param in studied.delays and start < 0:
        raise ParameterError("start", start, f"{param} is a delay: the range must start at "
                             "or above 0 (>= 0)")
    if stage is not None:
        stage(f"searching Hopf points along {param} in [{start:g}, {stop:g}] ...")
    plane = default_plane(studied)
    # along a delay: the discretised delay system (delays up to stop)
    system = studied.system_along(param, stop)
    if engineering:  # a beam/vehicle quantity: omega1, sigma (model B: geometry) follow it
        scan, system = engineering_hopf_points(studied.params, studied.label, param, start,
                                               stop, n_scan)
        names = tuple(n for n in dict.fromkeys(plane + ("sigma",)) if n in system.param_names)
        columns = (param, *names)
    elif is_delay_parameter(system, param):  # crossings of the characteristic equation
        if start < 0:
            raise ParameterError("start", start, f"{param} is a delay: the range must "
                                 "start at or above 0")
        scan = delay_hopf_points(system, param, start, stop, n_scan=n_scan)
        columns = tuple(dict.fromkeys((param,) + plane))
    else:
        scan = locate_hopf_points(system, param, start, stop, n_scan=n_scan)
        columns = tuple(dict.fromkeys((param,) + plane))
    delay = delay_description(system, param)
    if delay is not None and delay["axis"] and studied.maglev is not None:
        delay = _with_practical_margin(delay, studied.maglev, scan, stage)
    return dataclasses.replace(scan, columns=columns, system=system, delay=delay)


def _with_practical_margin(delay: dict, model: Any, scan: Any, stage: Any) -> dict:
    """The delay note of a scan along the maglev model's delay with the practical margin
    beyond its first crossing (the critical delay; see
    :func:`maglev_match.analyses.delay_margin.practical_delay_margin`)."""
    from maglev_match.analyses.delay_margin import practical_delay_margin

    first = min((h for h in scan.points if h.converged), key=lambda h: h.value, default=None)
    if first is None:
        return delay
    if stage is not None:
        stage("the practical margin beyond the critical delay: cycles along the delay ...")
    pr = practical_delay_margin(model, first.value, first.kind)
    words = (f"tau = {pr['value'] * 1e3:.4g} ms ({pr['reason']})" if pr["value"] is not None
             else f"not found ({pr['reason']})")
    return {**delay, "practical": pr,
            "text": delay["text"] + f"\n  practical margin of the delay: {words}"}


def _plane_axis(axis: Any, field_name: str) -> tuple[str, tuple[float, float] | None]:
    """A Hopf-curve axis: a name, or (name, low, high)."""
    if isinstance(axis, str):
        return axis, None
    try:
        name, lo, hi = axis
        return str(name), (float(lo), float(hi))
    except (TypeError, ValueError):
        raise ParameterError(field_name, axis, "expected a parameter name or (name, low, "
                             "high)") from None


@dataclass(frozen=True)
class RestartPoint:
    """Where a restarted Hopf curve was continued from (the saved file's point)."""

    path: str
    label: str
    values: tuple[float, float]
    text: str

    def as_json(self) -> dict[str, Any]:
        return {"file": self.path, "label": self.label, "values": list(self.values),
                "hopf_search": False}


@dataclass(frozen=True)
class HopfCurveStudy(Plottable):
    """The Hopf curve of a model in a plane of two parameters: every branch found (or the
    one continued from a saved point), the codimension-two points on them and a stability
    grid for shading.

    names, bounds : the plane's parameters and the bounds of each.
    curves : the :class:`~maglev_match.dynamics.hopf_curve.HopfCurve` branches.
    grid : (x values, y values, max Re(lambda) on the grid) or None.
    model, title : the model's label and the figure's title; is_user : a user model file.
    design_point : the model's values of the two parameters.
    units : the two parameters' units ('' for a user model).
    delay_notes : how a delay axis was handled; delay : the discretisation (or None).
    restart : the saved point a restart continued from (or None).
    warnings : what the search and the grid reported.
    """

    names: tuple[str, str]
    bounds: Mapping[str, tuple[float, float]]
    curves: list
    grid: tuple | None
    model: str
    title: str
    is_user: bool
    design_point: tuple[float, float]
    units: tuple[str, str]
    delay_notes: tuple[str, ...] = ()
    delay: dict | None = None
    restart: RestartPoint | None = None
    warnings: tuple[str, ...] = ()
    system: Any = field(default=None, repr=False, compare=False)
    params: Any = field(default=None, repr=False, compare=False)
    model_file: str | None = None

    def point_rows(self) -> list[dict[str, Any]]:
        """Every curve point: the two parameters, frequency, l1, branch, others_stable."""
        a, b = self.names
        return [{a: pt.values[0], b: pt.values[1], "frequency": pt.frequency, "l1": pt.l1,
                 "branch": k, "others_stable": pt.others_stable}
                for k, c in enumerate(self.curves) for pt in c.points]

    def special_rows(self) -> list[dict[str, Any]]:
        """The codimension-two points (GH with l2, BT, ZH, HH with the other frequency),
        labelled as AUTO does (a second branch's labels carry /k); a double-Hopf point
        seen again from the crossing branch is listed once."""
        a, b = self.names
        span0 = self.bounds[a][1] - self.bounds[a][0]
        span1 = self.bounds[b][1] - self.bounds[b][0]
        special: list[dict[str, Any]] = []
        for k, c in enumerate(self.curves):
            for sp in c.special_points:
                if sp.type == "HH" and any(
                        r["type"] == "HH" and abs(r[a] - sp.values[0]) <= 1e-6 * span0
                        and abs(r[b] - sp.values[1]) <= 1e-6 * span1 for r in special):
                    continue  # the same double-Hopf point seen from the crossing branch
                rec = {"type": sp.type, a: sp.values[0], b: sp.values[1],
                       "frequency": sp.frequency, "branch": k, "converged": sp.converged,
                       "located": sp.located, "label": f"{sp.label}" + (f"/{k}" if k else "")}
                if sp.type == "GH":
                    rec["l2"] = sp.l2
                if sp.type == "HH":
                    rec["other_frequency"] = sp.other_frequency
                special.append(rec)
        return special

    def branches(self) -> list[dict[str, Any]]:
        """How each branch ended."""
        return [{"converged": c.converged, "message": c.message, "n_points": len(c.points),
                 "closed": c.closed, "warnings": list(c.warnings)} for c in self.curves]

    def as_json(self) -> dict[str, Any]:
        return {"params": list(self.names), "model": self.model,
                "delay_notes": list(self.delay_notes),
                "restart": None if self.restart is None else self.restart.as_json(),
                "bounds": {n: list(self.bounds[n]) for n in self.names},
                "points": self.point_rows(), "special_points": self.special_rows(),
                "branches": self.branches(), "warnings": list(self.warnings)}

    def curve_dataset(self, k: int) -> Any:
        """Branch ``k`` as an annotated netCDF dataset, stamped as a restartable Hopf
        curve (:mod:`maglev_match.analyses.restart`): its two parameters, their bounds and
        the full parameter vector."""
        import numpy as np

        from maglev_match.analyses.restart import RestartKind, stamp
        from maglev_match.core.datasets import annotate

        system = self.system
        ds = annotate(self.curves[k].to_xarray(self.units, system.state_names), self.params)
        stamp(ds, RestartKind.HOPF_CURVE, system, self.model, "hopf-curve")
        if self.model_file is not None:  # a user model: the API's restart loads it again
            ds.attrs["model_file"] = str(Path(self.model_file).resolve())
        ds.attrs["curve_params"] = f"{self.names[0]},{self.names[1]}"
        for n in self.names:
            ds.attrs[f"bounds_{n}"] = np.array(self.bounds[n], float)
        ds["base_p"] = (("parameter",), np.asarray(system.p, float),
                        {"units": "parameter units", "long_name": "parameter vector of the "
                         "curve (the two curve parameters vary along it)"})
        return ds

    def to_xarray(self) -> Any:
        """The first branch's dataset (:meth:`curve_dataset`)."""
        return self.curve_dataset(0)


def _default_bounds(studied: StudiedModel, system: Any, names: tuple[str, str],
                    given: Mapping[str, tuple[float, float]]) -> dict[str, tuple[float, float]]:
    bounds = {}
    for n in names:
        if n in given:
            bounds[n] = (float(given[n][0]), float(given[n][1]))
        elif n in HOPF_CURVE_RANGES and not studied.is_user:
            bounds[n] = HOPF_CURVE_RANGES[n]
        elif n in studied.delays:  # a delay: from 0 (its design value may be 0)
            v = system.param(n) if n in system.param_names else 0.0
            bounds[n] = (0.0, 2.0 * v if v > 0 else DEFAULT_DELAY_RANGE)
        else:
            v = system.param(n)
            bounds[n] = (0.5 * v, 2.0 * v) if v > 0 else (v - 1.0, v + 1.0)
        if not bounds[n][0] < bounds[n][1]:
            raise ParameterError("bounds", f"{n}={bounds[n]}", "the range must be increasing")
        for v in bounds[n]:
            studied.validate_value(n, v)
    return bounds


@reported("hopf-curve", units=False)
def hopf_curve(params: Params | str | None = None, x: str | tuple | None = None,
               y: str | tuple | None = None, *, model: str = "unit", n_scan: int = 100,
               max_step: float = 1e-2, grid: int = 0,
               stage: Callable[[str], None] | None = None,
               config: str | Path | None = None, restart: str | Path | None = None,
               label: str | None = None, names: tuple[str, str] | None = None,
               bounds: dict[str, tuple[float, float]] | None = None,
               study: bool = False, progress: Callable[[str], None] | None = None,
               **overrides: Any) -> Any:
    """Every branch of the Hopf curve in a plane of two parameters (`maglev-match
    hopf-curve`).

    Branches are found by Hopf-point scans of `x` at three values of `y` (the middle, 10 %
    and 90 % of its range) and continued by pseudo-arclength on the standard defining
    system (Kuznetsov 2004, ch. 10; Govaerts 2000), with l1 along the curve and its
    codimension-two points (generalised Hopf with l2, Bogdanov-Takens, zero-Hopf, double
    Hopf). With `restart` and `label` a saved curve is continued from its point instead
    (both directions; no Hopf search; the saved parameter values unless values are given).

    Parameters
    ----------
    params : Params | str | None
        The parameter set (see [`resolve_params`][maglev_match.api.inputs.resolve_params]);
        None with `restart`: the saved values.
    x, y : str or (str, float, float), optional
        The plane's axes: a parameter name, or `(name, low, high)` with its bounds; default
        ("omega1", 30, 400) and ("sigma", 1e-4, 8e-4) for model A, ("omega1", 30, 400) and
        ("kD", 0.5 kD, 2 kD) for model B; a name without bounds gets those defaults (a
        delay 0 to twice its value, any other parameter 0.5 to 2 times its value). A user
        model must name its two parameters.
    model : str
        `"unit"`, `"vehicle"` or a user model file `FILE.py`.
    n_scan : int
        Values of each bracketing scan.
    max_step : float
        Largest continuation step, as a fraction of the ranges.
    grid : int
        Stability grid points per axis (shading of the figure; 0: none).
    stage : callable, optional
        Called with a line of text when a stage starts (the earlier name ``progress``
        still works and warns).
    config : str or Path, optional
        A TOML file applied on top of the preset.
    restart, label : optional
        A curve file written by `hopf-curve --out` and the point to continue from (`P<k>`
        or a codimension-two label such as `GH1`).
    bounds : dict, optional
        `{name: (low, high)}`: bounds of the plane's parameters (those not given in `x`,
        `y`; e.g. of the default plane when `x` and `y` are left out).
    names : deprecated
        The earlier form of `x` and `y` (`names=(x, y)`).
    study : bool
        Return the :class:`HopfCurveStudy` (curves, grid, codimension-two table, restart,
        netCDF datasets, figure) instead of the list of curves.
    **overrides : float
        Parameter values applied on top.

    Returns
    -------
    list of HopfCurve, or HopfCurveStudy with `study`
        One [`HopfCurve`][maglev_match.dynamics.hopf_curve.HopfCurve] per branch;
        `maglev_match.plots.plot(curves)` draws them with l1 along the curve.
    """
    import numpy as np

    from maglev_match.dynamics.hopf_curve import hopf_curves_from_scans, stability_grid

    if names is not None:
        deprecated("hopf_curve(params, names=(P1, P2), bounds={...})",
                   "hopf_curve(params, x=(P1, lo, hi), y=(P2, lo, hi))")
    if progress is not None:
        deprecated("hopf_curve(progress=...)", "hopf_curve(stage=...)")
        stage = stage or progress
    say = stage or (lambda text: None)
    own_values = params is not None or config is not None or bool(overrides)
    studied = resolve_model(params, model, config=config, **overrides)
    given: dict[str, tuple[float, float]] = dict(bounds or {})
    plane = default_plane(studied)
    if x is not None or y is not None:
        if x is None or y is None:
            if not plane:
                raise ParameterError("x" if x is None else "y", None, "give the two "
                                     f"parameters of model {studied.label}")
        (nx, bx), (ny, by) = (_plane_axis(x if x is not None else plane[0], "x"),
                              _plane_axis(y if y is not None else plane[1], "y"))
        names = (nx, ny)
        given.update({n: b for n, b in ((nx, bx), (ny, by)) if b})
    system = studied.system()
    params_used = studied.params
    restarted = None
    if restart is not None or label is not None:
        restarted, system, params_used = _restart(studied, restart, label, names, given,
                                                  max_step, own_values, overrides)
        names = restarted[1].names
    if names is None:
        if not plane:
            raise ParameterError("x", None, f"give the two parameters of model "
                                 f"{studied.label}, e.g. "
                                 f"{','.join(system.param_names[:2])}")
        names = plane
    names = tuple(names)
    if len(names) != 2 or names[0] == names[1]:
        raise ParameterError("names", names, "expected two different parameter names")
    for n in names:
        studied.check_param(n, "names")
    for n in given:
        if n not in names:
            raise ParameterError("bounds", n, f"not one of the curve's parameters "
                                 f"{','.join(names)}")
    lims = _default_bounds(studied, system, names, given)
    delay_notes = []
    for n in names:
        if n in studied.delays:  # the discretised delay system, sized for the largest delay
            lo, hi = lims[n]
            if lo < 0:
                raise ParameterError("bounds", f"{n}={lo:g}:{hi:g}", f"{n} is a delay: the "
                                     "range must start at or above 0")
            if lo < DELAY_FLOOR * hi:
                lims[n] = (DELAY_FLOOR * hi, hi)
                delay_notes.append(f"{n} from {DELAY_FLOOR * hi:g} (the discretised delay "
                                   f"system is singular at {n} = 0, the delay-free model)")
            if restarted is None:
                system = studied.system_along(n, hi)
    warnings: list[str] = []
    if restarted is not None:
        lims = restarted[2]
        curves = [restarted[0]]
        say(restarted[1].describe())
    else:
        a, b = lims[names[1]]
        scan_values = [a + f * (b - a) for f in (0.5, 0.1, 0.9)]
        say(f"scanning {names[0]} at {len(scan_values)} values of {names[1]} ...")
        curves, warnings = hopf_curves_from_scans(system, names, lims, scan_values,
                                                  n_scan=n_scan, max_step=max_step,
                                                  progress=stage)
    if not study:
        return curves
    grid_data = None
    if grid > 0:
        say(f"stability grid {grid} x {grid} ...")
        g1 = np.linspace(*lims[names[0]], grid)
        g2 = np.linspace(*lims[names[1]], grid)
        mr, ok = stability_grid(system, names, g1, g2)
        if not ok.all():
            warnings.append(f"equilibrium not found at {int((~ok).sum())} grid points")
        grid_data = (g1, g2, mr)
    preset = params if isinstance(params, str) and restarted is None else None
    return _study(studied, system, params_used, names, lims, curves, grid_data,
                  delay_notes, warnings, restarted, preset)


def _study(studied, system, params_used, names, lims, curves, grid_data, delay_notes,
           warnings, restarted, preset: str | None) -> HopfCurveStudy:
    from maglev_match.core.units import unit
    from maglev_match.maglev.catalog import model_info

    which = f"model {studied.label}" if studied.is_user else model_info(studied.label).short
    title = f"Hopf curve, {which}" + ("" if studied.is_user or preset is None
                                      else f" ({preset})")
    rp = None
    if restarted is not None:  # the saved values, not the preset's
        rs = restarted[1]
        title = f"Hopf curve, {which}, restarted from {rs.label} of {Path(rs.path).name}"
        rp = RestartPoint(rs.path, rs.label, tuple(rs.values), rs.describe())
    units = ("", "") if studied.is_user else (unit(names[0]), unit(names[1]))
    return HopfCurveStudy(
        names=names, bounds=lims, curves=curves, grid=grid_data, model=studied.label,
        title=title, is_user=studied.is_user,
        design_point=(system.param(names[0]), system.param(names[1])), units=units,
        delay_notes=tuple(delay_notes), delay=delay_description(system, names[0], False),
        restart=rp, warnings=tuple(warnings), system=system, params=params_used,
        model_file=studied.file)


def _restart(studied: StudiedModel, restart, label, names, given, max_step, own_values,
             overrides: Mapping[str, Any]):
    """The curve continued from a saved point: ((curve, restart, bounds), system, params).
    The curve parameters are the saved ones (other names are refused); ``given`` widens or
    narrows the saved bounds; without own values the saved parameter values are used."""
    import dataclasses

    import numpy as np

    from maglev_match.analyses.restart import (
        load_hopf_curve_restart,
        restart_hopf_curve,
        saved_params,
        saved_values,
    )

    if restart is None or label is None:
        raise ParameterError("restart/label", restart or label, "a restart needs the file "
                             "and the label of the point together")
    system, params = studied.system(), studied.params
    rs = load_hopf_curve_restart(restart, label, system)
    if not studied.is_user and rs.model != studied.label:
        from maglev_match.analyses.restart import RestartFileError

        raise RestartFileError(rs.path, f"was saved for model '{rs.model}', not for model "
                               f"'{studied.label}' (its attribute model); restart with the "
                               "model that saved it")
    if names is not None and tuple(names) != rs.names:
        raise ParameterError("x/y", ",".join(names), f"the saved curve is in "
                             f"({', '.join(rs.names)}); a restart continues it there")
    fixed = sorted(set(rs.names) & set(overrides))
    if fixed:
        raise ParameterError(fixed[0], overrides[fixed[0]], f"{fixed[0]} varies along the "
                             f"saved Hopf curve; a restart starts from the point {rs.label} "
                             f"({rs.names[0]} = {rs.values[0]:.8g}, {rs.names[1]} = "
                             f"{rs.values[1]:.8g}); leave it out")
    if not own_values:  # the saved values
        saved = saved_params(rs) if not studied.is_user else None
        if saved is not None:
            from maglev_match.maglev.models import maglev_model

            params, system = saved, maglev_model(saved, studied.label).system()
        else:
            vals = saved_values(rs)
            system = dataclasses.replace(system, p=np.array([vals[n]
                                                             for n in system.param_names]))
    lims = {**rs.bounds, **{k: (float(v[0]), float(v[1])) for k, v in given.items()}}
    curve, rs = restart_hopf_curve(restart, label, system, lims, max_step=max_step)
    return (curve, rs, lims), system, params

