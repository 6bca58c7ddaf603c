"""Hopf points of equilibria of x' = f(x, p) along one parameter: located on the
equilibrium branch by the Hopf test function, refined by Newton's method on the defining
system, validated, with crossing speed and first Lyapunov coefficient.

Model-agnostic: works on any :class:`~maglev_match.dynamics.system.System`.

Defining system (real form; Kuznetsov 2004, sec. 10.2.2), unknowns (x, v1, v2, omega,
free parameters):

    f(x, alpha) = 0,   J v1 + omega v2 = 0,   J v2 - omega v1 = 0,   <c, v1> = 1,   <c, v2> = 0

so that q = v1 + i v2 satisfies J q = i omega q. With one free parameter the system is
square and Newton's method refines a Hopf point to full precision; with two free parameters
it defines the Hopf curve (:mod:`maglev_match.dynamics.hopf_curve`, which imports this
module; this one does not import it). The Lyapunov coefficients are in
:mod:`maglev_match.dynamics.normal_forms`, re-exported here.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cache
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from maglev_match.core.aot import cached_kernel
from maglev_match.core.reprs import compact_repr
from maglev_match.core.results import Plottable
from maglev_match.dynamics.normal_forms import (
    first_lyapunov_coefficient,
    hopf_eigenvectors,
    second_lyapunov_coefficient,
)
from maglev_match.dynamics.system import System

__all__ = [
    "HopfPoint",
    "HopfScan",
    "locate_hopf_points",
    "refine_hopf_point",
    "first_lyapunov_coefficient",
    "second_lyapunov_coefficient",
    "hopf_eigenvectors",
]


# ----------------------------------------------------------------------------------------
# results
# ----------------------------------------------------------------------------------------
@dataclass(frozen=True)
class HopfPoint:
    """A Hopf point of the equilibrium along one parameter, refined on the defining system."""

    __repr__ = compact_repr

    param: str  # the continuation parameter name
    value: float  # its value at the Hopf point (SI unit of that parameter)
    x: np.ndarray  # equilibrium state there
    p: np.ndarray  # full parameter vector there
    frequency: float  # omega (rad/s), eigenvalues +-i omega
    q: np.ndarray  # complex right eigenvector, J q = i omega q, <q,q> = 1
    p_adj: np.ndarray  # complex adjoint eigenvector, J^T p = -i omega p, <p,q> = 1
    crossing_speed: float  # d Re(lambda)/d param (1/s per unit of param)
    l1: float  # first Lyapunov coefficient (paper eq. 24), 1/s with <q,q> = 1
    others_stable: bool  # all other eigenvalues in the open left half-plane
    converged: bool
    residual: float  # max |defining system| at the solution (scaled)
    warnings: tuple[str, ...] = ()
    message: str = ""  # why the point is not converged ('' when it is)

    @property
    def kind(self) -> str:
        """'subcritical' (l1 > 0), 'supercritical' (l1 < 0) or 'degenerate' (l1 = 0)."""
        return _criticality(self.l1)

    def to_xarray(self, param_unit: str = "", state_names: tuple[str, ...] | None = None):
        """The point as an :class:`xarray.Dataset`: the 0-d ``value`` (of :attr:`param`, in
        ``param_unit``), ``frequency`` (rad/s), ``crossing_speed``, ``l1`` (1/s),
        ``others_stable``, ``converged`` and ``residual``; over ``state`` the
        ``equilibrium`` and the real and imaginary parts of the eigenvector ``q`` and of the
        adjoint ``p_adj``; over ``parameter`` the parameter vector ``p``. Every variable
        has ``units`` and ``long_name``; the parameter's name, the criticality (``kind``),
        the message and the warnings (JSON list) are attributes. (No figure: a single
        point is drawn by its :class:`HopfScan`.)"""
        import json

        import xarray as xr

        from maglev_match import __version__

        unit = param_unit or "1"
        x = np.asarray(self.x, float)
        q, padj = np.asarray(self.q), np.asarray(self.p_adj)
        names = (list(state_names) if state_names is not None and len(state_names) == x.size
                 else [f"x{k}" for k in range(x.size)])
        n_q = q.size if q.size == x.size else None

        def scalar(value, units, long_name, dtype=float):
            return ((), np.asarray(value, dtype), {"units": units, "long_name": long_name})

        data: dict[str, Any] = {
            "value": scalar(self.value, unit, f"{self.param} at the Hopf point"),
            "frequency": scalar(self.frequency, "rad/s", "Hopf frequency omega "
                                "(eigenvalues +-i omega)"),
            "crossing_speed": scalar(self.crossing_speed, f"1/s per {unit}",
                                     f"d Re(lambda) / d {self.param} at the crossing"),
            "l1": scalar(self.l1, "1/s", "first Lyapunov coefficient (<q,q> = 1, "
                         "<p,q> = 1)"),
            "others_stable": scalar(self.others_stable, "1", "1 if every other eigenvalue "
                                    "has Re < 0", np.int8),
            "converged": scalar(self.converged, "1", "Newton on the Hopf defining system "
                                "converged and the point is valid (1) or not (0)", np.int8),
            "residual": scalar(self.residual, "1", "scaled residual of the defining system"),
            "equilibrium": ("state", x, {"units": "SI (see state)",
                                         "long_name": "equilibrium state (units per state)"}),
            "p": ("parameter", np.asarray(self.p, float), {
                "units": "SI (see parameter)", "long_name": "parameter vector at the point"}),
        }
        if n_q is not None:
            for key, vec, what in (("q", q, "eigenvector q, J q = i omega q"),
                                   ("p_adj", padj, "adjoint eigenvector p, <p,q> = 1")):
                for part, values in (("real", vec.real), ("imag", vec.imag)):
                    long_name = f"{'real' if part == 'real' else 'imaginary'} part of the {what}"
                    data[f"{key}_{part}"] = ("state", values, {"units": "1",
                                                               "long_name": long_name})
        coords = {"state": ("state", names, {"units": "1", "long_name": "state name"}),
                  "parameter": ("parameter", np.arange(np.asarray(self.p).size),
                                {"units": "1", "long_name": "entry of the parameter vector"})}
        attrs = {"title": f"Hopf point along {self.param}", "param": self.param,
                 "kind": self.kind, "message": self.message,
                 "warnings": json.dumps(list(self.warnings)),
                 "maglev_match_version": __version__}
        return xr.Dataset(data, coords=coords, attrs=attrs)


@dataclass(frozen=True)
class HopfScan(Plottable):
    """Hopf points found along one parameter interval."""

    __repr__ = compact_repr

    param: str
    start: float
    stop: float
    points: list[HopfPoint]
    scan_values: np.ndarray  # parameter along the equilibrium branch (branch order)
    max_real_part: np.ndarray  # max Re(lambda) there (1/s)
    warnings: tuple[str, ...] = ()
    special_points: tuple = ()  # LP, BP, H of the equilibrium branch (EquilibriumSpecialPoint)
    #: the parameters read off each point in its table row (:meth:`records`); the system
    #: the points belong to; how a delay system was discretised ({..., "text": ...})
    columns: tuple[str, ...] = ()
    system: Any = field(default=None, repr=False, compare=False)
    delay: dict | None = None

    def records(self) -> list[dict[str, Any]]:
        """One row per Hopf point: the :attr:`columns` (read off the point's parameter
        vector; the scanned parameter itself where the system does not have it, as a
        beam quantity), frequency, crossing speed, l1, kind, whether the other eigenvalues
        are stable, convergence, residual, warnings and AUTO's label H1, H2, ..."""
        rows = []
        for k, hp in enumerate(self.points):
            rec: dict[str, Any] = {}
            for n in self.columns:
                rec[n] = (hp.value if n == self.param and (
                    self.system is None or n not in self.system.param_names)
                    else self.system.param(n, hp.p))
            rec.update({"frequency": hp.frequency, "crossing_speed": hp.crossing_speed,
                        "l1": hp.l1, "kind": hp.kind, "others_stable": hp.others_stable,
                        "converged": hp.converged, "residual": hp.residual,
                        "warnings": list(hp.warnings), "label": f"H{k + 1}"})
            rows.append(rec)
        return rows

    def to_xarray(self):
        """The scan as an :class:`xarray.Dataset`: over ``scan`` the parameter along the
        equilibrium branch and its ``max_real_part`` (1/s; over ``scan_path`` when the scan
        ran on a parameter path of another length); over ``hopf`` (labels H1, H2, ...) the
        Hopf points' ``value``, ``frequency`` (rad/s), ``crossing_speed``, ``l1`` (1/s),
        ``others_stable``, ``converged``, ``residual`` and ``equilibrium`` (over ``state``);
        over ``special`` the branch's special points (LP, BP, H: ``special_type``,
        ``special_value``, ``special_frequency``). Units of the parameter from the system's
        ``param_units`` when known; the parameter's name, the search interval and the
        warnings (JSON list) are attributes."""
        import json

        import xarray as xr

        from maglev_match import __version__

        system = self.system
        unit = (getattr(system, "param_units", {}) or {}).get(self.param, "") if system \
            is not None else ""
        unit = unit or "1"
        vals = np.asarray(self.scan_values, float)
        mr = np.asarray(self.max_real_part, float)
        pts = self.points
        n = max((np.asarray(hp.x).size for hp in pts), default=0)
        state_names = getattr(system, "state_names", None)
        names = (list(state_names) if state_names is not None and len(state_names) == n
                 else [f"x{k}" for k in range(n)])
        eq = np.full((len(pts), n), np.nan)
        for k, hp in enumerate(pts):
            x = np.asarray(hp.x, float)
            eq[k, :x.size] = x

        def per_point(name, dtype=float):
            return np.array([getattr(hp, name) for hp in pts], dtype)

        margin_dim = "scan" if vals.size == mr.size else "scan_path"
        sps = self.special_points
        data: dict[str, Any] = {
            "max_real_part": (margin_dim, mr, {"units": "1/s", "long_name": "largest real "
                                               "part of the eigenvalues of the equilibrium"}),
            "value": ("hopf", per_point("value"), {"units": unit, "long_name":
                                                   f"{self.param} at the Hopf point"}),
            "frequency": ("hopf", per_point("frequency"), {"units": "rad/s", "long_name":
                                                           "Hopf frequency omega"}),
            "crossing_speed": ("hopf", per_point("crossing_speed"), {
                "units": f"1/s per {unit}",
                "long_name": f"d Re(lambda) / d {self.param} at the crossing"}),
            "l1": ("hopf", per_point("l1"), {"units": "1/s", "long_name": "first Lyapunov "
                                             "coefficient (<q,q> = 1, <p,q> = 1)"}),
            "others_stable": ("hopf", per_point("others_stable", np.int8), {
                "units": "1", "long_name": "1 if every other eigenvalue has Re < 0"}),
            "converged": ("hopf", per_point("converged", np.int8), {
                "units": "1", "long_name": "Hopf point converged and valid (1) or not (0)"}),
            "residual": ("hopf", per_point("residual"), {
                "units": "1", "long_name": "scaled residual of the defining system"}),
            "equilibrium": (("hopf", "state"), eq, {
                "units": "SI (see state)", "long_name": "equilibrium state at the Hopf "
                "point (units per state)"}),
            "special_type": ("special", np.array([str(sp.type) for sp in sps], dtype=str), {
                "units": "1", "long_name": "special point of the equilibrium branch (LP, "
                "BP or H)"}),
            "special_value": ("special", np.array([sp.value for sp in sps], float), {
                "units": unit, "long_name": f"{self.param} at the special point"}),
            "special_frequency": ("special", np.array([sp.frequency for sp in sps], float), {
                "units": "rad/s", "long_name": "frequency of the critical pair (H)"}),
        }
        coords = {
            "scan": ("scan", vals, {"units": unit, "long_name": f"{self.param} along the "
                                    "equilibrium branch (branch order)"}),
            "hopf": ("hopf", [f"H{k + 1}" for k in range(len(pts))], {
                "units": "1", "long_name": "Hopf point label"}),
            "state": ("state", names, {"units": "1", "long_name": "state name"}),
            "special": ("special", np.arange(len(sps)), {
                "units": "1", "long_name": "special point number along the branch"}),
        }
        if margin_dim == "scan_path":
            coords["scan_path"] = ("scan_path", np.arange(mr.size), {
                "units": "1", "long_name": "point of the scanned parameter path"})
        attrs = {"title": f"Hopf points along {self.param}", "param": self.param,
                 "start": float(self.start), "stop": float(self.stop),
                 "kind": json.dumps([hp.kind for hp in pts]),
                 "warnings": json.dumps(list(self.warnings)),
                 "maglev_match_version": __version__}
        if self.delay is not None:
            attrs["delay"] = json.dumps(self.delay, default=str)
        return xr.Dataset(data, coords=coords, attrs=attrs)








