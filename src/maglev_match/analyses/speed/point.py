"""Everything at one speed (:class:`SpeedPoint`, :func:`speed_point`).

The periodic response (:func:`periodic_response`) is the fixed point of the passage map
(:mod:`maglev_match.analyses.speed.passage`), found by Newton's method on that map with the
variational transfer matrices and the span hand-over as a linear jump
(:mod:`maglev_match.dynamics.integrate.passage`), not by simulating many spans. Its
multipliers (the eigenvalues of the span map's Jacobian; the dropped span gives exact zeros)
decide stability. As v -> 0 the multipliers follow the standstill eigenvalues: ln|mu| T^-1
tends to the mean over the passage of the rightmost real part of the frozen model (the
vehicle standing at each position, :func:`adiabatic_rate`), see ``docs/speed.md``.

Read-outs per speed, over one passage of the periodic response:

* the largest and smallest gap deviation c_j - c0 per levitation point, the largest and
  smallest current and whether it would reverse (the response is of the smooth model);
* the largest mid-span deflection of a span while the vehicle is on it (the span entering in
  slot B over the passage, then the same span in slot A until the rear leaves it) and the
  dynamic amplification factor DAF = that deflection over the largest static mid-span
  deflection under the vehicle's weights with the same modes
  (:func:`~maglev_match.maglev.moving.static_midspan_deflection`);
* the car body's peak vertical acceleration and Sperling's ride index Wz of its spectrum
  (:mod:`maglev_match.analyses.speed.ride`; the lines of a periodic signal are exact);
* the multipliers and the verdict;
* the matching index at speed (:mod:`maglev_match.analyses.speed.index`): the span under
  the vehicle suddenly displaced in its first mode, the mean deflection under the vehicle
  jumping by d; h(v) the critical d (smaller direction, worst position of the vehicle in the
  span) and chi(v) = h(v) / w0, the standstill index at v -> 0;
* the entry disturbance, a second read-out (:mod:`maglev_match.analyses.speed.critical`):
  the span being entered deflected before the vehicle reaches it; h_entry and
  chi_entry = h_entry / w0.

At v = 0 the values are those of the vehicle standing at mid-span
(:func:`standstill_point`)."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from maglev_match.analyses.speed.critical import (
    CriticalStatus,
    SpeedCritical,
    critical_disturbance_at_speed,
)
from maglev_match.analyses.speed.grid import KMH
from maglev_match.analyses.speed.index import SpeedIndex, index_at_speed
from maglev_match.analyses.speed.options import SpeedOptions, w0_of
from maglev_match.analyses.speed.passage import (
    lift_state,
    passage_problem,
    passage_readouts,
    quasi_static_state,
    slot_flags,
)
from maglev_match.core.params import Params
from maglev_match.core.reprs import compact_repr
from maglev_match.dynamics.integrate.passage import PeriodicPassage, solve_periodic_passage
from maglev_match.maglev import moving as mv
from maglev_match.maglev import moving_delay as md
from maglev_match.maglev.moving import MovingModel

__all__ = ["SpeedPoint", "speed_point", "standstill_point", "periodic_response",
           "adiabatic_rate"]


@dataclass(frozen=True)
class SpeedPoint:
    """Everything computed at one speed (SI units; arrays per levitation point).

    speed (m/s), period L / v (s; inf at v = 0). converged : the periodic response was found
    (the residual below the tolerance). stable : every multiplier inside the unit circle
    (at v = 0: every eigenvalue of the vehicle standing at mid-span in the left half-plane).
    largest_multiplier : max |mu| (NaN at v = 0); critical_multiplier (re, im);
    multipliers : the largest ones (re, im pairs); max_real_part : at v = 0 only (1/s).
    gap_dev_max / gap_dev_min (m), current_max / current_min (A), current_reverses.
    midspan_max : largest mid-span deflection of a span under the vehicle (m, downward);
    static_deflection : its static reference (m); daf : their ratio.
    body_acc_peak (m/s^2), wz (Sperling, vertical).
    down, up : the entry disturbance per direction (the span being entered deflected
    before the vehicle reaches it), a second read-out: h_entry (m) and chi_entry.
    h (m), w0 (m), chi : the index at speed (``index``, :class:`SpeedIndex`): the critical
    jump of the mean deflection under the vehicle, the smaller direction at the worst
    position, and chi(v) = h / w0 with the standstill index's w0.
    integration_error, residual, passages, jacobians : diagnostics of the periodic solve.
    warnings : what the numbers cannot be trusted for, in words."""

    __repr__ = compact_repr

    speed: float
    period: float
    converged: bool
    stable: bool | None
    largest_multiplier: float
    critical_multiplier: tuple[float, float]
    multipliers: tuple[tuple[float, float], ...]
    multiplier_method: str
    max_real_part: float
    gap_dev_max: tuple[float, ...]
    gap_dev_min: tuple[float, ...]
    current_max: tuple[float, ...]
    current_min: tuple[float, ...]
    current_reverses: bool
    midspan_max: float
    static_deflection: float
    daf: float
    body_acc_peak: float
    wz: float
    down: SpeedCritical | None
    up: SpeedCritical | None
    h: float
    w0: float
    chi: float
    integration_error: float
    residual: float
    passages: int
    jacobians: int
    samples: int
    warnings: tuple[str, ...] = field(default=())
    index: SpeedIndex | None = None
    h_entry: float = math.nan
    chi_entry: float = math.nan
    #: the delay of the outer loop this point was computed with (s)
    tau: float = 0.0
    #: the critical delay at this speed (:mod:`maglev_match.analyses.speed.delay`; NaN when
    #: not computed): tau_c (s), how its solve ended, the leading multiplier there (re, im;
    #: at v = 0 the rightmost root, 1/s), and its low-speed limit (the delay at which the
    #: position-averaged frozen spectral abscissa crosses 0, s)
    tau_c: float = math.nan
    tau_c_status: str = ""
    tau_c_multiplier: tuple[float, float] = (math.nan, math.nan)
    tau_c_frozen: float = math.nan

    @property
    def speed_kmh(self) -> float:
        return self.speed / KMH

    @property
    def gap_dev_abs_max(self) -> float:
        """The largest |c_j - c0| over all points (m)."""
        vals = [abs(v) for v in (*self.gap_dev_max, *self.gap_dev_min)]
        return max(vals) if vals else float("nan")

    @property
    def every_size_returned(self) -> bool:
        """The direction that decides chi(v) returned at every size up to its gap range (h
        is that range, as the standstill index counts it; no jump within the range caused
        contact)."""
        return bool(self.index is not None and np.isfinite(self.h)
                    and self.index.every_size_returned)

    @property
    def entry_at_ceiling(self) -> bool:
        """The entry disturbance's h_entry is its search's ceiling: in the direction that
        sets it every initial deflection up to the gap range returned."""
        if not np.isfinite(self.h_entry):
            return False
        setting = [c for c in (self.down, self.up) if c is not None
                   and c.supported() is not None and c.supported() == self.h_entry]
        return bool(setting) and all(c.status == CriticalStatus.ALL_RETURN for c in setting)

    def to_json(self) -> dict[str, Any]:
        d = dataclasses.asdict(self)
        d["every_size_returned"] = self.every_size_returned
        d["entry_at_ceiling"] = self.entry_at_ceiling
        return d

    @classmethod
    def from_json(cls, d: dict[str, Any]) -> SpeedPoint:
        d = dict(d)
        for k in ("every_size_returned", "entry_at_ceiling"):  # properties, recomputed
            d.pop(k, None)
        for k in ("down", "up"):
            if d.get(k) is not None:
                d[k] = SpeedCritical(**d[k])
        if d.get("index") is not None:
            d["index"] = SpeedIndex.from_json(d["index"])
        for k in ("gap_dev_max", "gap_dev_min", "current_max", "current_min", "warnings"):
            d[k] = tuple(d[k])
        d["critical_multiplier"] = tuple(d["critical_multiplier"])
        if "tau_c_multiplier" in d:
            d["tau_c_multiplier"] = tuple(d["tau_c_multiplier"])
        d["multipliers"] = tuple(tuple(m) for m in d["multipliers"])
        return cls(**d)


def _nan_point(v: float, params: Params, kind: MovingModel, message: str,
               n_pts: int) -> SpeedPoint:
    nan = float("nan")
    st, _ = mv.static_midspan_deflection(params, kind)
    return SpeedPoint(v, params.L / v if v > 0 else math.inf, False, None, nan, (nan, nan), (),
                      "", nan, (nan,) * n_pts, (nan,) * n_pts, (nan,) * n_pts, (nan,) * n_pts,
                      False, nan, st, nan, nan, nan, None, None, nan, w0_of(params, kind), nan,
                      nan, nan, 0, 0, 0, (message,), tau=float(params.tau))


def adiabatic_rate(params: Params, model: str, v: float, positions: int = 40) -> float:
    """The low-speed estimate of ln max|mu| / T (1/s): the mean over one passage of the
    largest real part of the eigenvalues of the vehicle standing at each position (both
    spans elastic), at ``positions`` equally spaced positions of the front (the adiabatic
    limit of a slowly varying linear system; exact as v -> 0 when that eigenvalue stays
    simple)."""
    kind = MovingModel(model)
    T = params.L / v
    reals = []
    for t in (np.arange(positions) + 0.5) * T / positions:
        xf = params.L + v * t
        x = quasi_static_state(params, kind, xf)
        fb, rb = slot_flags(params, kind, xf)
        p = mv.moving_param_vector(params, kind, v=0.0, x_front=xf, front_on_B=fb,
                                   rear_on_B=rb)
        J = mv.moving_system(params, kind, p).f_and_jacobian(x, p)[1]
        reals.append(float(np.max(np.linalg.eigvals(J[:-1, :-1]).real)))
    return float(np.mean(reals))


def _failed_point(v: float, params: Params, kind: MovingModel, message: str,
                  n_pts: int) -> SpeedPoint:
    """A speed without a periodic response. When the vehicle standing along the span grows
    so fast that the low-speed estimate of the largest multiplier, exp(T x the mean
    growth rate), exceeds 10, the verdict is 'unstable' on that estimate (h = chi = 0) and
    the warning says so; otherwise the verdict stays open."""
    pt = _nan_point(v, params, kind, message, n_pts)
    if v <= 0 or kind is MovingModel.FORCE:
        return pt
    try:
        est = adiabatic_rate(params, kind, v) * params.L / v
    except (FloatingPointError, np.linalg.LinAlgError):
        return pt
    if est > math.log(10.0):
        note = (f"the vehicle standing along the span grows at {est * v / params.L:.3g} 1/s "
                f"on average: the periodic response is strongly unstable (low-speed "
                f"estimate of the largest multiplier exp({est:.3g})) and could not be "
                "computed")
        return dataclasses.replace(pt, stable=False, largest_multiplier=float(math.exp(
            min(est, 700.0))), h=0.0, chi=0.0, warnings=(message, note))
    return pt


def periodic_response(params: Params, model: str, v: float,
                      options: SpeedOptions | None = None, *,
                      tau_max: float | None = None) -> PeriodicPassage:
    """The periodic response at speed v (m/s > 0): the fixed point of the span map from the
    quasi-static state at the hand-over, with its multipliers
    (:func:`~maglev_match.dynamics.integrate.passage.solve_periodic_passage`). With a delay
    ``params.tau`` > 0 that of the delayed model (``tau_max``: its discretisation sized for
    delays up to this, :func:`~maglev_match.analyses.speed.passage.passage_problem`)."""
    opts = options or SpeedOptions()
    kind = MovingModel(model)
    problem = passage_problem(params, kind, v, tau_max=tau_max)
    guess = quasi_static_state(params, kind, float(params.L))
    sl = mv.slot_slices(kind, params.n_modes)
    guess[sl["qB"]] = 0.0  # the span ahead is at rest at the hand-over
    guess[sl["qB_dot"]] = 0.0
    return solve_periodic_passage(problem, lift_state(problem, guess), opts.passage())


def _multiplier_pairs(values: np.ndarray, k: int = 8) -> tuple[tuple[float, float], ...]:
    vals = np.asarray(values, complex)[:k]
    return tuple((float(z.real), float(z.imag)) for z in vals)


def speed_point(params: Params, model: str, v: float,
                options: SpeedOptions | None = None, *,
                tau_max: float | None = None) -> SpeedPoint:
    """All read-outs at one speed v (m/s; v = 0 gives the standstill values,
    :func:`standstill_point`; ``tau_max``: a delay's discretisation sized for delays up to
    this, as in a map over the delay). Failures are reported in the point (``converged`` False and a
    warning), never raised."""
    opts = options or SpeedOptions()
    kind = MovingModel(model)
    n_pts = mv.layout_of(params, kind).n_loads if kind is not MovingModel.FORCE else 0
    if v == 0:
        return standstill_point(params, kind)
    try:
        sol = periodic_response(params, kind, v, opts, tau_max=tau_max)
    except FloatingPointError as exc:
        return _failed_point(v, params, kind, f"no periodic response: {exc}", n_pts)
    if not sol.converged or sol.multipliers is None:
        return _failed_point(v, params, kind, f"no periodic response: {sol.message}", n_pts)
    warnings: list[str] = []
    mult = sol.multipliers
    stable = mult.largest < 1.0
    try:
        ro, _ = passage_readouts(sol.problem, sol.run, params, kind, opts)
    except FloatingPointError as exc:
        return _nan_point(v, params, kind, f"read-outs failed: {exc}", n_pts)
    st, _ = mv.static_midspan_deflection(params, kind)
    w0 = w0_of(params, kind)
    reverses = bool(np.any(ro.current_min < 0)) if n_pts else False
    if reverses:
        warnings.append(f"the coil current on the periodic response would reverse (min "
                        f"{float(np.min(ro.current_min)):.3g} A): it is a response of the "
                        "smooth model; the clamped system differs there")
    out_of_range = bool(n_pts and (np.any(ro.gap_dev_min + params.c0 < params.gap_min)
                                   or np.any(ro.gap_dev_max + params.c0 > params.gap_max)))
    if out_of_range:
        warnings.append("the periodic response leaves the physical gap range: the vehicle "
                        "would touch the guideway at this speed")
    if sol.integration_error > 1e-3:
        warnings.append(f"the multipliers may be inaccurate: the variational solve and the "
                        f"state run differ by {sol.integration_error:.2g} (scaled)")
    if not stable:
        warnings.append(f"the periodic response is unstable (largest |multiplier| "
                        f"{mult.largest:.4g})")
    down = up = index = None
    h = chi = h_entry = chi_entry = float("nan")
    if kind is MovingModel.FORCE:
        pass
    elif not stable:
        h, chi = 0.0, 0.0
    elif out_of_range:
        h, chi = 0.0, 0.0
    elif opts.critical:
        try:
            index = index_at_speed(params, kind, v, sol, opts)
        except FloatingPointError as exc:
            warnings.append(f"the index at speed could not be computed: {exc}")
        if index is not None:
            h, chi = index.h, index.chi
            for q in index.positions:
                for c in (q.down, q.up):
                    side = "beam down" if c.direction > 0 else "beam up"
                    if c.status == "open":
                        warnings.append(
                            f"index at speed (centre at {q.fraction:g} L, {side}) not "
                            f"resolved: {c.unresolved} run(s) neither returned within "
                            f"{opts.spans} spans nor "
                            "collided")
        down, up = critical_disturbance_at_speed(params, kind, v, sol.x0, opts)
        sizes = [c.supported() for c in (down, up)]
        for c in (down, up):
            if c.status == CriticalStatus.OPEN:
                side = "beam down" if c.direction > 0 else "beam up"
                warnings.append(f"entry disturbance ({side}) not resolved: {c.unresolved} "
                                f"run(s) neither returned within {c.spans} spans nor "
                                "collided")
        if all(s is not None for s in sizes):
            h_entry = float(min(sizes))  # type: ignore[type-var]
            chi_entry = h_entry / w0 if w0 > 0 else float("nan")
    crit = mult.critical
    return SpeedPoint(
        speed=float(v), period=float(params.L / v), converged=True, stable=bool(stable),
        largest_multiplier=float(mult.largest),
        critical_multiplier=(float(crit.real), float(crit.imag)),
        multipliers=_multiplier_pairs(mult.values), multiplier_method=mult.method,
        max_real_part=float("nan"),
        gap_dev_max=tuple(map(float, ro.gap_dev_max)),
        gap_dev_min=tuple(map(float, ro.gap_dev_min)),
        current_max=tuple(map(float, ro.current_max)),
        current_min=tuple(map(float, ro.current_min)), current_reverses=reverses,
        midspan_max=float(ro.midspan_max), static_deflection=float(st),
        daf=float(ro.midspan_max / st) if st > 0 else float("nan"),
        body_acc_peak=float(ro.body_acc_peak), wz=float(ro.wz), down=down, up=up, h=h,
        w0=float(w0), chi=chi, integration_error=float(sol.integration_error),
        residual=float(sol.residual), passages=int(sol.passages), jacobians=int(sol.jacobians),
        samples=int(ro.samples), warnings=tuple(warnings), index=index, h_entry=h_entry,
        chi_entry=chi_entry, tau=float(params.tau))


def standstill_point(params: Params, model: str) -> SpeedPoint:
    """The values at v = 0: the vehicle standing at mid-span on slot A (its layout
    centred), both spans elastic. Stability from the eigenvalues of the Jacobian there (no
    passage, no multipliers); DAF = the equilibrium's mid-span deflection over the static
    reference (1 up to the levitation's redistribution of the weights); Wz and the
    acceleration 0; the index at speed and the entry disturbance are not computed there (the
    standstill index is `maglev-match index`)."""
    kind = MovingModel(model)
    lay = mv.layout_of(params, kind)
    n_pts = lay.n_loads if kind is not MovingModel.FORCE else 0
    x_front = 0.5 * (params.L + lay.extent)
    x = quasi_static_state(params, kind, x_front)
    fb, rb = slot_flags(params, kind, x_front)
    p = mv.moving_param_vector(params, kind, v=0.0, x_front=x_front, front_on_B=fb,
                               rear_on_B=rb)
    system = mv.moving_system(params, kind, p)
    if params.tau > 0 and kind is not MovingModel.FORCE:  # the delayed model's roots
        delayed = md.moving_delay_system(params, kind, p, tau=float(params.tau))
        pd = md.delayed_vector(p, params.tau)
        J = delayed.jacobian(delayed.lift(x, pd), pd)[:-1, :-1]
    else:
        J = system.jacobian(x, p)[:-1, :-1]
    lam = np.linalg.eigvals(J)
    mr = float(np.max(lam.real))
    st, _ = mv.static_midspan_deflection(params, kind)
    mid = float(np.max(system.observe("midspan", x, p)))
    nan = float("nan")
    if n_pts:
        gd = tuple(map(float, np.atleast_1d(system.observe("gap_deviation", x, p))))
        cu = tuple(map(float, np.atleast_1d(system.observe("current", x, p))))
    else:
        gd = cu = ()
    return SpeedPoint(
        speed=0.0, period=math.inf, converged=True, stable=bool(mr < 0),
        largest_multiplier=nan, critical_multiplier=(nan, nan), multipliers=(),
        multiplier_method="eigenvalues (v = 0)", max_real_part=mr, gap_dev_max=gd,
        gap_dev_min=gd, current_max=cu, current_min=cu,
        current_reverses=bool(cu and min(cu) < 0), midspan_max=mid, static_deflection=st,
        daf=mid / st if st > 0 else nan, body_acc_peak=0.0 if n_pts else nan,
        wz=0.0 if n_pts else nan, down=None, up=None, h=nan, w0=w0_of(params, kind), chi=nan,
        integration_error=nan, residual=0.0, passages=0, jacobians=0, samples=0,
        warnings=("v = 0: the vehicle standing at mid-span (no span is entered, so the "
                  "entry disturbance is not defined there; chi(v) tends to the standstill "
                  "index, `maglev-match index`, as v -> 0)",), tau=float(params.tau))
