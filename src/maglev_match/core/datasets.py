"""xarray forms of the results that are not continuation branches, self-describing on disk.

Every data variable and coordinate gets ``units`` (SI, as in the rest of the package) and a
``long_name``; every dataset gets the parameter set it was computed with (``params``, a JSON
object of every value including the derived ones) and the package version
(``maglev_match_version``) as attributes. This follows the CF conventions' use of
``units``/``long_name`` so that tools such as ``ncdump``, xarray and Panoply label axes
without the package.

* `simulation_dataset`: a simulated run: states, gaps, gap rates, coil currents and beam
  deflection against time;
* `root_locus_dataset`: eigenvalues of the equilibrium along one parameter;
* `annotate_map`: the design map of `maglev_match.analyses.maps.map_dataset`;
* `annotate`: the general helper the others use.
"""

from __future__ import annotations

import json
import re
from typing import TYPE_CHECKING, Any

import numpy as np

from maglev_match.core.params import PARAMETER_DOCS, Params

if TYPE_CHECKING:  # pragma: no cover
    import xarray as xr

# This module annotates results; it imports no module that computes them (the simulation
# imports it, never the other way round; the numerics layer does not import it at all).

__all__ = ["annotate", "annotate_map", "annotate_history", "simulation_dataset",
           "root_locus_dataset",
           "state_units", "LONG_NAMES", "UNITS"]

# long names of variables shared by several datasets
LONG_NAMES: dict[str, str] = {
    # design map
    "chi": "matching index chi = h / w0",
    "h": "basin size along the gap: largest gap deviation the equilibrium survives",
    "w0": "static beam deflection under one levitation unit",
    "stable": "equilibrium stable (1) or unstable (0)",
    "max_real_part": "largest real part of the eigenvalues of the equilibrium",
    "hopf_distance": "distance to the Hopf point used for h, along the x parameter",
    "case": "case that decided h (codes in the case_codes attribute)",
    "omega1_point": "beam first modal circular frequency at the grid point",
    "sigma_point": "force gain coefficient at the grid point",
    "current_reverses": "coil current on the deciding cycle would reverse (1) or not (0)",
    "resolved": "point resolved (1) or continuation failed (0)",
    "reason": "why the point is unresolved (0: resolved; codes in the reason_codes attribute)",
    # simulation
    "time": "time",
    "point": "levitation point number (1-based)",
    "mode": "beam mode number",
    "gap": "air gap between magnet and rail",
    "gap_deviation": "gap deviation from the rated gap c - c0",
    "gap_rate": "gap rate dc/dt",
    "current": "coil current (force-producing, max(i, 0) with the limits on)",
    "beam_deflection": "beam deflection (model A: equivalent deflection w; model B: modal "
                       "coordinates q_n)",
    # root locus
    "eigenvalue_real": "real part of the eigenvalue",
    "eigenvalue_imag": "imaginary part of the eigenvalue",
    "equilibrium_converged": "Newton's method converged at the equilibrium (1) or not (0)",
    "equilibrium": "equilibrium state",
    "index": "eigenvalue number, largest real part first",
    "state": "state name",
}
UNITS: dict[str, str] = {
    "time": "s", "point": "1", "mode": "1", "gap": "m", "gap_deviation": "m",
    "gap_rate": "m/s", "current": "A", "beam_deflection": "m", "eigenvalue_real": "1/s",
    "eigenvalue_imag": "rad/s", "max_real_part": "1/s", "equilibrium_converged": "1",
    "index": "1", "chi": "1", "h": "m", "w0": "m",
}

# states of model A (models/unit.py) and their meaning
_UNIT_STATES = {
    "z1": ("m", "levitation-frame displacement z1 (down positive)"),
    "z1_dot": ("m/s", "levitation-frame velocity z1'"),
    "z2": ("m", "car-body displacement z2 (down positive)"),
    "z2_dot": ("m/s", "car-body velocity z2'"),
    "w": ("m", "equivalent beam deflection w under the unit"),
    "w_dot": ("m/s", "beam deflection rate w'"),
    "di": ("A", "coil current deviation i - i0"),
    "y1": ("m", "observer output y1 (gap estimate)"),
    "v": ("m/s", "observer output y2 - z1' (velocity estimate)"),
}


