"""The two-parameter Hopf curve by pseudo-arclength continuation of the standard defining
system, its codimension-two points, and an independent stability grid.

Defining system (real form; Kuznetsov 2004, sec. 10.2.2), unknowns (x, v1, v2, omega,
alpha1, alpha2):

    f(x, alpha) = 0,   J v1 + omega v2 = 0,   J v2 - omega v1 = 0,   <c, v1> = 1,   <c, v2> = 0

so that q = v1 + i v2 satisfies J q = i omega q. Along the curve: l1 at every point;
generalised Hopf (GH, l1 = 0), zero-Hopf (ZH) and double-Hopf (HH) points located by
solving; Bogdanov-Takens (BT) when the frequency falls to zero.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from functools import cache

import jax
import jax.numpy as jnp
import numpy as np

from maglev_match.core.aot import cached_kernel
from maglev_match.core.reprs import compact_repr
from maglev_match.core.results import Plottable
from maglev_match.dynamics.continuation import (
    SOLVED,
    BranchPoint,
    ContinuationOptions,
    Correction,
    Event,
    SpecialPoint,
    SpecialPointKind,
    StopReason,
    continuation,
    label_points,
    signed_geometric_mean,
)
from maglev_match.dynamics.hopf import (
    HopfPoint,
    eigenvector_scale,
    hopf_defining_kernels,
    locate_hopf_points,
    normalise_pair,
    other_eigenvalues,
    pack_hopf,
    unpack_hopf,
)
from maglev_match.dynamics.normal_forms import (
    l1_from_forms,
    null_vector,
    second_lyapunov_coefficient,
)
from maglev_match.dynamics.system import System

__all__ = [
    "HopfCurvePoint",
    "CodimTwoPoint",
    "HopfCurve",
    "hopf_curve",
    "hopf_curves_from_scans",
    "stability_grid",
]


@dataclass(frozen=True)
class HopfCurvePoint:
    """One point of a two-parameter Hopf curve."""

    values: tuple[float, float]  # the two parameter values
    x: np.ndarray
    frequency: float  # omega (rad/s)
    l1: float  # first Lyapunov coefficient (1/s, <q,q> = 1)
    others_stable: bool  # every other eigenvalue has Re < 0
    n_unstable_others: int  # number of other eigenvalues with Re > 0


#: A codimension-two point on the Hopf curve: the package's one special-point record
#: (:class:`~maglev_match.dynamics.continuation.SpecialPoint`) with ``type`` GH
#: (generalised Hopf / Bautin, l1 = 0), BT (Bogdanov-Takens, omega -> 0), ZH (zero-Hopf, a
#: real eigenvalue at 0) or HH (double Hopf, a second imaginary pair); ``values`` the two
#: parameters there, ``l2`` (GH), ``other_frequency`` (HH), ``residual``, ``located``.
CodimTwoPoint = SpecialPoint


@dataclass(frozen=True)
class HopfCurve(Plottable):
    """A branch of the Hopf curve in the plane of two parameters."""

    __repr__ = compact_repr

    params: tuple[str, str]
    points: list[HopfCurvePoint]
    special_points: list[SpecialPoint]
    converged: bool
    message: str
    steps: int
    closed: bool = False  # the branch came back to its start
    warnings: tuple[str, ...] = ()

    def values(self) -> np.ndarray:
        """(n, 2) array of the two parameter values along the branch."""
        return np.array([pt.values for pt in self.points]).reshape(-1, 2)

    def l1(self) -> np.ndarray:
        return np.array([pt.l1 for pt in self.points])

    def frequency(self) -> np.ndarray:
        return np.array([pt.frequency for pt in self.points])

    def labels(self) -> list[str]:
        """Labels of the codimension-two points along the branch (GH1, HH1, ...)."""
        return [sp.label for sp in self.special_points]

    def to_xarray(self, units: tuple[str, str] = ("", ""),
                  state_names: tuple[str, ...] | None = None):
        """The branch as an :class:`xarray.Dataset`: both parameters, frequency, l1,
        equilibrium states and stability of the other eigenvalues per point; the
        codimension-two points with their labels. ``units`` of the two parameters.
        Every variable has ``units`` and ``long_name``."""
        import xarray as xr

        p1, p2 = self.params
        v = self.values()
        n = self.points[0].x.size if self.points else 0
        names = list(state_names) if state_names else [f"x{k}" for k in range(n)]
        data = {
            p1: (("point",), v[:, 0], {"units": units[0], "long_name": f"{p1} on the curve"}),
            p2: (("point",), v[:, 1], {"units": units[1], "long_name": f"{p2} on the curve"}),
            "frequency": (("point",), self.frequency(),
                          {"units": "rad/s", "long_name": "Hopf frequency omega"}),
            "l1": (("point",), self.l1(), {"units": "1/s", "long_name": "first Lyapunov "
                                           "coefficient (<q,q> = 1, <p,q> = 1)"}),
            "others_stable": (("point",), np.array([pt.others_stable for pt in self.points],
                                                   np.int8),
                              {"units": "1", "long_name": "1 if every other eigenvalue has "
                               "Re < 0"}),
            "equilibrium": (("point", "state"),
                            np.array([pt.x for pt in self.points]).reshape(-1, n),
                            {"units": "state units", "long_name": "equilibrium state"}),
        }
        sps = self.special_points
        coords = {"state": ("state", names, {"units": "1", "long_name": "state name"}),
                  "special_label": ("special", self.labels(),
                                    {"units": "1", "long_name": "special point label"})}
        nan = float("nan")
        data.update({
            "special_type": (("special",), np.array([sp.type for sp in sps], object),
                             {"units": "1", "long_name": "GH, BT, ZH or HH"}),
            f"special_{p1}": (("special",), np.array([sp.values[0] for sp in sps], float),
                              {"units": units[0], "long_name": f"{p1} at the point"}),
            f"special_{p2}": (("special",), np.array([sp.values[1] for sp in sps], float),
                              {"units": units[1], "long_name": f"{p2} at the point"}),
            "special_frequency": (("special",), np.array([sp.frequency for sp in sps], float),
                                  {"units": "rad/s", "long_name": "Hopf frequency there"}),
            "special_l2": (("special",), np.array([nan if sp.l2 is None else sp.l2
                                                   for sp in sps], float),
                           {"units": "1/s", "long_name": "second Lyapunov coefficient (GH)"}),
            "special_located": (("special",), np.array([sp.located for sp in sps], object),
                                {"units": "1", "long_name": "how it was located"}),
        })
        return xr.Dataset(data, coords=coords, attrs={
            "params": f"{p1},{p2}", "converged": int(self.converged),
            "message": self.message, "closed": int(self.closed),
            "title": f"Hopf curve in ({p1}, {p2})"})


@dataclass
class _Branch:
    """Working state of one direction of the continuation."""

    zs: list  # accepted points (unscaled z, each with its own normalisation vector)
    cs: list  # normalisation vectors c
    info: list  # (l1, n_pos_real_others, n_pos_complex_others, others_stable)
    message: str = ""
    ok: bool = True
    closed: bool = False
    bt: bool = False
    events: list = field(default_factory=list)  # codimension-two events of the driver






class _HopfCurveSolver:
    """Pseudo-arclength continuation of the standard Hopf defining system."""

    def __init__(self, system: System, params: tuple[str, str], base: np.ndarray,
                 bounds: dict[str, tuple[float, float]], omega0: float, tol: float):
        self.system = system
        self.n = system.dim
        self.idx = tuple(system.param_index(k) for k in params)
        self.params = params
        self.base = base
        self.bounds = [tuple(map(float, bounds[k])) for k in params]
        ranges = [abs(b - a) for a, b in self.bounds]
        self.S = eigenvector_scale(system, omega0, ranges)
        self.G, self.DG, self.GDG = hopf_defining_kernels(system.rhs, self.idx)
        self.pj = np.asarray(base)
        self.jac = system.derivatives.jacobian
        self.tol = tol

    # --- basic pieces ---
    def residual_and_jac(self, u: np.ndarray, c: np.ndarray):
        z = u * self.S
        g, A = self.GDG(z, self.pj, np.asarray(c))
        return np.asarray(g), np.asarray(A) * self.S[None, :]

    def tangent(self, u: np.ndarray, c: np.ndarray, orient: np.ndarray | None,
                A: np.ndarray | None = None) -> np.ndarray:
        """Unit tangent of the curve in scaled variables (oriented along ``orient``);
        ``A`` is the scaled Jacobian of the defining system if already known."""
        if A is None:
            _, A = self.residual_and_jac(u, c)
        if orient is None:
            _, _, vh = np.linalg.svd(A)
            t = vh[-1]
        else:
            M = np.vstack([A, orient[None, :]])
            rhs = np.zeros(A.shape[0] + 1)
            rhs[-1] = 1.0
            try:
                t = np.linalg.solve(M, rhs)
            except np.linalg.LinAlgError:
                _, _, vh = np.linalg.svd(A)
                t = vh[-1]
                if t @ orient < 0:
                    t = -t
        return t / np.linalg.norm(t)

    def correct(self, u_pred: np.ndarray, c: np.ndarray, row: np.ndarray, target: float,
                max_iter: int = 10) -> tuple[np.ndarray | None, int]:
        """Newton on [G(u) = 0; row . u = target]; returns (u, iterations) or (None, k)."""
        u = u_pred.copy()
        for k in range(1, max_iter + 1):
            g, A = self.residual_and_jac(u, c)
            self.last_jacobian = A
            H = np.concatenate([g, [row @ u - target]])
            M = np.vstack([A, row[None, :]])
            try:
                du = -np.linalg.solve(M, H)
            except np.linalg.LinAlgError:
                return None, k
            if not np.all(np.isfinite(du)):
                return None, k
            u = u + du
            if np.max(np.abs(du)) < self.tol:
                return u, k
        return None, max_iter

    def point_info(self, z: np.ndarray) -> tuple[float, int, int, bool, np.ndarray]:
        """l1, the numbers of other real / complex eigenvalues with Re > 0, others_stable,
        and the sorted other eigenvalues."""
        n = self.n
        x, _, _, om, al = unpack_hopf(z, n)
        pv = self.full_p(al)
        J = np.asarray(self.jac(x, pv))
        w = np.linalg.eigvals(J)
        others = other_eigenvalues(w, abs(om))
        others = others[np.lexsort((-np.abs(others.imag), -others.real))]
        if om > 0:
            q = z[n : 2 * n] + 1j * z[2 * n : 3 * n]
            q = q / np.linalg.norm(q[:getattr(self.system, "normal_form_dim", None)])
            padj = null_vector(J.T + 1j * om * np.eye(n))
            padj = padj / np.conj(np.vdot(padj, q))
            l1 = l1_from_forms(self.system.rhs, x, pv, J, om, q, padj)
        else:
            l1 = float("nan")
        imag_tol = 1e-7 * max(1.0, abs(om))
        pos = others.real > 0
        n_real = int(np.sum(pos & (np.abs(others.imag) <= imag_tol)))
        n_cplx = int(np.sum(pos & (np.abs(others.imag) > imag_tol)))
        return l1, n_real, n_cplx, bool(np.all(others.real < 0)), others

    def full_p(self, al) -> np.ndarray:
        pv = self.base.copy()
        pv[list(self.idx)] = al
        return pv

    def in_bounds(self, z: np.ndarray) -> int:
        """-1 if inside the bounds, else the index of a violated parameter."""
        al = z[3 * self.n + 1 :]
        for k, (a, b) in enumerate(self.bounds):
            lo, hi = min(a, b), max(a, b)
            if not lo <= al[k] <= hi:
                return k
        return -1

    # --- one direction, by the package's one continuation driver ---
    def run(self, z0: np.ndarray, c0: np.ndarray, t0: np.ndarray, h0: float, h_max: float,
            h_min: float, max_steps: int, progress, detect: bool = True) -> _Branch:
        br = _Branch(zs=[z0], cs=[c0], info=[self.point_info(z0)[:4]])
        prob = _HopfCurveProblem(self, br, c0, z0 / self.S, detect)
        opt = ContinuationOptions(ds=min(max(h0, h_min), h_max), ds_min=h_min, ds_max=h_max,
                                  max_steps=max_steps,
                                  newton_tol=self.tol, newton_max_iter=10)

        def notify(step, pt):
            if progress is not None:
                progress(len(br.zs))

        res = continuation(prob, z0 / self.S, t0, opt, progress=notify)
        br.events = [e for e in res.events if not e.name.startswith("B")]
        if res.stop_reason == StopReason.EVENT:
            ev = next(e for e in res.events if e.terminal)
            k = int(ev.name[1])
            a_pt = res.points[-2] if len(res.points) > 1 else res.points[-1]
            z_b = None
            if ev.point is not None:
                z_b = self.land_on_bound(a_pt.u, ev.point.u, prob.c, k)
            if z_b is not None:
                self.accept(br, z_b, prob.c)
            user = getattr(self, "user_bounds", None)
            if user is not None and tuple(sorted(self.bounds[k])) != user[k]:
                lo, hi = sorted(self.bounds[k])
                where = z_b[3 * self.n + 1 + k] if z_b is not None else float("nan")
                end = lo if abs(where - lo) <= abs(where - hi) else hi
                if end not in user[k]:
                    br.message = (f"reached the end of the valid range of {self.params[k]} "
                                  f"({self.params[k]} = {end:.6g})")
                else:
                    br.message = f"reached the bound of {self.params[k]}"
            else:
                br.message = f"reached the bound of {self.params[k]}"
        elif res.stop_reason == StopReason.PROBLEM:
            br.message = res.message
        elif res.stop_reason == StopReason.MAX_STEPS:
            br.ok = False
            br.message = f"stopped after max_steps = {max_steps}"
        elif res.stop_reason in (StopReason.STEP_TOO_SMALL, StopReason.NEWTON_FAILED):
            br.ok = False
            br.message = (f"step size fell below {h_min:g} at "
                          f"{self._where(br.zs[-1])} (corrector failed)")
        return br

    def accept(self, br: _Branch, z: np.ndarray, c: np.ndarray, info=None) -> np.ndarray:
        """Store a point; renew the normalisation <c, v1> = 1, <c, v2> = 0 when the
        eigenvector has drifted far from c (returns the c in force, ``c`` itself if kept)."""
        n = self.n
        x, v1, v2, om, al = unpack_hopf(z, n)
        c_new = c
        if max(np.linalg.norm(v1), np.linalg.norm(v2)) > 2.0 / np.linalg.norm(c):
            v1, v2 = normalise_pair(v1, v2)
            c_new = v1.copy()
        br.zs.append(pack_hopf(x, v1, v2, om, al))
        br.cs.append(c_new)
        # l1 and the other eigenvalues do not depend on the eigenvector normalisation
        br.info.append((info or self.point_info(br.zs[-1]))[:4])
        return c_new

    def land_on_bound(self, u_a, u_b, c, k) -> np.ndarray | None:
        n = self.n
        j = 3 * n + 1 + k
        a, b = self.bounds[k]
        za, zb = u_a * self.S, u_b * self.S
        bound = a if abs(zb[j] - a) < abs(zb[j] - b) else b
        frac = (bound - za[j]) / (zb[j] - za[j])
        u_pred = u_a + frac * (u_b - u_a)
        row = np.zeros_like(u_a)
        row[j] = 1.0
        u, _ = self.correct(u_pred, c, row, bound / self.S[j])
        return None if u is None else u * self.S

    def _where(self, z: np.ndarray) -> str:
        al = z[3 * self.n + 1 :]
        return ", ".join(f"{k} = {v:.6g}" for k, v in zip(self.params, al, strict=True))

@cache
def _pairs(n: int) -> tuple[np.ndarray, np.ndarray]:
    return np.triu_indices(n, 1)


class _HopfCurveProblem:
    """The Hopf defining system in two parameters as a problem for
    :func:`~maglev_match.dynamics.continuation.continuation`: scaled unknowns, Euclidean
    arclength; the eigenvector normalisation <c, v1> = 1, <c, v2> = 0 is renewed on
    acceptance when the eigenvector drifts; the bounds of both parameters are terminal
    test functions; the branch stops at a Bogdanov-Takens point (omega -> 0) or when it
    closes on itself."""

    def __init__(self, solver: _HopfCurveSolver, br: _Branch, c0: np.ndarray,
                 u_start: np.ndarray, detect: bool = True):
        self.detect = detect
        self.solver = solver
        self.br = br
        self.c = c0
        n = solver.n
        self.weights = np.ones_like(u_start)
        self.inv = np.ones_like(u_start)
        self.inv[n : 3 * n] = 0.0  # jumps and closure use the normalisation-free parts
        self.u_start = u_start.copy()
        self.accepted = 0

    def correct(self, u_pred, row, target, max_iter):
        u, its = self.solver.correct(u_pred, self.c, row, target, max_iter)
        if u is None:
            return None
        M = np.vstack([self.solver.last_jacobian, row[None, :]])
        return Correction(u=u, iterations=its, residual=0.0,
                          solve=lambda b, M=M: np.linalg.solve(M, b))

    def parameter(self, u) -> float:
        return float((u * self.solver.S)[3 * self.solver.n + 1])

    def test_functions(self, pt: BranchPoint) -> dict[str, float]:
        """Bounds of both parameters (terminal), and the codimension-two tests (Kuznetsov
        2004, sec. 10.3.1): GH = l1; ZH = the product of the other eigenvalues (zero when
        a real one passes 0); HH = the bialternate product of the other eigenvalues,
        prod_{i<j} (l_i + l_j) (zero when another pair reaches the imaginary axis, or on a
        real pair +-a, which the classifier drops)."""
        z = pt.u * self.solver.S
        al = z[3 * self.solver.n + 1 :]
        out = {}
        for k, (a, b) in enumerate(self.solver.bounds):
            lo, hi = min(a, b), max(a, b)
            out[f"B{k}lo"] = float(al[k] - lo)
            out[f"B{k}hi"] = float(hi - al[k])
        pinfo = self.solver.point_info(z)
        pt.info["pinfo"] = pinfo
        if self.detect:
            l1, _, _, _, others = pinfo
            pt.info["others"] = others
            out["GH"] = l1
            out["ZH"] = signed_geometric_mean(others / (1.0 + np.abs(others)))
            i, j = _pairs(others.size)
            sums = others[i] + others[j]
            out["HH"] = signed_geometric_mean(sums / (np.abs(others[i]) + np.abs(others[j])
                                             + 1e-300))
        return out

    def event_kind(self, name: str) -> str:
        return name if name in ("GH", "ZH", "HH") else SpecialPointKind.BOUND

    def terminal(self, name: str) -> bool:
        return name.startswith("B")

    def classify(self, name: str, pt: BranchPoint, a, b):
        if name.startswith("B"):
            return SpecialPointKind.BOUND
        if name == "HH":
            others = pt.info["others"]
            i, j = np.triu_indices(others.size, 1)
            k = int(np.argmin(np.abs(others[i] + others[j])))
            om2 = abs(others[i[k]].imag)
            if om2 <= 1e-6 * max(1.0, abs(float((pt.u * self.solver.S)[3 * self.solver.n]))):
                return None  # a real pair +-a of the other eigenvalues: no bifurcation
        return getattr(SpecialPointKind, name)

    def admissible(self, a: BranchPoint, u_new: np.ndarray, s: float) -> bool:
        return float(np.linalg.norm((u_new - a.u) * self.inv)) <= 3.0 * s

    def after_accept(self, pt: BranchPoint) -> BranchPoint:
        solver = self.solver
        c_new = solver.accept(self.br, pt.u * solver.S, self.c, pt.info.get("pinfo"))
        u = self.br.zs[-1] / solver.S
        # the driver's tangent (from this point's own corrector) holds unless the
        # eigenvector normalisation was renewed (an event solve in between may have left
        # another Jacobian in the solver, so it is not reused)
        t = pt.t if c_new is self.c else solver.tangent(u, c_new, pt.t * self.inv, None)
        self.c = c_new
        self.accepted += 1
        return BranchPoint(u=u, t=t, value=pt.value, correction=pt.correction,
                           tests=pt.tests, kind=pt.kind, info=pt.info)

    def stop(self, pt: BranchPoint) -> str | None:
        solver, n = self.solver, self.solver.n
        z = self.br.zs[-1]
        if z[3 * n] <= 1e-6 * abs(solver.S[3 * n]):
            self.br.bt = True
            return "frequency fell to zero (Bogdanov-Takens or neutral saddle)"
        if self.accepted > 11 and len(self.br.zs) >= 2:
            u, u_prev = z / solver.S, self.br.zs[-2] / solver.S
            h = float(np.linalg.norm(u - u_prev))
            d = float(np.linalg.norm((u - self.u_start) * self.inv))
            if d < 0.5 * h and float(np.linalg.norm((u_prev - self.u_start) * self.inv)) >= d:
                self.br.closed = True
                return "the curve closed on itself"
        return None


def hopf_curve(
    system: System,
    params: tuple[str, str],
    start: HopfPoint,
    bounds: dict[str, tuple[float, float]],
    p: np.ndarray | None = None,
    initial_step: float = 2e-3,
    max_step: float = 1e-2,
    min_step: float = 1e-9,
    max_steps: int = 5000,
    tol: float = 1e-10,
    both_directions: bool = True,
    detect_special_points: bool = True,
    progress: Callable[[int], None] | None = None,
) -> HopfCurve:
    """Continue a Hopf point in two parameters: the Hopf curve (paper Fig. 4).

    Pseudo-arclength continuation of the standard defining system
    f(x, alpha) = 0, J v1 + omega v2 = 0, J v2 - omega v1 = 0, <c, v1> = 1, <c, v2> = 0
    in scaled variables (states by ``system.state_scale``, parameters by the width of their
    bounds), so turning points in either parameter are passed. Along the curve: l1 at every
    point; generalised Hopf points (l1 = 0) located by solving l1(s) = 0 along the curve
    with l2 there; zero-Hopf (a real eigenvalue crosses 0) and double-Hopf (a second pair
    crosses the imaginary axis) points located by solving for the crossing eigenvalue's real
    part = 0; Bogdanov-Takens when the frequency falls to zero.

    Parameters
    ----------
    params : the two free parameter names; ``start.param`` must be one of them.
    start : a Hopf point (from :func:`locate_hopf_points`).
    bounds : {name: (lo, hi)} for both parameters; the branch stops on them.
    initial_step, max_step, min_step : arclength steps in scaled units (1 = the width of
        the bounds of a parameter).
    both_directions : continue both ways from ``start``.

    Returns
    -------
    :class:`HopfCurve`: points ordered along the branch, special points, diagnostics.
    A stalled continuation is reported (``converged`` False, ``message``), never raised.
    """
    if start.param not in params:
        raise ValueError(f"start point is along '{start.param}', not one of {params}")
    for k in params:
        if k not in bounds:
            raise ValueError(f"no bounds given for parameter '{k}'")
    base = np.array(start.p if p is None else p, float)
    base[system.param_index(start.param)] = start.value
    n = system.dim
    # the curve may not leave the parameters' valid ranges (System.param_ranges)
    valid = {k: system.valid_bounds(k, bounds[k]) for k in params}
    if any(lo >= hi for lo, hi in valid.values()):
        return HopfCurve(params=tuple(params), points=[], special_points=[], converged=False,
                         message="the bounds lie outside the parameters' valid ranges",
                         steps=0)
    solver = _HopfCurveSolver(system, tuple(params), base, valid, start.frequency, tol)
    solver.user_bounds = [tuple(sorted(map(float, bounds[k]))) for k in params]
    v1, v2 = normalise_pair(start.q.real, start.q.imag)
    c0 = v1.copy()
    al0 = base[list(solver.idx)]
    z0 = pack_hopf(start.x, v1, v2, start.frequency, al0)
    warnings: list[str] = []
    # make the start point exact for this normalisation
    u0, _ = solver.correct(z0 / solver.S, c0, np.zeros_like(z0), 0.0)
    if u0 is not None:
        z0 = u0 * solver.S
    if solver.in_bounds(z0) >= 0:
        return HopfCurve(params=tuple(params), points=[], special_points=[], converged=False,
                         message="the start point lies outside the bounds", steps=0)
    t0 = solver.tangent(z0 / solver.S, c0, None)
    branches = [solver.run(z0, c0, t0, initial_step, max_step, min_step, max_steps,
                           progress, detect_special_points)]
    if both_directions and not branches[0].closed:
        branches.append(solver.run(z0, c0, -t0, initial_step, max_step, min_step,
                                   max_steps, progress, detect_special_points))
    # assemble in order: reversed second direction, then the first
    zs, cs, info = list(branches[0].zs), list(branches[0].cs), list(branches[0].info)
    if len(branches) > 1:
        b = branches[1]
        zs = b.zs[:0:-1] + zs
        cs = b.cs[:0:-1] + cs
        info = b.info[:0:-1] + info
    special: list[SpecialPoint] = []
    events = (branches[1].events[::-1] if len(branches) > 1 else []) + branches[0].events
    if detect_special_points and _gh_at_start(branches):
        # l1 is exactly 0 at the start (a scan that starts on the GH point, e.g. at the middle
        # of a symmetric range): the driver locates sign changes inside steps, and a step
        # that starts on the zero has none, so the start point itself is the GH point
        events.insert(len(branches[1].events) if len(branches) > 1 else 0, Event(
            name="GH", kind=str(SpecialPointKind.GH), step=0, located=SOLVED, value=0.0,
            point=BranchPoint(u=z0 / solver.S, t=t0, value=float(al0[0]), correction=None)))
    for ev in events:
        special.extend(_codim_two(solver, ev, warnings))
    for br in branches:
        if br.bt:
            z = br.zs[-1]
            al = z[3 * n + 1 :]
            special.append(SpecialPoint(
                type=SpecialPointKind.BT, value=float(al[0]),
                values=(float(al[0]), float(al[1])), frequency=float(z[3 * n]),
                located="frequency fell to zero; the last solved point of the curve"))
    special = label_points(special)
    pts = []
    for z, inf in zip(zs, info, strict=True):
        x, _, _, om, al = unpack_hopf(z, n)
        pts.append(HopfCurvePoint(values=(float(al[0]), float(al[1])), x=x, frequency=om,
                                  l1=inf[0], others_stable=inf[3],
                                  n_unstable_others=inf[1] + inf[2]))
    ok = all(br.ok for br in branches)
    message = "; ".join(f"direction {k + 1}: {br.message}" for k, br in enumerate(branches))
    return HopfCurve(params=tuple(params), points=pts, special_points=special, converged=ok,
                     message=message, steps=len(pts) - 1,
                     closed=any(br.closed for br in branches), warnings=tuple(warnings))


def _gh_at_start(branches) -> bool:
    """Whether l1 is exactly 0 at the start point and changes sign through it (the first
    points of the two directions have opposite signs)."""
    if len(branches) < 2 or any(len(br.info) < 2 for br in branches):
        return False
    l1_start, l1_a, l1_b = branches[0].info[0][0], branches[0].info[1][0], branches[1].info[1][0]
    return l1_start == 0.0 and l1_a * l1_b < 0.0


def _codim_two(solver: _HopfCurveSolver, ev, warnings: list[str]) -> list[SpecialPoint]:
    """The codimension-two point of a located event of the Hopf curve (GH with l2)."""
    n = solver.n
    if ev.point is None:
        warnings.append(f"could not locate the {ev.kind} point after step {ev.step}: "
                        f"{ev.located}")
        return []
    z = ev.point.u * solver.S
    x, _, _, om, al = unpack_hopf(z, n)
    conv = ev.located == "solved"
    if not conv:
        warnings.append(f"{ev.kind} point after step {ev.step}: {ev.located}")
    res = abs(ev.value)
    if ev.kind == "GH":
        try:
            _, l2 = second_lyapunov_coefficient(solver.system, x, solver.full_p(al), om)
        except np.linalg.LinAlgError:
            l2 = float("nan")
        return [SpecialPoint(type=SpecialPointKind.GH, value=float(al[0]),
                             values=(float(al[0]), float(al[1])), frequency=om, l2=l2,
                             located=SOLVED if conv else "not solved", residual=float(res),
                             step=ev.step)]
    other = None
    if ev.kind == "HH":
        others = ev.point.info["others"]
        i, j = np.triu_indices(others.size, 1)
        k = int(np.argmin(np.abs(others[i] + others[j])))
        other = float(abs(others[i[k]].imag))
    return [SpecialPoint(type=SpecialPointKind(ev.kind), value=float(al[0]),
                         values=(float(al[0]), float(al[1])), frequency=om,
                         other_frequency=other, located=SOLVED if conv else "not solved",
                         residual=float(res), step=ev.step)]


@cache
def _newton_batch(rhs, n_iter: int = 12):
    jac = jax.jacfwd(rhs, argnums=0)

    def solve(x0, p):
        def body(x, _):
            return x - jnp.linalg.solve(jac(x, p), rhs(x, p)), None

        x, _ = jax.lax.scan(body, x0, None, length=n_iter)
        return x, rhs(x, p), jac(x, p)

    return cached_kernel(jax.vmap(solve, in_axes=(None, 0)), rhs, n_iter,
                         name="hopf_curve.newton_batch")


def stability_grid(
    system: System,
    params: tuple[str, str],
    values1: np.ndarray,
    values2: np.ndarray,
    p: np.ndarray | None = None,
    x0: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Largest real part of the Jacobian's eigenvalues at the equilibrium on a grid.

    Equilibria by a batched (vmapped) Newton iteration from ``x0`` (default the system's
    guess). Returns (max_real_part, converged), both shaped (len(values2), len(values1));
    max_real_part in 1/s, NaN where Newton did not converge.
    """
    base = system.p if p is None else np.asarray(p, float)
    i1, i2 = system.param_index(params[0]), system.param_index(params[1])
    V1, V2 = np.meshgrid(np.asarray(values1, float), np.asarray(values2, float))
    P = np.repeat(base[None, :], V1.size, axis=0)
    P[:, i1] = V1.ravel()
    P[:, i2] = V2.ravel()
    x_start = system.x_guess if x0 is None else np.asarray(x0, float)
    xs, fs, Js = _newton_batch(system.rhs)(jnp.asarray(x_start), jnp.asarray(P))
    xs, fs, Js = np.asarray(xs), np.asarray(fs), np.asarray(Js)
    denom = np.abs(Js) @ system.state_scale
    scaled = np.max(np.abs(fs) / np.where(denom > 0, denom, 1.0), axis=1)
    ok = np.isfinite(scaled) & (scaled < 1e-8)
    mr = np.full(V1.size, np.nan)
    good = np.where(ok)[0]
    if good.size:
        mr[good] = np.linalg.eigvals(Js[good]).real.max(axis=1)
    return mr.reshape(V1.shape), ok.reshape(V1.shape)


