"""Equilibria of x' = f(x, p): Newton's method, eigenvalues, stability, root locus, and
branches of equilibria in one parameter by pseudo-arclength continuation with their special
points (fold LP, branch point BP, Hopf H) located by solving.

Model-agnostic: works on any :class:`~maglev_match.dynamics.system.System`.

Branches (Kuznetsov 2004, sec. 10.2 and 10.4; Govaerts 2000). Unknowns u = (x / x_s,
alpha / alpha_s) with x_s the system's state scale and alpha_s the width of the search
interval; H(u) = f(x, alpha) / r_s with a fixed residual scale r_s. Test functions,
evaluated at every accepted point by :func:`~maglev_match.dynamics.continuation.continuation`:

* LP: the parameter component of the tangent, t_alpha (changes sign at a fold);
* BP: det [H_u; (W t)^T], the determinant of the bordered matrix (regular at a fold,
  singular at a branch point, where it changes sign; Govaerts 2000, sec. 4.2);
* H:  the bialternate-product test prod_{i<j} (lambda_i + lambda_j), normalised as the
  geometric mean of (lambda_i + lambda_j) / (|lambda_i| + |lambda_j|) with its sign; it
  vanishes at Hopf points and at neutral saddles (a real pair +-a); a located zero is a Hopf
  point only when the pair with lambda_i + lambda_j ~ 0 is complex.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import cache
from typing import Any

import jax
import numpy as np
import scipy.linalg

from maglev_match.core.aot import cached_kernel
from maglev_match.core.reprs import compact_repr
from maglev_match.core.results import Plottable
from maglev_match.dynamics.continuation import (
    SOLVED,
    BranchPoint,
    ContinuationOptions,
    SpecialPoint,
    SpecialPointKind,
    StopReason,
    continuation,
    dense_bordered_newton,
    label_points,
)
from maglev_match.dynamics.system import System

__all__ = [
    "EquilibriumResult",
    "StabilityResult",
    "RootLocusResult",
    "find_equilibrium",
    "eigenvalue_analysis",
    "stability",
    "root_locus",
    "EquilibriumSpecialPoint",
    "EquilibriumBranch",
    "equilibrium_branch",
]

# An eigenvalue whose condition number exceeds this is reported as ill-conditioned.
ILL_CONDITIONED = 1e8


@dataclass(frozen=True)
class EquilibriumResult:
    """An equilibrium found by Newton's method, with its diagnostics."""

    __repr__ = compact_repr

    x: np.ndarray
    p: np.ndarray
    converged: bool
    iterations: int
    residual: float  # max |f(x)| in the state's own units per second
    scaled_residual: float  # dimensionless, see System.scaled_residual
    message: str = ""


