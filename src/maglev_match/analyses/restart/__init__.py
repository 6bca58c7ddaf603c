"""Restart from saved branches: cycle branches, Hopf curves and equilibrium branches.

A saved branch is a netCDF file (``cycles --out``, ``hopf-curve --out``, or
:func:`save_equilibrium_branch`) that carries, besides its data, what a restart needs and
what a reader needs to trust it (:func:`stamp` adds these on writing). Loading is
validation first (:func:`load_cycle_restart`, :func:`load_hopf_curve_restart`,
:func:`load_equilibrium_restart`): every problem is one :class:`RestartFileError` naming
the file and what is wrong. A restart continues the saved branch at the saved parameter
values (:func:`check_parameters`). The library functions :func:`restart_cycle_branch`,
:func:`restart_hopf_curve` and :func:`restart_equilibrium_branch` load, check and continue
in one call; :func:`restart` is the one entry point for the Python API.

The package is organised by subject:

* :mod:`~maglev_match.analyses.restart.files`: the kinds of file and the errors, stamping
  a dataset, opening a file and telling its kind, the checks every kind shares, the saved
  parameter values of a restart point;
* :mod:`~maglev_match.analyses.restart.cycles`: the cycle branch's restart point and its
  continuation;
* :mod:`~maglev_match.analyses.restart.hopf_curve`: the Hopf curve's restart point and its
  continuation;
* :mod:`~maglev_match.analyses.restart.equilibria`: equilibrium-branch files (writing
  them), their restart point and its continuation;
* :mod:`~maglev_match.analyses.restart.entry`: the model a file names
  (:func:`saved_system`) and :func:`restart`, which dispatches on the kind of file.

Every public name is re-exported here, so ``maglev_match.analyses.restart.NAME`` keeps
working.
"""

from __future__ import annotations

from maglev_match.analyses.restart.cycles import (
    CycleRestart,
    RestartedCycleBranch,
    check_parameters,
    load_cycle_restart,
    restart_cycle_branch,
)
from maglev_match.analyses.restart.entry import restart, saved_system
from maglev_match.analyses.restart.equilibria import (
    EquilibriumRestart,
    equilibrium_branch_dataset,
    load_equilibrium_restart,
    restart_equilibrium_branch,
    save_equilibrium_branch,
)
from maglev_match.analyses.restart.files import (
    COMMAND_ATTR,  # noqa: F401  (re-exported)
    FILE_ATTR,  # noqa: F401  (re-exported)
    MODEL_ATTR,  # noqa: F401  (re-exported)
    SAME,  # noqa: F401  (re-exported)
    RestartFileError,
    RestartKind,
    RestartLabelError,
    RestartMismatch,
    file_kind,
    open_saved,
    saved_params,
    saved_values,
    stamp,
)
from maglev_match.analyses.restart.hopf_curve import (
    HopfCurveRestart,
    load_hopf_curve_restart,
    restart_hopf_curve,
)

__all__ = [
    "RestartKind", "RestartFileError", "RestartLabelError", "RestartMismatch", "stamp",
    "open_saved",
    "file_kind", "CycleRestart", "load_cycle_restart", "check_parameters",
    "RestartedCycleBranch", "restart_cycle_branch", "saved_values", "saved_params",
    "HopfCurveRestart", "load_hopf_curve_restart", "restart_hopf_curve",
    "equilibrium_branch_dataset", "save_equilibrium_branch", "EquilibriumRestart",
    "load_equilibrium_restart", "restart_equilibrium_branch", "saved_system", "restart",
]
