"""The public Python API: one function per analysis, re-exported at the package top level.

Every function takes the parameter set the same way:

* ``params`` — a :class:`~maglev_match.params.Params`, the name of a shipped preset
  (``"turnout-soft"``, ``"alpha1"``, ...) or ``None`` for the default preset;
* ``**overrides`` — parameter values applied on top, validated like ``--set NAME=VALUE``
  on the command line (for example ``kD=120`` or the beam data ``L=18, EI=2.0e10``, from
  which omega1 and sigma are derived).

The functions call the same library routines as the command line and return its result
objects (frozen dataclasses carrying their diagnostics). They add nothing numerical; the
methods and their sources are documented where they are implemented
(:mod:`maglev_match.dynamics`, :mod:`maglev_match.matching`, :mod:`maglev_match.maps`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from maglev_match import jax_setup  # noqa: F401  (float64 before any model is built)
from maglev_match.params import DEFAULT_PRESET, ParameterError, Params, load_params

if TYPE_CHECKING:  # pragma: no cover
    import xarray as xr

    from maglev_match.dynamics.cycles import CycleBranch
    from maglev_match.dynamics.equilibria import RootLocusResult, StabilityResult
    from maglev_match.dynamics.hopf import HopfCurve, HopfScan
    from maglev_match.dynamics.system import System
    from maglev_match.matching import MatchingIndex
    from maglev_match.simulation import MaglevSimulation

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
    "design_map",
    "MODELS",
]

MODELS = ("unit", "vehicle")
# Default search bounds of the Hopf curve, as on the command line (hopf-curve).
HOPF_CURVE_RANGES = {"omega1": (30.0, 400.0), "sigma": (1e-4, 8e-4)}
DEFAULT_PLANE = {"unit": ("omega1", "sigma"), "vehicle": ("omega1", "kD")}



def resolve_params(params: Params | str | None = None, **overrides: Any) -> Params:
    """The parameter set from a :class:`Params`, a preset name or ``None`` (the default
    preset ``turnout-soft``), with ``overrides`` applied and validated.

    Raises :class:`~maglev_match.params.ParameterError` naming the field, the value and
    the rule for an unknown name or an invalid value.
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
    """The :class:`~maglev_match.dynamics.system.System` (vector field with exact
    derivatives) of model A (``model="unit"``, 9 states) or B (``"vehicle"``, 16 + 2
    n_modes + 18 states). ``limited`` puts the current clamp into the vector field."""
    from maglev_match.models import build_system as _build

    return _build(resolve_params(params, **overrides), _check_model(model), limited=limited)


def stability(params: Params | str | None = None, *, model: str = "unit",
              **overrides: Any) -> StabilityResult:
    """Equilibrium, eigenvalues (1/s, largest real part first) and the stability verdict.

    Returns :class:`~maglev_match.dynamics.equilibria.StabilityResult`; ``margin`` is
    ``-max Re(lambda)`` in 1/s. Same computation as ``maglev-match stability``.
    """
    from maglev_match.dynamics.equilibria import stability as _stability

    return _stability(build_system(params, model, **overrides))


def root_locus(param: str, values: Sequence[float] | np.ndarray,
               params: Params | str | None = None, *, model: str = "unit",
               **overrides: Any) -> RootLocusResult:
    """Eigenvalues of the equilibrium as ``param`` runs through ``values`` (SI units of
    that parameter). Returns :class:`~maglev_match.dynamics.equilibria.RootLocusResult`;
    :func:`maglev_match.datasets.root_locus_dataset` turns it into an xarray Dataset."""
    from maglev_match.dynamics.equilibria import root_locus as _root_locus

    system = build_system(params, model, **overrides)
    _check_param(system, param, "param")
    return _root_locus(system, param, np.asarray(values, float))


def _check_param(system: System, name: str, field: str) -> None:
    if name not in system.param_names:
        raise ParameterError(field, name, "the model has no such parameter; choose one of "
                             + ", ".join(system.param_names))


def hopf_points(param: str = "omega1", start: float = 30.0, stop: float = 300.0,
                params: Params | str | None = None, *, model: str = "unit",
                n_scan: int = 200, **overrides: Any) -> HopfScan:
    """Hopf points of the equilibrium along ``param`` in [``start``, ``stop``].

    A scan of ``n_scan`` eigenvalue computations brackets each crossing of a complex pair;
    each bracket is refined by Newton's method on the Hopf defining system, and the first
    Lyapunov coefficient l1 is computed there by Kuznetsov's projection formula
    (Kuznetsov 2004, eq. 3.20). Returns :class:`~maglev_match.dynamics.hopf.HopfScan`
    (``points``: the :class:`~maglev_match.dynamics.hopf.HopfPoint` list). Same
    computation as ``maglev-match hopf``.
    """
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
    from maglev_match.params import PARAMETER_DOCS

    if name in PARAMETER_DOCS:
        params.replace(**{name: value})