@dataclass(frozen=True)
class StabilityResult(Plottable):
    """Eigenvalues of the Jacobian at an equilibrium and the stability verdict;
    ``.plot()`` draws the eigenvalues in the complex plane, ``.to_xarray()`` gives them
    with the equilibrium as a dataset."""

    __repr__ = compact_repr

    eigenvalues: np.ndarray  # sorted by real part, largest first (1/s)
    max_real_part: float  # the stability margin is -max_real_part (1/s)
    stable: bool
    condition_numbers: np.ndarray  # of each eigenvalue (same order)
    equilibrium: EquilibriumResult
    warnings: tuple[str, ...] = ()
    #: the system whose equilibrium this is (names of its states and parameters)
    system: Any = field(default=None, repr=False, compare=False)

    @property
    def margin(self) -> float:
        """Stability margin -max Re(lambda) (1/s): positive when stable."""
        return -self.max_real_part

    def to_xarray(self):
        """The eigenvalues and the equilibrium as an :class:`xarray.Dataset`:
        ``eigenvalue_real`` (1/s), ``eigenvalue_imag`` (rad/s) and ``condition_number``
        over ``index`` (largest real part first), ``equilibrium`` over ``state`` (named
        after the system's states when it is known), and the 0-d ``max_real_part``,
        ``margin`` (1/s), ``stable``, ``equilibrium_converged``, ``iterations``,
        ``residual`` and ``scaled_residual``; every variable with ``units`` and
        ``long_name``. Attributes: the verdict, the system's name, its parameter vector
        (``params``, JSON) and the warnings (JSON list)."""
        import json

        import xarray as xr

        from maglev_match import __version__

        eig = np.asarray(self.eigenvalues)
        eq = self.equilibrium
        x = np.asarray(eq.x, float)
        system = self.system
        names = (list(system.state_names) if system is not None
                 and len(system.state_names) == x.size else [f"x{k}" for k in range(x.size)])

        def scalar(value, units, long_name, dtype=float):
            return ((), np.asarray(value, dtype), {"units": units, "long_name": long_name})

        data: dict[str, Any] = {
            "eigenvalue_real": ("index", eig.real, {
                "units": "1/s", "long_name": "real part of the eigenvalue"}),
            "eigenvalue_imag": ("index", eig.imag, {
                "units": "rad/s", "long_name": "imaginary part of the eigenvalue"}),
            "condition_number": ("index", np.asarray(self.condition_numbers, float), {
                "units": "1", "long_name": "condition number of the eigenvalue"}),
            "equilibrium": ("state", x, {"units": "SI (see state)",
                                         "long_name": "equilibrium state (units per state)"}),
            "max_real_part": scalar(self.max_real_part, "1/s", "largest real part of the "
                                    "eigenvalues of the equilibrium"),
            "margin": scalar(self.margin, "1/s", "stability margin -max Re(lambda) "
                             "(positive when stable)"),
            "stable": scalar(self.stable, "1", "equilibrium stable (1) or not (0)", np.int8),
            "equilibrium_converged": scalar(eq.converged, "1", "Newton's method converged "
                                            "at the equilibrium (1) or not (0)", np.int8),
            "iterations": scalar(eq.iterations, "1", "Newton iterations", np.int64),
            "residual": scalar(eq.residual, "SI (see state) per second",
                               "max |f(x)| at the equilibrium"),
            "scaled_residual": scalar(eq.scaled_residual, "1",
                                      "scaled residual at the equilibrium"),
        }
        coords = {
            "index": ("index", np.arange(eig.size), {
                "units": "1", "long_name": "eigenvalue number, largest real part first"}),
            "state": ("state", names, {"units": "1", "long_name": "state name"}),
        }
        attrs: dict[str, Any] = {
            "title": "stability of the equilibrium",
            "verdict": "stable" if self.stable else "unstable",
            "warnings": json.dumps(list(self.warnings)),
            "maglev_match_version": __version__,
        }
        if eq.message:
            attrs["equilibrium_message"] = eq.message
        if system is not None:
            attrs["system"] = str(system.name)
            p = np.asarray(eq.p, float)
            if len(system.param_names) == p.size:
                attrs["params"] = json.dumps(dict(zip(system.param_names, p.tolist(),
                                                      strict=True)))
        return xr.Dataset(data, coords=coords, attrs=attrs)


