"""Restart of a saved Hopf curve (``hopf-curve --out``): the validated curve point
(:func:`load_hopf_curve_restart`, :class:`HopfCurveRestart`; P<k> or a codimension-two
point) and the continuation from it in both directions, after the point is refined on the
Hopf defining system (:func:`restart_hopf_curve`). The file checks are those of
:mod:`maglev_match.analyses.restart.files`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from maglev_match.analyses.restart.files import (
    MODEL_ATTR,
    SAME,
    RestartFileError,
    RestartKind,
    RestartMismatch,
    check_saved_model,
    expect_kind,
    label_error,
    open_saved,
    require_finite,
    saved_names,
    variable,
)

__all__ = ["HopfCurveRestart", "load_hopf_curve_restart", "restart_hopf_curve"]


# ---------------------------------------------------------------------------------------
# Hopf curves
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class HopfCurveRestart:
    """A validated point of a saved Hopf curve: the two curve parameters, their values, the
    equilibrium and frequency there, the full parameter vector and the saved bounds."""

    path: str
    label: str
    names: tuple[str, str]
    values: tuple[float, float]
    x: np.ndarray
    frequency: float
    p: np.ndarray
    parameter_names: tuple[str, ...]
    bounds: dict[str, tuple[float, float]]
    model: str
    params_json: str | None = None

    def describe(self) -> str:
        return (f"restart from {self.label} of {self.path}: {self.names[0]} = "
                f"{self.values[0]:.8g}, {self.names[1]} = {self.values[1]:.8g}, frequency "
                f"{self.frequency:.6g} rad/s")


def load_hopf_curve_restart(source: Any, label: str, system: Any = None) -> HopfCurveRestart:
    """Validate a saved Hopf curve and read the point ``label`` (P<k>, the k-th curve point,
    or a codimension-two point's label such as GH1: its equilibrium is taken from the
    nearest curve point and refined on restarting)."""
    ds, where = open_saved(source)
    expect_kind(ds, where, RestartKind.HOPF_CURVE)
    states = saved_names(ds, where, "state")
    params = saved_names(ds, where, "parameter")
    check_saved_model(ds, where, system, states, params)
    text = ds.attrs.get("curve_params")
    if not isinstance(text, str):
        raise RestartFileError(where, "lacks the attribute curve_params (the two parameters "
                               "of the curve); it was written before restarts of Hopf curves "
                               "existed: compute the curve again with --out")
    names = tuple(t.strip() for t in text.split(","))
    if len(names) != 2 or names[0] == names[1] or not set(names) <= set(params):
        raise RestartFileError(where, f"attribute curve_params = '{text}' does not name two "
                               "parameters of the saved model")
    v1 = variable(ds, where, names[0], ("point",))
    v2 = variable(ds, where, names[1], ("point",))
    om = variable(ds, where, "frequency", ("point",))
    eq = variable(ds, where, "equilibrium", ("point", "state"))
    base = require_finite(where, "base_p (the parameters of the curve)",
                          variable(ds, where, "base_p", ("parameter",)))
    if eq.shape[1] != len(states):
        raise RestartFileError(where, f"the saved equilibria have {eq.shape[1]} states, the "
                               f"file names {len(states)}")
    labels = [f"P{k}" for k in range(v1.size)]
    specials = ([str(v) for v in ds["special_label"].values]
                if "special_label" in ds.coords else [])
    if label in labels:
        k = labels.index(label)
        vals = (float(v1[k]), float(v2[k]))
        freq = float(om[k])
        x = eq[k]
    elif label in specials:
        j = specials.index(label)
        vals = (float(variable(ds, where, f"special_{names[0]}", ("special",))[j]),
                float(variable(ds, where, f"special_{names[1]}", ("special",))[j]))
        freq = float(variable(ds, where, "special_frequency", ("special",))[j])
        ok = np.isfinite(v1) & np.isfinite(v2) & np.all(np.isfinite(eq), axis=1)
        if not ok.any():
            raise RestartFileError(where, "has no finite curve point to take the equilibrium "
                                   "from")
        spans = np.array([np.ptp(v1[ok]) or 1.0, np.ptp(v2[ok]) or 1.0])
        d = np.hypot((v1 - vals[0]) / spans[0], (v2 - vals[1]) / spans[1])
        x = eq[int(np.nanargmin(np.where(ok, d, np.inf)))]
    else:
        raise label_error(where, label, labels, specials, "saved Hopf curve")
    require_finite(where, f"the curve point '{label}'", np.array(vals))
    require_finite(where, f"the equilibrium at '{label}'", x)
    if not (math.isfinite(freq) and freq > 0):
        raise RestartFileError(where, f"the frequency at '{label}' is {freq:g}: a Hopf point "
                               "needs a finite frequency > 0 rad/s (a Bogdanov-Takens end "
                               "point cannot be restarted)")
    bounds = {}
    for nm in names:
        b = ds.attrs.get(f"bounds_{nm}")
        try:
            lo, hi = (float(t) for t in np.asarray(b, float).ravel())
        except (TypeError, ValueError):
            raise RestartFileError(where, f"attribute bounds_{nm} is missing or not two "
                                   "numbers") from None
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
            raise RestartFileError(where, f"attribute bounds_{nm} = [{lo:g}, {hi:g}] is not an "
                                   "increasing finite range")
        bounds[nm] = (lo, hi)
    p = np.array(base, float)
    p[params.index(names[0])], p[params.index(names[1])] = vals
    model = ds.attrs.get(MODEL_ATTR)
    pj = ds.attrs.get("params")
    return HopfCurveRestart(path=where, label=label, names=(names[0], names[1]), values=vals,
                            x=np.array(x, float), frequency=freq, p=p,
                            parameter_names=tuple(params), bounds=bounds,
                            model=model if isinstance(model, str) else "",
                            params_json=pj if isinstance(pj, str) and pj.startswith("{")
                            else None)


def restart_hopf_curve(source: Any, label: str, system: Any,
                       bounds: Mapping[str, tuple[float, float]] | None = None,
                       **options: Any) -> tuple[Any, HopfCurveRestart]:
    """Continue a saved Hopf curve from its point ``label`` (in both directions) inside
    ``bounds`` (default: the saved ones; wider bounds extend the curve). The saved point is
    refined on the Hopf defining system first (it must converge there); ``system``'s
    parameters other than the two curve parameters must be the saved ones.

    Returns (the :class:`~maglev_match.dynamics.hopf_curve.HopfCurve`, the restart)."""
    from maglev_match.dynamics.hopf import refine_hopf_point
    from maglev_match.dynamics.hopf_curve import hopf_curve

    rs = load_hopf_curve_restart(source, label, system)
    diffs = [(n, float(system.p[k]), float(rs.p[k]))
             for k, n in enumerate(rs.parameter_names) if n not in rs.names
             and abs(system.p[k] - rs.p[k]) > SAME * max(abs(rs.p[k]), abs(system.p[k]), 1e-300)]
    if diffs:
        raise RestartMismatch(rs.path, diffs)
    bnds = dict(rs.bounds if bounds is None else bounds)
    hp = refine_hopf_point(system, rs.names[0], rs.values[0], rs.x, rs.frequency, p=rs.p,
                           bounds=bnds.get(rs.names[0]))
    if not hp.converged:
        raise RestartFileError(rs.path, f"the saved point '{label}' does not converge to a "
                               f"Hopf point of this model ({hp.message or 'Newton failed'})")
    return hopf_curve(system, rs.names, hp, bnds, **options), rs
