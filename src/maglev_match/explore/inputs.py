"""The explorer's inputs: the design's controls (their slider windows inside the
parameters' valid ranges), the state of the page as URL query values, their validation by
the command line's own rules, and what reproduces a state (the command line, a TOML file).

A state is a preset name and ``--set`` overrides, ``{"preset": "turnout-soft", "EI":
2.2e10, "kD": 140.0}``; in the URL it is the query ``?preset=turnout-soft&EI=2.2e10&kD=140``.
Every value is checked as ``maglev-match index --set NAME=VALUE`` checks it
(:func:`maglev_match.core.params.parse_assignment` and
:func:`~maglev_match.core.params.load_params`, then the index's own rule w0 > 0), so a
refused value carries the same message (field, value, rule)."""

from __future__ import annotations

import math
import shlex
import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from maglev_match.core.params import (
    DEFAULT_PRESET,
    FIELD_NAMES,
    ParameterError,
    ParameterWarning,
    Params,
    available_presets,
    load_params,
    parse_assignment,
    valid_range,
)

__all__ = ["Control", "CONTROLS", "State", "parse_query", "check_state", "command_line",
           "toml_text", "controls_json"]


@dataclass(frozen=True)
class Control:
    """One input of the page: a ``--set`` name, its words, the unit shown, the slider's
    window (a part of the parameter's valid range; a typed value may use the whole valid
    range) and whether the slider is logarithmic."""

    name: str
    label: str
    unit: str
    low: float
    high: float
    log: bool = True
    group: str = "beam"

    def as_json(self) -> dict[str, Any]:
        lo, hi = valid_range(self.name) or (-math.inf, math.inf)
        return {"name": self.name, "label": self.label, "unit": self.unit, "low": self.low,
                "high": self.high, "log": self.log, "group": self.group,
                "valid": [lo, hi]}


#: the page's controls, in order. The windows lie inside each parameter's valid range
#: (tests/test_explore.py checks it) and span every shipped preset's value.
CONTROLS: tuple[Control, ...] = (
    Control("L", "span L", "m", 5.0, 60.0, log=False),
    Control("EI", "bending stiffness EI", "N m^2", 2e9, 2e11),
    Control("mbar", "mass per length mbar", "kg/m", 200.0, 1e4),
    Control("omega1", "omega1 (set directly)", "rad/s", 20.0, 500.0, group="modal"),
    Control("sigma", "sigma (set directly)", "1/kg", 1e-5, 2e-3, group="modal"),
    Control("kP", "gap gain kP", "A/m", 500.0, 5e4, group="controller"),
    Control("kD", "velocity gain kD", "A s/m", 10.0, 1e3, group="controller"),
    Control("ke", "current gain ke", "V/A", 1.0, 200.0, group="controller"),
    Control("tau", "delay tau", "s", 0.0, 5e-3, log=False, group="controller"),
)
CONTROL_NAMES = tuple(c.name for c in CONTROLS)
#: query keys of a request that are not parameters: the page and its sequence number, what
#: to export,
#: the kind of background job (the model is chosen on the command line only), the page's
#: speed v (km/h; checked by the speed job's own rule)
REQUEST_KEYS = ("preset", "seq", "client", "what", "kind", "model", "v")


@dataclass(frozen=True)
class State:
    """A design of the page: the preset and the ``--set`` overrides (name -> value)."""

    preset: str = DEFAULT_PRESET
    values: tuple[tuple[str, float], ...] = ()

    @property
    def overrides(self) -> dict[str, float]:
        return dict(self.values)

    def query(self) -> dict[str, str]:
        """The URL query of the state (values as Python's shortest repr)."""
        return {"preset": self.preset, **{n: repr(float(v)) for n, v in self.values}}


def parse_query(query: Mapping[str, str]) -> tuple[State, dict[str, str]]:
    """A state from the URL's (or a request's) query: ``preset`` and ``NAME=VALUE`` with
    the ``--set`` names. Returns the state of the values that pass and the messages of
    those that do not ({field: message}, the command line's words); an unknown name is
    refused like ``--set`` refuses it."""
    errors: dict[str, str] = {}
    preset = str(query.get("preset") or DEFAULT_PRESET)
    if preset not in available_presets():
        errors["preset"] = str(ParameterError("preset", preset, "no such preset; available: "
                                              + ", ".join(available_presets())))
        preset = DEFAULT_PRESET
    values: dict[str, float] = {}
    for name, raw in query.items():
        if name in REQUEST_KEYS:
            continue
        try:
            key, value = parse_assignment(f"{name}={raw}")
        except ParameterError as e:
            errors[name] = str(e)
            continue
        values[key] = value
    state = State(preset, tuple(values.items()))
    return check_state(state, errors)


def check_state(state: State, errors: dict[str, str] | None = None
                ) -> tuple[State, dict[str, str]]:
    """Check each override alone on the preset, then all together, by the command line's
    rules; the overrides that fail leave the state (their message is kept by field)."""
    errors = dict(errors or {})
    good: dict[str, float] = {}
    for name, value in state.values:
        try:
            _params(state.preset, {name: value})
        except ParameterError as e:
            errors[name] = str(e)
        else:
            good[name] = value
    if good:
        try:
            _params(state.preset, good)
        except ParameterError as e:  # a rule between values: said at the field it names
            field = str(e.field) if str(e.field) in good else next(iter(good))
            errors[field] = str(e)
            good = {}
    return State(state.preset, tuple(good.items())), errors


def params_of(state: State) -> Params:
    """The validated parameter set of a state (raises :class:`ParameterError`)."""
    return _params(state.preset, state.overrides)


def _params(preset: str, overrides: dict[str, float]) -> Params:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ParameterWarning)
        p = load_params(preset, None, overrides)
    if not p.w0 > 0:  # the index's own rule (chi = h / w0), as `index` states it
        raise ParameterError("sigma", p.sigma, "must be > 0 for the index: chi = h / w0 "
                             f"needs a beam deflection w0 > 0 (w0 = {p.w0:g} m)")
    return p


def command_line(state: State, model: str, command: str = "index") -> str:
    """The equivalent command line of the state."""
    parts = ["maglev-match", command, "--preset", state.preset, "--model", model]
    for name, value in state.values:
        parts += ["--set", f"{name}={float(value)!r}"]
    return " ".join(shlex.quote(p) for p in parts)


def toml_text(state: State, model: str) -> str:
    """The state's every input value as a TOML file that ``--config FILE`` reads (the
    flat form of a preset: one ``name = value`` line per parameter)."""
    p = params_of(state)
    values = p.as_input_dict()
    lines = [f"# maglev-match explore: {command_line(state, model)}",
             f"# reproduce: maglev-match index --config FILE --model {model}",
             f'description = "explorer design on preset {state.preset}"']
    for name in FIELD_NAMES:
        if name in values:
            v = values[name]
            lines.append(f"{name} = {int(v) if isinstance(v, int) else repr(float(v))}")
    return "\n".join(lines) + "\n"


def controls_json(state: State) -> list[dict[str, Any]]:
    """The controls with the state's values (derived omega1, sigma from the beam when not
    set) for the page."""
    p = params_of(state)
    out = []
    for c in CONTROLS:
        d = c.as_json()
        d["value"] = float(getattr(p, c.name))
        d["explicit"] = c.name in state.overrides
        out.append(d)
    return out