@dataclass(frozen=True)
class RootLocusResult(Plottable):
    """Eigenvalues of the equilibrium along one parameter."""

    __repr__ = compact_repr

    param: str
    values: np.ndarray
    eigenvalues: np.ndarray  # (n_values, dim), each row sorted by real part desc
    max_real_part: np.ndarray
    converged: np.ndarray  # Newton converged at each value
    equilibria: np.ndarray  # (n_values, dim)
    warnings: tuple[str, ...] = field(default=())
    param_unit: str = ""  # the unit of ``param`` (from the system's param_units)
    #: the design point (the parameter's current value) and its eigenvalues, when known
    design_value: float | None = None
    design_eigenvalues: np.ndarray | None = field(default=None, repr=False)

    @property
    def stability_changes(self) -> list[float]:
        """Where max Re(lambda) changes sign between two values (linear interpolation; the
        Hopf search refines them)."""
        mr, v = np.asarray(self.max_real_part), np.asarray(self.values)
        out = []
        for k in range(len(v) - 1):
            if np.sign(mr[k]) != np.sign(mr[k + 1]):
                t = mr[k] / (mr[k] - mr[k + 1])
                out.append(float(v[k] + t * (v[k + 1] - v[k])))
        return out

    def to_xarray(self, params: Any = None, state_names: tuple[str, ...] | None = None):
        """The locus as an :class:`xarray.Dataset` over (parameter value, eigenvalue index):
        ``eigenvalue_real`` (1/s), ``eigenvalue_imag`` (rad/s), ``max_real_part``,
        ``equilibrium_converged`` and, with ``state_names``, the equilibrium states; every
        variable with ``units`` and ``long_name``. ``params`` (a parameter set: any object
        with ``as_dict()``) is stored as the JSON attribute ``params`` when given."""
        import json

        import xarray as xr

        from maglev_match import __version__

        dim = self.param
        eig = np.asarray(self.eigenvalues)
        data: dict[str, Any] = {
            "eigenvalue_real": ((dim, "index"), eig.real,
                                {"units": "1/s", "long_name": "real part of the eigenvalue"}),
            "eigenvalue_imag": ((dim, "index"), eig.imag,
                                {"units": "rad/s",
                                 "long_name": "imaginary part of the eigenvalue"}),
            "max_real_part": (dim, np.asarray(self.max_real_part),
                              {"units": "1/s", "long_name": "largest real part of the "
                               "eigenvalues of the equilibrium"}),
            "equilibrium_converged": (dim, np.asarray(self.converged).astype(np.int8),
                                      {"units": "1", "long_name": "Newton's method converged "
                                       "at the equilibrium (1) or not (0)"}),
        }
        coords: dict[str, Any] = {
            dim: (dim, np.asarray(self.values), {"units": self.param_unit or "1",
                                                 "long_name": dim}),
            "index": ("index", np.arange(eig.shape[1]),
                      {"units": "1", "long_name": "eigenvalue number, largest real part "
                       "first"})}
        if state_names is not None:
            data["equilibrium"] = ((dim, "state"), np.asarray(self.equilibria),
                                   {"units": "SI (see state)", "long_name": "equilibrium "
                                    "state (units per state)"})
            coords["state"] = ("state", list(state_names), {"units": "1",
                                                            "long_name": "state name"})
        attrs = {"title": f"root locus along {dim}", "maglev_match_version": __version__}
        if params is not None and hasattr(params, "as_dict"):
            attrs["params"] = json.dumps({k: (v.item() if isinstance(v, np.generic) else v)
                                          for k, v in params.as_dict().items()})
        return xr.Dataset(data, coords=coords, attrs=attrs)


def find_equilibrium(
    system: System,
    p: np.ndarray | None = None,
    x0: np.ndarray | None = None,
    tol: float = 1e-12,
    max_iter: int = 50,
) -> EquilibriumResult:
    """Solve f(x, p) = 0 by Newton's method with the exact Jacobian.

    Converged when the scaled residual (dimensionless) is below ``tol``. A singular
    Jacobian or a diverging iteration is reported in the result, never raised.
    """
    p = system.p if p is None else np.asarray(p, float)
    x = np.array(system.x_guess if x0 is None else x0, dtype=float)
    message = ""
    it = 0
    fx, J = system.f_and_jacobian(x, p)
    res = float(np.max(np.abs(fx) / system.residual_scale(J)))
    while res > tol and it < max_iter:
        it += 1
        try:
            dx = np.linalg.solve(J, -fx)
        except np.linalg.LinAlgError:
            message = "singular Jacobian during Newton iteration"
            break
        # damped step: halve until the residual decreases (robust far from the solution)
        lam = 1.0
        for _ in range(30):
            trial = x + lam * dx
            f_t, J_t = system.f_and_jacobian(trial, p)
            r_trial = float(np.max(np.abs(f_t) / system.residual_scale(J_t)))
            if np.isfinite(r_trial) and r_trial < res:
                break
            lam *= 0.5
        else:
            message = "line search failed: the residual does not decrease"
            break
        x, res, fx, J = trial, r_trial, f_t, J_t
    converged = bool(res <= tol)
    if not converged and not message:
        message = f"no convergence in {max_iter} iterations (scaled residual {res:.3e})"
    return EquilibriumResult(
        x=x,
        p=np.array(p),
        converged=converged,
        iterations=it,
        residual=float(np.max(np.abs(fx))),
        scaled_residual=float(res),
        message=message,
    )


