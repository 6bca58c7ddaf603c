"""What the explorer computes for a design, through :mod:`maglev_match.api` only, in the
server's one long-lived process (the compiled kernels stay warm; no recompilation when a
slider moves).

Two tiers run here:

* :meth:`Session.quick` (a slider moves): the equilibrium, its eigenvalues and the
  stability margin (`api.stability`), with the last released index shown beside it and
  marked as such;
* :meth:`Session.release` (the slider is let go): the headline index at that exact design
  (`api.matching_index`), warm-started from the previous release (``near=``: each solved
  critical disturbance continued, not searched again), with the basin-bounding cycle
  (gap deviation over one period) and the critical disturbed run (gap and current against
  time, just below the critical size of the deciding direction).

The background tier (Hopf curve) runs in a separate process (:mod:`.jobs`)."""

from __future__ import annotations

import math
import tempfile
import threading
from pathlib import Path
from typing import Any

import numpy as np

from maglev_match.explore.inputs import State, controls_json, params_of

__all__ = ["Session", "finite"]

#: fraction of the critical size at which the critical run is drawn (it just returns)
BELOW_CRITICAL = 1.0 - 1e-3
#: points of the cycle's gap deviation over one period
CYCLE_POINTS = 201


def finite(v: Any) -> Any:
    """JSON-safe numbers: NaN and infinities become None (JSON has no NaN), recursively."""
    if isinstance(v, dict):
        return {k: finite(x) for k, x in v.items()}
    if isinstance(v, list | tuple):
        return [finite(x) for x in v]
    if isinstance(v, np.ndarray):
        return finite(v.tolist())
    if isinstance(v, np.generic):
        v = v.item()
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


