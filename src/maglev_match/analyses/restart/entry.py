"""The one entry point of the Python API for saved branches: the model a saved file names,
at its saved parameter values (:func:`saved_system`), and :func:`restart`, which reads the
kind of file and continues it with the restart of that kind
(:mod:`~maglev_match.analyses.restart.cycles`,
:mod:`~maglev_match.analyses.restart.hopf_curve`,
:mod:`~maglev_match.analyses.restart.equilibria`).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import Any

import numpy as np

from maglev_match.analyses.restart.cycles import restart_cycle_branch
from maglev_match.analyses.restart.equilibria import restart_equilibrium_branch
from maglev_match.analyses.restart.files import (
    MODEL_ATTR,
    RestartFileError,
    RestartKind,
    file_kind,
    open_saved,
    require_finite,
    saved_names,
    variable,
)
from maglev_match.analyses.restart.hopf_curve import restart_hopf_curve
from maglev_match.maglev.catalog import MODEL_NAMES

__all__ = ["saved_system", "restart"]


# ---------------------------------------------------------------------------------------
# one entry point (the Python API's restart)
# ---------------------------------------------------------------------------------------
_SAVED_P = {RestartKind.CYCLE_BRANCH: "hopf_p", RestartKind.HOPF_CURVE: "base_p",
            RestartKind.EQUILIBRIUM_BRANCH: "p"}


def saved_system(source: Any) -> tuple[Any, Any]:
    """The model a saved file was computed with, at its saved parameter values:
    (System, Params or None). Model A or B from the file's ``model`` and ``params``
    attributes; a user model from its ``model_file`` attribute (the file is loaded again).
    A file that names neither is a :class:`RestartFileError` (give the system yourself)."""
    import dataclasses

    ds, where = open_saved(source)
    kind, what = file_kind(ds)
    if kind is None:
        raise RestartFileError(where, f"not a saved branch (it is {what})")
    model = ds.attrs.get(MODEL_ATTR)
    pj = ds.attrs.get("params")
    if model in MODEL_NAMES and isinstance(pj, str):
        from maglev_match.core.params import FIELD_NAMES, ParameterError, make_params
        from maglev_match.maglev.models import build_system

        try:
            params = make_params({k: v for k, v in json.loads(pj).items()
                                  if k in FIELD_NAMES})
        except (ValueError, TypeError, AttributeError, ParameterError) as exc:
            raise RestartFileError(where, "its parameter set (attribute params) is not valid: "
                                   f"{' '.join(str(exc).split())[:160]}") from None
        return build_system(params, model), params
    mfile = ds.attrs.get("model_file")
    if isinstance(mfile, str) and mfile.endswith(".py"):
        from maglev_match.maglev.user import load_model

        system = load_model(mfile).system()
        names = saved_names(ds, where, "parameter")
        p = require_finite(where, _SAVED_P[kind],
                           variable(ds, where, _SAVED_P[kind], ("parameter",)))
        if list(names) != list(system.param_names):
            raise RestartFileError(where, f"the model file {mfile} has other parameters than "
                                   "the saved branch")
        return dataclasses.replace(system, p=np.array(p, float)), None
    raise RestartFileError(where, "does not say which model computed it (no model/params or "
                           "model_file attribute): pass the system to restart with")


def restart(source: Any, label: str, system: Any = None, *, param: str | None = None,
            stop: float | None = None, bounds: Mapping[str, tuple[float, float]] | None = None,
            **options: Any) -> Any:
    """Continue any saved branch from its point ``label`` — the Python API's restart.

    The kind of file decides what is continued: a cycle branch (``cycles --out``;
    ``param`` may name another parameter to continue in), a Hopf curve (``hopf-curve
    --out``; ``bounds`` default the saved ones) or an equilibrium branch
    (:func:`save_equilibrium_branch`; ``stop`` is required). Without ``system`` the saved
    model at its saved parameter values is used (:func:`saved_system`); a cycle branch of
    model A or B then gets the physical limits the ``cycles`` command uses (the coil
    current and the gap range), unless ``limits`` is given. ``options`` go to the
    continuation.

    Returns
    -------
    :class:`RestartedCycleBranch`, or (HopfCurve, :class:`HopfCurveRestart`), or
    (EquilibriumBranch, :class:`EquilibriumRestart`).
    """
    ds, where = open_saved(source)
    kind, what = file_kind(ds)
    if kind is None:
        raise RestartFileError(where, f"not a saved branch (it is {what})")
    params = None
    if system is None:
        system, params = saved_system(source)
    if kind is RestartKind.CYCLE_BRANCH:
        if params is not None and "limits" not in options:
            from maglev_match.maglev.limits import cycle_limit_margins

            options["limits"] = cycle_limit_margins(params)
        return restart_cycle_branch(source, label, system, param=param, **options)
    if kind is RestartKind.HOPF_CURVE:
        return restart_hopf_curve(source, label, system, bounds, **options)
    if stop is None:
        raise ValueError("restart of an equilibrium branch: give stop, the value of the "
                         "continued parameter where the branch should end")
    return restart_equilibrium_branch(source, label, system, stop, **options)
