"""Curves of cycle bifurcations in two parameters (`maglev-match cycle-curve`): the fold of
cycles (LPC), the period doubling (PD) or the Neimark-Sacker (torus) bifurcation (NS)
continued in a plane (x, y), for the maglev models
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

from maglev_match.api.progress import reported
from maglev_match.core.params import ParameterError, Params
from maglev_match.core.results import Plottable

__all__ = ["cycle_curve", "CycleCurveStudy"]

KINDS = ("LPC", "PD", "NS")


@dataclass(frozen=True)
class CycleCurveStudy(Plottable):
    """A curve of cycle bifurcations and where it started.

    model : 'unit', 'vehicle' or a user model file's name; kind : 'LPC', 'PD' or 'NS';
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
        non-critical multiplier, reliability, kind; on an NS curve also kappa = cos theta
        of the critical pair e^{+-i theta} and the NS coefficient d of the normal form
        z -> e^{i theta} z (1 + d |z|^2) (d < 0 supercritical) with its estimated error;
        on a PD curve the flip coefficient c of the
        normal form eta -> -eta + c eta^3 (c > 0 supercritical) and its estimated error."""
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
            if self.kind == "NS":
                r["kappa"] = c.kappa
                r["ns_coefficient"], r["ns_error"] = c.ns_coefficient, c.ns_error
            if self.kind == "PD":
                r["flip_coefficient"], r["flip_error"] = c.flip, c.flip_error
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
        if not self.is_user:  # the files are in SI units, as every dataset of the package
            from maglev_match.core.units import si_unit

            seen = {n for c in self.curve.points for n in c.extrema}
            units = {n: si_unit(n) for n in (self.x, self.y, *seen)}
        ds = self.curve.to_xarray(units)
        if not self.is_user and self.params is not None:  # the version and the parameters
            from maglev_match.core.datasets import annotate

            ds = annotate(ds, self.params)
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


@reported("cycle-curve", units=False)
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
    """The fold of cycles (`kind="LPC"`), period doubling (`"PD"`) or Neimark-Sacker
    (torus) bifurcation (`"NS"`) of cycles continued in the plane (`x`, `y`)
    (`maglev-match cycle-curve`), both ways from its start.

    Parameters
    ----------
    params : Params | str | None
        The parameter set (see [`resolve_params`][maglev_match.api.inputs.resolve_params]).
    kind : str
        "LPC", "PD" or "NS".
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
        LPC1); with `restart`, required. `GH1`, `GH2`, ...: the LPC curve born at that
        generalised Hopf point of the Hopf curve in (`x`, `y`) (branch switching; `x`
        within `start`/`stop`, `y` within `bounds`, else `hopf-curve`'s default plane).
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
        The curve stops where its cycle reaches a gap limit (and, with False, where the
        coil current reaches zero): the point solved there, the reason "reached a physical
        limit" and the limit's name in its message.
    config : str or Path, optional
        A TOML file applied on top of the preset.
    stage : callable, optional
        Called with a line of text when a stage starts.
    **overrides : float
        Parameter values applied on top.

    Returns
    -------
    CycleCurveStudy
        The curve (points, special points CPC/LPPD/LPNS, LPPD/PDNS or R1-R4/LPNS/PDNS
        (NS), why it stopped, its
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
    elif label is not None and str(label).startswith("GH"):
        if kind != "LPC":
            raise ParameterError("label", label, "a generalised Hopf point starts an LPC "
                                 "curve (--kind LPC)")
        return _from_gh(params, x, y, label, model, at, bnds, start, stop, ntst, ncol,
                        max_steps, marks, config, say, overrides, t0, ignore_current)
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
    limits = _limits_of(is_user, prm, ignore_current)
    curve = _cycle_curve(system, orbit, kind, (x, y), ranges=bnds, direction=0,
                         max_steps=max_steps, marks=tuple(float(m) for m in marks),
                         limits=limits)
    say(f"{kind} curve: {len(curve.points)} points, {curve.message}")
    return CycleCurveStudy(model=studied_label, kind=kind, x=x, y=y, at=at_used, curve=curve,
                           start_label=start_label, start_branch=branch,
                           restart_of=restart_of, elapsed=time.perf_counter() - t0,
                           is_user=is_user, params=prm)


def _limits_of(is_user: bool, prm, ignore_current: bool):
    """The physical limits a maglev model's curve stops at (the gap limits, and the
    current limit unless ``ignore_current``); None for a user model."""
    if is_user or prm is None:
        return None
    from maglev_match.maglev.limits import cycle_limit_margins

    return cycle_limit_margins(prm, include_current=not ignore_current)


def _from_gh(params, x, y, label, model, at, bnds, start, stop, ntst, ncol, max_steps,
             marks, config, say, overrides, t0, ignore_current=False) -> CycleCurveStudy:
    """The LPC curve born at the generalised Hopf point ``label`` (GH1, GH2, ... in the
    order of the Hopf curves of the plane): the Hopf curve in (x, y) (as `hopf-curve`
    computes it; x within --from/--to, y within its --range, else that command's default
    plane), then :func:`~maglev_match.dynamics.cycle_curves.lpc_from_generalised_hopf`
    with a step of 1 % of y's range to the side where a fold is born; the curve's GH end is
    a fifth of that step before GH (its cycles shrink to the equilibrium there)."""
    import numpy as np

    from maglev_match.api.hopf import hopf_curve
    from maglev_match.api.inputs import resolve_model
    from maglev_match.dynamics.cycle_curves import lpc_from_generalised_hopf

    xa = (x, start, stop) if start is not None and stop is not None else x
    ya = (y, *bnds[y]) if y in bnds else y
    vals = {**overrides, **dict(at or {})}
    say(f"the Hopf curve in ({x}, {y}) for its generalised Hopf points ...")
    curves = hopf_curve(params, xa, ya, model=model, config=config, **vals)
    ghs = [(sp, c) for c in curves for sp in c.special_points if sp.type == "GH"]
    if not ghs:
        raise ParameterError("label", label, f"the Hopf curve in ({x}, {y}) has no "
                             "generalised Hopf point there")
    try:
        sp, c = ghs[int(str(label)[2:]) - 1]
    except (ValueError, IndexError):
        raise ParameterError("label", label, f"the Hopf curve has GH1 to GH{len(ghs)}") \
            from None
    studied = resolve_model(params, model, config=config, **vals)
    system = studied.system()
    near = min(c.points, key=lambda q: abs(q.values[0] - sp.values[0])
               + abs(q.values[1] - sp.values[1]))
    pg = system.params_with(**{x: sp.values[0], y: sp.values[1]})
    lo, hi = bnds.get(y, (min(q.values[1] for q in c.points), max(q.values[1] for q in
                                                                   c.points)))
    step = 0.01 * (hi - lo) if hi > lo else 0.01
    bnds = dict(bnds)
    bnds.setdefault(y, (lo, hi))
    # the curve stops where its cycle reaches a physical limit, as from a branch's point
    limits = _limits_of(studied.is_user, studied.params, ignore_current)
    last: Exception | None = None
    say(f"branch switching at {label} ({x} = {sp.values[0]:.8g}, {y} = {sp.values[1]:.8g}) "
        "...")
    for offset in (step, -step):
        # the GH side of the curve ends a fifth of the step before GH, where its cycles
        # shrink to the equilibrium (and the collocation problem degenerates)
        ylo, yhi = bnds[y]
        edge = sp.values[1] + 0.2 * offset
        ranges = {**bnds, y: (max(ylo, edge), yhi) if offset > 0 else (ylo, min(yhi, edge))}
        try:
            curve, branch = lpc_from_generalised_hopf(
                system, near.x, pg, sp.frequency, (x, y), offset=offset, l2=sp.l2,
                ntst=40 if ntst is None else ntst, ncol=4 if ncol is None else ncol,
                ranges=ranges, direction=0, max_steps=max_steps,
                marks=tuple(float(m) for m in marks), limits=limits,
                scales=(0.05 * (stop - start) if start is not None and stop is not None
                        and stop != start else None, abs(step) * 5.0))
            break
        except ValueError as exc:
            last = exc
    else:
        raise ParameterError("label", label, f"no fold of cycles found near {label}: "
                             f"{last}") from None
    if not np.isfinite(sp.l2 if sp.l2 is not None else np.nan):
        curve = _with_warning(curve, f"l2 at {label} is not known: the side of the fold "
                              "was found by trying both")
    return CycleCurveStudy(model=studied.label, kind="LPC", x=x, y=y, at=dict(at or {}),
                           curve=curve, start_label=f"{label} of the Hopf curve",
                           start_branch=branch, elapsed=time.perf_counter() - t0,
                           is_user=studied.is_user, params=studied.params)


def _with_warning(curve, text: str):
    from dataclasses import replace

    return replace(curve, warnings=tuple(curve.warnings) + (text,))


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