def hopf_curve(params: Params | str | None = None, *, names: tuple[str, str] | None = None,
               bounds: dict[str, tuple[float, float]] | None = None, model: str = "unit",
               n_scan: int = 100, max_step: float = 1e-2,
               progress: Callable[[str], None] | None = None,
               **overrides: Any) -> list[HopfCurve]:
    """Every branch of the Hopf curve in the plane ``names`` (default (omega1, sigma) for
    model A, (omega1, kD) for model B) inside ``bounds``.

    Branches are found by Hopf-point scans of ``names[0]`` at three values of ``names[1]``
    (the middle, 10 % and 90 % of its range) and continued by pseudo-arclength on the
    standard defining system (Kuznetsov 2004, sec. 10.2; Govaerts 2000), with l1 along the
    curve and its codimension-two points (generalised Hopf with l2, Bogdanov-Takens,
    zero-Hopf, double Hopf). Default bounds: omega1 30-400 rad/s, sigma 1e-4-8e-4 1/kg,
    any other parameter 0.5-2 times its value. Returns a list of
    :class:`~maglev_match.dynamics.hopf.HopfCurve`. Same as ``maglev-match hopf-curve``.
    """
    from maglev_match.dynamics.hopf import hopf_curve as _hopf_curve
    from maglev_match.dynamics.hopf import locate_hopf_points

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
    curves: list[HopfCurve] = []
    for v2 in (a + f * (b - a) for f in (0.5, 0.1, 0.9)):
        p = system.params_with(**{names[1]: v2})
        scan = locate_hopf_points(system, names[0], *lims[names[0]], p, n_scan=n_scan)
        for hp in scan.points:
            if not hp.converged or _on_curve(hp, curves, names, system, lims):
                continue
            if progress is not None:
                progress(f"continuing the Hopf curve through {names[0]} = {hp.value:.6g}, "
                         f"{names[1]} = {v2:.6g}")
            curves.append(_hopf_curve(system, names, hp, lims, max_step=max_step))
    return curves


def _on_curve(hp, curves, names, system, bounds) -> bool:
    """Whether a Hopf point lies on a branch already computed (2 % of the plane and of
    the frequency)."""
    w = np.array([system.param(n, hp.p) for n in names])
    span = np.array([bounds[n][1] - bounds[n][0] for n in names])
    for c in curves:
        v = c.values()
        if len(v) == 0:
            continue
        d = np.min(np.hypot(*((v - w) / span).T)
                   + np.abs(c.frequency() - hp.frequency) / hp.frequency)
        if d < 2e-2:
            return True
    return False


def cycle_branch(param: str = "omega1", params: Params | str | None = None, *,
                 model: str = "unit", start: float | None = None, stop: float | None = None,
                 n_scan: int = 100, ntst: int = 80, ncol: int = 4, max_steps: int = 300,
                 ignore_current: bool = False,
                 progress: Callable[[int, Any], None] | None = None,
                 **overrides: Any) -> CycleBranch:
    """The branch of periodic orbits born at the Hopf point nearest the design value of
    ``param``, continued in ``param`` until a physical limit, a fold or ``max_steps``.

    Hopf points are searched in [``start``, ``stop``] (default: the design value / 4 to
    x 4). The orbits are solved by orthogonal collocation at Gauss points on an adaptive
    mesh (``ntst`` intervals, ``ncol`` points; de Boor & Swartz 1973, Doedel's AUTO
    notes), continued by pseudo-arclength; Floquet multipliers from the monodromy matrix
    of the condensed collocation blocks (Doedel, Keller & Kernevez 1991). Returns
    :class:`~maglev_match.dynamics.cycles.CycleBranch`. Same as ``maglev-match cycles``.
    """
    from maglev_match.dynamics.cycles import cycle_branch as _cycle_branch
    from maglev_match.dynamics.hopf import locate_hopf_points
    from maglev_match.limits_check import cycle_limit_margins

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
    """Simulate model A or B over [0, ``t_end``] s with the physical limits (current never
    reverses; leaving the gap range [gap_min, gap_max] ends the run as a collision).

    Initial state: ``initial`` ("equilibrium", or "pressed" for model B: the vehicle at
    equilibrium on the undeflected beam), then ``x5`` (model A: initial beam deflection,
    m; negative opens the gap) or ``q1`` (model B: first modal coordinate, m); ``x0`` gives
    the whole state instead. Returns :class:`~maglev_match.simulation.MaglevSimulation`
    (``outcome``: collision / converged / running / failed). Same as
    ``maglev-match simulate``; :func:`maglev_match.datasets.simulation_dataset` gives the
    history with units.
    """
    from maglev_match.dynamics.simulate import SimulationOptions
    from maglev_match.simulation import initial_state, simulate_maglev

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