def _criticality(l1: float) -> str:
    if not math.isfinite(l1):
        return "unknown"
    if l1 > 0:
        return "subcritical"
    if l1 < 0:
        return "supercritical"
    return "degenerate"


# ----------------------------------------------------------------------------------------
# compiled kernels (cached per right-hand side, so nothing recompiles per call)
# ----------------------------------------------------------------------------------------








@cache
def hopf_defining_kernels(rhs, idx: tuple[int, ...]):
    """Hopf defining system G(z, p, c) and its Jacobian, with z = (x, v1, v2, omega,
    alpha[idx]); G has 3n + 2 components and z has 3n + 1 + len(idx)."""

    def G(z, p, c):
        n = c.shape[0]
        x, v1, v2 = z[:n], z[n : 2 * n], z[2 * n : 3 * n]
        om = z[3 * n]
        pp = p.at[jnp.array(idx)].set(z[3 * n + 1 :])

        def fp(y):
            return rhs(y, pp)

        fx, jv1 = jax.jvp(fp, (x,), (v1,))
        jv2 = jax.jvp(fp, (x,), (v2,))[1]
        return jnp.concatenate([
            fx, jv1 + om * v2, jv2 - om * v1, jnp.stack([c @ v1 - 1.0, c @ v2])
        ])

    DG = jax.jacfwd(G, argnums=0)
    return (cached_kernel(G, rhs, idx, name="hopf.G"),
            cached_kernel(DG, rhs, idx, name="hopf.DG"),
            cached_kernel(lambda z, p, c: (G(z, p, c), DG(z, p, c)), rhs, idx,
                          name="hopf.G_DG"))


