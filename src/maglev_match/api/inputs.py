"""What an API call analyses: the parameter set and the model, resolved and checked once.

Every API function takes ``params`` (a :class:`~maglev_match.core.params.Params`, the name
of a shipped preset, or None for the default preset), ``model`` ('unit', 'vehicle' or the
path of a user model file ``FILE.py``), optionally ``config`` (a TOML file on top of a
preset) and ``**overrides`` (values applied on top, as ``--set NAME=VALUE``). A user model
file takes no preset or config: its ``**overrides`` are the file's own parameters.

:func:`resolve_model` turns them into a :class:`StudiedModel`, which every workflow asks
for its system (the ODE, or the discretised delay system along a delay axis), the design
value of a parameter and the checks of a parameter name or value.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from maglev_match.core.params import (
    DEFAULT_PRESET,
    PARAMETER_DOCS,
    ParameterError,
    Params,
    available_presets,
    load_params,
    warn_overridden,
)
from maglev_match.maglev.catalog import MODEL_NAMES, model_info, names_text

if TYPE_CHECKING:  # pragma: no cover
    from maglev_match.dynamics.system import System

__all__ = ["resolve_params", "resolve_model", "StudiedModel", "is_model_file",
           "MAGLEV_DELAYS", "build_system"]

#: the delay parameters of the maglev models
MAGLEV_DELAYS = ("tau",)


def is_model_file(model: Any) -> bool:
    """Whether ``model`` names a user model file (a path ending in .py)."""
    return isinstance(model, str | Path) and str(model).endswith(".py")


def resolve_params(params: Params | str | None = None, *, config: str | Path | None = None,
                   **overrides: Any) -> Params:
    """The parameter set of an API call, validated.

    Parameters
    ----------
    params : Params | str | None
        A [`Params`][maglev_match.core.params.Params], the name of a shipped preset, or
        None for the default preset `turnout-soft`.
    config : str or Path, optional
        A TOML file applied on top of a preset (`--config`).
    **overrides : float
        Values applied on top (beam data such as `EI` re-derive omega1 and sigma).

    Returns
    -------
    Params
        The parameter set.

    Raises
    ------
    ParameterError
        For an unknown name or an invalid value, naming the field, the value and the rule.
    """
    if params is None or isinstance(params, str):
        return load_params(params or DEFAULT_PRESET, config, dict(overrides))
    if not isinstance(params, Params):
        raise ParameterError("params", type(params).__name__,
                             "must be a Params, a preset name or None")
    if config is not None:
        raise ParameterError("config", str(config), "applies on top of a preset name, not "
                             "of a ready Params")
    return params.replace(**overrides) if overrides else params


def names_a_preset(value: Any) -> bool:
    """Whether a positional string is a parameter set (a preset name) rather than the
    parameter name of an earlier signature."""
    return isinstance(value, str) and value in available_presets()


@dataclass(frozen=True)
class StudiedModel:
    """The model an API call analyses.

    label : 'unit', 'vehicle' or the model file's name (used in output names and JSON).
    description : one line naming the model and its key values, for text output.
    params : the maglev parameter set (None for a user model file).
    maglev : the :class:`~maglev_match.maglev.base.MaglevModel` (None for a user model).
    user : the loaded :class:`~maglev_match.maglev.user.UserModel` (None for a maglev one).
    values : a user model's parameter values given on top of its defaults.
    """

    label: str
    description: str
    params: Params | None = None
    maglev: Any = None
    user: Any = None
    values: Mapping[str, float] = field(default_factory=dict)

    @property
    def is_user(self) -> bool:
        return self.user is not None

    @property
    def file(self) -> str | None:
        """The user model file (None for a maglev model)."""
        return None if self.user is None else str(self.user.path)

    @property
    def delays(self) -> tuple[str, ...]:
        """The delay parameters (the maglev models: tau; a user model: its DELAYS)."""
        return tuple(self.user.delays) if self.user is not None else MAGLEV_DELAYS

    def system(self, *, limited: bool = False, tau_max: float | None = None) -> Any:
        """The model's :class:`~maglev_match.dynamics.system.System` at its values; with
        ``tau_max`` the discretised delay system sized for a delay axis up to it (where
        the model has a delay)."""
        if self.user is not None:
            if limited:
                raise ParameterError("limited", True, "a user model file has no physical "
                                     "limits")
            return _user_system(self.user, dict(self.values), tau_max=tau_max)
        return self.maglev.system(limited=limited, tau_max=tau_max)

    def system_along(self, param: str, largest: float) -> Any:
        """The system for an axis of ``param`` up to ``largest``: the discretised delay
        system sized for it when ``param`` is a delay, else the model's system."""
        return self.system(tau_max=largest if param in self.delays else None)

    def design_value(self, param: str) -> float:
        """The current value of ``param`` (a model parameter, a delay, or for the maglev
        models a beam/vehicle quantity such as EI)."""
        if self.params is not None and (param in MAGLEV_DELAYS or param in PARAMETER_DOCS):
            return float(getattr(self.params, param))
        system = self.system()
        if param in self.delays and param not in system.param_names:
            return float(self.user.params[param]) if self.user is not None else 0.0
        return float(system.param(param))

    def check_param(self, name: str, field: str, *, delays: bool = True,
                    engineering: bool = False) -> None:
        """``name`` must be a parameter of the model (a delay counts when ``delays``; a
        beam/vehicle quantity of the maglev models when ``engineering``)."""
        if delays and name in self.delays:
            return
        if engineering and self.params is not None:
            from maglev_match.analyses.engineering import is_engineering

            if is_engineering(name):
                return
        names = self.system().param_names
        if name not in names:
            which = f"model '{self.label}'"
            raise ParameterError(field, name, f"{which} has no such parameter; choose one "
                                 f"of {', '.join(names)}")

    def validate_value(self, name: str, value: float) -> None:
        """A value of a maglev parameter outside its rule (omega1 <= 0 ...) is refused,
        naming the parameter."""
        if self.params is not None and name in PARAMETER_DOCS:
            self.params.replace(**{name: value})

    def with_values(self, field: str = "--at", **values: Any) -> StudiedModel:
        """The same model with more values set (the command line's ``--at``)."""
        if not values:
            return self
        if self.user is not None:
            merged = {**self.values, **_user_values(self.user, values, field)}
            return replace(self, values=merged,
                           description=_user_description(self.user, merged))
        try:
            params = self.params.replace(**values)
        except TypeError as exc:
            raise ParameterError(field, ",".join(values), f"unknown parameter ({exc})") \
                from None
        warn_overridden(params, set(values))  # e.g. L=20 while omega1 is set explicitly
        from maglev_match.maglev.models import maglev_model

        return replace(self, params=params, maglev=maglev_model(params, self.maglev.name),
                       description=_maglev_description(self.maglev.name, params))


