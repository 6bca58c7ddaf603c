"""The shipped maglev models as :class:`~maglev_match.maglev.base.MaglevModel` objects, and
the table that maps their names to them.

* :class:`UnitModel` — model A: one levitation unit on the first beam mode (9 states,
  :mod:`maglev_match.maglev.unit`);
* :class:`VehicleModel` — model B: three levitation frames and a car body over a
  multi-mode beam (16 + 2 n_modes + 18 states, :mod:`maglev_match.maglev.vehicle`).

:func:`maglev_model` builds one from a parameter set and a name; adding a model means a
subclass here (or in its own module) and an entry in :data:`MODELS` and in
:data:`~maglev_match.maglev.catalog.CATALOG`.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import cached_property

import jax.numpy as jnp
import numpy as np

from maglev_match.core.params import ParameterError, Params
from maglev_match.maglev import beam, clamp, unit, vehicle
from maglev_match.maglev.base import CriticalSearch, DisturbanceLine, MaglevModel
from maglev_match.maglev.catalog import CATALOG, model_info
from maglev_match.maglev.moving import MovingModel

__all__ = ["UnitModel", "VehicleModel", "MODELS", "maglev_model", "build_system"]


class UnitModel(MaglevModel):
    """Model A: one levitation unit on the first beam mode (9 states)."""

    info = CATALOG["unit"]
    # 10 sizes per round: three rounds reach 1e-5 m over a 10 mm range (11^3 > 1e-2 / 1e-5)
    critical_search = CriticalSearch(t_max=20.0, tol=1e-5, max_extend=2, batch=10,
                                     max_rounds=12)
    cycle_newton = "full"
    blas_threads = None
    parts_beside = True

    @property
    def param_names(self) -> tuple[str, ...]:
        return unit.PARAM_NAMES

    @property
    def state_names(self) -> tuple[str, ...]:
        return unit.STATE_NAMES

    def param_vector(self) -> np.ndarray:
        return unit.param_vector(self.params)

    def _build_system(self, *, limited, tau_max, nodes):
        return unit.unit_system(self.params, limited, tau_max=tau_max, nodes=nodes)

    def _build_dde(self, *, limited: bool):
        return unit.unit_dde(self.params, limited)

    def _build_clamped(self):
        if self.params.tau > 0:  # the clamp on the discretised delay system
            return clamp.unit_delay_clamped(self.system())
        return clamp.unit_clamped(self.params)

    @property
    def moving_kind(self) -> MovingModel:
        return MovingModel.UNIT

    def gap(self) -> Callable:
        return unit.gap

    def equilibrium(self) -> np.ndarray:
        return np.zeros(len(unit.STATE_NAMES))

    def _initial_state(self, initial, *, x5, q1):
        if initial == "pressed":
            raise ParameterError("initial", initial, "'pressed' applies to model B (vehicle)")
        if q1 is not None:
            raise ParameterError("q1", q1, "modal coordinates apply to model B (vehicle)")
        x = self.equilibrium()
        if x5 is not None:
            x[4] = float(x5)
        return x

    def history_parts(self, x):
        return x[:, 6] + self.params.i0, ("time", x[:, 4]), {}

    @property
    def levitation_current(self) -> float:
        return float(self.params.i0)

    offset_words = ""

    def state_labels(self) -> tuple[str, ...]:
        return tuple(f"x{k + 1}" for k in range(len(unit.STATE_NAMES)))  # as --x5

    @cached_property
    def w0(self) -> float:
        return float(self.params.w0)

    def _build_disturbance(self, direction: int) -> DisturbanceLine:
        """x5(0) = direction * d, everything else at equilibrium: direction -1 is the
        paper's case (the beam above its static position, the gap opens)."""
        p = self.params
        n = len(unit.STATE_NAMES)
        # x5 = -d opens the gap (c = c0 + d): upper limit at d = gap_max - c0
        gap_range = (p.gap_max - p.c0) if direction < 0 else (p.c0 - p.gap_min)
        step = np.zeros(n)
        step[4] = float(direction)

        def x0_of(sizes: np.ndarray) -> np.ndarray:
            x0 = np.zeros((np.size(sizes), n))
            x0[:, 4] = direction * np.asarray(sizes)
            return x0

        return DisturbanceLine(direction, np.zeros(n), step, float(gap_range),
                               self.info.disturbance_labels[0 if direction < 0 else 1], x0_of)

    def hopf_search(self) -> dict[str, tuple[float, float]]:
        """omega1 within a factor 4 of the design value (sigma fixed), sigma within a
        factor 10 (omega1 fixed), inside the valid ranges."""
        w, s = float(self.params.omega1), float(self.params.sigma)  # type: ignore[arg-type]
        out = {"omega1": (w / 4.0, min(4.0 * w, 1e5))}
        if s > 0:
            out["sigma"] = (s / 10.0, min(10.0 * s, 0.1))
        return out

    def disturbance_derivative(self, direction: int, size: float) -> None:
        return None  # x5(0) = direction d does not move with the parameters

    def engineering_names(self) -> tuple[str, ...]:
        return beam.unit_engineering_names(self.params)

    def derived_map(self) -> Callable:
        return beam.unit_derived_map(self.params)


