"""The earlier argument forms of the API functions, kept working with a warning.

Version 0.1's functions took their arguments in other orders (``hopf_points("omega1", 30,
300, params)``, ``cycle_branch("omega1", params)``, ``root_locus("omega1", values,
params)``, ``hopf_curve(params, names=..., bounds=...)``, ``design_map("omega1=40:190:100",
"sigma=...", preset)``). Each function recognises its old form, warns with
:func:`deprecated` (:class:`DeprecationWarning`, naming the new form) and goes on; the old
forms go away in :data:`REMOVED_IN`.
"""

from __future__ import annotations

import warnings

__all__ = ["deprecated", "REMOVED_IN"]

#: The version in which the earlier argument forms stop working.
REMOVED_IN = "0.4"


def deprecated(old: str, new: str) -> None:
    """Warn that the call form ``old`` is deprecated in favour of ``new``."""
    warnings.warn(f"{old} is deprecated; write {new}", DeprecationWarning, stacklevel=3)
