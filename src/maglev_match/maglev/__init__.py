"""The maglev models: what a maglev model is (:mod:`~maglev_match.maglev.base`), the
shipped models and their table (:mod:`~maglev_match.maglev.models`), their names for the
command line (:mod:`~maglev_match.maglev.catalog`, light), their equations (``unit``,
``vehicle``), their forms with the current clamp (``clamp``) and at speed (``moving``),
their physical limits (``limits``), the beam formulas (``beam``) and user model files
(``user``). Physics only: the numerical methods are in :mod:`maglev_match.dynamics`.

Importing this package loads nothing else (the command line reads the catalog before JAX).
"""

from __future__ import annotations

from typing import Any


def __getattr__(name: str) -> Any:
    """``maglev_match.models.build_system`` of version 0.1 (deprecated)."""
    if name == "build_system":
        import warnings

        warnings.warn("maglev_match.models.build_system is deprecated: use "
                      "maglev_match.maglev.models.maglev_model(params, name).system() (or "
                      "maglev_match.build_system); it goes away in 0.4", DeprecationWarning,
                      stacklevel=2)
        from maglev_match.maglev.models import build_system

        return build_system
    raise AttributeError(f"module 'maglev_match.maglev' has no attribute '{name}'")
