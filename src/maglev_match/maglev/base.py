"""What a maglev model is: :class:`MaglevModel`, the one interface every analysis uses.

A maglev model is a parameter set (:class:`~maglev_match.core.params.Params`) together with
the forms of its equations that the analyses need. Model A (one levitation unit,
:class:`~maglev_match.maglev.models.UnitModel`) and model B (the full vehicle,
:class:`~maglev_match.maglev.models.VehicleModel`) are the two shipped; the analyses never
ask which one they have.

What a model provides (the abstract members below):

* **forms of its equations**: :meth:`~MaglevModel.system` (the smooth ODE, or with
  ``limited`` the current clamp inside the vector field for simulation; with a delay
  ``tau > 0`` the discretised delay system), :meth:`~MaglevModel.dde` (the delay form),
  :meth:`~MaglevModel.clamped` (the current clamp as a piecewise-smooth system of free and
  held modes) and :attr:`~MaglevModel.moving_kind` (its form at speed, in
  :mod:`maglev_match.maglev.moving`);
* **its physical limits**: :meth:`~MaglevModel.gap` (the gap of every levitation point);
  the gap-limit events of a simulation and the limit margins of a cycle follow from it
  (:meth:`~MaglevModel.gap_events`, :meth:`~MaglevModel.cycle_limits`);
* **its states**: :meth:`~MaglevModel.equilibrium` and :meth:`~MaglevModel.initial_state`
  (the named initial states of its simulations);
* **what the matching index needs**: :attr:`~MaglevModel.w0` (the static deflection),
  :meth:`~MaglevModel.disturbance` (the disturbance line whose critical size is
  h_simulation), :meth:`~MaglevModel.hopf_search` (where the nearest Hopf point is looked
  for), and the settings of its critical-disturbance search and cycle corrector;
* **what the sensitivities need**: :meth:`~MaglevModel.engineering_names` and
  :meth:`~MaglevModel.derived_map` (beam and vehicle data to its parameters, w0 and h_max,
  as a JAX function) and :meth:`~MaglevModel.disturbance_derivative`.

Forms are built once per model object and kept (an analysis that asks twice gets the same
object): build the model once per parameter set and pass it on.
"""

from __future__ import annotations

import abc
from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property
from typing import Any, ClassVar

import numpy as np

from maglev_match.core.params import ParameterError, Params
from maglev_match.maglev.catalog import ModelInfo

__all__ = ["MaglevModel", "DisturbanceLine", "CriticalSearch", "INITIAL_CONDITIONS", "form"]

#: the named initial states of the maglev models' simulations (each model takes those of
#: :attr:`MaglevModel.initial_states`)
INITIAL_CONDITIONS = ("equilibrium", "pressed")


@dataclass(frozen=True)
class DisturbanceLine:
    """The disturbed initial states of the matching index in one direction.

    A size d >= 0 (m, measured as the beam deflection it adds) gives the initial state
    ``x0_of([d])[0]``; the line is straight, ``x0(d) = base + d * step`` (``step`` per metre).
    ``gap_range`` is the largest meaningful size: the one that puts a gap on its limit at
    t = 0. ``label`` names the direction in words. ``x0_of`` is the model's own formula
    (kept exactly as the bisection evaluates it).
    """

    direction: int
    base: np.ndarray
    step: np.ndarray
    gap_range: float
    label: str
    x0_of: Callable[[np.ndarray], np.ndarray]


@dataclass(frozen=True)
class CriticalSearch:
    """The settings of a model's bisection of the critical disturbance
    (:func:`~maglev_match.analyses.simulation.critical_disturbance`): first horizon
    ``t_max`` (s), bracket width ``tol`` (m), horizon doublings ``max_extend``, sizes per
    batched round ``batch`` and the bound on rounds ``max_rounds``."""

    t_max: float
    tol: float
    max_extend: int
    batch: int
    max_rounds: int

    def as_kwargs(self) -> dict[str, Any]:
        return {"t_max": self.t_max, "tol": self.tol, "max_extend": self.max_extend,
                "batch": self.batch, "max_rounds": self.max_rounds}


def form(method: Callable) -> Callable:
    """Build a model's form once per model object and arguments (hashable), and keep it:
    an analysis that asks twice gets the same object."""
    import functools

    @functools.wraps(method)
    def cached(self, *args: Any, **kwargs: Any) -> Any:
        memo = self.__dict__.setdefault("_forms", {})
        key = (method.__name__, args, tuple(sorted(kwargs.items())))
        if key not in memo:
            memo[key] = method(self, *args, **kwargs)
        return memo[key]

    return cached