def _on_curve(hp, curves: Sequence[HopfCurve], names: tuple[str, str], system: System,
              bounds: Mapping[str, tuple[float, float]]) -> bool:
    """Whether a Hopf point lies on a branch already computed: within 2 % in the plane
    (scaled by the bounds) plus the relative frequency difference."""
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


def hopf_curves_from_scans(
    system: System,
    names: tuple[str, str],
    bounds: Mapping[str, tuple[float, float]],
    scan_values: Sequence[float],
    n_scan: int = 100,
    max_step: float = 1e-2,
    progress: Callable[[str], None] | None = None,
) -> tuple[list[HopfCurve], list[str]]:
    """Every branch of the Hopf curve met by Hopf searches along names[0] (inside its
    bounds) at the given values of names[1], each branch continued inside ``bounds`` and
    computed once (a Hopf point on a branch already found starts no new one).

    Returns the branches and the warnings of the searches.
    """
    curves: list[HopfCurve] = []
    warnings: list[str] = []
    lo, hi = bounds[names[0]]
    for v2 in scan_values:
        p = system.params_with(**{names[1]: v2})
        scan = locate_hopf_points(system, names[0], lo, hi, p, n_scan=n_scan)
        warnings.extend(scan.warnings)
        for hp in scan.points:
            if not hp.converged or _on_curve(hp, curves, names, system, bounds):
                continue
            if progress is not None:
                progress(f"continuing the branch through {names[0]} = {hp.value:.6g}, "
                         f"{names[1]} = {v2:.6g}")
            curves.append(hopf_curve(system, names, hp, bounds, max_step=max_step))
    return curves, warnings