class VehicleModel(MaglevModel):
    """Model B: three levitation frames and a car body over an n-mode beam."""

    info = CATALOG["vehicle"]
    # 8 sizes per round: three rounds reach 2e-5 m (9^3 > 1e-2 / 2e-5)
    critical_search = CriticalSearch(t_max=10.0, tol=2e-5, max_extend=1, batch=8,
                                     max_rounds=8)
    # the chord corrector: 2.2x less CPU for its 40-state cycles (measured on turnout-soft)
    cycle_newton = "chord"
    # the collocation blocks are small dense matrices; BLAS threads only contend for the
    # cores there (the Floquet condensation: 1.5 s per cycle with OpenBLAS's threads on
    # the 2-core machine under load, 0.05 s single-threaded; measured)
    blas_threads = 1
    parts_beside = True
    initial_states = ("equilibrium", "pressed")

    @property
    def n_modes(self) -> int:
        return int(self.params.n_modes)

    @property
    def param_names(self) -> tuple[str, ...]:
        return vehicle.PARAM_NAMES

    @property
    def state_names(self) -> tuple[str, ...]:
        return vehicle.state_names(self.n_modes)

    def param_vector(self) -> np.ndarray:
        return vehicle.param_vector(self.params)

    def _build_system(self, *, limited, tau_max, nodes):
        return vehicle.vehicle_system(self.params, limited, tau_max=tau_max, nodes=nodes)

    def _build_dde(self, *, limited: bool):
        return vehicle.vehicle_dde(self.params, limited)

    def _build_clamped(self):
        return clamp.vehicle_clamped(self.params)

    @property
    def moving_kind(self) -> MovingModel:
        return MovingModel.VEHICLE

    def gap(self) -> Callable:
        return vehicle.gap_function(self.n_modes)

    def equilibrium(self) -> np.ndarray:
        return vehicle.equilibrium_guess(self.params)

    def _initial_state(self, initial, *, x5, q1):
        if x5 is not None:
            raise ParameterError("x5", x5, "the beam deflection x5 applies to model A (unit)")
        x = (vehicle.pressed_initial_state(self.params) if initial == "pressed"
             else self.equilibrium())
        if q1 is not None:
            x[vehicle.layout(self.n_modes)["q"].start] = float(q1)
        return x

    def history_parts(self, x):
        lay = vehicle.layout(self.n_modes)
        return (x[:, lay["i"]], (("time", "mode"), x[:, lay["q"]]),
                {"mode": np.arange(1, self.n_modes + 1)})

    @property
    def levitation_current(self) -> float:
        return float(self.params.i0_vehicle)

    def describe_state(self, x: np.ndarray) -> str:
        """'vehicle pressed onto the free beam' (with q1(0) where it is set), else the
        states that differ from the equilibrium."""
        lay = vehicle.layout(self.n_modes)
        x = np.asarray(x, float)
        pressed = vehicle.pressed_initial_state(self.params)
        if np.allclose(x, pressed, rtol=0, atol=1e-15):
            return "vehicle pressed onto the free beam"
        q = x[lay["q"]]
        rest = np.delete(x - pressed, np.r_[lay["q"]])
        if np.allclose(rest, 0.0, atol=1e-15) and np.allclose(q[1:], 0.0, atol=1e-15):
            return f"pressed onto the free beam, q1(0) = {q[0] * 1e3:.3g} mm"
        return super().describe_state(x)

    @cached_property
    def pressed_geometry(self) -> tuple[np.ndarray, np.ndarray, float]:
        """(x_eq, delta, w_mid): the static equilibrium, ``delta = pressed - x_eq`` the step
        to the vehicle pressed onto the free beam (every modal coordinate from q_n* to 0),
        and w_mid = sum_n q_n* sin(n pi / 2) the static mid-span deflection (m). The state
        x_eq + (d / w_mid) delta lifts the beam's mid-span by d metres above its static
        position (d = w_mid is the paper's initial state)."""
        x_eq = self.equilibrium()
        delta = vehicle.pressed_initial_state(self.params) - x_eq
        q_static = x_eq[vehicle.layout(self.n_modes)["q"]]
        n = np.arange(1, self.n_modes + 1)
        w_mid = float(np.sum(q_static * np.sin(n * np.pi / 2.0)))
        return x_eq, delta, w_mid

    @property
    def w0(self) -> float:
        return self.pressed_geometry[2]

    def _build_disturbance(self, direction: int) -> DisturbanceLine:
        """x_eq + s (pressed - x_eq), the size d = s w_mid measured as the mid-span beam
        displacement (m) from its static position: direction -1 lifts the beam towards the
        free beam (d = w_mid is "pressed onto the free beam"), +1 pushes it further down."""
        p = self.params
        x_eq, delta, w_mid = self.pressed_geometry
        gap_fn = self.gap()
        system = self.system(limited=True)
        # gap change per metre of mid-span lift, at each point: c_j(s) - c0 is linear in s
        dgap = (np.asarray(gap_fn(jnp.asarray(x_eq + delta), jnp.asarray(system.p)))
                - p.c0) / w_mid
        # lifting (direction -1) opens the gaps (dgap > 0); pushing down closes them
        slope = float(np.max(np.abs(dgap)))
        room = (p.gap_max - p.c0) if direction < 0 else (p.c0 - p.gap_min)

        def x0_of(sizes: np.ndarray) -> np.ndarray:
            s = (-direction) * np.asarray(sizes) / w_mid
            return x_eq[None, :] + s[:, None] * delta[None, :]

        return DisturbanceLine(direction, x_eq, (-direction) * delta / w_mid,
                               float(room / slope),
                               self.info.disturbance_labels[0 if direction < 0 else 1], x0_of)

    def hopf_search(self) -> dict[str, tuple[float, float]]:
        """omega1 within a factor 4 of the design value (the beam stiffness)."""
        w = float(self.params.omega1)  # type: ignore[arg-type]
        return {"omega1": (w / 4.0, min(4.0 * w, 1e5))}

    def disturbance_derivative(self, direction: int, size: float) -> np.ndarray:
        """The line moves with the parameters (equilibrium, pressed state, mid-span
        deflection): d x0 / dp by forward-mode differentiation."""
        return vehicle.pressed_line_derivative(self.params, direction, size)

    def engineering_names(self) -> tuple[str, ...]:
        return beam.vehicle_engineering_names(self.params)

    def derived_map(self) -> Callable:
        return beam.vehicle_derived_map(self.params)


#: name -> model class
MODELS: dict[str, type[MaglevModel]] = {"unit": UnitModel, "vehicle": VehicleModel}


def maglev_model(params: Params | MaglevModel, name: str = "unit", *,
                 field: str = "model") -> MaglevModel:
    """The maglev model ``name`` ('unit' or 'vehicle') at the parameter set ``params``; a
    model object given as ``params`` is returned as it is (``name`` is then not read). A
    :class:`ParameterError` naming ``field`` for an unknown name."""
    if isinstance(params, MaglevModel):
        return params
    info = model_info(name, field)
    return MODELS[info.name](params)


def build_system(params: Params, model: str = "unit", limited: bool = False, *,
                 tau_max: float | None = None):
    """The :class:`~maglev_match.dynamics.system.System` of model ``'unit'`` (A) or
    ``'vehicle'`` (B) for a parameter set: the ODE when ``params.tau = 0``, the discretised
    delay system when ``params.tau > 0`` or when ``tau_max`` asks for a delay axis up to
    that value (``maglev_model(params, model).system(...)``)."""
    return maglev_model(params, model).system(limited=limited, tau_max=tau_max)
