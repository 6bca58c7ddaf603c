"""maglev-match: stability, Hopf bifurcations, limit cycles and the vehicle-track beam
matching index chi = h / w0 for EMS maglev systems.

The public API lives at the top level of the package::

    import maglev_match as mm

    p = mm.load_preset("turnout-soft")
    mm.stability(p)                       # eigenvalues and the verdict
    mm.matching_index(p, simulate=False)  # chi = h / w0 with the case that decided h
    mm.matching_index(p, model="vehicle") # the full vehicle
    ds = mm.design_map(p, x=("omega1", 60, 160, 11), y=("sigma", 3e-4, 5e-4, 5))
    mm.plot(ds, "map.png")                # any result with a figure; or result.plot()

Importing the package is cheap: the names below are loaded on first use (module
``__getattr__``, PEP 562), so ``import maglev_match`` does not import JAX, Dask, xarray or
matplotlib.
"""

from __future__ import annotations

import importlib
from pathlib import Path
from typing import TYPE_CHECKING, Any

from maglev_match import legacy_paths

legacy_paths.install()  # the module paths of version 0.1 keep working, with a warning

__version__ = "0.1.0"

# public name -> module that defines it
_LAZY: dict[str, str] = {
    "Params": "maglev_match.core.params",
    "ParameterError": "maglev_match.core.params",
    "load_params": "maglev_match.core.params",
    "load_preset": "maglev_match.core.params",
    "available_presets": "maglev_match.core.params",
    "System": "maglev_match.dynamics.system",
    "build_system": "maglev_match.api",
    "stability": "maglev_match.api",
    "root_locus": "maglev_match.api",
    "hopf_points": "maglev_match.api",
    "hopf_curve": "maglev_match.api",
    "cycle_branch": "maglev_match.api",
    "simulate": "maglev_match.api",
    "matching_index": "maglev_match.api",
    "index_sensitivity": "maglev_match.api",
    "design_search": "maglev_match.api",
    "design_map": "maglev_match.api",
    "study_report": "maglev_match.present.documents",
    "reproduce": "maglev_match.present.documents",
    "restart_branch": "maglev_match.api",
    "speed_sweep": "maglev_match.api",
    "show_progress": "maglev_match.api",
    # figures: plot(result) draws any result; the figure functions themselves
    "plot": "maglev_match.plots",
    "figure_of": "maglev_match.plots",
    "root_locus_figure": "maglev_match.plots.rootlocus",
    "hopf_scan_figure": "maglev_match.plots.hopf",
    "hopf_curve_figure": "maglev_match.plots.hopf",
    "cycle_diagram": "maglev_match.plots.cycles",
    "simulation_figure": "maglev_match.plots.simulate",
    "map_figure": "maglev_match.plots.maps",
    "tornado_figure": "maglev_match.plots.design",
    "design_path_figure": "maglev_match.plots.design",
    "load_model": "maglev_match.maglev.user",
}

# the user-model loader ships in its own module; list it only where that module exists
if not (Path(__file__).parent / "maglev" / "user.py").exists():
    del _LAZY["load_model"]

__all__ = sorted([*_LAZY, "__version__"])

if TYPE_CHECKING:  # for type checkers and IDEs; never executed
    from maglev_match.api import (  # noqa: F401
        build_system,
        cycle_branch,
        design_map,
        design_search,
        hopf_curve,
        hopf_points,
        index_sensitivity,
        matching_index,
        restart_branch,
        root_locus,
        show_progress,
        simulate,
        speed_sweep,
        stability,
    )
    from maglev_match.core.params import (  # noqa: F401
        ParameterError,
        Params,
        available_presets,
        load_params,
        load_preset,
    )
    from maglev_match.dynamics.system import System  # noqa: F401
    from maglev_match.plots import figure_of, plot  # noqa: F401
    from maglev_match.present.documents import reproduce, study_report  # noqa: F401


def __getattr__(name: str) -> Any:
    """Load a public name on first access (PEP 562)."""
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'maglev_match' has no attribute '{name}'")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value  # later accesses skip this function
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))
