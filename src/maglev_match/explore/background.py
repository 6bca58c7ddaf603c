"""What the explorer's background tier computes (in its child process, :mod:`.jobs`),
each through :mod:`maglev_match.api`, as JSON-ready dicts for the page; the result's own
``.to_xarray()`` goes with it as netCDF bytes under :data:`NETCDF` (the export).

* ``hopf_curve``: the Hopf curve(s) in the model's default plane (`api.hopf_curve`);
* ``tile``: a small map of the headline index (`api.design_map`, simulated part
  included) in the (omega1, sigma) plane around the design, from which the page
  interpolates chi while a slider moves;
* ``speed``: the vehicle at speed over identical spans (`api.speed_sweep`): chi(v),
  DAF and Sperling's Wz against speed, with the standstill headline;
* ``cycle_branch``: the branch of periodic orbits born at the Hopf point nearest the
  design along omega1 (`api.cycle_study`), with stability and AUTO labels."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

__all__ = ["KINDS", "NETCDF", "TILE_POINTS", "TILE_SPAN", "SPEED_STEPS", "V_MIN", "V_MAX",
           "check_speed", "hopf_curve_job", "tile_job", "speed_job", "cycle_branch_job"]

#: the key of a result's netCDF bytes (taken out before the result goes to the page)
NETCDF = "_netcdf"
#: points of the map tile per axis, and its half-width (relative) around the design: a
#: 5 x 5 headline tile costs about 8 s warm on a quiet 2-core machine (bench_explore.py)
TILE_POINTS = 5
TILE_SPAN = 0.15
#: the speed sweep: from standstill to the page's speed v in this many steps
SPEED_STEPS = 3
#: the page's speed v (km/h): 0 (standstill) or from V_MIN (the sweep's steps v / 3 then
#: are at least `speed`'s slowest 1 km/h) to `speed`'s fastest 900 km/h
V_MIN, V_MAX = 3.0, 900.0
#: the cycle branch's continuation steps and mesh (coarser than `cycles`' default)
BRANCH_STEPS = 60
BRANCH_NTST = 40


def _f(v: Any) -> float | None:
    v = float(v)
    return v if math.isfinite(v) else None


def _netcdf(ds: Any) -> bytes:
    from maglev_match.core.io import netcdf_bytes

    return netcdf_bytes(ds)


def hopf_curve_job(params: Any, model: str, say: Callable[[str], None]) -> dict[str, Any]:
    """The Hopf curve(s) in the model's default plane (`api.hopf_curve`), as JSON-ready
    branches: the two parameters along each branch, l1 along it (l1 > 0 subcritical,
    drawn dashed; l1 < 0 supercritical, solid), and its codimension-two points with their
    AUTO/MatCont labels. netCDF: the first branch's dataset (`curve_dataset(0)`)."""
    import numpy as np

    from maglev_match import api

    say("continuing the Hopf curve ...")
    st = api.hopf_curve(params, model=model, stage=say, study=True)
    curves = st.curves
    branches = []
    for c in curves:
        vals = np.asarray(c.values(), float)
        branches.append({
            "params": list(c.params), "x": vals[:, 0].tolist(), "y": vals[:, 1].tolist(),
            "l1": np.asarray(c.l1(), float).tolist(), "converged": bool(c.converged),
            "message": c.message,
            "special": [{"label": sp.label, "type": str(sp.type),
                         "x": float(sp.values[0]), "y": float(sp.values[1])}
                        for sp in c.special_points if getattr(sp, "values", None) is not None],
        })
    names = branches[0]["params"] if branches else []
    design = [float(getattr(params, n)) for n in names] if names else []
    out: dict[str, Any] = {"branches": branches, "names": names, "design": design}
    if branches:
        out[NETCDF] = _netcdf(st.to_xarray())
    return out


def tile_axes(params: Any) -> tuple[tuple[str, float, float, int], tuple[str, float, float,
                                                                          int]]:
    """The tile's axes: omega1 and sigma each +-TILE_SPAN around the design."""
    w, s = float(params.omega1), float(params.sigma)
    return (("omega1", w * (1 - TILE_SPAN), w * (1 + TILE_SPAN), TILE_POINTS),
            ("sigma", s * (1 - TILE_SPAN), s * (1 + TILE_SPAN), TILE_POINTS))