def eigenvalue_analysis(J: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eigenvalues of J sorted by real part (largest first) and their condition numbers
    1 / |<left, right>| with unit eigenvectors."""
    w, vl, vr = scipy.linalg.eig(J, left=True, right=True)
    order = np.lexsort((-np.abs(w.imag), -w.real))
    w, vl, vr = w[order], vl[:, order], vr[:, order]
    dots = np.abs(np.sum(np.conj(vl) * vr, axis=0))
    with np.errstate(divide="ignore"):
        cond = np.where(dots > 0, 1.0 / dots, np.inf)
    return w, cond


def stability(
    system: System,
    p: np.ndarray | None = None,
    x0: np.ndarray | None = None,
    equilibrium: EquilibriumResult | None = None,
) -> StabilityResult:
    """Equilibrium, eigenvalues of its Jacobian and the verdict (stable iff all Re < 0)."""
    eq = equilibrium or find_equilibrium(system, p, x0)
    w, cond = eigenvalue_analysis(system.jacobian(eq.x, eq.p))
    warnings = []
    if not eq.converged:
        warnings.append(f"equilibrium not converged: {eq.message}")
    worst = float(np.max(cond)) if cond.size else 0.0
    if worst > ILL_CONDITIONED:
        warnings.append(
            f"eigenvalue problem ill-conditioned (largest eigenvalue condition number {worst:.2e})"
        )
    max_re = float(np.max(w.real))
    return StabilityResult(
        eigenvalues=w,
        max_real_part=max_re,
        stable=bool(max_re < 0 and eq.converged),
        condition_numbers=cond,
        equilibrium=eq,
        warnings=tuple(warnings),
        system=system,
    )


def root_locus(
    system: System,
    param: str,
    values: Sequence[float] | np.ndarray,
    p: np.ndarray | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> RootLocusResult:
    """Eigenvalues of the equilibrium as ``param`` runs through ``values``.

    The equilibrium is continued naturally: each Newton solve starts from the previous one.
    """
    values = np.asarray(values, dtype=float)
    base = system.p if p is None else np.asarray(p, float)
    eigs, eqs, conv = [], [], []
    x = system.x_guess
    warnings: list[str] = []
    for k, v in enumerate(values):
        pk = system.params_with(base, **{param: float(v)})
        eq = find_equilibrium(system, pk, x)
        if eq.converged:
            x = eq.x
        else:
            warnings.append(f"{param} = {v:g}: {eq.message}")
        w, _ = eigenvalue_analysis(system.jacobian(eq.x, pk))
        eigs.append(w)
        eqs.append(eq.x)
        conv.append(eq.converged)
        if progress is not None:
            progress(k + 1, len(values))
    eig_arr = np.array(eigs)
    return RootLocusResult(
        param=param,
        values=values,
        eigenvalues=eig_arr,
        max_real_part=eig_arr.real.max(axis=1),
        converged=np.array(conv),
        equilibria=np.array(eqs),
        warnings=tuple(warnings),
        param_unit=system.param_units.get(param, ""),
    )


# ----------------------------------------------------------------------------------------
# branches of equilibria by pseudo-arclength continuation
# ----------------------------------------------------------------------------------------
#: A special point of an equilibrium branch (LP, BP or H), located by solving inside its
#: step: the package's one special-point record
#: (:class:`~maglev_match.dynamics.continuation.SpecialPoint`) with the equilibrium ``x``,
#: its ``eigenvalues`` and, for H, the ``frequency`` omega of the critical pair (rad/s).
EquilibriumSpecialPoint = SpecialPoint


@dataclass(frozen=True)
class EquilibriumBranch:
    """A branch of equilibria in one parameter (points in order along the arclength)."""

    __repr__ = compact_repr

    param: str
    values: np.ndarray  # parameter at each point (its unit)
    states: np.ndarray  # (n_points, dim) equilibria
    eigenvalues: np.ndarray  # (n_points, dim), each row sorted by real part desc
    special_points: tuple[SpecialPoint, ...]
    stop_reason: StopReason
    message: str
    p: np.ndarray  # parameter vector (the continued entry is replaced along the branch)
    steps: int = 0
    rejected_steps: int = 0
    warnings: tuple[str, ...] = ()

    @property
    def max_real_part(self) -> np.ndarray:
        return self.eigenvalues.real.max(axis=1)

    @property
    def stable(self) -> np.ndarray:
        return self.max_real_part < 0


@cache
def _branch_kernel(rhs):
    """(f, f_x, f_p e) at (x, p) in one jitted call (cached per right-hand side)."""
    jac = jax.jacfwd(rhs, argnums=0)

    def kernel(x, p, e):
        fx, fe = jax.jvp(lambda q: rhs(x, q), (p,), (e,))
        return fx, jac(x, p), fe

    return cached_kernel(kernel, rhs, name="equilibria.branch")


def _sorted_eigs(w: np.ndarray) -> np.ndarray:
    return w[np.lexsort((-np.abs(w.imag), -w.real))]


def pair_crossings(wa: np.ndarray, wb: np.ndarray) -> int:
    """Number of complex eigenvalues (Im > 0) of wa whose nearest eigenvalue in wb has a
    real part of the other sign: complex pairs that crossed the imaginary axis."""
    k = 0
    for lam in wa[wa.imag > 1e-9]:
        mu = wb[int(np.argmin(np.abs(wb - lam)))]
        if mu.imag > 1e-9 and (lam.real > 0) != (mu.real > 0):
            k += 1
    return k


@cache
def _pairs(n: int) -> tuple[np.ndarray, np.ndarray]:
    return np.triu_indices(n, 1)


def _hopf_test(w: np.ndarray) -> tuple[float, int, int]:
    """Signed geometric mean of (l_i + l_j) / (|l_i| + |l_j|), i < j (real number), and the
    pair (i, j) with the smallest normalised |l_i + l_j|."""
    n = w.size
    if n < 2:
        return 1.0, 0, 0
    i, j = _pairs(n)
    s = w[i] + w[j]
    den = np.abs(w[i]) + np.abs(w[j])
    r = np.where(den > 0, s / np.where(den > 0, den, 1.0), 0.0)
    k = int(np.argmin(np.abs(r)))
    if np.any(np.abs(r) == 0):
        return 0.0, int(i[k]), int(j[k])
    g = float(np.exp(np.mean(np.log(np.abs(r)))))
    # the product is real: non-real sums come with their conjugates (product |.|^2 > 0),
    # so its sign is the product of the signs of the real sums
    real_r = np.abs(r.imag) <= 1e-12 * np.abs(r)
    sign = float(np.prod(np.sign(r.real[real_r]))) if np.any(real_r) else 1.0
    return sign * g, int(i[k]), int(j[k])


class EquilibriumProblem:
    """f(x, alpha) = 0 in scaled unknowns, for :func:`continuation`."""

    def __init__(self, system: System, param: str, base: np.ndarray, x0: np.ndarray,
                 alpha_scale: float, tol: float):
        self.system = system
        self.k = system.param_index(param)
        self.base = np.array(base, float)
        self.xs = np.asarray(system.state_scale, float)
        self.alpha_scale = float(alpha_scale)
        n = system.dim
        _, J0 = system.f_and_jacobian(x0, self.base)
        self.rs = system.residual_scale(J0 * 1.0)
        self.weights = np.concatenate([np.full(n, 1.0 / n), [1.0]])
        self.tol = tol
        self.min_split = 0.0  # smallest step that admissible() may still reject
        self._last = None  # the last correction
        self._kernel = _branch_kernel(system.rhs)
        self._e = np.zeros(self.base.size)
        self._e[self.k] = 1.0

    def unpack(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        n = self.system.dim
        p = self.base.copy()
        p[self.k] = u[n] * self.alpha_scale
        return u[:n] * self.xs, p

    def pack(self, x: np.ndarray, alpha: float) -> np.ndarray:
        return np.concatenate([np.asarray(x, float) / self.xs, [alpha / self.alpha_scale]])

    def parameter(self, u: np.ndarray) -> float:
        return float(u[-1] * self.alpha_scale)

    def fun(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """H(u) and H_u(u) = [f_x X_s, f_alpha alpha_s] / r_s (one compiled call)."""
        x, p = self.unpack(u)
        fx, J, fa = (np.asarray(a) for a in self._kernel(x, p, self._e))
        A = np.column_stack([J * self.xs[None, :], fa * self.alpha_scale]) / self.rs[:, None]
        return fx / self.rs, A

    def correct(self, u_pred, row, target, max_iter):
        self._last = dense_bordered_newton(self.fun, u_pred, row, target, self.tol, max_iter)
        return self._last

    def eigenvalues(self, u: np.ndarray) -> np.ndarray:
        x, p = self.unpack(u)
        return _sorted_eigs(np.linalg.eigvals(self.system.jacobian(x, p)))

    def test_functions(self, pt: BranchPoint) -> dict[str, float]:
        # the Jacobian of the corrector's last iterate (within the Newton tolerance of
        # the solution) serves for the eigenvalues and the bordered determinant
        _, A = pt.correction.data
        J = A[:, :-1] * self.rs[:, None] / self.xs[None, :]
        w = _sorted_eigs(np.linalg.eigvals(J))
        pt.info["eigenvalues"] = w
        M = np.vstack([A, (self.weights * pt.t)[None, :]])
        h, _, _ = _hopf_test(w)
        return {"LP": float(pt.t[-1]), "BP": float(np.linalg.det(M)), "H": h}

    def event_kind(self, name: str) -> SpecialPointKind:
        return {"LP": SpecialPointKind.LP, "BP": SpecialPointKind.BP,
                "H": SpecialPointKind.HOPF}[name]

    def classify(self, name, pt: BranchPoint, a, b):
        if name != "H":
            return self.event_kind(name)
        w = self.eigenvalues(pt.u)
        _, i, j = _hopf_test(w)
        om = abs(w[i].imag)
        # a neutral saddle (real pair +-a) also zeroes the test: not a Hopf point
        if om <= 1e-8 * max(1.0, float(np.max(np.abs(w)))):
            return None
        return SpecialPointKind.HOPF

    def admissible(self, a: BranchPoint, u_new: np.ndarray, s: float) -> bool:
        """Reject a jump to another branch (the corrected point must stay near the
        predictor), and a step in which two or more complex pairs cross the imaginary
        axis (their signs would cancel in the Hopf test): the step is then halved until
        each crossing has a step of its own (down to ``min_split``)."""
        d = u_new - a.u
        if float(np.sqrt(np.sum(self.weights * d * d))) > 3.0 * s:
            return False
        wa = a.info.get("eigenvalues")
        if wa is None or s <= self.min_split:
            return True
        return pair_crossings(wa, self._eigs_of_correction(u_new)) <= 1

    def _eigs_of_correction(self, u: np.ndarray) -> np.ndarray:
        """Eigenvalues of J at a corrected point, from the corrector's last Jacobian."""
        corr = self._last
        if corr is None or corr.u is not u:
            return self.eigenvalues(u)
        _, A = corr.data
        return np.linalg.eigvals(A[:, :-1] * self.rs[:, None] / self.xs[None, :])


def equilibrium_branch(
    system: System,
    param: str,
    start: float,
    stop: float,
    p: np.ndarray | None = None,
    x0: np.ndarray | None = None,
    options: ContinuationOptions | None = None,
    n_points: int = 200,
    progress: Callable[[int, int], None] | None = None,
) -> EquilibriumBranch:
    """The branch of equilibria through the equilibrium at ``param`` = ``start``, followed by
    pseudo-arclength continuation towards ``stop`` (through folds), with LP, BP and Hopf
    points located by solving their test functions inside the step.

    Parameters
    ----------
    system : the ODE system; ``p`` its parameter vector (default the system's).
    param : the continuation parameter; ``start``, ``stop`` the search interval (its unit).
    x0 : guess of the equilibrium at ``start`` (default the system's guess).
    options : continuation options; by default the largest step is 1 / (n_points - 1) of
        the interval (in the scaled arclength), so the branch is sampled at least as finely
        as a grid of ``n_points`` values, and the bounds are the interval.
    progress : progress(k, n_points) after each accepted point.

    Returns
    -------
    :class:`EquilibriumBranch`; failure is a stop reason and a warning, never raised.
    """
    base = np.array(system.p if p is None else p, float)
    lo, hi = sorted((float(start), float(stop)))
    width = hi - lo if hi > lo else max(1.0, abs(lo))
    pk = system.params_with(base, **{param: float(start)})
    outside = system.range_violation(param, float(start))
    if outside:  # the model is not defined there
        return EquilibriumBranch(
            param=param, values=np.zeros(0), states=np.zeros((0, system.dim)),
            eigenvalues=np.zeros((0, system.dim), complex), special_points=(),
            stop_reason=StopReason.NEWTON_FAILED, message=f"the start {outside}", p=base,
            warnings=(f"the equilibrium branch cannot start: {outside}",))
    valid = system.valid_bounds(param, None)
    eq = find_equilibrium(system, pk, x0)
    if not eq.converged and eq.scaled_residual > 1e-9:
        return EquilibriumBranch(
            param=param, values=np.array([float(start)]), states=eq.x[None, :],
            eigenvalues=_sorted_eigs(np.linalg.eigvals(system.jacobian(eq.x, pk)))[None, :],
            special_points=(), stop_reason=StopReason.NEWTON_FAILED,
            message=f"no equilibrium at {param} = {start:g}: {eq.message}", p=base,
            warnings=(f"{param} = {start:g}: equilibrium not found ({eq.message})",))
    ds_max = 1.0 / max(int(n_points) - 1, 1)
    opt = options or ContinuationOptions(ds=0.25 * ds_max, ds_min=1e-7 * ds_max,
                                         ds_max=ds_max, max_steps=50 * int(n_points),
                                         newton_tol=1e-10, param_bounds=(lo, hi))
    if valid is not None:  # never beyond the valid range (a stop there, with a warning)
        opt = dataclasses.replace(opt, param_bounds=system.valid_bounds(param,
                                                                         opt.param_bounds))
    prob = EquilibriumProblem(system, param, base, eq.x, width, opt.newton_tol)
    prob.min_split = 1e3 * opt.ds_min
    u0 = prob.pack(eq.x, float(start))
    t0 = np.zeros_like(u0)
    t0[-1] = 1.0 if stop >= start else -1.0

    def notify(step, pt):
        if progress is not None:
            progress(min(step + 1, n_points), n_points)

    res = continuation(prob, u0, t0, opt, progress=notify)
    warnings: list[str] = []
    if res.stop_reason in (StopReason.STEP_TOO_SMALL, StopReason.NEWTON_FAILED,
                           StopReason.MAX_STEPS):
        warnings.append(f"equilibrium continuation stopped: {res.message}")
    values = np.array([pt.value for pt in res.points])
    states = np.array([prob.unpack(pt.u)[0] for pt in res.points]).reshape(-1, system.dim)
    eigs = np.array([pt.info["eigenvalues"] for pt in res.points])
    specials = []
    for ev in res.events:
        if ev.kind == SpecialPointKind.BOUND:
            if valid is not None and res.points and min(
                    abs(res.points[-1].value - b) for b in (lo, hi)) > 1e-9 * max(
                    1.0, abs(res.points[-1].value)):
                warnings.append(f"the equilibrium branch reached the end of the valid range "
                                f"of {param} at {res.points[-1].value:.8g}")
            continue
        kind = SpecialPointKind(ev.kind)
        if ev.point is None:
            warnings.append(f"{kind} between steps {ev.step} and {ev.step + 1}: {ev.located}")
            continue
        w = ev.point.info["eigenvalues"]
        om = 0.0
        if kind == SpecialPointKind.HOPF:
            _, i, _ = _hopf_test(w)
            om = float(abs(w[i].imag))
        if ev.located != SOLVED:
            warnings.append(f"{kind} at {param} = {ev.point.value:.8g}: {ev.located}")
        specials.append(SpecialPoint(
            type=kind, value=ev.point.value, x=prob.unpack(ev.point.u)[0], eigenvalues=w,
            frequency=om, step=ev.step, located=ev.located))
    specials = label_points(specials)
    return EquilibriumBranch(param=param, values=values, states=states, eigenvalues=eigs,
                             special_points=tuple(specials), stop_reason=res.stop_reason,
                             message=res.message, p=base, steps=max(len(res.points) - 1, 0),
                             rejected_steps=res.rejected, warnings=tuple(warnings))
