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
    """Warn that the call form ``old`` is deprecated in favour of ``new``, at the user's
    line (the first frame outside the API package, wrappers included)."""
    import os
    import sys

    here = os.path.dirname(os.path.abspath(__file__))
    level, frame = 2, sys._getframe(1)  # stacklevel 2 is the caller of this function
    while frame is not None and os.path.dirname(os.path.abspath(frame.f_code.co_filename)) \
            == here:
        level, frame = level + 1, frame.f_back
    warnings.warn(f"{old} is deprecated; write {new}", DeprecationWarning, stacklevel=level)