def state_units(name: str) -> tuple[str, str]:
    """(unit, long name) of a state of model A or B, by its name in the model."""
    if name in _UNIT_STATES:
        return _UNIT_STATES[name]
    body = {"0": "car body", "1": "frame 1", "2": "frame 2", "3": "frame 3"}
    if m := re.fullmatch(r"z(\d)(_dot)?", name):
        return ("m/s", f"vertical velocity of the {body[m[1]]}") if m[2] else \
            ("m", f"vertical displacement of the {body[m[1]]} (down positive)")
    if m := re.fullmatch(r"th(\d)(_dot)?", name):
        return ("rad/s", f"pitch rate of the {body[m[1]]}") if m[2] else \
            ("rad", f"pitch angle of the {body[m[1]]}")
    if m := re.fullmatch(r"q(\d+)(_dot)?", name):
        return ("m/s", f"rate of beam modal coordinate {m[1]}") if m[2] else \
            ("m", f"beam modal coordinate q{m[1]} (undeflected beam = 0)")
    if m := re.fullmatch(r"i(\d)", name):
        return "A", f"coil current of levitation point {m[1]}"
    if m := re.fullmatch(r"y1_(\d)", name):
        return "m", f"observer output y1 of levitation point {m[1]}"
    if m := re.fullmatch(r"v(\d)", name):
        return "m/s", f"observer velocity estimate of levitation point {m[1]}"
    return "", name


def _version() -> str:
    from maglev_match import __version__

    return __version__


def annotate(ds: xr.Dataset, params: Params | None = None, *,
             units: dict[str, str] | None = None,
             long_names: dict[str, str] | None = None) -> xr.Dataset:
    """Give every data variable and coordinate of ``ds`` a ``units`` and a ``long_name``
    (keeping those already set), and the parameter set and package version as attributes.

    Lookup order: ``units``/``long_names`` given here, then the tables of this module,
    then the parameter table (for coordinates named after a parameter). A variable left
    without either raises ``ValueError``, so a writer cannot ship an undocumented field.
    Returns ``ds`` (modified in place).
    """
    units = {**UNITS, **(units or {})}
    long_names = {**LONG_NAMES, **(long_names or {})}
    for name in list(ds.data_vars) + list(ds.coords):
        var = ds[name]
        key = str(name)
        unit, meaning = PARAMETER_DOCS.get(key, ("", ""))
        if "units" not in var.attrs:
            var.attrs["units"] = units.get(key, unit)
        if not var.attrs.get("long_name"):
            var.attrs["long_name"] = long_names.get(key, meaning)
        if var.attrs["units"] in ("", "-"):
            var.attrs["units"] = "1"  # dimensionless (CF convention)
        if not var.attrs["long_name"]:
            raise ValueError(f"no long name for variable '{key}'")
    ds.attrs["maglev_match_version"] = _version()
    if params is not None:
        ds.attrs["params"] = json.dumps({k: _plain(v) for k, v in params.as_dict().items()})
    return ds


def _plain(v: Any) -> Any:
    if isinstance(v, np.generic):
        return v.item()
    return v


def annotate_map(ds: xr.Dataset, params: Params) -> xr.Dataset:
    """The design map with long names, units, the base parameter set and the version."""
    return annotate(ds, params)


def simulation_dataset(sim: Any) -> xr.Dataset:
    """A simulated run (a :class:`~maglev_match.analyses.simulation.MaglevSimulation`) as an
    :class:`xarray.Dataset` with units and long names: ``sim.to_xarray()``, which builds
    the history and annotates it with :func:`annotate_history`.

    Variables: every state (SI units), ``gap``, ``gap_deviation``, ``gap_rate`` and
    ``current`` per levitation point, ``beam_deflection``; attributes: outcome, collision
    time/limit/point, model, horizon, gap limits, the parameter set and the version.
    """
    return sim.to_xarray()


def annotate_history(ds: xr.Dataset, sim: Any, title: str) -> xr.Dataset:
    """The history dataset of a simulated run (``simulation.history_dataset``) with units,
    long names, the ``title``, the parameter set and the version."""
    extra_u, extra_l = {}, {}
    for name in ds.data_vars:
        if name in UNITS:
            continue
        u, lname = state_units(str(name))
        extra_u[str(name)], extra_l[str(name)] = u, lname
    ds.attrs["title"] = title
    return annotate(ds, sim.params, units=extra_u, long_names=extra_l)


def root_locus_dataset(res: Any, params: Params | None = None,
                       state_names: tuple[str, ...] | None = None) -> xr.Dataset:
    """A root locus (:class:`~maglev_match.dynamics.equilibria.RootLocusResult`) as an
    :class:`xarray.Dataset` over (parameter value, eigenvalue index): its own
    ``to_xarray`` (``eigenvalue_real`` (1/s), ``eigenvalue_imag`` (rad/s),
    ``max_real_part``, ``equilibrium_converged`` and, with ``state_names``, the equilibrium
    states), annotated with the parameter set."""
    return annotate(res.to_xarray(params, state_names), params)
