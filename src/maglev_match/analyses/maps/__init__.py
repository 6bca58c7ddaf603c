"""Maps of stability and the matching index over two-parameter design grids.

A grid is two swept parameters of a :class:`~maglev_match.core.params.Params`: model-A
parameters (omega1, sigma, kP, kD, ke, ...) or engineering quantities (L, EI, mbar, l, k)
from which omega1 and sigma derive. Every grid point is validated before any work starts.

What a map stores (see :func:`map_dataset`): the *headline* index ``chi`` = min(chi_paper,
chi_simulation), the index the reading of ``maglev-match index`` uses, and its two parts:

* ``chi_paper`` = h / w0 by the paper's definition (Chen, Ma, Luo & Zou 2019), h from the
  unstable cycle that bounds the basin or the gap range;
* ``chi_simulation`` = h_simulation / w0, h_simulation the smaller of the critical
  beam-deflection disturbances in the two directions (``h_simulation_up``: x5(0) < 0,
  ``h_simulation_down``: x5(0) > 0) found by simulation with the physical limits on.

Unstable points are their own category: ``stable`` = 0 and every index variable NaN there
(the paper writes chi = 0, which a colour scale would show as a poor stable design). A point
where a part could not be resolved is marked (``resolved`` = 0, ``reason`` a code of
:data:`REASON_CODES`) and its index is NaN, never a number filled in.

Work is split into tiles of whole rows (fixed y, x varying). Within a row the cycles are
*continued along the row*: the row is a path through parameter space
(:func:`~maglev_match.dynamics.paths.path_system`), its Hopf points are located on that
path, and from each one the cycle branch is followed across the adjacent stable stretch;
h at every grid point of the stretch is read off that one branch. The critical disturbances
are *followed* too (:func:`critical_sizes_batch`, warm-started from the neighbouring points:
the row below within a tile, else a coarse-to-fine order along the row), a few batched
simulations per point instead of a cold search of ~60. Tiles run through the package's job
runner (:mod:`maglev_match.core.jobs`: here, or on a Dask cluster, a local one by default
or an existing scheduler), are written to a checkpoint folder as they finish, and a resumed
map skips the tiles already there. Tile results do not depend on which worker ran them, so
a resumed map equals a map computed in one go bit for bit.

The package, one subject per module:

* :mod:`~maglev_match.analyses.maps.spec`: the axes, the map's spec and its checks, the
  stored variables and their codes, the simulation's search settings;
* :mod:`~maglev_match.analyses.maps.rows`: the paper's index along a row (:func:`compute_row`);
* :mod:`~maglev_match.analyses.maps.simulated`: the simulated critical disturbances along
  the rows (:func:`critical_sizes_batch`);
* :mod:`~maglev_match.analyses.maps.tiles`: a tile (:func:`compute_tile`), the whole map
  through the package's job runner (:func:`run_map`, :mod:`maglev_match.core.jobs`), its
  dataset (:func:`map_dataset`) and warnings;
* :mod:`~maglev_match.analyses.maps.check`: the self-check (:func:`spot_check`).

The names below are re-exported here. The runner's names (:class:`TileCount`,
:func:`run_pieces_on_dask`, :func:`local_cluster`, :func:`dask_log_capture`,
:func:`remove_checkpoint`, :data:`SINGLE_THREADED_ENV`) live in
:mod:`maglev_match.core.jobs` and are re-exported for the modules that import them from
here. A monkeypatch must patch the module where a name is looked up (e.g.
``maglev_match.analyses.maps.tiles.compute_tile``, which :func:`run_map` runs).
"""

from __future__ import annotations

from maglev_match.analyses.maps.check import (
    SPOT_CHECK_FRACTION,
    SPOT_CHECK_MAX,
    SPOT_CHECK_TOL,
    spot_check,
)
from maglev_match.analyses.maps.rows import (
    DELAY_FLOOR,
    FINE_SCAN,
    PATH_PAD,
    REFINE_WINDOW,
    SCAN_BATCH,
    SCAN_PER_NODE,
    compute_row,
    hopf_test_sign,
    path_eigenvalues,
    row_extension,
    scan_hopf_points,
    stretches,
)
from maglev_match.analyses.maps.simulated import (
    ANCHOR_SPACING,
    DIRECTIONS,
    SINGLE_SPREAD,
    WARM_ANCHOR_SPACING,
    critical_sizes_batch,
    simulate_row,
    simulate_rows,
)
from maglev_match.analyses.maps.spec import (
    BASIS_CODES,
    CASE_CODES,
    MAP_MODELS,
    MAP_VARIABLES,
    MAX_POINTS,
    REASON_CODES,
    REASON_FAILED,
    REASON_MAX_STEPS,
    REASON_NO_BRANCH,
    REASON_NO_HOPF,
    REASON_SIM_ROUNDS,
    REASON_SIM_UNDECIDED,
    SIM_CHUNK,
    TILE_FORMAT,
    Axis,
    MapSpec,
    parse_axis,
    simulation_settings,
)
from maglev_match.analyses.maps.tiles import (
    assemble,
    compute_tile,
    map_dataset,
    map_warnings,
    run_map,
)
from maglev_match.core.jobs import (
    DASK_LOGGERS,
    MALLOC_MMAP_THRESHOLD,
    MALLOC_TRIM_THRESHOLD,
    SCHEDULER_TIMEOUT,
    SINGLE_THREADED_ENV,
    TileCount,
    dask_log_capture,
    local_cluster,
    remove_checkpoint,
    run_pieces_on_dask,
    workers_ignore_sigint,
)

__all__ = ["Axis", "MapSpec", "parse_axis", "compute_row", "compute_tile", "run_map",
           "map_dataset", "spot_check", "map_warnings", "critical_sizes_batch",
           "simulation_settings", "remove_checkpoint", "dask_log_capture", "MAP_VARIABLES",
           "REASON_CODES", "CASE_CODES", "BASIS_CODES", "MAP_MODELS", "assemble",
           "TileCount", "run_pieces_on_dask", "local_cluster", "workers_ignore_sigint",
           "row_extension", "path_eigenvalues", "hopf_test_sign", "scan_hopf_points",
           "stretches", "simulate_rows", "simulate_row", "SINGLE_THREADED_ENV",
           "MALLOC_TRIM_THRESHOLD", "MALLOC_MMAP_THRESHOLD", "SCHEDULER_TIMEOUT",
           "DASK_LOGGERS", "MAX_POINTS", "TILE_FORMAT", "SIM_CHUNK", "SPOT_CHECK_FRACTION",
           "SPOT_CHECK_MAX", "SPOT_CHECK_TOL", "SCAN_PER_NODE", "SCAN_BATCH", "PATH_PAD",
           "DELAY_FLOOR", "REFINE_WINDOW", "FINE_SCAN", "DIRECTIONS", "ANCHOR_SPACING",
           "WARM_ANCHOR_SPACING", "SINGLE_SPREAD", "REASON_FAILED", "REASON_MAX_STEPS",
           "REASON_NO_HOPF", "REASON_NO_BRANCH", "REASON_SIM_UNDECIDED", "REASON_SIM_ROUNDS"]
