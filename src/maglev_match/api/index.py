"""The headline matching index (`maglev-match index`), its sensitivities (`sensitivity`)
and the spread of chi from parameter scatter (`index --scatter`, `--monte-carlo`)."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from maglev_match.api.inputs import resolve_params
from maglev_match.api.progress import reported
from maglev_match.core.params import ParameterError, Params, refuse_delay
from maglev_match.core.results import Plottable
from maglev_match.maglev.catalog import model_info

if TYPE_CHECKING:  # pragma: no cover
    from maglev_match.analyses.matching import MatchingIndex
    from maglev_match.analyses.sensitivity import IndexSensitivity

__all__ = ["matching_index", "index_sensitivity", "index_spread", "IndexSpread",
           "check_scatter", "scatter_rows", "refuse_delay"]


def _index_params(params: Params | str | None, config: str | Path | None,
                  overrides: Mapping[str, Any]) -> Params:
    """The parameter set of an index: chi = h / w0 needs a beam deflection w0 > 0."""
    base = resolve_params(params, config=config, **overrides)
    if not base.w0 > 0:
        raise ParameterError("sigma", base.sigma, "must be > 0 for the index: chi = h / w0 "
                             f"needs a beam deflection w0 > 0 (w0 = {base.w0:g} m)")
    return base


def matching_index(params: Params | str | None = None, *, model: str = "unit",
                   simulate: bool = True, config: str | Path | None = None,
                   stage: Callable[[str], None] | bool | None = None,
                   near: MatchingIndex | None = None, **overrides: Any) -> MatchingIndex:
    """The headline matching index chi = min(chi_paper, chi_simulation) of model A or the
    full vehicle (`maglev-match index [--model vehicle]`).

    The paper's chi = h / w0: h = 0 if the equilibrium is unstable; the largest gap
    deviation of the unstable cycle around the stable equilibrium (model B: over all six
    levitation points); or gap_max - c0 when no such cycle lies within the gap range. w0 is
    the static beam deflection (model A: sigma (m + M) g / omega1^2; model B: at mid-span
    under the vehicle). chi_simulation = h_simulation / w0 with h_simulation the critical
    disturbance simulated with the physical limits (solved where a grazing contact or a
    basin boundary decides it).

    Parameters
    ----------
    params : Params | str | None
        The parameter set (see [`resolve_params`][maglev_match.api.inputs.resolve_params]).
    model : str
        `"unit"` (model A) or `"vehicle"` (model B, 40 states).
    simulate : bool
        Also compute h_simulation (default; the headline is then the smaller of the two
        parts); False: the paper's chi only.
    config : str or Path, optional
        A TOML file applied on top of the preset.
    stage : callable or bool, optional
        Called with a line of text as each stage starts; False: silent; default: lines on
        standard error when progress is shown (see
        [`show_progress`][maglev_match.api.progress.show_progress]).
    near : MatchingIndex, optional
        The index at a neighbouring design (same model): each critical disturbance it
        solved is continued to this design (predicted from the neighbour, corrected by
        Newton on the same grazing or basin-boundary condition, checked by two simulations
        just below and above) instead of searched again; where that does not hold (the
        mechanism changes), the full search runs. ``simulation["up"]["continuation"]``
        (and ``"down"``) says which, and why. For designs visited one after another, as
        in a parameter study in one process.
    **overrides : float
        Parameter values applied on top.

    Returns
    -------
    MatchingIndex
        chi, h, w0, the case that decided h and its diagnostics; see
        [`MatchingIndex`][maglev_match.analyses.matching.MatchingIndex].
    """
    from maglev_match.analyses.matching import matching_index as _matching_index
    from maglev_match.api.progress import reporting

    p = resolve_params(params, config=config, **overrides)
    name = model_info(model).name
    extra = {} if near is None else {"near": near}
    with reporting("index", stage, False) as (say, _):
        return _matching_index(p, model=name, simulate=simulate, stage=say, **extra)


@reported("sensitivity", units=False)
def index_sensitivity(params: Params | str | None = None, *, model: str = "unit",
                      boundaries: bool = True, simulate: bool = True,
                      index: MatchingIndex | None = None, config: str | Path | None = None,
                      stage: Callable[[str], None] | None = None,
                      **overrides: Any) -> IndexSensitivity:
    """Exact d chi / d p of the headline index for every parameter (`maglev-match
    sensitivity`): implicit differentiation of the converged cycle that decides h, or of
    the solved critical disturbance where chi_simulation is the headline, the elasticities
    (p / chi) d chi / d p, the stability margin's sensitivities and, with `boundaries`,
    each parameter's value at the nearest stability boundary.

    Parameters
    ----------
    params : Params | str | None
        The parameter set (see [`resolve_params`][maglev_match.api.inputs.resolve_params]).
    model : str
        `"unit"` (model A) or `"vehicle"` (model B).
    boundaries : bool
        Also solve each parameter's value at the stability boundary.
    simulate : bool
        Differentiate the headline index (default); False: the paper's chi only
        (`--no-simulation`).
    index : MatchingIndex, optional
        The index at these parameters, already computed (it is then not computed again).
    config : str or Path, optional
        A TOML file applied on top of the preset.
    stage : callable, optional
        Called with a line of text once the inputs are checked and the work starts.
    **overrides : float
        Parameter values applied on top.

    Returns
    -------
    IndexSensitivity
        See `maglev_match.analyses.sensitivity.IndexSensitivity`; `.plot()` draws the
        tornado figure.
    """
    from maglev_match.analyses.sensitivity import index_sensitivity as _index_sensitivity

    base = _index_params(params, config, overrides)
    refuse_delay(base, "the sensitivities of the index")
    if stage is not None:
        stage("computing the index and its sensitivities ...")
    return _index_sensitivity(base, index, boundaries=boundaries,
                              model=model_info(model).name, simulate=simulate)


def scatter_rows(params: Params | str | None = None, *, model: str = "unit",
                 **overrides: Any) -> tuple[str, ...]:
    """The parameters that can scatter: those with a row in the model's sensitivity table
    (its own parameters, with the beam data in place of the derived modal values)."""
    from maglev_match.maglev.models import maglev_model

    return maglev_model(resolve_params(params, **overrides), model).engineering_names()


def check_scatter(params: Params | str | None = None, scatter: Mapping[str, float] = (), *,
                  model: str = "unit", **overrides: Any) -> None:
    """Every scattered name must have a row in the sensitivity table of ``model`` (checked
    before any computation, so a typo costs no index)."""
    if not scatter:
        return
    refuse_delay(resolve_params(params, **overrides), "the spread of chi and the "
                 "sensitivities it is built on")
    rows = scatter_rows(params, model=model, **overrides)
    for name in scatter:
        if name == "tau":
            raise ParameterError("scatter", name, "the delay has no row in the sensitivity "
                                 "table (the sensitivities are those of the delay-free "
                                 f"model); scatter one of {', '.join(rows)}")
        if name not in rows:
            raise ParameterError("scatter", name, "has no row in the sensitivity table of "
                                 "this model (a derived or unused value; rows: "
                                 f"{', '.join(rows)})")


@dataclass(frozen=True)
class IndexSpread(Plottable):
    """The spread of chi from parameter scatter: ``linearised`` ({chi, sd, contributions})
    from the exact sensitivities, and ``sampled`` (a
    :class:`~maglev_match.analyses.sensitivity.SampledSpread`) when a Monte Carlo study
    ran, else None. ``.plot()`` draws the histogram of the sampled chi (else the
    linearised contributions), ``.to_xarray()`` gives both as a dataset."""

    linearised: dict[str, Any] | None
    sampled: Any = None

    def as_json(self) -> dict[str, Any]:
        return {"spread": self.linearised,
                "monte_carlo": None if self.sampled is None else self.sampled.as_json()}

    def to_xarray(self) -> Any:
        """The spread as an :class:`xarray.Dataset`. Linearised (when computed): the 0-d
        ``chi`` at the base point and ``sd_linearised``, and ``contribution`` (each
        scattered parameter's part of the standard deviation) over ``parameter``. Sampled
        (when a Monte Carlo study ran): ``chi_sample`` over ``sample`` (NaN where the index
        failed or the set was invalid), the drawn ``parameter_sample`` over (``sample``,
        ``parameter``), and the 0-d ``chi_mean``, ``chi_sd``, ``chi_q05``, ``chi_q50``,
        ``chi_q95``, ``samples``, ``failed`` and ``invalid``. Parameter values are in their
        SI units (``parameter_unit``)."""
        import numpy as np
        import xarray as xr

        from maglev_match.core.datasets import annotate
        from maglev_match.core.params import PARAMETER_DOCS

        lin, mc = self.linearised, self.sampled
        names = list(mc.names if mc is not None else (lin or {}).get("contributions", {}))
        data: dict[str, Any] = {}
        units: dict[str, str] = {}
        longs: dict[str, str] = {}
        if lin is not None:
            parts = lin.get("contributions", {})
            data["chi"] = ((), float(lin["chi"]))
            data["sd_linearised"] = ((), float(lin["sd"]))
            data["contribution"] = ("parameter", np.array(
                [float(parts.get(n, np.nan)) for n in names], float))
            units.update(sd_linearised="1", contribution="1")
            longs.update(chi="headline matching index at the base point",
                         sd_linearised="standard deviation of chi to first order",
                         contribution="part of the linearised standard deviation due to "
                                      "the parameter, |d chi / d p| p s_p")
        if mc is not None:
            q = mc.quantiles
            data.update({
                "chi_sample": ("sample", np.asarray(mc.chi, float)),
                "parameter_sample": (("sample", "parameter"), np.asarray(mc.samples, float)),
                "chi_mean": ((), float(mc.mean)), "chi_sd": ((), float(mc.sd)),
                "chi_q05": ((), float(q.get("5%", np.nan))),
                "chi_q50": ((), float(q.get("50%", np.nan))),
                "chi_q95": ((), float(q.get("95%", np.nan))),
                "samples": ((), np.int64(mc.n)), "failed": ((), np.int64(mc.failed)),
                "invalid": ((), np.int64(mc.invalid))})
            units.update({k: "1" for k in ("chi_sample", "chi_mean", "chi_sd", "chi_q05",
                                            "chi_q50", "chi_q95", "samples", "failed",
                                            "invalid")})
            units["parameter_sample"] = "SI (see parameter_unit)"
            longs.update(
                chi_sample="matching index chi (no simulation) of the sampled parameter set",
                parameter_sample="sampled parameter value", chi_mean="mean of the sampled chi",
                chi_sd="standard deviation of the sampled chi",
                chi_q05="5 % quantile of the sampled chi", chi_q50="median of the sampled chi",
                chi_q95="95 % quantile of the sampled chi", samples="samples drawn",
                failed="samples whose index did not converge",
                invalid="samples outside the parameter rules (not computed)")
        coords: dict[str, Any] = {}
        if names:
            coords["parameter"] = ("parameter", names)
            data["parameter_unit"] = ("parameter", np.array(
                [PARAMETER_DOCS.get(n, ("",))[0] for n in names], dtype=str))
            units.update(parameter="1", parameter_unit="1")
            longs.update(parameter="scattered parameter",
                         parameter_unit="SI unit of the parameter")
        if mc is not None:
            coords["sample"] = ("sample", np.arange(mc.n))
            units["sample"] = "1"
            longs["sample"] = "sample number"
        ds = xr.Dataset(data, coords=coords, attrs={
            "title": "maglev-match spread of chi under parameter scatter",
            "linearised": int(lin is not None), "monte_carlo": int(mc is not None)})
        return annotate(ds, units=units, long_names=longs)


@reported("scatter")
def index_spread(params: Params | str | None = None, scatter: Mapping[str, float] = (), *,
                 model: str = "unit", index: MatchingIndex | None = None,
                 sensitivity: IndexSensitivity | None = None,
                 monte_carlo: int | None = None, checkpoint: str | Path | None = None,
                 seed: int = 0, resume: bool = False, workers: int | None = None,
                 scheduler: str | None = None,
                 stage: Callable[[str], None] | None = None,
                 progress: Callable[[int, int], None] | None = None,
                 config: str | Path | None = None, **overrides: Any) -> IndexSpread:
    """The spread of the headline chi when parameters scatter (`index --scatter NAME=PCT
    [--monte-carlo N]`): to first order from the exact sensitivities (independent
    parameters with relative standard deviations ``scatter``, name -> percent), and with
    `monte_carlo` the distribution of chi over N sampled parameter sets (chunk by chunk on
    Dask, each chunk saved in `checkpoint`; `resume` reuses finished chunks).

    Parameters
    ----------
    params : Params | str | None
        The parameter set (see [`resolve_params`][maglev_match.api.inputs.resolve_params]).
    scatter : mapping
        {name: relative standard deviation in percent}.
    model : str
        `"unit"` or `"vehicle"`.
    index, sensitivity : optional
        The index, or its sensitivities (without boundaries), already computed.
    monte_carlo : int, optional
        Samples of the Monte Carlo study.
    checkpoint : str or Path
        The study's folder (required with `monte_carlo`).
    seed, resume, workers, scheduler : as for the Monte Carlo study
        (:func:`maglev_match.analyses.sensitivity.sampled_spread`).
    stage, progress : callables, optional
        A line of text per stage; `progress(done, total)` per chunk.
    config : str or Path, optional
        A TOML file applied on top of the preset.
    **overrides : float
        Parameter values applied on top.

    Returns
    -------
    IndexSpread
    """
    from maglev_match.analyses.sensitivity import linearised_spread, sampled_spread

    if monte_carlo is not None and not scatter:
        raise ParameterError("monte_carlo", monte_carlo, "needs at least one scattered "
                             "parameter (scatter NAME=PCT)")
    if not scatter:
        return IndexSpread(None, None)
    base = _index_params(params, config, overrides)
    check_scatter(base, scatter, model=model)
    say = stage or (lambda text: None)
    if sensitivity is None:
        say("sensitivities for the linearised spread ...")
        sensitivity = index_sensitivity(base, model=model, boundaries=False, index=index)
    for name in scatter:
        try:
            sensitivity.row(name)
        except KeyError:
            raise ParameterError("scatter", name, "has no row in the sensitivity table "
                                 "(a derived value: scatter its beam parameters)") from None
    spread = linearised_spread(sensitivity, scatter)
    sampled = None
    if monte_carlo is not None:
        if checkpoint is None:
            raise ParameterError("checkpoint", None, "a Monte Carlo study needs a folder for "
                                 "its chunks")
        say(f"Monte Carlo, {monte_carlo} samples ...")
        sampled = sampled_spread(base, scatter, monte_carlo, Path(checkpoint), seed=seed,
                                 resume=resume, workers=workers, scheduler=scheduler,
                                 linearised=spread, model=model_info(model).name,
                                 progress=progress)
    return IndexSpread(spread, sampled)
