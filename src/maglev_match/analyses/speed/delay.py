"""The critical delay of the outer control loop at speed: the smallest delay tau at which
the periodic response over identical spans loses stability (a Floquet multiplier of the span
map leaves the unit circle), per speed, located by solving.

The delayed model at speed is the standstill delay model applied to the moving models
(:mod:`maglev_match.maglev.moving_delay`), discretised; its periodic response and
multipliers come from the same periodic solve as without delay
(:func:`~maglev_match.analyses.speed.point.periodic_response`).

Method (:func:`critical_delay_at_speed`): g(tau) = ln max|mu|(tau), the logarithm of the
leading multiplier's modulus (zero exactly where |mu| = 1, and better scaled than |mu| - 1
at low speed, where |mu| = exp(T x a mean growth rate) spans many decades). A first guess
is the low-speed estimate below; the bracket [a, b] with g(a) < 0 < g(b) is grown from it by
steps of 1 %, each step's factor squared (down to :data:`TAU_FLOOR`, up to the longest delay
the discretisation resolves at that speed), then Brent's method solves g = 0 to a relative
tolerance of 1e-9 in tau. One discretisation (its number of Chebyshev intervals sized for
the bracket's top) serves the whole solve, so the function solved is smooth in tau.

Low-speed limit (:func:`frozen_rate`, :func:`frozen_critical_delay`). As v -> 0 the vehicle
crosses a span slowly compared with its own dynamics, and every multiplier follows one root
of the vehicle frozen at each position (the adiabatic limit of a slowly varying linear
system): ln|mu| / T tends to the mean over the positions of that root's real part. The
leading multiplier is then the root *branch* with the largest mean real part, followed
continuously along the span, which is not the mean of the spectral abscissa (the rightmost
root at each position, whichever it is) when different roots are rightmost at different
positions: the mean of a maximum exceeds the maximum of the means. On the unit with a delay
this is the case: near mid-span the controller's fast root (about 140 rad/s) is rightmost,
near the supports the slow suspension root (-0.389 1/s) is, and the delay at which the
abscissa's mean crosses 0 (1.599 ms on turnout-soft with one mode per span) lies far below
the crossing of the controller's branch mean (1.947 ms), which is the true limit (the tests
check the growth between two low speeds against both). Computed here independently of any
periodic solve: quasi-static states at 40 positions, the roots of the discretised delay
system's Jacobian there (v = 0), the :data:`TRACKED` rightmost ones at the first position
followed from position to position by a one-to-one assignment to the closest roots, their
mean real parts, and the largest solved for 0 in tau. The mid-span value
(``positions=None``) is the vehicle standing at mid-span; with one mode per span the unit
there is model A, and its critical delay is model A's.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from maglev_match.analyses.speed.options import SpeedOptions
from maglev_match.analyses.speed.passage import quasi_static_state, slot_flags
from maglev_match.analyses.speed.point import periodic_response
from maglev_match.core.params import Params
from maglev_match.core.reprs import compact_repr
from maglev_match.maglev import moving as mv
from maglev_match.maglev import moving_delay as md
from maglev_match.maglev.moving import MovingModel

__all__ = ["TAU_FLOOR", "SpeedCriticalDelay", "frozen_positions", "frozen_rate",
           "with_critical_delay",
           "frozen_critical_delay", "critical_delay_at_speed"]

#: the smallest delay (s) a bracket of the critical delay is grown down to
TAU_FLOOR = 1e-5
#: relative tolerance of the solve in tau
TAU_RTOL = 1e-9
#: root branches followed along the span for the low-speed limit
TRACKED = 8


@dataclass(frozen=True)
class SpeedCriticalDelay:
    """The critical delay at one speed (SI units).

    speed (m/s); value : tau_c (s; 0 when the response is unstable without delay, NaN when
    not found); status : "solved", "unstable without delay", "stable in range" (stable up
    to the longest delay the discretisation resolves), "failed"; multiplier (re, im) : the
    leading multiplier at tau_c (at v = 0: the rightmost root, 1/s); bracket (s);
    evaluations : periodic solves (eigen-analyses at v = 0) used; frozen : the low-speed
    limit (the position-averaged frozen estimate, s; NaN when not computed); nodes : the
    Chebyshev intervals of the discretisation; message : why it failed, or ''."""

    __repr__ = compact_repr

    speed: float
    value: float
    status: str
    multiplier: tuple[float, float]
    bracket: tuple[float, float]
    evaluations: int
    frozen: float = math.nan
    nodes: int = 0
    message: str = ""

    def to_json(self) -> dict:
        return dataclasses.asdict(self)

    @classmethod
    def from_json(cls, d: dict) -> SpeedCriticalDelay:
        d = dict(d)
        d["multiplier"] = tuple(d["multiplier"])
        d["bracket"] = tuple(d["bracket"])
        return cls(**d)


# ---------------------------------------------------------------------------------------
# the frozen (v = 0) spectra and the low-speed limit
# ---------------------------------------------------------------------------------------
def frozen_positions(params: Params, kind: MovingModel, positions: int | None = 40
                     ) -> np.ndarray:
    """Front positions (m from slot A's left support) of the frozen vehicle: ``positions``
    equally spaced over one passage (the midpoints of equal parts, as
    :func:`~maglev_match.analyses.speed.point.adiabatic_rate`), or None: the vehicle centred
    at mid-span only."""
    L = float(params.L)
    if positions is None:
        return np.array([0.5 * (L + mv.layout_of(params, kind).extent)])
    return L + (np.arange(int(positions)) + 0.5) * L / int(positions)


class _Frozen:
    """The frozen vehicle's discretised delay systems at a set of positions (quasi-static
    states and parameter vectors computed once, one discretisation sized for ``tau_max``)."""

    def __init__(self, params: Params, kind: MovingModel, fronts: np.ndarray, tau_max: float):
        self.params, self.kind = params, MovingModel(kind)
        self.items = []
        for xf in fronts:
            x = quasi_static_state(params, self.kind, float(xf))
            fb, rb = slot_flags(params, self.kind, float(xf))
            p = mv.moving_param_vector(params, self.kind, v=0.0, x_front=float(xf),
                                       front_on_B=fb, rear_on_B=rb)
            self.items.append((x, p))
        self.system = md.moving_delay_system(params, self.kind, self.items[0][1],
                                             tau=tau_max, tau_max=tau_max)
        self.evaluations = 0

    def spectra(self, tau: float) -> list[np.ndarray]:
        """The characteristic roots (1/s) of the discretised system at every position for
        the delay tau (s), those with Im >= 0, rightmost first."""
        out = []
        for x, p in self.items:
            pd = md.delayed_vector(p, tau)
            J = self.system.jacobian(self.system.lift(x, pd), pd)[:-1, :-1]
            lam = np.linalg.eigvals(J)
            lam = lam[lam.imag >= -1e-9 * np.maximum(1.0, np.abs(lam))]
            out.append(lam[np.argsort(-lam.real)])
        self.evaluations += 1
        return out

    def abscissae(self, tau: float) -> np.ndarray:
        """The spectral abscissa (1/s) at every position for the delay tau (s)."""
        return np.array([float(s[0].real) for s in self.spectra(tau)])

    def tracked(self, tau: float, branches: int = TRACKED) -> float:
        """max over root branches of the branch's mean real part (1/s): the ``branches``
        rightmost roots at the first position, each followed from position to position
        (the closest root, one-to-one, by an assignment on the ``2 branches`` rightmost)."""
        from scipy.optimize import linear_sum_assignment

        spec = self.spectra(tau)
        cur = spec[0][:branches]
        total = cur.real.copy()
        for lam in spec[1:]:
            cand = lam[:2 * branches]
            cost = np.abs(cur[:, None] - cand[None, :])
            rows, cols = linear_sum_assignment(cost)
            nxt = cur.copy()
            nxt[rows] = cand[cols]
            cur = nxt
            total += cur.real
        return float(np.max(total / len(spec)))


def frozen_rate(params: Params, model: str, tau: float, positions: int | None = 40,
                tau_max: float | None = None, *, tracked: bool = True) -> float:
    """The low-speed limit of ln max|mu| / T (1/s) at the delay ``tau`` (s), from the
    discretised delay system frozen at ``positions`` positions (``positions=None``: the
    vehicle centred at mid-span): with ``tracked``, the largest mean real part of a root
    followed along the span (module docstring); otherwise the mean of the spectral
    abscissa (the rightmost root at each position, whichever it is)."""
    kind = MovingModel(model)
    fr = _Frozen(params, kind, frozen_positions(params, kind, positions),
                 tau if tau_max is None else tau_max)
    return fr.tracked(tau) if tracked else float(np.mean(fr.abscissae(tau)))


def _bracket_and_solve(g, guess: float, top: float, grow: float = 1.01):
    """Grow a bracket of a sign change of g (negative below) from ``guess`` within
    [TAU_FLOOR, top] (steps of a factor ``grow``, squared after every step) and solve it by
    Brent's method. Returns (root or None, (a, b), status, message)."""
    import scipy.optimize

    a = b = min(max(guess, TAU_FLOOR), top)
    ga = gb = g(a)
    if ga < 0:
        while gb < 0:
            if b >= top:
                return None, (a, b), "stable in range", (
                    f"stable up to {top:.4g} s, the longest delay the discretisation "
                    "resolves")
            a, ga = b, gb
            b = min(b * grow, top)
            grow = min(grow * grow, 2.0)
            gb = g(b)
    else:
        while ga >= 0:
            if a <= TAU_FLOOR:
                return None, (a, b), "unstable without delay", (
                    f"unstable down to {TAU_FLOOR:g} s")
            b, gb = a, ga
            a = max(a / grow, TAU_FLOOR)
            grow = min(grow * grow, 2.0)
            ga = g(a)
    root = scipy.optimize.brentq(g, a, b, xtol=1e-15, rtol=TAU_RTOL, maxiter=100)
    return float(root), (float(a), float(b)), "solved", ""