def _maglev_description(name: str, params: Params) -> str:
    info = model_info(name)
    return (f"Model {info.letter} ({info.title}), omega1 = {params.omega1:.4g} rad/s, "
            f"sigma = {params.sigma:.4g} 1/kg")


def _user_description(user: Any, values: Mapping[str, float]) -> str:
    vals = user.values_with(values)
    return (f"Model {user.name} ({user.path}, {len(user.states)} states), "
            + ", ".join(f"{k} = {v:.6g}" for k, v in vals.items()))


def _user_values(user: Any, overrides: Mapping[str, Any], field: str = "--set"
                 ) -> dict[str, float]:
    """A user model's parameter values from ``overrides`` (numbers or numeric text): an
    unknown name lists the valid ones, a value must be a finite number."""
    values: dict[str, float] = {}
    for name, raw in overrides.items():
        if name not in user.params:
            raise ParameterError(field, name, f"model file {user.path} has no such "
                                 f"parameter; valid names: {', '.join(user.params) or '(none)'}")
        try:
            v = float(raw)
        except (TypeError, ValueError):
            raise ParameterError(name, raw, "must be a number") from None
        if not math.isfinite(v):
            raise ParameterError(name, raw, "must be finite")
        values[name] = v
    return values


def _user_system(user: Any, values: dict[str, float], *, tau_max: float | None = None,
                 field: str = "--set") -> Any:
    """The user model's system at ``values``, refused (before any work) when its
    right-hand side or Jacobian is not finite at X0 there: an overflow such as
    ``rho=1e308`` is a numerical failure to name, not a verdict to print."""
    problem = user.numerical_problem(values)
    if problem is not None:
        given = " ".join(f"{k}={v:g}" for k, v in values.items())
        raise ParameterError(field, given or "(defaults)", f"numerical failure: {problem}; "
                             "choose values that keep it finite" if given else
                             f"model file {user.path}: numerical failure at the defaults: "
                             f"{problem}")
    return user.system(values, tau_max=tau_max)


