"""The public Python API: one function per analysis, re-exported at the package top level.

Every function has one signature style, ``function(params, ..., **overrides)``:

* ``params`` (first) — a :class:`~maglev_match.core.params.Params`, the name of a shipped
  preset (``"turnout-soft"``, ``"alpha1"``, ...) or ``None`` for the default preset;
* then what the analysis varies (``param``, ``values``, the axes ``x=("omega1", 40, 190,
  100)`` of a map ...) and its keyword options (``model="unit"`` or ``"vehicle"`` wherever
  the command line has ``--model``);
* ``**overrides`` — parameter values applied on top, validated like ``--set NAME=VALUE``
  on the command line (for example ``kD=120`` or the beam data ``L=18, EI=2.0e10``, from
  which omega1 and sigma are derived).

The earlier forms (``hopf_points("omega1", 30, 300, params)``, ``cycle_branch("omega1",
params)``, ``root_locus("omega1", values, params)``, ``hopf_curve(params, names=...,
bounds=...)``, ``design_map("omega1=40:190:100", "sigma=...", preset)``) still work and
warn (:class:`DeprecationWarning`). The sensitivities, the design search and the report
are :func:`index_sensitivity`, :func:`design_search` and :func:`study_report`
(``maglev_match.analyses.sensitivity``, ``.design`` and ``.report`` name the modules). Every result
with a figure has ``.plot(path=None)``; :func:`maglev_match.plots.plot` draws any of them.

The functions call the same library routines as the command line and return its result
objects (frozen dataclasses carrying their diagnostics). They add nothing numerical; the
methods and their sources are documented where they are implemented
(:mod:`maglev_match.dynamics`, :mod:`maglev_match.analyses.matching`,
:mod:`maglev_match.analyses.maps`).
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from maglev_match.core import jax_setup  # noqa: F401  (float64 before any model is built)
from maglev_match.core.params import DEFAULT_PRESET, ParameterError, Params, load_params

if TYPE_CHECKING:  # pragma: no cover
    import xarray as xr

    from maglev_match.analyses.design import DesignResult
    from maglev_match.analyses.matching import MatchingIndex
    from maglev_match.analyses.sensitivity import IndexSensitivity
    from maglev_match.analyses.simulation import MaglevSimulation
    from maglev_match.analyses.speed.sweep import SpeedSweep
    from maglev_match.dynamics.cycles import CycleBranch
    from maglev_match.dynamics.equilibria import RootLocusResult, StabilityResult
    from maglev_match.dynamics.hopf import HopfScan
    from maglev_match.dynamics.hopf_curve import HopfCurve
    from maglev_match.dynamics.system import System
    from maglev_match.present.report import ReportResult

__all__ = [
    "resolve_params",
    "build_system",
    "stability",
    "root_locus",
    "hopf_points",
    "hopf_curve",
    "cycle_branch",
    "simulate",
    "matching_index",
    "index_sensitivity",
    "design_search",
    "design_map",
    "study_report",
    "restart_branch",
    "speed_sweep",
    "MODELS",
]

MODELS = ("unit", "vehicle")
# Default search bounds of the Hopf curve, as on the command line (hopf-curve).
HOPF_CURVE_RANGES = {"omega1": (30.0, 400.0), "sigma": (1e-4, 8e-4)}
DEFAULT_PLANE = {"unit": ("omega1", "sigma"), "vehicle": ("omega1", "kD")}


def _deprecated(old: str, new: str) -> None:
    warnings.warn(f"{old} is deprecated; write {new}", DeprecationWarning, stacklevel=3)


def _names_a_preset(value: Any) -> bool:
    """Whether a positional string is a parameter set (a preset name) rather than the
    parameter name of an earlier signature."""
    from maglev_match.core.params import available_presets

    return isinstance(value, str) and value in available_presets()


def resolve_params(params: Params | str | None = None, **overrides: Any) -> Params:
    """The parameter set of an API call, validated.

    Parameters
    ----------
    params : Params | str | None
        A [`Params`][maglev_match.core.params.Params], the name of a shipped preset, or None for
        the default preset `turnout-soft`.
    **overrides : float
        Values applied on top (beam data such as `EI` re-derive omega1 and sigma).

    Returns
    -------
    Params
        The parameter set.

    Raises
    ------
    ParameterError
        For an unknown name or an invalid value, naming the field, the value and the rule.
    """
    if params is None or isinstance(params, str):
        return load_params(params or DEFAULT_PRESET, None, dict(overrides))
    if not isinstance(params, Params):
        raise ParameterError("params", type(params).__name__,
                             "must be a Params, a preset name or None")
    return params.replace(**overrides) if overrides else params


def _check_model(model: str) -> str:
    if model not in MODELS:
        raise ParameterError("model", model, "must be 'unit' or 'vehicle'")
    return model


def build_system(params: Params | str | None = None, model: str = "unit", *,
                 limited: bool = False, **overrides: Any) -> System:
    """The ODE system of model A or B, with exact derivatives.

    Parameters
    ----------
    params : Params | str | None
        The parameter set: a [`Params`][maglev_match.core.params.Params], the name of a shipped
        preset, or None for the default preset `turnout-soft`.
    model : str
        `"unit"` (model A, 9 states) or `"vehicle"` (model B, 40 states with 3 modes).
    **overrides : float
        Parameter values applied on top, validated like `--set NAME=VALUE`.
    limited : bool
        Put the current clamp (the current never reverses) into the vector field.

    Returns
    -------
    System
        The [`System`][maglev_match.dynamics.system.System] (vector field, parameter
        vector, state names, read-outs).
    """
    from maglev_match.maglev.models import build_system as _build

    return _build(resolve_params(params, **overrides), _check_model(model), limited=limited)


def stability(params: Params | str | None = None, *, model: str = "unit",
              **overrides: Any) -> StabilityResult:
    """Equilibrium, eigenvalues and the stability verdict (`maglev-match stability`).

    The Jacobian is exact (automatic differentiation); the equilibrium is stable when every
    eigenvalue has a negative real part.

    Parameters
    ----------
    params : Params | str | None
        The parameter set: a [`Params`][maglev_match.core.params.Params], the name of a shipped
        preset, or None for the default preset `turnout-soft`.
    model : str
        `"unit"` (model A, 9 states) or `"vehicle"` (model B, 40 states with 3 modes).
    **overrides : float
        Parameter values applied on top, validated like `--set NAME=VALUE`.

    Returns
    -------
    StabilityResult
        Eigenvalues (1/s, largest real part first), `stable`, `margin` = -max Re(lambda)
        (1/s), the equilibrium and warnings; see
        [`StabilityResult`][maglev_match.dynamics.equilibria.StabilityResult].
    """
    from maglev_match.dynamics.equilibria import stability as _stability

    return _stability(build_system(params, model, **overrides))


def root_locus(params: Params | str | None = None, param: str = "omega1",
               values: Sequence[float] | np.ndarray | None = None, *, model: str = "unit",
               **overrides: Any) -> RootLocusResult:
    """Eigenvalues of the equilibrium along one parameter (`maglev-match root-locus`).

    Parameters
    ----------
    params : Params | str | None
        The parameter set: a [`Params`][maglev_match.core.params.Params], the name of a shipped
        preset, or None for the default preset `turnout-soft`.
    param : str
        The parameter to vary (any parameter of the model).
    values : array_like, optional
        Its values, in its SI unit (default: 151 values from 40 to 190, as the command).
    model : str
        `"unit"` (model A, 9 states) or `"vehicle"` (model B, 40 states with 3 modes).
    **overrides : float
        Parameter values applied on top, validated like `--set NAME=VALUE`.

    Returns
    -------
    RootLocusResult
        See [`RootLocusResult`][maglev_match.dynamics.equilibria.RootLocusResult];
        `.plot()` draws it, `.to_xarray()` gives its dataset.
    """
    from maglev_match.dynamics.equilibria import root_locus as _root_locus

    if isinstance(params, str) and not _names_a_preset(params):  # root_locus(param, values, p)
        _deprecated("root_locus(param, values, params)",
                    "root_locus(params, param, values)")
        params, param, values = values, params, param
    values = np.linspace(40.0, 190.0, 151) if values is None else values
    system = build_system(params, model, **overrides)
    _check_param(system, param, "param")
    return _root_locus(system, param, np.asarray(values, float))


def _check_param(system: System, name: str, field: str) -> None:
    if name not in system.param_names:
        raise ParameterError(field, name, "the model has no such parameter; choose one of "
                             + ", ".join(system.param_names))


def hopf_points(params: Params | str | None = None, param: str = "omega1",
                start: float = 30.0, stop: float = 300.0, *, model: str = "unit",
                n_scan: int = 200, **overrides: Any) -> HopfScan:
    """Hopf points of the equilibrium along one parameter (`maglev-match hopf`).

    A scan of `n_scan` eigenvalue computations brackets each crossing of a complex pair
    of eigenvalues; each bracket is refined by Newton's method on the Hopf defining system,
    and the first Lyapunov coefficient l1 is computed there by Kuznetsov's projection
    formula (Kuznetsov 2004, ch. 3 and 5): l1 > 0 subcritical, l1 < 0 supercritical.

    Parameters
    ----------
    params : Params | str | None
        The parameter set: a [`Params`][maglev_match.core.params.Params], the name of a shipped
        preset, or None for the default preset `turnout-soft`.
    param : str
        The parameter to vary.
    start, stop : float
        The interval searched, in the parameter's SI unit.
    model : str
        `"unit"` (model A, 9 states) or `"vehicle"` (model B, 40 states with 3 modes).
    n_scan : int
        Values of the bracketing scan.
    **overrides : float
        Parameter values applied on top, validated like `--set NAME=VALUE`.

    Returns
    -------
    HopfScan
        `points`: the [`HopfPoint`][maglev_match.dynamics.hopf.HopfPoint]s (value,
        frequency, crossing speed, l1), with the scan itself; see
        [`HopfScan`][maglev_match.dynamics.hopf.HopfScan]; `.plot()` draws it.
    """
    if isinstance(params, str) and not _names_a_preset(params):  # (param, start, stop, p)
        _deprecated("hopf_points(param, start, stop, params)",
                    "hopf_points(params, param, start, stop)")
        # old positions: (param, start, stop, params); a number in `stop` is the default
        old_params = None if isinstance(stop, int | float) else stop
        params, param, start, stop = old_params, params, param, start
    from maglev_match.dynamics.hopf import locate_hopf_points

    if not start < stop:
        raise ParameterError("start", start, f"must be smaller than stop = {stop:g}")
    if n_scan < 2:
        raise ParameterError("n_scan", n_scan, "must be at least 2")
    base = resolve_params(params, **overrides)
    for v in (start, stop):
        _validate_value(base, param, v)
    system = build_system(base, model)
    _check_param(system, param, "param")
    return locate_hopf_points(system, param, float(start), float(stop), n_scan=int(n_scan))


def _validate_value(params: Params, name: str, value: float) -> None:
    from maglev_match.core.params import PARAMETER_DOCS

    if name in PARAMETER_DOCS:
        params.replace(**{name: value})


def _plane_axis(axis: Any, field: str) -> tuple[str, tuple[float, float] | None]:
    """A Hopf-curve axis: a name, or (name, low, high)."""
    if isinstance(axis, str):
        return axis, None
    try:
        name, lo, hi = axis
        return str(name), (float(lo), float(hi))
    except (TypeError, ValueError):
        raise ParameterError(field, axis, "expected a parameter name or (name, low, high)")\
            from None


def hopf_curve(params: Params | str | None = None, x: str | tuple | None = None,
               y: str | tuple | None = None, *, model: str = "unit", n_scan: int = 100,
               max_step: float = 1e-2, progress: Callable[[str], None] | None = None,
               names: tuple[str, str] | None = None,
               bounds: dict[str, tuple[float, float]] | None = None,
               **overrides: Any) -> list[HopfCurve]:
    """Every branch of the Hopf curve in a plane of two parameters (`maglev-match
    hopf-curve`).

    Branches are found by Hopf-point scans of `x` at three values of `y` (the middle, 10 %
    and 90 % of its range) and continued by pseudo-arclength on the standard defining
    system (Kuznetsov 2004, ch. 10; Govaerts 2000), with l1 along the curve and its
    codimension-two points (generalised Hopf with l2, Bogdanov-Takens, zero-Hopf, double
    Hopf).

    Parameters
    ----------
    params : Params | str | None
        The parameter set (see [`resolve_params`][maglev_match.api.resolve_params]).
    x, y : str or (str, float, float), optional
        The plane's axes: a parameter name, or `(name, low, high)` with its bounds; default
        ("omega1", 30, 400) and ("sigma", 1e-4, 8e-4) for model A, ("omega1", 30, 400) and
        ("kD", 0.5 kD, 2 kD) for model B; a name without bounds gets those defaults (any
        other parameter 0.5 to 2 times its value).
    model : str
        `"unit"` or `"vehicle"`.
    n_scan : int
        Values of each bracketing scan.
    max_step : float
        Largest continuation step, as a fraction of the ranges.
    progress : callable, optional
        Called with a line of text when a branch starts.
    names, bounds : deprecated
        The earlier form of `x` and `y` (`names=(x, y)`, `bounds={name: (low, high)}`).
    **overrides : float
        Parameter values applied on top.

    Returns
    -------
    list of HopfCurve
        One [`HopfCurve`][maglev_match.dynamics.hopf_curve.HopfCurve] per branch;
        `maglev_match.plots.plot(curves)` draws them with l1 along the curve.
    """
    if names is not None or bounds is not None:
        _deprecated("hopf_curve(params, names=(P1, P2), bounds={...})",
                    "hopf_curve(params, x=(P1, lo, hi), y=(P2, lo, hi))")
    if x is not None or y is not None:
        (nx, bx), (ny, by) = (_plane_axis(x if x is not None else
                                          DEFAULT_PLANE[_check_model(model)][0], "x"),
                              _plane_axis(y if y is not None else
                                          DEFAULT_PLANE[_check_model(model)][1], "y"))
        names = (nx, ny)
        bounds = {**(bounds or {}), **{n: b for n, b in ((nx, bx), (ny, by)) if b}}
    from maglev_match.dynamics.hopf_curve import hopf_curves_from_scans

    base = resolve_params(params, **overrides)
    system = build_system(base, model)
    names = tuple(names) if names is not None else DEFAULT_PLANE[_check_model(model)]
    if len(names) != 2 or names[0] == names[1]:
        raise ParameterError("names", names, "expected two different parameter names")
    for n in names:
        _check_param(system, n, "names")
    lims: dict[str, tuple[float, float]] = {}
    for n in names:
        if bounds and n in bounds:
            lims[n] = (float(bounds[n][0]), float(bounds[n][1]))
        elif n in HOPF_CURVE_RANGES:
            lims[n] = HOPF_CURVE_RANGES[n]
        else:
            v = system.param(n)
            lims[n] = (0.5 * v, 2.0 * v) if v > 0 else (v - 1.0, v + 1.0)
        if not lims[n][0] < lims[n][1]:
            raise ParameterError("bounds", f"{n}={lims[n]}", "the range must be increasing")
        for v in lims[n]:
            _validate_value(base, n, v)
    a, b = lims[names[1]]
    curves, _ = hopf_curves_from_scans(system, names, lims,
                                       [a + f * (b - a) for f in (0.5, 0.1, 0.9)],
                                       n_scan=n_scan, max_step=max_step, progress=progress)
    return curves


def cycle_branch(params: Params | str | None = None, param: str = "omega1", *,
                 model: str = "unit", start: float | None = None, stop: float | None = None,
                 n_scan: int = 100, ntst: int = 80, ncol: int = 4, max_steps: int = 300,
                 ignore_current: bool = False,
                 progress: Callable[[int, Any], None] | None = None,
                 **overrides: Any) -> CycleBranch:
    """The branch of periodic orbits born at the Hopf point nearest the design value of
    `param` (`maglev-match cycles`).

    The orbits are solved by orthogonal collocation at Gauss points on an adaptive mesh (de
    Boor & Swartz 1973; Doedel's AUTO notes) and continued by pseudo-arclength until a
    physical limit, a failure or `max_steps`; Floquet multipliers come from the monodromy
    matrix of the condensed collocation blocks (Doedel, Keller & Kernevez 1991).

    Parameters
    ----------
    params : Params | str | None
        The parameter set: a [`Params`][maglev_match.core.params.Params], the name of a shipped
        preset, or None for the default preset `turnout-soft`.
    param : str
        The continuation parameter.
    model : str
        `"unit"` (model A, 9 states) or `"vehicle"` (model B, 40 states with 3 modes).
    start, stop : float, optional
        Where Hopf points are searched (default: the design value / 4 to x 4).
    n_scan : int
        Values of the bracketing scan.
    ntst, ncol : int
        Mesh intervals and collocation points per interval (2 to 7).
    max_steps : int
        Continuation steps.
    ignore_current : bool
        Do not stop where the coil current reaches zero (only the gap limits stop).
    progress : callable, optional
        Called as `progress(step, cycle)` after each accepted step.
    **overrides : float
        Parameter values applied on top, validated like `--set NAME=VALUE`.

    Returns
    -------
    CycleBranch
        See [`CycleBranch`][maglev_match.dynamics.cycles.CycleBranch].
    """
    from maglev_match.dynamics.cycles import cycle_branch as _cycle_branch
    from maglev_match.dynamics.hopf import locate_hopf_points
    from maglev_match.maglev.limits import cycle_limit_margins

    if isinstance(params, str) and not _names_a_preset(params):  # cycle_branch(param, p)
        _deprecated("cycle_branch(param, params)", "cycle_branch(params, param)")
        old_params = param if isinstance(param, Params) or _names_a_preset(param) else None
        params, param = old_params, params
    if not 2 <= ncol <= 7:
        raise ParameterError("ncol", ncol, "must be between 2 and 7")
    if ntst < 4:
        raise ParameterError("ntst", ntst, "must be at least 4")
    base = resolve_params(params, **overrides)
    system = build_system(base, model)
    _check_param(system, param, "param")
    design = system.param(param)
    a = design / 4 if start is None else float(start)
    b = design * 4 if stop is None else float(stop)
    if not (np.isfinite(a) and np.isfinite(b)) or a == b:
        raise ParameterError("start/stop", f"[{a}, {b}]", "the search range is empty")
    scan = locate_hopf_points(system, param, min(a, b), max(a, b), n_scan=n_scan)
    hopfs = [h for h in scan.points if h.converged]
    if not hopfs:
        raise ParameterError("start/stop", f"[{min(a, b):.6g}, {max(a, b):.6g}]",
                             f"no Hopf point of the equilibrium along {param} there; "
                             "widen the range")
    hopf = min(hopfs, key=lambda h: abs(h.value - design))
    limits = cycle_limit_margins(base, include_current=not ignore_current)
    return _cycle_branch(system, hopf, param, ntst=ntst, ncol=ncol, max_steps=max_steps,
                         limits=limits, progress=progress)


def simulate(params: Params | str | None = None, *, model: str = "unit",
             t_end: float = 5.0, x5: float | None = None, initial: str = "equilibrium",
             q1: float | None = None, x0: Sequence[float] | np.ndarray | None = None,
             limits: bool = True, n_save: int = 5001, rtol: float = 1e-8,
             atol: float = 1e-8, **overrides: Any) -> MaglevSimulation:
    """Simulate model A or B with the physical limits (`maglev-match simulate`).

    With `limits` the coil current never reverses and leaving the gap range
    [gap_min, gap_max] ends the run as a collision.

    Parameters
    ----------
    params : Params | str | None
        The parameter set: a [`Params`][maglev_match.core.params.Params], the name of a shipped
        preset, or None for the default preset `turnout-soft`.
    model : str
        `"unit"` (model A, 9 states) or `"vehicle"` (model B, 40 states with 3 modes).
    t_end : float
        Horizon (s).
    x5 : float, optional
        Model A: initial beam deflection x5(0) (m); negative opens the gap.
    initial : str
        `"equilibrium"`, or for model B `"pressed"` (the vehicle at equilibrium on the
        undeflected beam).
    q1 : float, optional
        Model B: first modal coordinate q1(0) (m, undeflected beam = 0).
    x0 : array_like, optional
        The whole initial state (overrides the above).
    limits : bool
        The physical limits.
    n_save : int
        Saved time points.
    rtol, atol : float
        Tolerances (atol in units of each state's typical size).
    **overrides : float
        Parameter values applied on top, validated like `--set NAME=VALUE`.

    Returns
    -------
    MaglevSimulation
        Outcome (collision / converged / running / failed), collision time, limit and
        point; see [`MaglevSimulation`][maglev_match.analyses.simulation.MaglevSimulation].
    """
    from maglev_match.analyses.simulation import initial_state, simulate_maglev
    from maglev_match.dynamics.integrate.simulate import SimulationOptions

    _check_model(model)
    if not t_end > 0:
        raise ParameterError("t_end", t_end, "the horizon must be > 0 s")
    if n_save < 2:
        raise ParameterError("n_save", n_save, "need at least 2 saved points")
    base = resolve_params(params, **overrides)
    state = None if x0 is None else np.asarray(x0, float).ravel()
    x_init = initial_state(base, model, initial=initial, x5=x5, q1=q1, state=state)
    return simulate_maglev(base, model, x_init, t_end, limited=limits, n_save=n_save,
                           options=SimulationOptions(rtol=rtol, atol=atol))


def matching_index(params: Params | str | None = None, *, model: str = "unit",
                   simulate: bool = True, **overrides: Any) -> MatchingIndex:
    """The matching index chi = h / w0 of model A or the full vehicle (`maglev-match index
    [--model vehicle]`).

    h = 0 if the equilibrium is unstable; the largest gap deviation of the unstable cycle
    around the stable equilibrium (model B: over all six levitation points); or
    gap_max - c0 when no such cycle lies within the gap range. w0 is the static beam
    deflection (model A: sigma (m + M) g / omega1^2; model B: at mid-span under the vehicle).

    Parameters
    ----------
    params : Params | str | None
        The parameter set (see [`resolve_params`][maglev_match.api.resolve_params]).
    model : str
        `"unit"` (model A) or `"vehicle"` (model B, 40 states).
    simulate : bool
        Also compute h_simulation, the critical disturbance found by simulations with the
        limits on (slower).
    **overrides : float
        Parameter values applied on top.

    Returns
    -------
    MatchingIndex
        chi, h, w0, the case that decided h and its diagnostics; see
        [`MatchingIndex`][maglev_match.analyses.matching.MatchingIndex].
    """
    from maglev_match.analyses.matching import matching_index as _matching_index

    return _matching_index(resolve_params(params, **overrides), model=_check_model(model),
                           simulate=simulate)


def index_sensitivity(params: Params | str | None = None, *, model: str = "unit",
                      boundaries: bool = True, simulate: bool = True,
                      **overrides: Any) -> IndexSensitivity:
    """Exact d chi / d p of the headline index for every parameter (`maglev-match
    sensitivity`): implicit differentiation of the converged cycle that decides h, or of
    the solved critical disturbance where chi_simulation is the headline, the elasticities
    (p / chi) d chi / d p, the stability margin's sensitivities and, with `boundaries`,
    each parameter's value at the nearest stability boundary.

    Parameters
    ----------
    params : Params | str | None
        The parameter set (see [`resolve_params`][maglev_match.api.resolve_params]).
    model : str
        `"unit"` (model A) or `"vehicle"` (model B).
    boundaries : bool
        Also solve each parameter's value at the stability boundary.
    simulate : bool
        Differentiate the headline index (default); False: the paper's chi only
        (`--no-simulation`).
    **overrides : float
        Parameter values applied on top.

    Returns
    -------
    IndexSensitivity
        See `maglev_match.analyses.sensitivity.IndexSensitivity`; `.plot()`
        draws the tornado figure.
    """
    from maglev_match.analyses.sensitivity import index_sensitivity as _index_sensitivity

    base = resolve_params(params, **overrides)
    if not base.w0 > 0:
        raise ParameterError("sigma", base.sigma, "must be > 0 for the index: chi = h / w0 "
                             f"needs a beam deflection w0 > 0 (w0 = {base.w0:g} m)")
    return _index_sensitivity(base, boundaries=boundaries, model=_check_model(model),
                              simulate=simulate)


def design_search(params: Params | str | None = None, *,
                  vary: Mapping[str, tuple[float, float]],
                  minimize: str | None = None, maximize: str | None = None,
                  require: Mapping[str, float] | Sequence[str] = (), model: str = "unit",
                  grid: int | None = None, starts: int = 2, simulate: bool = True,
                  progress: Callable[[str], None] | None = None,
                  **overrides: Any) -> DesignResult:
    """The cheapest design, or the one with the largest chi, meeting requirements
    (`maglev-match design`): SLSQP on exact gradients from several grid starts (Nocedal &
    Wright 2006, ch. 18), every candidate re-checked by the full index.

    Parameters
    ----------
    params : Params | str | None
        The base parameter set (see [`resolve_params`][maglev_match.api.resolve_params]).
    vary : mapping
        `{name: (low, high)}` of the varied parameters, e.g. `{"EI": (5e9, 4e10)}`.
    minimize, maximize : str
        Exactly one: a varied parameter to make as small as possible, or `"chi"`.
    require : mapping or sequence of str
        Lower bounds, `{"chi": 5, "margin": 0.5}` or `["chi>=5", "margin>=0.5"]`
        (chi, margin (1/s), chi_simulation).
    model : str
        `"unit"` or `"vehicle"`.
    grid, starts : int
        Start-grid points per varied parameter (default 9 for one, 5 for two) and
        optimiser runs.
    simulate : bool
        Constrain the headline index (default: both chi_paper and chi_simulation meet a
        requirement on chi); False: the paper's chi only (`--no-simulation`).
    progress : callable, optional
        Called with a line of text at each stage.
    **overrides : float
        Parameter values applied on top of the base.

    Returns
    -------
    DesignResult
        See `maglev_match.analyses.design.DesignResult`; `.plot()` draws the search.
    """
    from maglev_match.analyses.design import (
        DesignProblem,
        Goal,
        MaglevEvaluator,
        check_vary_ranges,
        optimise_design,
        parse_requirement,
        parse_vary,
        refuse_switched_off,
    )

    if (minimize is None) == (maximize is None):
        raise ParameterError("minimize/maximize", minimize or maximize,
                             "give exactly one of them")
    if not vary:
        raise ParameterError("vary", vary, "give at least one parameter range")
    variables = tuple(parse_vary(f"{n}={float(lo)!r}:{float(hi)!r}")
                      for n, (lo, hi) in dict(vary).items())
    texts = ([f"{k}>={float(v)!r}" for k, v in require.items()]
             if isinstance(require, Mapping) else list(require))
    reqs = tuple(parse_requirement(r) for r in texts)
    refuse_switched_off(reqs, texts, simulate, "require", "simulate=False")
    goal = Goal.MINIMIZE if minimize is not None else Goal.MAXIMIZE
    problem = DesignProblem(variables, goal, minimize or maximize or "", reqs)
    base = resolve_params(params, **overrides)
    for var in variables:  # both ends must be valid parameter values
        base.replace(**{var.name: var.lo})
        base.replace(**{var.name: var.hi})
    check_vary_ranges(base, variables, "vary")  # valid sets with a meaningful chi throughout
    evaluator = MaglevEvaluator(base, problem.names, model=_check_model(model),
                                simulate=simulate)
    return optimise_design(problem, evaluator, grid=grid, starts=starts, progress=progress)


def restart_branch(source: str | Path | Any, label: str, system: System | None = None, *,
            param: str | None = None, stop: float | None = None,
            bounds: Mapping[str, tuple[float, float]] | None = None,
            **options: Any) -> Any:
    """Continue a saved branch from one of its points (`cycles --restart FILE --label L`,
    `hopf-curve --restart FILE --label L`). The file says what it holds; no Hopf point is
    searched again. (Named `restart_branch` because `maglev_match.analyses.restart` is the module
    that reads the files.)

    Parameters
    ----------
    source : str, Path or xarray.Dataset
        A branch file written by `cycles --out` or `hopf-curve --out` (or by
        `maglev_match.analyses.restart.save_equilibrium_branch`).
    label : str
        The point to continue from: `P<k>` for the k-th saved point, or a special point's
        label (`LPC1`, `PD1`, `GH1`, ...).
    system : System, optional
        The model; by default the saved model at its saved parameter values (model A or B,
        or the user model file the branch names). Its names and values must match the
        saved ones (all but the continued parameter), else a clear error names them.
    param : str, optional
        A cycle branch: continue in another parameter (default the saved one).
    stop : float, optional
        An equilibrium branch: where the continued parameter should end (required there).
    bounds : mapping, optional
        A Hopf curve: `{name: (low, high)}` for its two parameters (default the saved ones).
    **options
        Passed to the continuation (e.g. `max_steps`, `ntst`).

    Returns
    -------
    RestartedCycleBranch, or (HopfCurve, HopfCurveRestart), or (EquilibriumBranch,
    EquilibriumRestart); see `maglev_match.analyses.restart`. A damaged or mismatched file raises
    `maglev_match.analyses.restart.RestartFileError` naming the file and the problem.
    """
    from maglev_match.analyses.restart import restart as _restart

    return _restart(source, label, system, param=param, stop=stop, bounds=bounds, **options)


def study_report(params: Params | str | None = None, out: str | Path = "report.html", *,
                 quick: bool = False, vehicle: bool = True, t_end: float = 3.0,
                 label: str = "", progress: Callable[[str], None] | None = None,
                 **overrides: Any) -> ReportResult:
    """The self-contained HTML study report of one vehicle-beam pair (`maglev-match
    report`): parameters, stability, root locus, Hopf curve, cycles, time histories, the
    matching index and its sensitivities; figures embedded (and written as PNG/SVG to
    `<out stem>_figures/`).

    Parameters
    ----------
    params : Params | str | None
        The parameter set (see [`resolve_params`][maglev_match.api.resolve_params]).
    out : str or Path
        The HTML file.
    quick : bool
        Coarse, fast settings (previews).
    vehicle : bool
        Also analyse model B (the full vehicle).
    t_end : float
        Simulation horizon (s).
    label : str
        A name for the study (default: the preset name, or "parameter set").
    progress : callable, optional
        Called with each section's title before it runs.
    **overrides : float
        Parameter values applied on top.

    Returns
    -------
    ReportResult
        The written file, its figures and every section's data; see
        `maglev_match.present.report.ReportResult`.
    """
    from maglev_match.present.report import ReportSettings
    from maglev_match.present.report import study_report as _study_report

    if not t_end > 0:
        raise ParameterError("t_end", t_end, "the horizon must be > 0 s")
    base = resolve_params(params, **overrides)
    settings = ReportSettings.quick_settings() if quick else ReportSettings()
    settings = ReportSettings(**{**settings.as_dict(), "include_vehicle": vehicle,
                                 "t_end": t_end})
    name = label or (params if isinstance(params, str) else "parameter set")
    return _study_report(base, out, settings, label=name, progress=progress)


def _map_axis(axis: Any, field: str) -> str:
    """A map axis as the command line writes it (NAME=START:STOP:COUNT) from the keyword
    form (name, start, stop, count); the command-line string itself is the deprecated
    form. Validation (names, counts, order) is :func:`maglev_match.analyses.maps.parse_axis`'s."""
    if isinstance(axis, str):
        _deprecated(f'design_map({field}="NAME=START:STOP:COUNT")',
                    f'design_map(params, {field}=("NAME", START, STOP, COUNT))')
        return axis
    try:
        name, start, stop, count = axis
    except (TypeError, ValueError):
        raise ParameterError(field, axis, "expected (name, start, stop, count), e.g. "
                             '("omega1", 40, 190, 100)') from None
    if isinstance(count, float) and count.is_integer():
        count = int(count)
    if not isinstance(count, int) or isinstance(count, bool):
        raise ParameterError(field, axis, "the count must be a whole number")
    try:
        return f"{name}={float(start)!r}:{float(stop)!r}:{count}"
    except (TypeError, ValueError):
        raise ParameterError(field, axis, "start and stop must be numbers") from None


def design_map(params: Params | str | None = None,
               x: tuple | str = ("omega1", 40.0, 190.0, 100),
               y: tuple | str = ("sigma", 2e-4, 6e-4, 100), *,
               config: str | Path | None = None, workers: int | None = 0,
               scheduler: str | None = None, checkpoint: str | Path | None = None,
               resume: bool = False, rows_per_tile: int = 4, ntst: int = 30,
               progress: Callable[[int, int], None] | None = None,
               simulate: bool = True, preset: str | None = None,
               **overrides: Any) -> xr.Dataset:
    """The headline index chi = min(chi_paper, chi_simulation), its parts and stability
    over a grid of two parameters (`maglev-match map`).

    Parameters
    ----------
    params : Params | str | None
        The base point: a [`Params`][maglev_match.core.params.Params], a preset name or None
        for the default preset.
    x, y : tuple
        The axes, `(name, start, stop, count)`, e.g. `("omega1", 40, 190, 100)`; name is
        any parameter, including the beam data L, EI, mbar, l, k (omega1 and sigma are then
        derived at every point). (The command-line strings `"omega1=40:190:100"` still
        work, with a DeprecationWarning.)
    config : str or Path, optional
        A TOML file applied on top of a preset `params` (`--config`).
    workers : int or None
        0 (default): compute in this process; n > 0: a local Dask cluster of n
        single-threaded worker processes; None: one per core.
    scheduler : str, optional
        Address of an existing Dask scheduler, `tcp://host:port`.
    checkpoint : str or Path, optional
        Folder for finished tiles (then `resume` reuses them); without it the map is
        assembled in memory and nothing is written.
    resume : bool
        Reuse the finished tiles of `checkpoint`.
    rows_per_tile : int
        Rows of the grid per task.
    ntst : int
        Collocation intervals of the cycles.
    progress : callable, optional
        Called as `progress(done_tiles, total_tiles)`.
    simulate : bool
        Simulate the critical disturbances (default), so that chi is the headline index;
        False: the paper's index only (`--no-simulation`; chi is then chi_paper).
    preset : str, optional
        Deprecated: the preset name, now given as `params`.
    **overrides : float
        Parameter values applied on top of the base point (`--set`).

    Returns
    -------
    xarray.Dataset
        Variables chi (the headline index), chi_paper, chi_simulation, h,
        h_simulation_up, h_simulation_down, chi_basis, w0, stable, max_real_part,
        hopf_distance, case, omega1_point, sigma_point, current_reverses, resolved, reason
        over the dimensions (y, x) (index variables NaN where unstable or unresolved), the
        rows' Hopf points hopf_x and, for two model parameters as axes, the continued Hopf
        curve; units and long names, the base parameter set and the package version as
        attributes. Equal, value for value, to the netCDF file `maglev-match map` writes
        for the same grid (see `maglev_match.analyses.maps.map_dataset`);
        `maglev_match.plots.plot(ds)` draws the map figure.
    """
    if isinstance(params, str) and "=" in params:  # design_map("NAME=A:B:N", "NAME=...", p)
        _deprecated('design_map("X=A:B:N", "Y=A:B:N", preset)',
                    'design_map(params, x=("X", A, B, N), y=("Y", A, B, N))')
        old_preset = y if isinstance(y, str) and "=" not in y else None
        params, x, y = None, params, x
        preset = preset or old_preset
    if preset is not None:
        if params is not None and not isinstance(params, str):
            pass  # a ready Params wins, as before
        else:
            _deprecated("design_map(..., preset=NAME)", "design_map(NAME, ...)")
            params = preset
    x, y = _map_axis(x, "x"), _map_axis(y, "y")
    if params is None or isinstance(params, str):
        base = load_params(params or DEFAULT_PRESET, config, dict(overrides))
    else:
        base = resolve_params(params, **overrides)
    from maglev_match.analyses.maps import MapSpec, compute_tile, map_dataset, parse_axis, run_map
    from maglev_match.core.datasets import annotate_map

    ax, ay = parse_axis(x, "x"), parse_axis(y, "y")
    if rows_per_tile < 1:
        raise ParameterError("rows_per_tile", rows_per_tile, "must be at least 1")
    spec = MapSpec(base=base.as_input_dict(), x=ax, y=ay, rows_per_tile=rows_per_tile,
                   ntst=ntst, simulate=simulate)
    spec.validate()
    if checkpoint is not None:
        data = run_map(spec, Path(checkpoint), resume=resume, scheduler=scheduler,
                       workers=workers, progress=progress)
    else:
        tiles = _compute_tiles(spec, compute_tile, workers, scheduler, progress)
        data = {k: np.concatenate([tiles[t][k] for t in spec.tiles], axis=0)
                for k in tiles[spec.tiles[0]]}
    return annotate_map(map_dataset(spec, data), base)


def speed_sweep(params: Params | str | None = None, *, model: str = "unit",
                speeds: Sequence[float] | None = None,
                kmh: tuple[float, float, float] = (0.0, 150.0, 5.0), critical: bool = True,
                spans: int = 40, workers: int | None = 0, scheduler: str | None = None,
                checkpoint: str | Path | None = None, resume: bool = False,
                progress: Callable[[int, int], None] | None = None,
                **overrides: Any) -> SpeedSweep:
    """The vehicle at speed over identical spans, swept over speed (`maglev-match speed`).

    At every speed the periodic response (one span passage, found as the fixed point of
    the span map), its multipliers and verdict, the gap deviation and current per
    levitation point, the mid-span deflection and DAF, the car body's peak acceleration and
    Sperling's Wz, the critical initial deflection of the span being entered and
    chi(v) = h(v) / w0; then the resonance speeds in the range and the speeds where the
    periodic response changes stability, located by solving.

    Parameters
    ----------
    params : Params | str | None
        The parameter set (see [`resolve_params`][maglev_match.api.resolve_params]).
    model : str
        `'unit'`, `'vehicle'` or `'force'` (a constant moving force).
    speeds : sequence of float, optional
        The speeds in m/s; without them, `kmh` = (from, to, step) in km/h as on the
        command line (from 0 to 150 by 5 by default; v = 0 gives the standstill values).
    critical : bool
        Compute the critical disturbance at speed (slower).
    spans : int
        Spans a disturbed run may take to return to the periodic response.
    workers, scheduler, checkpoint, resume, progress
        As for [`design_map`][maglev_match.api.design_map]: 0 computes here, n > 0 on a
        local Dask cluster, None one worker per core; `checkpoint` keeps a tile per speed
        (then `resume` reuses them).
    **overrides : float
        Parameter values applied on top.

    Returns
    -------
    SpeedSweep
        One [`SpeedPoint`][maglev_match.analyses.speed.sweep.SpeedPoint] per speed, the resonance
        speeds
        and the stability changes; `.to_xarray()` and `.plot()` give the netCDF dataset and
        the figure of the command line.
    """
    from maglev_match.analyses.speed.sweep import KMH, SpeedOptions, speeds_kmh
    from maglev_match.analyses.speed.sweep import speed_sweep as _speed_sweep

    p = resolve_params(params, **overrides)
    if speeds is None:
        speeds = list(speeds_kmh(*kmh) * KMH)
    return _speed_sweep(p, model, list(speeds), SpeedOptions(critical=critical, spans=spans),
                        checkpoint=None if checkpoint is None else Path(checkpoint),
                        resume=resume, scheduler=scheduler, workers=workers,
                        progress=progress)


def _compute_tiles(spec, compute_tile, workers, scheduler, progress) -> dict:
    """Every tile of ``spec`` in memory: here (workers == 0) or on Dask."""
    total = len(spec.tiles)
    out: dict = {}
    if progress:
        progress(0, total)
    if workers == 0 and scheduler is None:
        for t in spec.tiles:
            out[t] = compute_tile(spec, t)
            if progress:
                progress(len(out), total)
        return out
    from dask.distributed import Client, as_completed

    from maglev_match.analyses.maps import local_cluster

    cluster = None
    if scheduler is None:
        cluster = local_cluster(workers)
        client = Client(cluster)
    else:
        client = Client(scheduler)
    try:
        futures = {client.submit(compute_tile, spec, t, pure=False, retries=2): t
                   for t in spec.tiles}
        for fut in as_completed(futures):
            out[futures[fut]] = fut.result()
            if progress:
                progress(len(out), total)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    return out