def matching_index(params: Params | str | None = None, *, simulate: bool = True,
                   **overrides: Any) -> MatchingIndex:
    """The matching index chi = h / w0 of model A, with the case that decided h.

    h = 0 if the equilibrium is unstable; the maximum gap deviation of the unstable cycle
    around the stable equilibrium; or gap_max - c0 when no such cycle lies within the gap
    range. w0 = sigma (m + M) g / omega1^2 is the static beam deflection. With
    ``simulate``, h is cross-checked by simulations with the limits on
    (``h_simulation``). Returns :class:`~maglev_match.matching.MatchingIndex`. Same as
    ``maglev-match index``.
    """
    from maglev_match.matching import matching_index as _matching_index

    return _matching_index(resolve_params(params, **overrides), simulate=simulate)


def design_map(x: str = "omega1=40:190:100", y: str = "sigma=2e-4:6e-4:100",
               preset: str | None = DEFAULT_PRESET, *, params: Params | None = None,
               config: str | Path | None = None, workers: int | None = 0,
               scheduler: str | None = None, checkpoint: str | Path | None = None,
               resume: bool = False, rows_per_tile: int = 2, ntst: int = 30,
               progress: Callable[[int, int], None] | None = None,
               **overrides: Any) -> xr.Dataset:
    """Stability, h, w0 and chi over a grid of two parameters, as an xarray Dataset.

    Parameters
    ----------
    x, y : the axes, ``NAME=START:STOP:COUNT`` as on the command line (``--x``/``--y``);
        NAME is any parameter, including the beam data L, EI, mbar, l, k.
    preset, config, overrides : the base point (preset, then a TOML file, then
        NAME=VALUE overrides), as ``--preset``/``--config``/``--set``; or ``params``, a
        ready :class:`Params` (then ``preset`` and ``config`` are ignored).
    workers : 0 (default) computes in this process; n > 0 starts a local Dask cluster
        of n single-threaded worker processes; None uses one per core.
    scheduler : address of an existing Dask scheduler (``tcp://host:port``).
    checkpoint : optional folder for tiles (then ``resume`` reuses finished ones); without
        it the map is assembled in memory and nothing is written.
    rows_per_tile, ntst : tile height (rows) and collocation intervals for the cycles.
    progress : called as ``progress(done_tiles, total_tiles)``.

    Returns
    -------
    xarray.Dataset
        The map of :func:`maglev_match.maps.map_dataset` (dimensions named after the two
        parameters, y first) with long names, the base parameter set and the package
        version as attributes; equal, value for value, to the netCDF file that
        ``maglev-match map`` writes for the same grid.
    """
    from maglev_match.datasets import annotate_map
    from maglev_match.maps import MapSpec, compute_tile, map_dataset, parse_axis, run_map

    if params is not None:
        base = resolve_params(params, **overrides)
    else:
        base = load_params(preset, config, dict(overrides))
    ax, ay = parse_axis(x, "x"), parse_axis(y, "y")
    if rows_per_tile < 1:
        raise ParameterError("rows_per_tile", rows_per_tile, "must be at least 1")
    spec = MapSpec(base=base.as_input_dict(), x=ax, y=ay, rows_per_tile=rows_per_tile,
                   ntst=ntst)
    spec.validate()
    if checkpoint is not None:
        data = run_map(spec, Path(checkpoint), resume=resume, scheduler=scheduler,
                       workers=workers, progress=progress)
    else:
        tiles = _compute_tiles(spec, compute_tile, workers, scheduler, progress)
        data = {k: np.concatenate([tiles[t][k] for t in spec.tiles], axis=0)
                for k in tiles[spec.tiles[0]]}
    return annotate_map(map_dataset(spec, data), base)


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
    import os

    from dask.distributed import Client, LocalCluster, as_completed

    from maglev_match.maps import SINGLE_THREADED_ENV

    cluster = None
    if scheduler is None:
        cluster = LocalCluster(n_workers=workers or os.cpu_count() or 1, threads_per_worker=1,
                               processes=True, dashboard_address=None,
                               env=SINGLE_THREADED_ENV)
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