def tile_job(params: Any, model: str, say: Callable[[str], None]) -> dict[str, Any]:
    """The headline index over a TILE_POINTS x TILE_POINTS grid in (omega1, sigma) around
    the design (`api.design_map` with its simulated part; the map's own spot check on one
    point). chi is NaN (None) where the design is unstable or the point unresolved."""
    import numpy as np

    from maglev_match import api

    x, y = tile_axes(params)
    n = TILE_POINTS
    ds = api.design_map(params, x=x, y=y, model=model, rows_per_tile=1, check_fraction=0.0,
                        progress=lambda done, total: say(f"map tile: row {done} of {total}"),
                        stage=say)
    chi = np.asarray(ds["chi"].values, float)
    return {"names": ["omega1", "sigma"],
            "x": np.linspace(x[1], x[2], n).tolist(), "y": np.linspace(y[1], y[2], n).tolist(),
            "chi": [[_f(v) for v in row] for row in chi],
            "resolved": int(np.isfinite(chi).sum()), "points": int(chi.size),
            "design": [float(params.omega1), float(params.sigma)],
            "warnings": list(api.map_warnings(ds)), NETCDF: _netcdf(ds)}


def check_speed(v: float) -> float:
    """The page's speed v (km/h), checked (a ParameterError naming ``v``)."""
    from maglev_match.core.params import ParameterError

    if not math.isfinite(v):
        raise ParameterError("v", v, "must be a finite number (km/h)")
    if not (v == 0 or V_MIN <= v <= V_MAX):
        raise ParameterError("v", v, f"must be 0 (standstill) or from {V_MIN:g} to "
                             f"{V_MAX:g} km/h")
    return v


def speed_job(params: Any, model: str, say: Callable[[str], None], v: float = 0.0
              ) -> dict[str, Any]:
    """The vehicle at speed over identical spans (`api.speed_sweep`) up to the page's speed
    v (km/h): the sweep 0, v/3, 2v/3, v without the index at speed (DAF, Sperling's Wz, the
    verdict of the periodic response), then the index chi(v) at v with the standstill
    headline of the same sweep (`critical=True` at v alone: the slow part)."""
    from maglev_match import api

    kmh = [check_speed(float(v)) * k / SPEED_STEPS for k in range(SPEED_STEPS + 1)]
    say(f"periodic response at {', '.join(f'{x:g}' for x in kmh)} km/h ...")
    sw = api.speed_sweep(params, model=model, speeds=[x / 3.6 for x in kmh], critical=False,
                         progress=lambda done, total: say(f"speed {done} of {total}"))
    say(f"the index at {v:g} km/h and at standstill ...")
    at = api.speed_sweep(params, model=model, speeds=[kmh[-1] / 3.6], critical=True)
    pv, stand = at.points[0], at.standstill or {}
    pts = sw.points
    return {"kmh": [p.speed * 3.6 for p in pts], "daf": [_f(p.daf) for p in pts],
            "wz": [_f(p.wz) for p in pts], "stable": [p.stable for p in pts],
            "converged": [bool(p.converged) for p in pts],
            "v": float(v), "chi_v": _f(pv.chi), "daf_v": _f(pv.daf), "wz_v": _f(pv.wz),
            "stable_v": pv.stable, "standstill_chi": _f(stand.get("chi", math.nan)),
            "warnings": list(sw.warnings) + list(at.warnings),
            NETCDF: _netcdf(sw.to_xarray())}


def cycle_branch_job(params: Any, model: str, say: Callable[[str], None]) -> dict[str, Any]:
    """The branch of periodic orbits from the Hopf point nearest the design along omega1
    (`api.cycle_study`): the gap deviation's largest size (max |gap - c0|) against omega1,
    stable or not, and the special points with their AUTO labels (LPC, PD, NS, BP and the
    contacts with a limit)."""
    from maglev_match import api

    say("searching the Hopf point along omega1 and continuing its cycles ...")
    study = api.cycle_study(params, "omega1", model=model, ntst=BRANCH_NTST,
                            max_steps=BRANCH_STEPS,
                            progress=lambda step, c: say(f"cycle branch: step {step}"))
    if not study.branches:
        return {"param": "omega1", "points": [], "special": [], "hopf": None,
                "message": "no Hopf point along omega1 near the design"}
    rows = study.branch_rows(0)
    pts = [{"x": r["omega1"], "size": max(abs(r["gap_dev_max"]), abs(r["gap_dev_min"])),
            "stable": bool(r["stable"]), "period": r["period"]} for r in rows]
    special = [{"x": r["omega1"], "size": max(abs(r["gap_dev_max"]), abs(r["gap_dev_min"])),
                "label": r["label"], "type": str(r["type"])} for r in study.special_rows(0)]
    h = study.chosen[0] if study.chosen else None
    return {"param": "omega1", "points": pts, "special": special,
            "hopf": None if h is None else {"x": float(h.value), "label": "H"},
            "design": float(params.omega1), "message": "",
            NETCDF: _netcdf(study.branch_dataset(0))}


#: the kinds of background job: name -> function(params, model, say) -> JSON-ready dict
KINDS: dict[str, Callable[..., dict[str, Any]]] = {
    "hopf_curve": hopf_curve_job, "tile": tile_job, "speed": speed_job,
    "cycle_branch": cycle_branch_job}
