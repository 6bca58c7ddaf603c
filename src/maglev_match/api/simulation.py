"""Simulations (`maglev-match simulate`): a maglev model with its physical limits from a
named or explicit initial state, a user model file from its X0 or a given state, and the
vehicle at speed over N spans (`simulate --speed V --spans N`)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from maglev_match.api.inputs import resolve_model, resolve_params
from maglev_match.api.progress import reported
from maglev_match.core.params import ParameterError, Params
from maglev_match.core.results import Plottable

if TYPE_CHECKING:  # pragma: no cover
    import numpy as np

    from maglev_match.analyses.simulation import MaglevSimulation
    from maglev_match.analyses.speed.spans import SpanRun

__all__ = ["simulate", "simulate_over_spans", "UserSimulation", "SPANS_MAX"]

#: The most spans of a run over spans.
SPANS_MAX = 1000


@dataclass(frozen=True)
class UserSimulation(Plottable):
    """One run of a user model file (no physical limits): the integrator's result, the
    model's name and file, and its state names; ``.plot()`` draws the time history of
    every state, ``.to_xarray()`` gives it as a dataset.

    outcome : 'converged' | 'running' | 'failed' (a user model has no collision).
    """

    model: str
    model_file: str
    state_names: tuple[str, ...]
    result: Any = field(repr=False)

    @property
    def outcome(self) -> str:
        return str(self.result.outcome)

    @property
    def warnings(self) -> tuple[str, ...]:
        return tuple(self.result.warnings)

    def summary(self) -> dict[str, Any]:
        """The outcome and the final state (machine-readable, the model's units)."""
        res = self.result
        return {"model": self.model, "model_file": self.model_file, "outcome": res.outcome,
                "final_time": res.final_time,
                "final_state": dict(zip(self.state_names, res.final_state.tolist(),
                                        strict=True)),
                "converged_time": res.converged_time, "accepted": res.accepted,
                "rejected": res.rejected, "warnings": list(res.warnings)}

    def history(self) -> tuple[Any, Any]:
        """(times, states): the saved history, one row per saved time."""
        return self.result.t, self.result.x

    def to_xarray(self) -> Any:
        """The history as an :class:`xarray.Dataset`: ``x`` (the states) over (``time``,
        ``state``), the state names as the ``state`` coordinate (rows after the run ended
        are NaN), the 0-d ``final_time``, ``final_state`` (over ``state``) and
        ``converged_time`` (NaN when not converged). A user model states no units: times
        are in seconds (or the model's time unit), the states in the model's own units.
        The model, its file, the outcome, the step counts and the warnings (JSON list) are
        attributes."""
        import json

        import numpy as np
        import xarray as xr

        from maglev_match.core.datasets import annotate

        res = self.result
        conv = float("nan") if res.converged_time is None else float(res.converged_time)
        ds = xr.Dataset(
            {"x": (("time", "state"), np.asarray(res.x, float)),
             "final_time": ((), float(res.final_time)),
             "final_state": (("state",), np.asarray(res.final_state, float)),
             "converged_time": ((), conv)},
            coords={"time": ("time", np.asarray(res.t, float)),
                    "state": ("state", list(self.state_names))},
            attrs={"title": f"maglev-match simulation, user model {self.model}",
                   "model": self.model, "model_file": str(self.model_file),
                   "outcome": str(res.outcome), "accepted": int(res.accepted),
                   "rejected": int(res.rejected), "warnings": json.dumps(list(res.warnings))})
        own = "the model's units (see state)"
        return annotate(ds, units={"x": own, "final_state": own,
                                   "final_time": "s", "converged_time": "s"},
                        long_names={"x": "state of the user model",
                                    "final_time": "time at which the run ended",
                                    "final_state": "state at which the run ended",
                                    "converged_time": "start of the final stretch within "
                                                      "the convergence tolerance (NaN: "
                                                      "not converged)"})


def simulate(params: Params | str | None = None, *, model: str = "unit",
             t_end: float = 5.0, x5: float | None = None, initial: str = "equilibrium",
             q1: float | None = None, x0: Sequence[float] | np.ndarray | None = None,
             limits: bool = True, n_save: int = 5001, rtol: float = 1e-8,
             atol: float = 1e-8, config: str | Path | None = None,
             **overrides: Any) -> MaglevSimulation | UserSimulation:
    """Simulate model A or B with the physical limits (`maglev-match simulate`), or a user
    model file.

    With `limits` the coil current never reverses and leaving the gap range
    [gap_min, gap_max] ends the run as a collision. A user model file runs from `x0`
    (default: its X0) without physical limits.

    Parameters
    ----------
    params : Params | str | None
        The parameter set (see [`resolve_params`][maglev_match.api.inputs.resolve_params]).
    model : str
        `"unit"` (model A, 9 states), `"vehicle"` (model B, 40 states with 3 modes) or a
        user model file `FILE.py`.
    t_end : float
        Horizon (s).
    x5 : float, optional
        Model A: initial beam deflection x5(0) (m); negative opens the gap.
    initial : str
        `"equilibrium"`, or for model B `"pressed"` (the vehicle at equilibrium on the
        undeflected beam).
    q1 : float, optional
        Model B: first modal coordinate q1(0) (m, undeflected beam = 0).
    x0 : array_like, optional
        The whole initial state (overrides the above).
    limits : bool
        The physical limits (maglev models).
    n_save : int
        Saved time points.
    rtol, atol : float
        Tolerances (atol in units of each state's typical size).
    config : str or Path, optional
        A TOML file applied on top of the preset.
    **overrides : float
        Parameter values applied on top, validated like `--set NAME=VALUE`.

    Returns
    -------
    MaglevSimulation or UserSimulation
        Outcome (collision / converged / running / failed), collision time, limit and
        point; see [`MaglevSimulation`][maglev_match.analyses.simulation.MaglevSimulation].
    """
    import numpy as np

    from maglev_match.dynamics.integrate.simulate import SimulationOptions

    if not t_end > 0:
        raise ParameterError("t_end", t_end, "the horizon must be > 0 s")
    if n_save < 2:
        raise ParameterError("n_save", n_save, "need at least 2 saved points")
    if not (rtol > 0 and atol > 0):
        raise ParameterError("rtol/atol", (rtol, atol), "must be > 0")
    studied = resolve_model(params, model, config=config, **overrides)
    options = SimulationOptions(rtol=rtol, atol=atol)
    if studied.is_user:
        from maglev_match.dynamics.integrate.simulate import simulate as _simulate

        system = studied.system()
        n = len(studied.user.states)
        state = studied.user.x0 if x0 is None else np.asarray(x0, float).ravel()
        if state.shape != (n,):
            raise ParameterError("x0", f"{state.size} values", f"model {studied.label} has "
                                 f"{n} states ({', '.join(studied.user.states)})")
        res = _simulate(system, _lifted(system, state), t_end, options=options,
                        n_save=n_save)
        if res.x.shape[-1] != n:  # a delay model's discretised past: keep the model's states
            import dataclasses

            res = dataclasses.replace(
                res, x=np.asarray(res.x)[:, :n], final_state=np.asarray(res.final_state)[:n],
                event_state=None if res.event_state is None else
                np.asarray(res.event_state)[:n])
        return UserSimulation(studied.label, studied.file, tuple(studied.user.states), res)
    from maglev_match.analyses.simulation import simulate_maglev

    m = studied.maglev
    state = None if x0 is None else np.asarray(x0, float).ravel()
    x_init = m.initial_state(initial, x5=x5, q1=q1, state=state)
    return simulate_maglev(m, x0=x_init, t_end=t_end, limited=limits, n_save=n_save,
                           options=options)


def _lifted(system: Any, x: Any) -> Any:
    """A model state as a state of ``system`` (a discretised delay system holds the past:
    a constant past)."""
    lift = getattr(system, "lift", None)
    return x if lift is None else lift(x)


@reported("simulate", units=False)
def simulate_over_spans(params: Params | str | None = None, *, model: str = "unit",
                        kmh: float = 100.0, spans: int = 10, limits: bool = True,
                        config: str | Path | None = None,
                        stage: Callable[[str], None] | None = None,
                        irregularity: str | None = None, seed: int | None = None,
                        **overrides: Any) -> SpanRun:
    """The vehicle at speed over `spans` identical spans, from rigid ground and off again,
    with the periodic response overlaid (`maglev-match simulate --speed V --spans N`).

    Parameters
    ----------
    params : Params | str | None
        The parameter set (see [`resolve_params`][maglev_match.api.inputs.resolve_params]).
    model : str
        `"unit"`, `"vehicle"` or `"force"` (a constant moving force).
    kmh : float
        The speed (km/h), in (0, 900].
    spans : int
        Spans (1 to :data:`SPANS_MAX`).
    limits : bool
        The physical limits.
    config : str or Path, optional
        A TOML file applied on top of the preset.
    stage : callable, optional
        Called with a line of text once the inputs are checked and the run starts.
    irregularity : str, optional
        A guideway irregularity under every levitation point, `KIND:NAME=VALUE,...` as for
        [`speed_sweep`][maglev_match.api.speed.speed_sweep] (then no periodic response is
        overlaid).
    seed : int, optional
        The seed of a random profile (default: its `seed0`).
    **overrides : float
        Parameter values applied on top.

    Returns
    -------
    SpanRun
        The run, its read-outs per span and passage; `.to_xarray()` and `.plot()`.
    """
    import math

    from maglev_match.analyses.speed.grid import KMH, SPEED_MAX, SPEED_MIN
    from maglev_match.analyses.speed.spans import simulate_over_spans as _over_spans
    from maglev_match.analyses.speed.sweep import SpeedOptions, check_speed_setup

    kmh_max, kmh_min = SPEED_MAX / KMH, SPEED_MIN / KMH
    if not (math.isfinite(kmh) and kmh_min <= kmh <= kmh_max):
        raise ParameterError("kmh", kmh, f"must lie in [{kmh_min:g}, {kmh_max:g}] km/h for a "
                             "run over spans (slower, one span passage lasts longer than a "
                             "run at speed can integrate)")
    p = resolve_params(params, config=config, **overrides)
    check_speed_setup(p, model, [kmh * KMH], spans, delay=False,
                      refuse_delay="a run over a finite number of spans has no delay of the "
                      "outer loop yet")
    if spans > SPANS_MAX:
        raise ParameterError("spans", spans, f"must be at most {SPANS_MAX} for a run over "
                             "spans")
    prof = None
    if irregularity is None and config is not None:
        from maglev_match.maglev.irregularity import irregularity_in_config

        irregularity = irregularity_in_config(config)
    if irregularity is not None:
        from maglev_match.analyses.speed.irregular import check_irregular_setup

        prof = check_irregular_setup(p, model, [kmh * KMH], irregularity, spans, warmup=0)
        if seed is not None and (isinstance(seed, bool) or not isinstance(seed, int)
                                 or seed < 0):
            raise ParameterError("--seed", seed, "must be a whole number >= 0")
    elif seed is not None:
        raise ParameterError("--seed", seed, "goes with --irregularity random:...")
    if stage is not None:
        stage(f"running model {model} over {spans} spans at {kmh:g} km/h"
              + ("" if prof is None else f" over an irregular guideway ({prof.describe()})")
              + " ...")
    return _over_spans(p, model, kmh * KMH, spans, limited=limits,
                       options=SpeedOptions(critical=False), profile=prof,
                       seed=(prof.seed0 if seed is None else seed) if prof else 0)
