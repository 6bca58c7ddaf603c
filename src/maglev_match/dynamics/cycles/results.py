"""What a cycle branch returns: the converged cycles (:class:`CyclePoint`, with multipliers,
read-outs and the continuation state to restart from, :class:`RestartState`), the branch
(:class:`CycleBranch`, with its special points and why it stopped, :class:`CycleStop`), a
cycle solved at a fixed parameter (:class:`CorrectionResult`); the branch as an
:class:`xarray.Dataset` with units and long names on every variable (:func:`branch_to_xarray`,
saved as netCDF) and the restart state of a saved point (:func:`load_restart`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from enum import StrEnum
from typing import Any

import numpy as np

from maglev_match.core.reprs import compact_repr
from maglev_match.core.results import Plottable
from maglev_match.dynamics.continuation import SpecialPoint, SpecialPointKind
from maglev_match.dynamics.cycles.orbits import HopfStart, PeriodicOrbit
from maglev_match.dynamics.system import System

__all__ = [
    "CorrectionResult",
    "CycleBranch",
    "CyclePoint",
    "CycleStop",
    "RestartState",
    "branch_to_xarray",
    "load_restart",
]


class CycleStop(StrEnum):
    """Why a cycle branch stopped (the strings of JSON and files)."""

    STOP_AT = "reached stop_at"
    CONTACT = "contact with a physical limit"
    LIMIT = "contact with a physical limit"  # the earlier name of CONTACT (alias)
    BOUND = "left parameter range"
    RANGE = "reached the end of the parameter's valid range"
    HOMOCLINIC = "homoclinic approach"
    PERIOD = "homoclinic approach"  # the earlier name of HOMOCLINIC (alias)
    HOPF = "the family closed at a Hopf point"
    STEP_TOO_SMALL = "step too small"
    NEWTON_FAILED = "newton failed"
    MAX_STEPS = "max_steps"


@dataclass(frozen=True)
class RestartState:
    """What a continuation needs to go on from a cycle: the profile on its mesh, period,
    parameter, the tangent (same layout, physical units: d profile, d T, d lambda per unit
    of scaled arclength), the next step size and the count of accepted steps (for the mesh
    adaptation schedule)."""

    mesh: np.ndarray
    states: np.ndarray
    period: float
    value: float
    t_states: np.ndarray
    t_period: float
    t_value: float
    ds: float
    accepted: int


@dataclass(frozen=True)
class CyclePoint:
    """One converged cycle on a branch with its Floquet multipliers and read-outs."""

    __repr__ = compact_repr

    value: float  # continuation parameter
    period: float  # s
    orbit: PeriodicOrbit
    multipliers: np.ndarray  # nontrivial Floquet multipliers (the one nearest 1 removed)
    trivial_multiplier: complex  # should be 1: its distance to 1 is an accuracy check
    n_unstable: int  # multipliers with |mu| > 1 (trivial excluded)
    stable: bool
    extrema: Mapping[str, tuple[float, float]]  # observable -> (max, min) over the cycle
    converged: bool
    iterations: int
    residual: float
    kind: str = "step"  # "step", "stop_at", "contact", "bound", or a special-point type
    reliable: bool = True  # |trivial multiplier - 1| within tolerance: stability trusted
    restart: RestartState | None = None  # to continue from this point (saved branches)
    stability: str = ""  # Stability: stable, unstable, neutral (|mu| ~ 1) or unknown

    def max(self, name: str) -> float:
        return self.extrema[name][0]

    def min(self, name: str) -> float:
        return self.extrema[name][1]


@dataclass(frozen=True)
class CycleBranch(Plottable):
    """A branch of periodic orbits continued in one parameter from a Hopf point."""

    __repr__ = compact_repr

    param: str
    hopf: HopfStart
    points: tuple[CyclePoint, ...]
    special_points: tuple[SpecialPoint, ...]
    stopped_reason: str
    warnings: tuple[str, ...] = ()
    ntst: int = 0
    ncol: int = 0
    steps: int = 0  # continuation steps taken (accepted)
    rejected_steps: int = 0
    newton_iterations: int = 0  # corrector iterations over the whole run (linear solves)
    factorizations: int = 0  # factorisations of the bordered Jacobian over the run
    message: str = ""  # how the branch ended, in words (a homoclinic approach, a Hopf point)
    chart_from: float | None = None  # parameter where the regular chart took over (or None)

    @property
    def closed_at(self) -> SpecialPoint | None:
        """The Hopf point where the family of cycles ends (special point H), if it does."""
        return next((sp for sp in self.special_points
                     if sp.type == SpecialPointKind.HOPF), None)

    @property
    def values(self) -> np.ndarray:
        return np.array([c.value for c in self.points])

    @property
    def periods(self) -> np.ndarray:
        return np.array([c.period for c in self.points])

    @property
    def stable(self) -> np.ndarray:
        return np.array([c.stable for c in self.points], dtype=bool)

    @property
    def n_unstable(self) -> np.ndarray:
        return np.array([c.n_unstable for c in self.points], dtype=int)

    @property
    def converged(self) -> np.ndarray:
        return np.array([c.converged for c in self.points], dtype=bool)

    def observable_max(self, name: str) -> np.ndarray:
        return np.array([c.extrema[name][0] for c in self.points])

    def observable_min(self, name: str) -> np.ndarray:
        return np.array([c.extrema[name][1] for c in self.points])

    @property
    def last(self) -> CyclePoint | None:
        return self.points[-1] if self.points else None

    def to_xarray(self, system: System | None = None, param_unit: str = "",
                  state_units: Sequence[str] | None = None):
        """The full branch as an xarray Dataset (see :func:`branch_to_xarray`)."""
        return branch_to_xarray(self, system, param_unit, state_units)


@dataclass(frozen=True)
class CorrectionResult:
    """A cycle solved at a fixed parameter value (Newton on the collocation system)."""

    point: CyclePoint | None
    converged: bool
    iterations: int
    message: str = ""


def _point_labels(branch: CycleBranch) -> list[str]:
    return [f"P{k}" for k in range(len(branch.points))]


def branch_to_xarray(branch: CycleBranch, system: System | None = None,
                     param_unit: str = "", state_units: Sequence[str] | None = None):
    """The full branch as an :class:`xarray.Dataset`: parameter values, periods, profiles on
    each point's mesh, multipliers, stability, the continuation state needed to restart
    (tangent, next step, accepted steps), the special points with their labels and solved
    orbits, and the Hopf start. Every variable has ``units`` and ``long_name``."""
    import xarray as xr

    pts = list(branch.points)
    sps = [sp for sp in branch.special_points if sp.point is not None]
    n = len(branch.hopf.x)
    N = pts[0].orbit.states.shape[0] if pts else (sps[0].point.orbit.states.shape[0]
                                                    if sps else 1)
    names = list(system.state_names) if system is not None else [f"x{k}" for k in range(n)]
    su = list(state_units) if state_units is not None else [""] * n
    unit_of_states = ", ".join(f"{a} [{b}]" for a, b in zip(names, su, strict=True))
    pname = branch.param

    def cyc_arrays(cs: list[CyclePoint]):
        k = len(cs)
        nm = n - 1
        rs = [c.restart for c in cs]
        mult = np.full((k, nm), np.nan, complex)
        for i, c in enumerate(cs):
            mu = np.asarray(c.multipliers, complex)
            mult[i, : mu.size] = mu
        def rv(attr, shape):
            out = np.full((k, *shape), np.nan)
            for i, r in enumerate(rs):
                if r is not None:
                    out[i] = getattr(r, attr)
            return out
        return {
            "value": np.array([c.value for c in cs]),
            "period": np.array([c.period for c in cs]),
            "profile": np.array([c.orbit.states for c in cs]).reshape(k, N, n),
            "mesh": np.array([c.orbit.mesh for c in cs]).reshape(k, -1),
            "mult_re": mult.real, "mult_im": mult.imag,
            "triv_re": np.array([complex(c.trivial_multiplier).real for c in cs]),
            "triv_im": np.array([complex(c.trivial_multiplier).imag for c in cs]),
            "stable": np.array([c.stable for c in cs], np.int8),
            "reliable": np.array([c.reliable for c in cs], np.int8),
            "n_unstable": np.array([c.n_unstable for c in cs], np.int32),
            "kind": np.array([c.kind for c in cs], object),
            "r_mesh": rv("mesh", (branch.ntst + 1,)),
            "r_states": rv("states", (N, n)), "r_period": rv("period", ()),
            "r_value": rv("value", ()), "r_t_states": rv("t_states", (N, n)),
            "r_t_period": rv("t_period", ()), "r_t_value": rv("t_value", ()),
            "r_ds": rv("ds", ()), "r_accepted": rv("accepted", ()),
        }

    def add(ds_vars, prefix, dim, arr):
        pr = f"{prefix}_" if prefix else ""
        what = "special point" if prefix else "branch point"
        spec = [
            ("value", (dim,), param_unit, f"{pname} at the {what}"),
            ("period", (dim,), "s", "period of the cycle"),
            ("profile", (dim, "node", "state"), "state units",
             f"cycle states at the collocation nodes ({unit_of_states})"),
            ("mesh", (dim, "mesh_node"), "1", "mesh in normalised time t / T"),
            ("mult_re", (dim, "multiplier"), "1", "nontrivial Floquet multipliers, real part"),
            ("mult_im", (dim, "multiplier"), "1", "nontrivial Floquet multipliers, imag part"),
            ("triv_re", (dim,), "1", "trivial Floquet multiplier (should be 1), real part"),
            ("triv_im", (dim,), "1", "trivial Floquet multiplier, imaginary part"),
            ("stable", (dim,), "1", "1 if no multiplier lies outside the unit circle"),
            ("reliable", (dim,), "1", "1 if the trivial multiplier is within tolerance of 1"),
            ("n_unstable", (dim,), "1", "number of multipliers outside the unit circle"),
            ("kind", (dim,), "1", "kind of point (step, stop_at, contact, LPC, PD, ...)"),
            ("r_mesh", (dim, "mesh_node"), "1", "restart: mesh the continuation went on with"),
            ("r_states", (dim, "node", "state"), "state units",
             "restart: profile on the restart mesh"),
            ("r_period", (dim,), "s", "restart: period"),
            ("r_value", (dim,), param_unit, f"restart: {pname}"),
            ("r_t_states", (dim, "node", "state"), "state units per unit arclength",
             "restart: tangent of the profile"),
            ("r_t_period", (dim,), "s per unit arclength", "restart: tangent of the period"),
            ("r_t_value", (dim,), f"{param_unit} per unit arclength".strip(),
             f"restart: tangent of {pname}"),
            ("r_ds", (dim,), "1", "restart: next arclength step (scaled units)"),
            ("r_accepted", (dim,), "1", "restart: accepted steps so far (mesh schedule)"),
        ]
        for key, dims, units, long in spec:
            ds_vars[pr + key] = (dims, arr[key], {"units": units, "long_name": long})

    data: dict[str, Any] = {}
    coords: dict[str, Any] = {"state": ("state", names, {"long_name": "state name",
                                                          "units": "1"})}
    if pts:
        add(data, "", "point", cyc_arrays(pts))
        coords["label"] = ("point", _point_labels(branch), {"long_name": "point label",
                                                              "units": "1"})
    if sps:
        add(data, "special", "special", cyc_arrays([sp.point for sp in sps]))
        coords["special_label"] = ("special", [sp.label for sp in sps],
                                   {"long_name": "special point label", "units": "1"})
        for key, vals, long in (("special_type", [sp.type for sp in sps], "type (LPC, BP, "
                                 "PD, NS; contact: a physical limit reached)"),
                                ("special_located", [sp.located for sp in sps], "how it was "
                                 "located: solved, or why not"),
                                ("special_detail", [sp.detail for sp in sps], "detail")):
            data[key] = (("special",), np.array(vals, object), {"units": "1",
                                                                 "long_name": long})
        data["special_step"] = (("special",), np.array([sp.step for sp in sps], np.int32),
                                {"units": "1", "long_name": "index of the point before it"})
    h = branch.hopf
    data["hopf_x"] = (("state",), np.asarray(h.x, float),
                      {"units": "state units", "long_name": "equilibrium at the Hopf point"})
    data["hopf_q_re"] = (("state",), np.real(h.q), {"units": "1", "long_name":
                                                   "critical eigenvector, real part"})
    data["hopf_q_im"] = (("state",), np.imag(h.q), {"units": "1", "long_name":
                                                   "critical eigenvector, imaginary part"})
    pnames = list(system.param_names) if system is not None else \
        [f"p{k}" for k in range(len(h.p))]
    coords["parameter"] = ("parameter", pnames, {"long_name": "parameter name", "units": "1"})
    data["hopf_p"] = (("parameter",), np.asarray(h.p, float),
                      {"units": "parameter units", "long_name": "parameters at the Hopf point"})
    end = branch.closed_at
    attrs = {"param": pname, "param_unit": param_unit, "ntst": branch.ntst,
             "ncol": branch.ncol, "stopped_reason": str(branch.stopped_reason),
             "end": branch.message,
             "closed_at_hopf": np.nan if end is None else float(end.value),
             "hopf_value": h.value, "hopf_frequency": h.frequency,
             "hopf_l1": np.nan if h.l1 is None else h.l1,
             "title": f"branch of periodic orbits in {pname} from a Hopf point"}
    return xr.Dataset(data, coords=coords, attrs=attrs)


def load_restart(path_or_dataset, label: str) -> tuple[HopfStart, RestartState, str]:
    """The Hopf start and the restart state of the point ``label`` (P<k> for a branch
    point, or a special point's label such as LPC1) of a saved branch; also the parameter
    name. Raises KeyError naming the labels on offer when ``label`` is not there."""
    import xarray as xr

    ds = path_or_dataset if isinstance(path_or_dataset, xr.Dataset) else \
        xr.load_dataset(path_or_dataset, engine="h5netcdf")
    labels = [str(v) for v in ds["label"].values] if "label" in ds.coords else []
    specials = [str(v) for v in ds["special_label"].values] if "special_label" in ds.coords \
        else []
    if label in labels:
        k, pre = labels.index(label), ""
    elif label in specials:
        k, pre = specials.index(label), "special_"
    else:
        raise KeyError(f"label '{label}' is not in the saved branch; it has: "
                       + ", ".join(labels[:3] + (["..."] if len(labels) > 4 else [])
                                   + labels[-1:] + specials))

    def v(name):
        return np.asarray(ds[pre + name].values[k])

    if not np.isfinite(float(v("r_period"))):
        raise KeyError(f"point '{label}' has no restart data (a located end point)")
    state = RestartState(mesh=v("r_mesh"), states=v("r_states"), period=float(v("r_period")),
                         value=float(v("r_value")), t_states=v("r_t_states"),
                         t_period=float(v("r_t_period")), t_value=float(v("r_t_value")),
                         ds=float(v("r_ds")), accepted=int(v("r_accepted")))
    l1 = float(ds.attrs["hopf_l1"])
    start = HopfStart(param=str(ds.attrs["param"]), value=float(ds.attrs["hopf_value"]),
                      x=np.asarray(ds["hopf_x"].values), p=np.asarray(ds["hopf_p"].values),
                      frequency=float(ds.attrs["hopf_frequency"]),
                      q=np.asarray(ds["hopf_q_re"].values) + 1j * np.asarray(
                          ds["hopf_q_im"].values),
                      l1=None if not np.isfinite(l1) else l1)
    return start, state, str(ds.attrs["param"])
