"""Curves of cycle bifurcations in two parameters (`maglev-match cycle-curve`): the fold of
cycles (LPC) or the period doubling (PD) continued in a plane (x, y), for the maglev models
and user model files.

The start is decided here, once: either a branch of cycles along x at the given values
(:func:`~maglev_match.api.cycles.cycle_study`: the Hopf point nearest the design value,
the branch, its first special point of the kind, or the one named by ``label``), or a
saved branch and the label of its special point (``restart``, ``label``; no Hopf search,
the saved model, mesh and values). The curve itself is
:func:`~maglev_match.dynamics.cycle_curves.cycle_curve` (a minimally augmented collocation
system; its docstring gives the method).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from maglev_match.core.params import ParameterError, Params
from maglev_match.core.results import Plottable

__all__ = ["cycle_curve", "CycleCurveStudy"]

KINDS = ("LPC", "PD")


@dataclass(frozen=True)
class CycleCurveStudy(Plottable):
    """A curve of cycle bifurcations and where it started.

    model : 'unit', 'vehicle' or a user model file's name; kind : 'LPC' or 'PD';
    x, y : the plane's parameters (the curve's p1, p2); at : values fixed with them;
    curve : the :class:`~maglev_match.dynamics.cycle_curves.CycleCurve`;
    start_label : the special point it started from; start_branch : the one-parameter
    branch it was located on (None for a restart); restart_of : 'LABEL of FILE' for a
    restart; elapsed : seconds.
    """

    model: str
    kind: str
    x: str
    y: str
    at: Mapping[str, float]
    curve: Any
    start_label: str
    start_branch: Any = None
    restart_of: str = ""
    elapsed: float = 0.0
    is_user: bool = False
    params: Params | None = field(default=None, repr=False, compare=False)

    @property
    def warnings(self) -> tuple[str, ...]:
        return tuple(self.curve.warnings)

    @property
    def ok(self) -> bool:
        return bool(self.curve.ok)

    def rows(self) -> list[dict[str, Any]]:
        """One row per curve point: x, y, period, amplitude, extrema, the largest
        non-critical multiplier, reliability, kind."""
        import numpy as np

        out = []
        for c in self.curve.points:
            r: dict[str, Any] = {self.x: c.values[0], self.y: c.values[1], "period": c.period,
                                 "amplitude": c.amplitude}
            for name, (hi, lo) in c.extrema.items():
                r[f"{name}_max"], r[f"{name}_min"] = hi, lo
            r["max_abs_multiplier"] = float(np.max(np.abs(c.multipliers))) \
                if c.multipliers.size else float("nan")
            r["reliable"] = c.reliable
            r["kind"] = c.kind
            out.append(r)
        return out

    def special_rows(self) -> list[dict[str, Any]]:
        return [{"label": s.label, "type": s.type, self.x: s.values[0], self.y: s.values[1],
                 "period": s.period, "located": s.located, "detail": s.detail}
                for s in self.curve.special_points]

    def as_json(self) -> dict[str, Any]:
        cv = self.curve
        return {"model": self.model, "kind": self.kind, "params": [self.x, self.y],
                "at": dict(self.at), "start": self.start_label,
                **({"restart_of": self.restart_of} if self.restart_of else {}),
                "points": self.rows(), "special_points": self.special_rows(),
                "stopped_reason": cv.stopped_reason, "message": cv.message,
                "ok": cv.ok, "steps": cv.steps, "rejected_steps": cv.rejected_steps,
                "newton_iterations": cv.newton_iterations,
                "mesh": {"ntst": cv.ntst, "ncol": cv.ncol},
                "warnings": list(cv.warnings), "elapsed_s": self.elapsed}

    def to_xarray(self) -> Any:
        """The curve as an annotated dataset (units of the maglev parameters)."""
        units = {}
        if not self.is_user:
            from maglev_match.core.units import unit

            units = {n: unit(n) for n in (self.x, self.y)}
            units.update({"gap_deviation": "m", "current": "A"})
        ds = self.curve.to_xarray(units)
        ds.attrs.update({"model": self.model, "start": self.start_label,
                         "restart_of": self.restart_of,
                         "at": ", ".join(f"{k}={v:g}" for k, v in self.at.items())})
        return ds


def _check_bounds(bounds: Mapping[str, Any] | None, x: str, y: str
                  ) -> dict[str, tuple[float, float]]:
    import math

    out = {}
    for name, pair in (bounds or {}).items():
        if name not in (x, y):
            raise ParameterError("bounds", name, f"a range is given for the curve's "
                                 f"parameters only ({x}, {y})")
        try:
            lo, hi = (float(v) for v in pair)
        except (TypeError, ValueError):
            raise ParameterError("bounds", pair, f"the range of {name} must be two numbers "
                                 "(low, high)") from None
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
            raise ParameterError("bounds", f"{name}={lo:g}:{hi:g}", "must be finite with "
                                 "low < high")
        out[name] = (lo, hi)
    return out


def cycle_curve(params: Params | str | None = None, kind: str = "LPC", x: str = "omega1",
                y: str = "sigma", *, model: str = "unit", at: Mapping[str, Any] | None = None,
                bounds: Mapping[str, tuple[float, float]] | None = None,
                label: str | None = None, restart: str | Path | None = None,
                start: float | None = None, stop: float | None = None,
                ntst: int | None = None, ncol: int | None = None, max_steps: int = 200,
                marks: Sequence[float] = (), ignore_current: bool = True,
                config: str | Path | None = None,
                stage: Callable[[str], None] | None = None,
                **overrides: Any) -> CycleCurveStudy:
    """The fold of cycles (`kind="LPC"`) or period doubling (`"PD"`) continued in the
    plane (`x`, `y`) (`maglev-match cycle-curve`), both ways from its start.

    Parameters
    ----------
    params : Params | str | None
        The parameter set (see [`resolve_params`][maglev_match.api.inputs.resolve_params]).
    kind : str
        "LPC" or "PD".
    x, y : str
        The curve's parameters: cycles are continued in `x` at the given `y` to locate the
        start, then the curve in (`x`, `y`).
    model : str
        `"unit"`, `"vehicle"` or a user model file `FILE.py`.
    at : mapping, optional
        Values fixed with the others (e.g. `{"sigma": 4e-4}`: the start's `y`).
    bounds : dict, optional
        `{name: (low, high)}` for `x` and/or `y`: the curve ends on them (a point solved
        on the bound). Default: `y` within 0.5 to 2 times its start value.
    label : str, optional
        The special point to start from (default: the first of `kind` on the branch, e.g.
        LPC1); with `restart`, required.
    restart : str or Path, optional
        A branch file written by `cycles --out`: start from its special point `label`
        (no Hopf search; the saved model, mesh and values).
    start, stop : float, optional
        Where the Hopf point of the start branch is searched along `x` (as `cycles
        --from/--to`).
    ntst, ncol : int, optional
        The start branch's mesh (default 80, 4); the curve keeps it.
    max_steps : int
        Continuation steps each way.
    marks : sequence of float
        Values of `y` at which a point is solved exactly on the curve (kind "mark").
    ignore_current : bool
        The start branch does not stop where the coil current reaches zero (default True:
        a fold of the basin-bounding cycle usually lies beyond it); the maglev models only.
    config : str or Path, optional
        A TOML file applied on top of the preset.
    stage : callable, optional
        Called with a line of text when a stage starts.
    **overrides : float
        Parameter values applied on top.

    Returns
    -------
    CycleCurveStudy
        The curve (points, special points CPC/LPPD/LPNS or LPPD/PDNS, why it stopped, its
        warnings), its table (`rows`, `special_rows`, `as_json`), `.to_xarray()` and
        `.plot()`. A numerical failure is reported in the curve, not raised.
    """
    import numpy as np

    from maglev_match.dynamics.cycle_curves import cycle_curve as _cycle_curve

    say = stage or (lambda text: None)
    kind = str(kind).upper()
    if kind not in KINDS:
        raise ParameterError("kind", kind, f"must be one of {', '.join(KINDS)}")
    if x == y:
        raise ParameterError("x/y", f"{x},{y}", "the curve's two parameters must differ")
    if not (isinstance(max_steps, int) and max_steps >= 1):
        raise ParameterError("max_steps", max_steps, "must be an integer >= 1")
    bnds = _check_bounds(bounds, x, y)
    t0 = time.perf_counter()
    if restart is not None:
        if label is None:
            raise ParameterError("restart/label", restart, "a restart needs the label of a "
                                 f"special point of the saved branch (e.g. {kind}1)")
        saved_type = str(label).rstrip("0123456789")
        if saved_type in ("LPC", "PD", "NS", "BP") and saved_type != kind:
            raise ParameterError("label", label, f"{label} is a {saved_type}; a {kind} curve "
                                 f"starts from a {kind} (e.g. {kind}1) or a branch point P<k> "
                                 "at one")
        system, orbit, studied_label, is_user, prm, at_used = _from_file(
            params, model, restart, label, at, config, overrides)
        branch, restart_of, start_label = None, f"{label} of {restart}", label
    else:
        from maglev_match.api.cycles import cycle_study

        kw = {} if str(model).endswith(".py") else {"ignore_current": ignore_current}
        say(f"locating the {kind} on a branch of cycles along {x} ...")
        st = cycle_study(params, x, model=model, at=at, start=start, stop=stop, ntst=ntst,
                         ncol=ncol, config=config, stage=stage, **kw, **overrides)
        branch, system = st.branches[0], st.system
        if y not in system.param_names:
            raise ParameterError("y", y, f"model '{st.model}' has no such parameter; choose "
                                 f"one of {', '.join(system.param_names)}")
        found = [sp for sp in branch.special_points if sp.point is not None and (
            sp.label == label if label is not None else sp.type == kind)]
        if not found:
            have = ", ".join(sp.label for sp in branch.special_points) or "none"
            raise ParameterError("label" if label else "kind", label or kind,
                                 f"no {label or kind} on the branch of cycles along {x} (its "
                                 f"special points: {have}; the branch ended: "
                                 f"{branch.stopped_reason})")
        if found[0].type != kind:
            raise ParameterError("label", label, f"{label} is a {found[0].type}, not a {kind}")
        orbit, start_label = found[0].point.orbit, found[0].label
        studied_label, is_user, prm, at_used = st.model, st.is_user, st.params, dict(at or {})
        restart_of = ""
    p = np.asarray(orbit.p, float)
    y0 = float(p[system.param_index(y)])
    if y not in bnds:
        lo, hi = sorted((0.5 * y0, 2.0 * y0)) if y0 != 0 else (-1.0, 1.0)
        bnds[y] = (lo, hi)
    say(f"continuing the {kind} curve in ({x}, {y}) from {start_label} ...")
    curve = _cycle_curve(system, orbit, kind, (x, y), ranges=bnds, direction=0,
                         max_steps=max_steps, marks=tuple(float(m) for m in marks))
    say(f"{kind} curve: {len(curve.points)} points, {curve.message}")
    return CycleCurveStudy(model=studied_label, kind=kind, x=x, y=y, at=at_used, curve=curve,
                           start_label=start_label, start_branch=branch,
                           restart_of=restart_of, elapsed=time.perf_counter() - t0,
                           is_user=is_user, params=prm)


def _from_file(params, model, restart, label, at, config, overrides):
    """(system, orbit, model label, is_user, params, at) of a saved branch's point."""
    from dataclasses import replace

    from maglev_match.analyses.restart import (
        check_parameters,
        load_cycle_restart,
        saved_params,
        saved_values,
    )
    from maglev_match.api.inputs import resolve_model
    from maglev_match.dynamics.cycles import PeriodicOrbit

    own = params is not None or config is not None or bool(overrides) or bool(at)
    studied = resolve_model(params, model, config=config, **overrides)
    studied = studied.with_values(**dict(at or {}))
    system = studied.system()
    rs = load_cycle_restart(restart, label, system)
    prm = studied.params
    if not own:
        if studied.is_user:
            vals = saved_values(rs)
            studied = replace(studied, values={n: vals[n] for n in studied.user.params
                                               if n in vals})
            system = studied.system()
        else:
            saved = saved_params(rs)
            if saved is not None:
                from maglev_match.maglev.models import maglev_model

                prm = saved
                system = maglev_model(saved, studied.label).system()
    check_parameters(rs, system, rs.param)  # given values must be the saved ones
    orbit = PeriodicOrbit(mesh=rs.state.mesh, ncol=rs.ncol, states=rs.state.states,
                          period=rs.state.period, p=rs.p)
    return system, orbit, studied.label, studied.is_user, prm, dict(at or {})