class Session:
    """The explorer's computations for one model; the last released index is kept as the
    warm start of the next release. Thread-safe (one computation at a time)."""

    def __init__(self, model: str = "unit") -> None:
        from maglev_match.maglev.catalog import model_info

        self.model = model_info(model).name
        self._lock = threading.Lock()
        self._last: Any = None  # the MatchingIndex of the last release
        self._last_state: State | None = None
        self._last_run: Any = None

    # ----- tier (a): a slider moves -----------------------------------------------------
    def quick(self, state: State) -> dict[str, Any]:
        """Equilibrium, eigenvalues and margin at the state (no index computed)."""
        from maglev_match import api

        params = params_of(state)
        with self._lock:
            st = api.stability(params, model=self.model)
            last = self._last
        eig = np.asarray(st.eigenvalues)
        out = {"stable": bool(st.stable), "margin": float(st.margin),
               "max_real_part": float(st.max_real_part),
               "eigenvalues": [[float(z.real), float(z.imag)] for z in eig],
               "omega1": float(params.omega1), "sigma": float(params.sigma),
               "w0": float(params.w0), "warnings": list(st.warnings),
               "controls": controls_json(state)}
        if last is not None:
            out["last_release"] = {"chi": float(last.chi), "hopf_param": last.hopf_param,
                                   "hopf_value": last.hopf_value,
                                   "note": "at the last released design, not this one"}
        return finite(out)

    # ----- tier (b): release ------------------------------------------------------------
    def release(self, state: State) -> dict[str, Any]:
        """The headline index at the state, warm-started from the previous release, with
        the cycle and the critical run."""
        from maglev_match import api

        params = params_of(state)
        with self._lock:
            near = self._last
            warm = "continued from the previous design" if near is not None else "cold"
            try:
                res = api.matching_index(params, model=self.model, stage=False, near=near)
            except Exception as e:  # noqa: BLE001 - the warm start failed: say so, go cold
                if near is None:
                    raise
                warm = f"the warm start failed ({type(e).__name__}: {e}); computed cold"
                res = api.matching_index(params, model=self.model, stage=False)
            self._last, self._last_state = res, state
            cycle = self._cycle_curve(res, params)
            run = self._critical_run(res, params)
        data = res.as_json()
        sim = data.get("simulation") or {}
        continuation = {k: (sim.get(k) or {}).get("continuation") for k in ("up", "down")
                        if isinstance(sim.get(k), dict)}
        return finite({"index": data, "warm_start": warm, "continuation": continuation,
                       "cycle": cycle, "run": run, "controls": controls_json(state),
                       "limits": {"gap_min": float(params.gap_min),
                                  "gap_max": float(params.gap_max), "c0": float(params.c0)}})

    def last_index(self) -> Any:
        return self._last

    def _cycle_curve(self, res: Any, params: Any) -> dict[str, Any] | None:
        """The basin-bounding cycle's gap deviation (gap - c0, m) over one period: the
        levitation point of the largest deviation."""
        from maglev_match import api

        cyc = getattr(res, "cycle", None)
        if cyc is None or getattr(cyc, "orbit", None) is None:
            return None
        import jax

        orbit = cyc.orbit
        s = np.linspace(0.0, 1.0, CYCLE_POINTS)
        x = orbit.evaluate(s)
        studied = api.resolve_model(params, self.model)
        gap = np.asarray(jax.vmap(studied.maglev.gap(), in_axes=(0, None))(
            x, np.asarray(orbit.p, float)))
        dev = gap.reshape(len(s), -1) - float(params.c0)
        j = int(np.argmax(np.max(np.abs(dev), axis=0)))
        return {"t": (s * float(orbit.period)).tolist(), "gap_deviation": dev[:, j].tolist(),
                "period": float(orbit.period), "stable": bool(cyc.stable),
                "point": j + 1, "kind": str(cyc.kind)}

    def _critical_run(self, res: Any, params: Any) -> dict[str, Any] | None:
        """The run just below the critical size of the direction with the smaller critical
        disturbance (the one chi_simulation reads), with the physical limits."""
        from maglev_match import api

        crits = [c for c in (getattr(res, "critical_up", None),
                             getattr(res, "critical_down", None))
                 if c is not None and c.size is not None and math.isfinite(c.size)]
        if not crits:
            self._last_run = None
            return None
        crit = min(crits, key=lambda c: c.size)
        studied = api.resolve_model(params, self.model)
        line = studied.maglev.disturbance(int(crit.direction))
        size = BELOW_CRITICAL * float(crit.size)
        x0 = np.asarray(line.x0_of(np.array([size])))[0]
        t_star = crit.t_star if crit.t_star is not None else 0.1
        t_end = float(min(2.0, max(0.3, 4.0 * t_star)))
        sim = api.simulate(params, model=self.model, x0=x0, t_end=t_end, n_save=801)
        self._last_run = sim
        ds = sim.to_xarray()
        dev = np.asarray(ds["gap_deviation"].values)
        j = int(np.argmax(np.max(np.abs(dev), axis=0)))
        return {"t": ds["time"].values.tolist(), "gap": ds["gap"].values[:, j].tolist(),
                "current": ds["current"].values[:, j].tolist(), "point": j + 1,
                "size": size, "critical_size": float(crit.size),
                "direction": line.label, "mechanism": crit.mechanism,
                "outcome": sim.outcome}

    # ----- exports ----------------------------------------------------------------------
    def netcdf(self, kind: str) -> bytes:
        """The last release's index (``index``) or critical run (``run``) as netCDF-4
        bytes: the result object's ``.to_xarray()``."""
        with self._lock:
            obj = {"index": self._last, "run": self._last_run}.get(kind)
            if obj is None:
                raise LookupError(f"no {kind} result yet: release a design first")
            from maglev_match.core.io import netcdf_bytes

            return netcdf_bytes(obj.to_xarray())

    def figure(self, kind: str, fmt: str) -> bytes:
        """The product's own figure of the last release (``index``: the index result's
        ``.plot()``; ``run``: the critical run's ``.plot()``) as PNG or SVG bytes."""
        with self._lock:
            obj = {"index": self._last, "run": self._last_run}.get(kind)
            if obj is None:
                raise LookupError(f"no {kind} figure yet: release a design first")
            with tempfile.TemporaryDirectory() as tmp:
                path = Path(tmp) / f"{kind}.{fmt}"
                obj.plot(path)
                return path.read_bytes()
