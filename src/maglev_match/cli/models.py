"""``--model``: the built-in maglev models (``unit``, ``vehicle``) or a user model file.

A value ending in ``.py`` is a user model (see :mod:`maglev_match.maglev.user`): ``--set
NAME=VALUE`` then applies to the file's PARAMS and ``--preset``/``--config`` (maglev parameter
sets) do not apply (:func:`maglev_match.cli.common.model_inputs`; the API loads the file).
Commands whose physics only make sense for the maglev models refuse a file with one clear
line (:func:`refuse_model_file`).
"""

from __future__ import annotations

from typing import Annotated

import typer

from maglev_match.cli.common import UserError


def is_model_file(model: str) -> bool:
    """True when a ``--model`` value names a Python file rather than a built-in model
    (the same rule as :func:`maglev_match.maglev.user.is_model_file`, without importing
    that module: a usage error must not wait for JAX)."""
    return str(model).endswith(".py")


__all__ = ["is_model_file", "refuse_model_file", "MaglevOnlyModelOpt"]


#: ``--model`` on the commands that analyse the maglev models themselves (index, map,
#: report, reproduce): accepted only to refuse a model file with a clear message.
MaglevOnlyModelOpt = Annotated[
    str | None, typer.Option("--model", hidden=True,
                             help="Not an option of this command (maglev models only).")
]


def refuse_model_file(model: str | None, command: str) -> None:
    """Commands built on the maglev physics (index, map, report, reproduce) refuse a file
    (and any other --model value: they choose the maglev models themselves)."""
    if model is None:
        return
    if is_model_file(model):
        raise UserError(f"--model {model}: '{command}' works on the maglev models only; "
                        "user model files are accepted by stability, root-locus, hopf, "
                        "hopf-curve, cycles and simulate")
    raise UserError(f"--model {model}: '{command}' has no --model option (it analyses the "
                    "maglev models itself)")
