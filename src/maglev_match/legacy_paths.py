"""The package's earlier module paths, kept working with a deprecation warning.

Version 0.2 arranged the modules in layers (``core``, ``dynamics``, ``maglev``,
``analyses``, ``present``; see docs/architecture.md). Code written against 0.1 imports the
old paths (``maglev_match.matching``, ``maglev_match.models.unit``, ...). A finder on
:data:`sys.meta_path` resolves each of them to the module at its new path (the same module
object, so attributes, classes and monkeypatches are shared) and warns once per path with
:class:`DeprecationWarning`. The old paths go away in version 0.4.

Standard library only: :mod:`maglev_match` installs the finder on import, before anything
heavy is loaded.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys
import warnings

__all__ = ["MOVED", "REMOVED_IN", "install"]

#: The version in which the old module paths stop working.
REMOVED_IN = "0.4"

#: old module path -> new module path
MOVED: dict[str, str] = {
    "maglev_match.aot": "maglev_match.core.aot",
    "maglev_match.checkpoint": "maglev_match.core.checkpoint",
    "maglev_match.critical": "maglev_match.analyses.critical",
    "maglev_match.datasets": "maglev_match.core.datasets",
    "maglev_match.design": "maglev_match.analyses.design",
    "maglev_match.dynamics.passage": "maglev_match.dynamics.integrate.passage",
    "maglev_match.dynamics.simulate": "maglev_match.dynamics.integrate.simulate",
    "maglev_match.dynamics.threshold": "maglev_match.dynamics.integrate.threshold",
    "maglev_match.engineering": "maglev_match.analyses.engineering",
    "maglev_match.errors": "maglev_match.core.errors",
    "maglev_match.interrupts": "maglev_match.core.interrupts",
    "maglev_match.io": "maglev_match.core.io",
    "maglev_match.jax_setup": "maglev_match.core.jax_setup",
    "maglev_match.limits_check": "maglev_match.maglev.limits",
    "maglev_match.maps": "maglev_match.analyses.maps",
    "maglev_match.matching": "maglev_match.analyses.matching",
    "maglev_match.models": "maglev_match.maglev",
    "maglev_match.models.clamp": "maglev_match.maglev.clamp",
    "maglev_match.models.limits": "maglev_match.maglev.limits",
    "maglev_match.models.moving": "maglev_match.maglev.moving",
    "maglev_match.models.unit": "maglev_match.maglev.unit",
    "maglev_match.models.user": "maglev_match.maglev.user",
    "maglev_match.models.vehicle": "maglev_match.maglev.vehicle",
    "maglev_match.options": "maglev_match.core.options",
    "maglev_match.params": "maglev_match.core.params",
    "maglev_match.report": "maglev_match.present.report",
    "maglev_match.reproduce": "maglev_match.present.reproduce",
    "maglev_match.reprs": "maglev_match.core.reprs",
    "maglev_match.restart": "maglev_match.analyses.restart",
    "maglev_match.ride": "maglev_match.analyses.speed.ride",
    "maglev_match.sensitivity": "maglev_match.analyses.sensitivity",
    "maglev_match.simulation": "maglev_match.analyses.simulation",
    "maglev_match.speed": "maglev_match.analyses.speed.sweep",
    "maglev_match.speed_grid": "maglev_match.analyses.speed.grid",
    "maglev_match.speed_maps": "maglev_match.analyses.speed.maps",
    "maglev_match.speed_spans": "maglev_match.analyses.speed.spans",
    "maglev_match.units": "maglev_match.core.units",
}


class _Alias(importlib.abc.Loader):
    def __init__(self, new: str) -> None:
        self.new = new

    def create_module(self, spec):
        return importlib.import_module(self.new)

    def exec_module(self, module) -> None:  # the module is already executed
        return None


class _MovedFinder(importlib.abc.MetaPathFinder):
    def find_spec(self, fullname, path=None, target=None):
        new = MOVED.get(fullname)
        if new is None:
            return None
        warnings.warn(f"{fullname} is deprecated: import {new} (the old module paths go "
                      f"away in maglev-match {REMOVED_IN})", DeprecationWarning, stacklevel=3)
        return importlib.util.spec_from_loader(fullname, _Alias(new))


def install() -> None:
    """Put the finder on :data:`sys.meta_path` (once)."""
    if not any(isinstance(f, _MovedFinder) for f in sys.meta_path):
        sys.meta_path.insert(0, _MovedFinder())