@cache
def _crossing_kernel(rhs):
    """d/ds [J(x + s dx, p + s dp) v] at s = 0 (real v)."""

    def dJv(x, p, v, dx, dp):
        def Jv(y, pp):
            return jax.jvp(lambda z: rhs(z, pp), (y,), (v,))[1]

        return jax.jvp(Jv, (x, p), (dx, dp))[1]

    return cached_kernel(dJv, rhs, name="hopf.dJv")


# ----------------------------------------------------------------------------------------
# eigenvectors and Lyapunov coefficients
# ----------------------------------------------------------------------------------------








# ----------------------------------------------------------------------------------------
# Hopf points along one parameter
# ----------------------------------------------------------------------------------------
def pack_hopf(x, v1, v2, omega, alphas) -> np.ndarray:
    return np.concatenate([x, v1, v2, [omega], np.atleast_1d(alphas)])


def unpack_hopf(z: np.ndarray, n: int):
    return z[:n], z[n : 2 * n], z[2 * n : 3 * n], float(z[3 * n]), z[3 * n + 1 :]


def normalise_pair(v1: np.ndarray, v2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotate q = v1 + i v2 by a phase so that v1 is orthogonal to v2, scale |v1| = 1."""
    q = v1 + 1j * v2
    # phase theta maximising |Re(e^{i theta} q)|: principal axis of the ellipse
    theta = -0.5 * np.angle(np.sum(q * q))
    q = q * np.exp(1j * theta)
    scale = np.linalg.norm(q.real)
    if scale == 0:
        scale = 1.0
    q = q / scale
    return q.real.copy(), q.imag.copy()


def other_eigenvalues(w: np.ndarray, omega: float) -> np.ndarray:
    """The eigenvalues other than the pair closest to +-i omega."""
    if w.size < 2:
        return w[:0]
    k1 = int(np.argmin(np.abs(w - 1j * omega)))
    rest = np.delete(w, k1)
    k2 = int(np.argmin(np.abs(rest + 1j * omega)))
    return np.delete(rest, k2)


def refine_hopf_point(
    system: System,
    param: str,
    value: float,
    x: np.ndarray,
    omega: float,
    q: np.ndarray | None = None,
    p: np.ndarray | None = None,
    tol: float = 1e-11,
    max_iter: int = 30,
    value_scale: float | None = None,
    bounds: tuple[float, float] | None = None,
) -> HopfPoint:
    """Refine an approximate Hopf point by Newton's method on the defining system
    (x, v1, v2, omega, param), then compute eigenvectors, crossing speed and l1.

    A converged Newton iteration is validated before the point is called converged
    (Kuznetsov 2004, sec. 10.2.2: the defining system also has spurious solutions, e.g.
    neutral saddles, and Newton may run to a Hopf point of another, unphysical region):
    omega > 0, +-i omega is an eigenvalue pair of the Jacobian there (to 1e-6 relative),
    and the parameter lies inside ``bounds``. Otherwise ``converged`` is False and the
    reason is the point's ``message`` (and a warning). Every Newton iterate must also lie
    in the system's valid range of ``param`` (:attr:`System.param_ranges`): the model is
    not defined outside it (a negative frequency or mass), so an iteration that leaves it
    stops there, not converged, whatever it might have converged to afterwards.

    Parameters
    ----------
    value, x, omega : initial guesses (parameter value, equilibrium state, frequency rad/s).
    q : guess of the complex eigenvector (computed from J when not given).
    value_scale : typical size of ``param`` for the convergence test (default |value|).
    bounds : (lo, hi) of ``param``, the search interval (None: not checked); the
        system's ``param_ranges`` (valid range) is checked too.
    """
    base = system.p if p is None else np.asarray(p, float)
    k = system.param_index(param)
    n = system.dim
    pk = system.params_with(base, **{param: value})
    warnings: list[str] = []
    if q is None:
        w, V = np.linalg.eig(system.jacobian(x, pk))
        j = int(np.argmin(np.abs(w - 1j * omega)))
        q = V[:, j]
    v1, v2 = normalise_pair(np.real(q), np.imag(q))
    c = v1.copy()
    z = pack_hopf(np.asarray(x, float), v1, v2, omega, [value])
    G, DG, _ = hopf_defining_kernels(system.rhs, (k,))
    pj = np.asarray(base)
    cj = np.asarray(c)
    scale = eigenvector_scale(system, omega, [value_scale or abs(value) or 1.0])
    converged = False
    res = np.inf
    n_iter = 0
    left_range = ""
    for n_iter in range(1, max_iter + 1):  # noqa: B007 (n_iter reported below)
        g = np.asarray(G(np.asarray(z), pj, cj))
        A = np.asarray(DG(np.asarray(z), pj, cj))
        try:
            dz = -np.linalg.solve(A, g)
        except np.linalg.LinAlgError:
            warnings.append("singular Hopf defining system (degenerate Hopf point?)")
            break
        if not np.all(np.isfinite(dz)):
            warnings.append("non-finite Newton step")
            break
        z = z + dz
        left = system.range_violation(param, float(z[-1]))
        if left or not np.all(np.isfinite(z)):
            # the model is not defined there (e.g. a negative beam frequency): the Newton
            # path left the valid range, whatever it would converge to afterwards
            left_range = left or "non-finite Newton iterate"
            warnings.append(f"the Newton path left the valid range at iteration {n_iter}: "
                            f"{left_range}")
            break
        step = float(np.max(np.abs(dz) / scale))
        # converged on a small step, or on a residual at round-off level after a small step
        # (the step may stall slightly above tol when the unknowns are far from unit scale)
        if step < tol:
            converged = True
            break
        if step < 1e-6:
            g_new = np.asarray(G(np.asarray(z), pj, cj))
            if np.max(np.abs(g_new[n:])) < 1e-13 * max(1.0, abs(omega)) and np.max(
                    np.abs(g_new[:n]) / (np.abs(A[:n, :n]) @ system.state_scale + 1e-300)
            ) < 1e-13:
                converged = True
                break
    g = np.asarray(G(np.asarray(z), pj, cj))
    res = float(np.max(np.abs(g[:n]) / (np.abs(np.asarray(system.jacobian(z[:n],
                system.params_with(base, **{param: float(z[-1])}))))
                @ system.state_scale + 1e-300)))
    res = max(res, float(np.max(np.abs(g[n:]) / (abs(z[3 * n]) + 1.0))))
    if not converged and not left_range:
        warnings.append(f"Newton on the Hopf defining system did not converge in {n_iter} steps")
    xs, v1, v2, om, al = unpack_hopf(z, n)
    if om < 0:
        om, v2 = -om, -v2
    val = float(al[0])
    pv = system.params_with(base, **{param: val})
    message = ""
    if converged:
        message = _hopf_validation(system, param, val, xs, pv, om, omega, bounds)
        if message:
            converged = False
            warnings.append(f"not a valid Hopf point: {message}")
    elif left_range:
        message = f"the Newton path left the valid range: {left_range}"
    else:
        message = f"Newton on the Hopf defining system did not converge in {n_iter} steps"
    hp = _hopf_point_at(system, param, val, xs, pv, om, converged, res, warnings)
    return dataclasses.replace(hp, message=message) if message else hp


def _hopf_validation(system, param, val, xs, pv, om, omega_guess, bounds) -> str:
    """Why a solution of the defining system is not an acceptable Hopf point ('' if it is)."""
    if not (np.all(np.isfinite(xs)) and math.isfinite(val) and math.isfinite(om)):
        return "non-finite solution"
    if not om > 1e-8 * max(1.0, abs(omega_guess)):
        return f"frequency omega = {om:.3g} rad/s is not positive (Bogdanov-Takens?)"
    w = np.linalg.eigvals(system.jacobian(xs, pv))
    dist = float(np.min(np.abs(w - 1j * om)))
    if dist > 1e-6 * max(1.0, om):
        return (f"+-i {om:.6g} is not an eigenvalue pair of the Jacobian (nearest "
                f"eigenvalue {dist:.2e} away)")
    if bounds is not None:
        lo, hi = sorted(map(float, bounds))
        slack = 1e-12 * max(1.0, abs(lo) if math.isfinite(lo) else 1.0,
                            abs(hi) if math.isfinite(hi) else 1.0)
        if not lo - slack <= val <= hi + slack:
            return f"{param} = {val:.8g} lies outside [{lo:g}, {hi:g}] (the search bounds)"
    return system.range_violation(param, val)


def _hopf_point_at(system, param, val, xs, pv, om, converged, res, warnings) -> HopfPoint:
    J = system.jacobian(xs, pv)
    q, padj = hopf_eigenvectors(J, om, getattr(system, "normal_form_dim", None))
    # crossing speed: d lambda / d alpha = <p, (dJ/dalpha along the equilibrium branch) q>
    fa = system.param_derivative(xs, pv, param)
    try:
        dx = -np.linalg.solve(J, fa)
    except np.linalg.LinAlgError:
        dx = np.zeros_like(xs)
        warnings.append("singular Jacobian: crossing speed ignores the equilibrium's drift")
    dp = np.zeros_like(pv)
    dp[system.param_index(param)] = 1.0
    kern = _crossing_kernel(system.rhs)
    args = (np.asarray(xs), np.asarray(pv))
    dJq = (np.asarray(kern(*args, np.asarray(q.real), np.asarray(dx), np.asarray(dp)))
           + 1j * np.asarray(kern(*args, np.asarray(q.imag), np.asarray(dx),
                                  np.asarray(dp))))
    speed = float(np.real(np.vdot(padj, dJq)))
    l1 = first_lyapunov_coefficient(system, xs, pv, om, q, padj)
    w = np.linalg.eigvals(J)
    others = other_eigenvalues(w, om)
    others_stable = bool(np.all(others.real < 0))
    if abs(speed) < 1e-12 * max(1.0, om):
        warnings.append("crossing speed is zero: the transversality condition fails")
    return HopfPoint(
        param=param, value=val, x=np.asarray(xs), p=np.asarray(pv), frequency=float(om),
        q=q, p_adj=padj, crossing_speed=speed, l1=float(l1), others_stable=others_stable,
        converged=bool(converged), residual=float(res), warnings=tuple(warnings),
    )


def eigenvector_scale(system: System, omega: float, alpha_scales) -> np.ndarray:
    n = system.dim
    return np.concatenate([
        system.state_scale, np.ones(2 * n), [max(abs(omega), 1.0)], np.asarray(alpha_scales)
    ])


def locate_hopf_points(
    system: System,
    param: str,
    start: float,
    stop: float,
    p: np.ndarray | None = None,
    n_scan: int = 200,
    progress: Callable[[int, int], None] | None = None,
) -> HopfScan:
    """Hopf points of the equilibrium as ``param`` runs from ``start`` to ``stop``.

    The equilibrium is followed by pseudo-arclength continuation
    (:func:`~maglev_match.dynamics.equilibria.equilibrium_branch`, through folds, so every
    part of an S-shaped equilibrium curve is visited), sampled at least as finely as
    ``n_scan`` values; the Hopf test function (bialternate product) is located by solving
    inside its step, then each point is refined to full precision by Newton's method on
    the Hopf defining system (x, v1, v2, omega, param) and validated
    (:func:`refine_hopf_point`). ``scan_values`` and ``max_real_part`` are the branch's
    parameter values and largest real parts, in branch order.
    """
    from maglev_match.dynamics.continuation import SpecialPointKind, StopReason
    from maglev_match.dynamics.equilibria import equilibrium_branch

    base = system.p if p is None else np.asarray(p, float)
    branch = equilibrium_branch(system, param, start, stop, p=base, n_points=int(n_scan),
                                progress=progress)
    warnings = list(branch.warnings)
    lo, hi = sorted((float(start), float(stop)))
    specials = list(branch.special_points)
    values, max_re = branch.values, branch.max_real_part
    design = float(base[system.param_index(param)])
    reached = abs(float(branch.values[-1]) - float(stop)) <= 1e-9 * max(1.0, hi - lo)
    if (branch.stop_reason in (StopReason.NEWTON_FAILED, StopReason.STEP_TOO_SMALL)
            and not reached and lo < design < hi):
        # The equilibrium was lost on the way (or not found at the interval's end, far from
        # the system's guess): follow it again from the design value, where the guess is
        # an equilibrium, towards both ends of the interval.
        parts = [equilibrium_branch(system, param, design, end, p=base,
                                    n_points=max(int(n_scan) // 2, 3)) for end in (start, stop)]
        warnings = [f"the equilibrium was lost ({'; '.join(branch.warnings) or branch.message})"
                    f"; followed again from the design value {param} = {design:.6g} towards "
                    "both ends"]
        for b in parts:
            warnings.extend(b.warnings)
            specials.extend(b.special_points)
        values = np.concatenate([parts[0].values[::-1], parts[1].values[1:]])
        max_re = np.concatenate([parts[0].max_real_part[::-1], parts[1].max_real_part[1:]])
    points: list[HopfPoint] = []
    for sp in specials:
        if sp.type != SpecialPointKind.HOPF:
            continue
        hp = refine_hopf_point(system, param, sp.value, sp.x, sp.frequency, p=base,
                               value_scale=max(abs(sp.value), hi - lo), bounds=(lo, hi))
        if sp.located != "solved":
            hp = _with_warning(hp, f"Hopf test function {sp.located}")
        if any(abs(hp.value - o.value) <= 1e-9 * max(1.0, abs(o.value))
               and abs(hp.frequency - o.frequency) <= 1e-6 * o.frequency for o in points):
            continue
        points.append(hp)
    points.sort(key=lambda h: h.value)
    return HopfScan(param=param, start=float(start), stop=float(stop), points=points,
                    scan_values=values, max_real_part=max_re,
                    warnings=tuple(warnings), special_points=tuple(specials))


def _with_warning(hp: HopfPoint, msg: str) -> HopfPoint:
    return dataclasses.replace(hp, warnings=hp.warnings + (msg,))