def frozen_critical_delay(params: Params, model: str, positions: int | None = 40,
                          guess: float = 1e-3, *, tracked: bool = True
                          ) -> SpeedCriticalDelay:
    """The delay (s) at which the low-speed growth rate (:func:`frozen_rate`, ``tracked``
    or the mean spectral abscissa) crosses 0: the v -> 0 limit of the critical delay at
    speed (``positions=None``: the vehicle frozen at mid-span, the critical delay standing
    still there). Speed 0 in the result; ``multiplier`` holds the rightmost root at the
    middle position (re, im; 1/s)."""
    kind = MovingModel(model)
    top = md.max_delay_at_speed(params, kind, 0.0)
    fronts = frozen_positions(params, kind, positions)
    tau_max = min(top, 4.0 * guess)
    fr = _Frozen(params, kind, fronts, tau_max)

    def g(tau: float) -> float:
        if tracked and positions is not None:
            return fr.tracked(tau)
        return float(np.mean(fr.abscissae(tau)))

    try:
        root, br, status, msg = _bracket_and_solve(g, guess, tau_max)
        if status == "stable in range" and tau_max < top:
            fr = _Frozen(params, kind, fronts, top)
            tau_max = top
            root, br, status, msg = _bracket_and_solve(g, guess, top)
    except (FloatingPointError, np.linalg.LinAlgError, ValueError, RuntimeError) as exc:
        return SpeedCriticalDelay(0.0, math.nan, "failed", (math.nan,) * 2, (math.nan,) * 2,
                                  fr.evaluations, message=str(exc))
    mu = (math.nan, math.nan)
    if root is not None:
        x, p = fr.items[len(fr.items) // 2]
        pd = md.delayed_vector(p, root)
        lam = np.linalg.eigvals(fr.system.jacobian(fr.system.lift(x, pd), pd)[:-1, :-1])
        z = lam[int(np.argmax(lam.real))]
        mu = (float(z.real), abs(float(z.imag)))
    value = root if root is not None else (0.0 if status.startswith("unstable") else math.nan)
    return SpeedCriticalDelay(0.0, float(value), status, mu, br, fr.evaluations,
                              frozen=float(value), nodes=fr.system.nodes, message=msg)


def critical_delay_at_speed(params: Params, model: str, v: float,
                            options: SpeedOptions | None = None, *,
                            guess: float | None = None) -> SpeedCriticalDelay:
    """The critical delay at speed v (m/s; module docstring): the smallest tau (s) at which
    the periodic response's leading multiplier reaches the unit circle, solved in tau (at
    v = 0: the vehicle frozen at mid-span, :func:`frozen_critical_delay`). ``guess``: the
    start of the bracket (default: the low-speed limit). Failures are reported in the
    result (status "failed" and the message), never raised."""
    opts = options or SpeedOptions()
    kind = MovingModel(model)
    if v == 0:
        return frozen_critical_delay(params, kind, positions=None)
    frozen = math.nan
    if guess is None:
        est = frozen_critical_delay(params, kind)
        frozen = est.value
        guess = est.value if np.isfinite(est.value) and est.value > 0 else 1e-3
    top = md.max_delay_at_speed(params, kind, v)
    tau_max = min(top, 2.0 * guess)
    count = [0]
    mus: dict[float, complex] = {}

    def g(tau: float) -> float:
        count[0] += 1
        sol = periodic_response(params.replace(tau=float(tau)), kind, v, opts,
                                tau_max=tau_max)
        if not sol.converged or sol.multipliers is None:
            raise FloatingPointError(f"no periodic response at tau = {tau:.6g} s: "
                                     f"{sol.message}")
        mus[tau] = sol.multipliers.critical
        return float(sol.multipliers.log_abs[0])

    try:
        root, br, status, msg = _bracket_and_solve(g, guess, tau_max)
        if status == "stable in range" and tau_max < top:
            tau_max = top
            root, br, status, msg = _bracket_and_solve(g, guess, top)
    except (FloatingPointError, np.linalg.LinAlgError, ValueError, RuntimeError) as exc:
        return SpeedCriticalDelay(float(v), math.nan, "failed", (math.nan,) * 2,
                                  (math.nan,) * 2, count[0], frozen=frozen, message=str(exc))
    nodes = md.moving_delay_system(
        params, kind, mv.moving_param_vector(params, kind, v=v), tau=tau_max,
        tau_max=tau_max).nodes
    mu = mus.get(root) if root is not None else None
    if status.startswith("unstable"):
        # unstable down to the floor: is the delay-free response unstable too?
        sol0 = periodic_response(params.replace(tau=0.0), kind, v, opts)
        count[0] += 1
        if sol0.converged and sol0.multipliers is not None and sol0.multipliers.largest >= 1:
            return SpeedCriticalDelay(float(v), 0.0, status, (math.nan,) * 2, br, count[0],
                                      frozen=frozen, nodes=nodes,
                                      message="the periodic response is unstable without "
                                      "delay")
        status, msg = "failed", msg + "; stable without delay: the crossing lies below"
    value = root if root is not None else math.nan
    return SpeedCriticalDelay(
        float(v), float(value), status,
        (math.nan, math.nan) if mu is None else (float(mu.real), float(mu.imag)), br,
        count[0], frozen=frozen, nodes=nodes, message=msg)


def with_critical_delay(point, params: Params, model: str, options: SpeedOptions | None = None):
    """A :class:`~maglev_match.analyses.speed.point.SpeedPoint` with its critical delay
    (:func:`critical_delay_at_speed`, the low-speed limit as its guess) filled in."""
    kind = MovingModel(model)
    est = frozen_critical_delay(params, kind)
    guess = est.value if np.isfinite(est.value) and est.value > 0 else None
    cd = critical_delay_at_speed(params, kind, point.speed, options, guess=guess)
    warnings = point.warnings
    if cd.status != "solved":
        warnings = warnings + (f"critical delay at {point.speed * 3.6:g} km/h: {cd.status}"
                               + (f" ({cd.message})" if cd.message else ""),)
    if est.status != "solved":
        warnings = warnings + (f"low-speed limit of the critical delay: {est.status}"
                               + (f" ({est.message})" if est.message else ""),)
    return dataclasses.replace(point, tau_c=cd.value, tau_c_status=cd.status,
                               tau_c_multiplier=cd.multiplier, tau_c_frozen=est.value,
                               warnings=warnings)
