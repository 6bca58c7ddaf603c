"""The equilibrium: its stability (`maglev-match stability`), the root locus along one
parameter (`root-locus`) and the shipped parameter sets (`presets`)."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from maglev_match.api.compat import deprecated
from maglev_match.api.inputs import names_a_preset, resolve_model
from maglev_match.core.params import ParameterError, Params

if TYPE_CHECKING:  # pragma: no cover
    import numpy as np

    from maglev_match.dynamics.equilibria import RootLocusResult, StabilityResult

__all__ = ["stability", "root_locus", "presets", "PresetRow"]


def stability(params: Params | str | None = None, *, model: str = "unit",
              config: str | Path | None = None, **overrides: Any) -> StabilityResult:
    """Equilibrium, eigenvalues and the stability verdict (`maglev-match stability`).

    The Jacobian is exact (automatic differentiation); the equilibrium is stable when every
    eigenvalue has a negative real part.

    Parameters
    ----------
    params : Params | str | None
        The parameter set: a [`Params`][maglev_match.core.params.Params], the name of a
        shipped preset, or None for the default preset `turnout-soft`.
    model : str
        `"unit"` (model A, 9 states), `"vehicle"` (model B, 40 states with 3 modes) or a
        user model file `FILE.py`.
    config : str or Path, optional
        A TOML file applied on top of the preset.
    **overrides : float
        Parameter values applied on top, validated like `--set NAME=VALUE` (for a user
        model file: its own parameters).

    Returns
    -------
    StabilityResult
        Eigenvalues (1/s, largest real part first), `stable`, `margin` = -max Re(lambda)
        (1/s), the equilibrium, the model (`system`) and warnings; see
        [`StabilityResult`][maglev_match.dynamics.equilibria.StabilityResult].
    """
    from maglev_match.dynamics.equilibria import stability as _stability

    studied = resolve_model(params, model, config=config, **overrides)
    return _stability(studied.system())


def root_locus(params: Params | str | None = None, param: str = "omega1",
               values: Sequence[float] | np.ndarray | None = None, *, model: str = "unit",
               config: str | Path | None = None, progress: Any = None,
               **overrides: Any) -> RootLocusResult:
    """Eigenvalues of the equilibrium along one parameter (`maglev-match root-locus`).

    A beam or vehicle quantity (L, EI, mbar, l, k, s, s0) of the maglev models moves omega1
    and sigma with it (model B also its geometry): the eigenvalues are computed on the
    model's parameters at each value (:mod:`maglev_match.analyses.engineering`).

    Parameters
    ----------
    params : Params | str | None
        The parameter set (see [`resolve_params`][maglev_match.api.inputs.resolve_params]).
    param : str
        The parameter to vary (any parameter of the model, or beam/vehicle data).
    values : array_like, optional
        Its values, in its SI unit (default: 151 values from 40 to 190, as the command).
    model : str
        `"unit"`, `"vehicle"` or a user model file `FILE.py`.
    config : str or Path, optional
        A TOML file applied on top of the preset.
    progress : callable, optional
        Called as `progress(done, total)` after each value.
    **overrides : float
        Parameter values applied on top, validated like `--set NAME=VALUE`.

    Returns
    -------
    RootLocusResult
        See [`RootLocusResult`][maglev_match.dynamics.equilibria.RootLocusResult], with the
        design point and its eigenvalues; `.plot()` draws it, `.to_xarray()` gives its
        dataset, `.stability_changes` where max Re(lambda) changes sign.
    """
    import numpy as np

    from maglev_match.analyses.engineering import engineering_nodes, is_engineering
    from maglev_match.core.units import unit
    from maglev_match.dynamics.equilibria import root_locus as _root_locus
    from maglev_match.dynamics.equilibria import stability as _stability
    from maglev_match.dynamics.paths import PATH_PARAM, path_system

    if isinstance(params, str) and not names_a_preset(params):  # root_locus(param, values, p)
        deprecated("root_locus(param, values, params)", "root_locus(params, param, values)")
        params, param, values = values, params, param
    values = np.linspace(40.0, 190.0, 151) if values is None else np.asarray(values, float)
    if values.ndim != 1 or values.size < 2:
        raise ParameterError("values", values.size, "need at least 2 values")
    studied = resolve_model(params, model, config=config, **overrides)
    engineering = studied.params is not None and is_engineering(param)
    studied.check_param(param, "param", delays=False, engineering=True)
    for v in (values[0], values[-1]):
        studied.validate_value(param, float(v))
    system = studied.system()
    if engineering:  # the path through the model parameters at each value: t = k exact
        path = path_system(system, engineering_nodes(studied.params, studied.label, param,
                                                     values))
        res = _root_locus(path, PATH_PARAM, np.arange(values.size, dtype=float),
                          progress=progress)
        res = dataclasses.replace(res, param=param, values=values, param_unit=unit(param))
    else:
        res = _root_locus(system, param, values, progress=progress)
    return dataclasses.replace(res, design_value=studied.design_value(param),
                               design_eigenvalues=_stability(system).eigenvalues)


@dataclasses.dataclass(frozen=True)
class PresetRow:
    """One shipped parameter set: its beam values, description and its changes against
    the preset it derives from ({name: (base value, value)})."""

    name: str
    omega1: float
    sigma: float
    w0: float
    EI: float
    L: float
    mbar: float
    description: str
    base: str | None
    changes: dict[str, tuple[float, float]]

    def as_json(self) -> dict[str, Any]:
        return {"name": self.name, "omega1": self.omega1, "sigma": self.sigma, "w0": self.w0,
                "EI": self.EI, "L": self.L, "mbar": self.mbar,
                "description": self.description, "base": self.base,
                "changes": {k: {"base": a, "value": b} for k, (a, b) in self.changes.items()}}


def presets() -> list[PresetRow]:
    """The shipped parameter sets (`maglev-match presets`), in name order."""
    from maglev_match.core.params import available_presets, load_preset, preset_info

    rows = []
    for name in available_presets():
        p = load_preset(name)
        info = preset_info(name)
        rows.append(PresetRow(name, float(p.omega1), float(p.sigma), float(p.w0),
                              float(p.EI), float(p.L), float(p.mbar), info.description,
                              info.base, dict(info.changes)))
    return rows
