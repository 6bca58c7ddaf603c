"""The public Python API and the one front door of the library: the command line and the
figures reach the computations only through these functions.

Every function has one signature style, ``function(params, ..., **overrides)``:

* ``params`` (first) — a :class:`~maglev_match.core.params.Params`, the name of a shipped
  preset (``"turnout-soft"``, ``"alpha1"``, ...) or ``None`` for the default preset;
* then what the analysis varies (``param``, ``values``, the axes ``x=("omega1", 40, 190,
  100)`` of a map ...) and its keyword options (``model="unit"`` or ``"vehicle"`` wherever
  the command line has ``--model``, a user model file ``"FILE.py"`` where the command
  accepts one; ``config`` a TOML file on top of the preset);
* ``**overrides`` — parameter values applied on top, validated like ``--set NAME=VALUE``
  on the command line (for example ``kD=120`` or the beam data ``L=18, EI=2.0e10``, from
  which omega1 and sigma are derived; for a user model file, its own parameters).

The domain decisions are made here, once, for both front ends: which Hopf method a
parameter needs (ordinary, beam/vehicle data, delay), the delay axis of a model, which Hopf
point a branch of cycles starts from, the restart of a saved branch, the design search and
the tiled runs of maps and sweeps. Each function returns a result object (frozen
dataclasses carrying their diagnostics) with ``.plot(path=None, **options)`` and, where it
holds gridded or branch data, ``.to_xarray()``.

The earlier forms (``hopf_points("omega1", 30, 300, params)``, ``cycle_branch("omega1",
params)``, ``root_locus("omega1", values, params)``, ``hopf_curve(params, names=...,
bounds=...)``, ``design_map("omega1=40:190:100", "sigma=...", preset)``) still work and
warn (:class:`DeprecationWarning`, :mod:`maglev_match.api.compat`). The methods and their
sources are documented where they are implemented (:mod:`maglev_match.dynamics`,
:mod:`maglev_match.analyses`).
"""

from __future__ import annotations

import importlib
from typing import Any

#: public name -> the submodule that defines it (loaded on first use, PEP 562: importing
#: the API loads no NumPy or JAX, so that the command line answers usage errors at once)
_NAMES: dict[str, str] = {
    "resolve_params": "inputs", "resolve_model": "inputs", "StudiedModel": "inputs",
    "is_model_file": "inputs", "build_system": "inputs",
    "stability": "linear", "root_locus": "linear", "presets": "linear",
    "PresetRow": "linear",
    "hopf_points": "hopf", "hopf_curve": "hopf", "HopfCurveStudy": "hopf",
    "HOPF_CURVE_RANGES": "hopf",
    "cycle_branch": "cycles", "restart_branch": "cycles", "cycle_study": "cycles",
    "CycleStudy": "cycles", "saved_model": "cycles",
    "cycle_curve": "cycle_curves", "CycleCurveStudy": "cycle_curves",
    "simulate": "simulation", "simulate_over_spans": "simulation",
    "UserSimulation": "simulation",
    "matching_index": "index", "index_sensitivity": "index", "index_spread": "index",
    "IndexSpread": "index", "check_scatter": "index", "scatter_rows": "index",
    "design_search": "design", "check_requirements": "design", "design_problem": "design",
    "design_map": "maps", "map_warnings": "maps", "remove_tiles": "maps",
    "speed_sweep": "speed", "speed_map": "speed", "ride_reading": "speed",
    "show_progress": "progress",
    "iso_curve": "iso", "iso_inputs": "iso", "restart_iso_curve": "iso",
}

__all__ = [
    "resolve_params",
    "resolve_model",
    "StudiedModel",
    "is_model_file",
    "build_system",
    "stability",
    "root_locus",
    "presets",
    "PresetRow",
    "hopf_points",
    "hopf_curve",
    "HopfCurveStudy",
    "HOPF_CURVE_RANGES",
    "cycle_branch",
    "cycle_study",
    "CycleStudy",
    "saved_model",
    "cycle_curve",
    "CycleCurveStudy",
    "simulate",
    "simulate_over_spans",
    "UserSimulation",
    "matching_index",
    "index_sensitivity",
    "index_spread",
    "IndexSpread",
    "check_scatter",
    "scatter_rows",
    "design_search",
    "check_requirements",
    "design_problem",
    "design_map",
    "map_warnings",
    "remove_tiles",
    "speed_map",
    "ride_reading",
    "restart_branch",
    "speed_sweep",
    "show_progress",
    "iso_curve",
    "iso_inputs",
    "restart_iso_curve",
    "MODELS",
    "RestartFileError",
    "RestartLabelError",
    "RestartMismatch",
]


def __getattr__(name: str) -> Any:
    """Load a public name on first access. The errors of a saved branch that cannot be
    restarted live with the branch files (:mod:`maglev_match.analyses.restart`)."""
    if name == "MODELS":
        from maglev_match.maglev.catalog import MODEL_NAMES

        return MODEL_NAMES
    if name == "study_report":  # (0.1's API; the documents sit above the API)
        import warnings

        warnings.warn("maglev_match.api.study_report is deprecated: use "
                      "maglev_match.study_report (maglev_match.present.documents); it goes "
                      "away in 0.4", DeprecationWarning, stacklevel=2)
        return importlib.import_module("maglev_match.present.documents").study_report
    if name in ("RestartFileError", "RestartLabelError", "RestartMismatch"):
        from maglev_match.analyses import restart

        return getattr(restart, name)
    module = _NAMES.get(name)
    if module is None:
        raise AttributeError(f"module 'maglev_match.api' has no attribute '{name}'")
    value = getattr(importlib.import_module(f"maglev_match.api.{module}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