def resolve_model(params: Params | str | None = None, model: Any = "unit", *,
                  config: str | Path | None = None, field: str = "--set",
                  **overrides: Any) -> StudiedModel:
    """The :class:`StudiedModel` of an API call: ``model`` 'unit' or 'vehicle' at the
    parameter set (``params``, ``config``, ``**overrides``), or a user model file (``model``
    a path ending in .py) with ``**overrides`` setting its own parameters (a preset or
    ``config`` does not apply to it)."""
    from maglev_match.maglev.base import MaglevModel

    if isinstance(model, MaglevModel):
        return StudiedModel(label=model.name,
                            description=_maglev_description(model.name, model.params),
                            params=model.params, maglev=model)
    if is_model_file(model):
        if config is not None:
            raise ParameterError("config", str(config), "maglev parameter files do not apply "
                                 f"to a user model ({model}); set its parameters instead")
        if params is not None:
            raise ParameterError("params", params if isinstance(params, str) else "Params",
                                 f"maglev parameter sets do not apply to a user model "
                                 f"({model}); set its parameters instead")
        from maglev_match.maglev.user import load_model

        user = load_model(model)
        values = _user_values(user, overrides, field)
        _user_system(user, values, field=field)  # refuses values it cannot analyse
        return StudiedModel(label=user.name, description=_user_description(user, values),
                            user=user, values=values)
    if str(model) not in MODEL_NAMES:
        raise ParameterError("model", model, f"must be {names_text().replace(' or ', ', ')} "
                             "or a model file ending in .py")
    info = model_info(model)
    p = resolve_params(params, config=config, **overrides)
    from maglev_match.maglev.models import maglev_model

    return StudiedModel(label=info.name, description=_maglev_description(info.name, p),
                        params=p, maglev=maglev_model(p, info.name))


def build_system(params: Params | str | None = None, model: str = "unit", *,
                 limited: bool = False, **overrides: Any) -> System:
    """The ODE system of model A or B, with exact derivatives.

    Parameters
    ----------
    params : Params | str | None
        The parameter set: a [`Params`][maglev_match.core.params.Params], the name of a shipped
        preset, or None for the default preset `turnout-soft`.
    model : str
        `"unit"` (model A, 9 states) or `"vehicle"` (model B, 40 states with 3 modes).
    **overrides : float
        Parameter values applied on top, validated like `--set NAME=VALUE`.
    limited : bool
        Put the current clamp (the current never reverses) into the vector field.

    Returns
    -------
    System
        The [`System`][maglev_match.dynamics.system.System] (vector field, parameter
        vector, state names, read-outs).
    """
    from maglev_match.maglev.models import maglev_model

    return maglev_model(resolve_params(params, **overrides), model).system(limited=limited)
