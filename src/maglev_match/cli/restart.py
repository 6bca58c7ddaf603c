"""``cycles --restart FILE --label L`` and ``hopf-curve --restart FILE --label L``: the
command line's words for a saved branch that cannot be restarted. The restart itself (no
Hopf search, the saved model, mesh and values, the refusals of what does not apply) is the
API's (:func:`maglev_match.api.cycles.cycle_study`, :func:`maglev_match.api.hopf.hopf_curve`)
over the branch files of :mod:`maglev_match.analyses.restart`."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

from maglev_match.cli.common import UserError

__all__ = ["restart_error_context"]


@contextlib.contextmanager
def restart_error_context() -> Iterator[None]:
    """A saved branch that cannot be restarted as a command-line error (exit code 2):
    ``--label L: ...`` for a label the file does not have, ``--restart: ...`` for a file
    that cannot be used or does not match the model."""
    from maglev_match import api

    try:
        yield
    except api.RestartLabelError as exc:
        raise UserError(f"--label {exc.label}: {exc}") from None
    except (api.RestartFileError, api.RestartMismatch) as exc:
        raise UserError(f"--restart: {exc}") from None