def _display_unit(name: str) -> tuple[str, float]:
    """The unit a state is shown in, and its factor from SI."""
    if name.endswith("_dot") or name in ("v",) or (name.startswith("v") and name[1:].isdigit()):
        return "mm/s", 1e3
    if name in ("di",) or (name.startswith("i") and name[1:].isdigit()):
        return "A", 1.0
    if name.startswith("th"):
        return "mrad", 1e3
    return "mm", 1e3


class MaglevModel(abc.ABC):
    """A maglev model at one parameter set (see the module docstring for what a model
    provides). Subclasses set :attr:`info` and implement the abstract members."""

    #: name, letter, title and the words for its parts (:mod:`maglev_match.maglev.catalog`)
    info: ClassVar[ModelInfo]
    #: the bisection settings of its critical disturbance
    critical_search: ClassVar[CriticalSearch]
    #: the corrector of its cycles on the index's branch ('full' Newton or 'chord')
    cycle_newton: ClassVar[str] = "full"
    #: BLAS threads while its cycles are continued (None: the library's default)
    blas_threads: ClassVar[int | None] = None
    #: the named initial states of its simulations
    initial_states: ClassVar[tuple[str, ...]] = ("equilibrium",)
    #: may the index's simulated part run in a second thread beside the paper's part
    #: (:mod:`maglev_match.core.beside`)? Only for models whose code is safe there: a user
    #: model file's code runs under process-wide guards (maglev/user.py), so it stays in one
    #: thread
    parts_beside: ClassVar[bool] = False

    def __init__(self, params: Params) -> None:
        if not isinstance(params, Params):
            raise ParameterError("params", type(params).__name__, "must be a Params")
        self.params = params

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.info.label}, preset {self.params.preset!r})"

    # ----- names ------------------------------------------------------------------------
    @property
    def name(self) -> str:
        """The model's name ('unit', 'vehicle')."""
        return self.info.name

    @property
    def n_points(self) -> int:
        """Levitation points."""
        return self.info.points

    @property
    @abc.abstractmethod
    def param_names(self) -> tuple[str, ...]:
        """The names of its parameter vector (without the delay)."""

    @property
    def state_names(self) -> tuple[str, ...]:
        return self.system().state_names

    @property
    def n_states(self) -> int:
        return len(self.state_names)

    def param_vector(self) -> np.ndarray:
        """The parameter vector of its ODE (in :attr:`param_names` order)."""
        return np.array([float(getattr(self.params, n)) for n in self.param_names])

    # ----- forms ------------------------------------------------------------------------
    @form
    def system(self, *, limited: bool = False, tau_max: float | None = None,
               nodes: int | None = None) -> Any:
        """The :class:`~maglev_match.dynamics.system.System`: the smooth ODE, or with
        ``limited`` the current clamp in the vector field (simulations); with
        ``params.tau > 0``, a ``tau_max`` (a delay axis up to it) or ``nodes`` the
        discretised delay system."""
        return self._build_system(limited=limited, tau_max=tau_max, nodes=nodes)

    @abc.abstractmethod
    def _build_system(self, *, limited: bool, tau_max: float | None,
                      nodes: int | None) -> Any:
        """Build :meth:`system` (called once per combination)."""

    @form
    def dde(self, *, limited: bool = False) -> Any:
        """The delay form: a :class:`~maglev_match.dynamics.delay.DelayDifferentialSystem`
        whose outer control loop reads its command ``tau`` late."""
        return self._build_dde(limited=limited)

    @abc.abstractmethod
    def _build_dde(self, *, limited: bool) -> Any:
        """Build :meth:`dde`."""

    @form
    def clamped(self) -> Any:
        """The current clamp as a :class:`~maglev_match.dynamics.hybrid.HybridSystem`
        (free and held modes of each levitation point)."""
        return self._build_clamped()

    @abc.abstractmethod
    def _build_clamped(self) -> Any:
        """Build :meth:`clamped`."""

    @property
    @abc.abstractmethod
    def moving_kind(self) -> Any:
        """Its form at speed: the :class:`~maglev_match.maglev.moving.MovingModel` member."""

    # ----- limits -----------------------------------------------------------------------
    @abc.abstractmethod
    def gap(self) -> Callable[[Any, Any], Any]:
        """``gap(x, p)``: the gap of every levitation point (m), a JAX function of one
        state and the parameter vector (one function object per model structure, so
        compiled code is shared)."""

    @form
    def gap_events(self) -> Any:
        """The gap limits as simulation events (entries 2(j-1), 2(j-1)+1: gap_j - gap_min
        and gap_max - gap_j of point j; negative is a collision)."""
        from maglev_match.maglev.limits import gap_limit_events

        return gap_limit_events(self.gap(), float(self.params.gap_min),
                                float(self.params.gap_max))

    def cycle_limits(self, include_current: bool = True) -> Callable:
        """The limit margins of a periodic orbit (``limits`` of the cycle continuation)."""
        from maglev_match.maglev.limits import cycle_limit_margins

        return cycle_limit_margins(self.params, include_current=include_current)

    # ----- states -----------------------------------------------------------------------
    @abc.abstractmethod
    def equilibrium(self) -> np.ndarray:
        """The static equilibrium state."""

    def initial_state(self, initial: str = "equilibrium", *, x5: float | None = None,
                      q1: float | None = None, state: Any = None) -> np.ndarray:
        """A named initial state (:attr:`initial_states`), with the disturbances the model
        takes (``x5``: model A's beam deflection; ``q1``: model B's first modal
        coordinate), or an explicit ``state``."""
        if state is not None:
            x = np.asarray(state, dtype=float).ravel()
            if x.shape != (self.n_states,):
                raise ParameterError("x0", f"{x.size} values",
                                     f"model '{self.name}' has {self.n_states} states")
            if not np.all(np.isfinite(x)):
                raise ParameterError("x0", "non-finite", "every state must be a finite number")
            return x
        if initial not in INITIAL_CONDITIONS:
            raise ParameterError("initial", initial,
                                 "must be one of " + ", ".join(INITIAL_CONDITIONS))
        return self._initial_state(initial, x5=x5, q1=q1)

    @abc.abstractmethod
    def _initial_state(self, initial: str, *, x5: float | None, q1: float | None
                       ) -> np.ndarray:
        """:meth:`initial_state` for a valid name (the model refuses what does not apply)."""

    @abc.abstractmethod
    def history_parts(self, x: np.ndarray) -> tuple[np.ndarray, Any, dict[str, Any]]:
        """The read-outs of a saved history (rows of states): the coil current of every
        levitation point (A, before the clamp; rows x points), the beam deflection as an
        xarray variable (dims, values), and the coordinates those dims add."""

    @property
    @abc.abstractmethod
    def levitation_current(self) -> float:
        """The coil current at the equilibrium (A), per levitation point."""

    #: how a state's offset is said (model A's states are offsets already)
    offset_words: ClassVar[str] = " from equilibrium"

    def state_labels(self) -> tuple[str, ...]:
        """The states' names in words (model A: the paper's x1..x9)."""
        return self.state_names

    def describe_state(self, x: np.ndarray) -> str:
        """An initial state in words: the states that differ from the equilibrium (at most
        three, shown in mm, mm/s, mrad or A)."""
        eq = self.equilibrium()
        x = np.asarray(x, float)
        diff = np.nonzero(np.abs(x - eq) > 1e-15)[0]
        if diff.size == 0:
            return "from the equilibrium"
        names = self.state_labels()
        raw = self.state_names
        parts = []
        for k in diff[:3]:
            unit, scale = _display_unit(raw[k])
            parts.append(f"{names[k]}(0) = {(x[k] - eq[k]) * scale:.3g} {unit}"
                         f"{self.offset_words}")
        if diff.size > 3:
            parts.append(f"and {diff.size - 3} more states")
        return ", ".join(parts)

    # ----- the matching index -----------------------------------------------------------
    @property
    @abc.abstractmethod
    def w0(self) -> float:
        """The static beam deflection the index divides by (m)."""

    @form
    def disturbance(self, direction: int) -> DisturbanceLine:
        """The index's disturbance line in ``direction`` (-1: beam up / lifted, the gap
        opens; +1: beam down / pushed, the gap closes)."""
        if direction not in (-1, 1):
            raise ParameterError("direction", direction, "must be -1 or +1")
        return self._build_disturbance(int(direction))

    @abc.abstractmethod
    def _build_disturbance(self, direction: int) -> DisturbanceLine:
        """Build :meth:`disturbance` for a valid direction."""

    @abc.abstractmethod
    def hopf_search(self) -> dict[str, tuple[float, float]]:
        """Where the nearest Hopf point is looked for: {parameter: (low, high)}."""

    @abc.abstractmethod
    def disturbance_derivative(self, direction: int, size: float) -> np.ndarray | None:
        """d x0 / dp along the disturbance line at ``size`` (rows: states, columns: the
        parameter vector), or None where the line does not move with the parameters."""

    # ----- sensitivities ----------------------------------------------------------------
    @abc.abstractmethod
    def engineering_names(self) -> tuple[str, ...]:
        """The parameters of d chi / d p: its own, with the derived modal values replaced
        by the beam's where they are derived, and gap_max."""

    @abc.abstractmethod
    def derived_map(self) -> Callable:
        """q (values of :meth:`engineering_names`) -> (parameter vector, w0, h_max), a JAX
        function (so its Jacobian is exact)."""

    @cached_property
    def h_max(self) -> float:
        """h when no unstable cycle bounds the basin within the gap range: gap_max - c0."""
        return float(self.params.gap_max - self.params.c0)
