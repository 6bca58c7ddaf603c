"""The documents, called as the API functions are: the HTML study report of one
vehicle-beam pair (`maglev-match report`) and the reproduction of the paper's figures and
claims (`reproduce`). Documents are built from results, above the API (the command line and
the package's top level call these)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from maglev_match.api.inputs import resolve_params
from maglev_match.core.params import ParameterError, Params

if TYPE_CHECKING:  # pragma: no cover
    from maglev_match.present.report import ReportResult

__all__ = ['study_report', 'reproduce', 'report_sections', 'REPRODUCE_SECTIONS']


def study_report(params: Params | str | None = None, out: str | Path = "report.html", *,
                 quick: bool = False, vehicle: bool = True, t_end: float = 3.0,
                 label: str = "", progress: Callable[[str], None] | None = None,
                 config: str | Path | None = None, **overrides: Any) -> ReportResult:
    """The self-contained HTML study report of one vehicle-beam pair (`maglev-match
    report`): parameters, stability, root locus, Hopf curve, cycles, time histories, the
    matching index and its sensitivities; figures embedded (and written as PNG/SVG to
    `<out stem>_figures/`).

    Parameters
    ----------
    params : Params | str | None
        The parameter set (see [`resolve_params`][maglev_match.api.inputs.resolve_params]).
    out : str or Path
        The HTML file.
    quick : bool
        Coarse, fast settings (previews).
    vehicle : bool
        Also analyse model B (the full vehicle).
    t_end : float
        Simulation horizon (s).
    label : str
        A name for the study (default: the preset name, or "parameter set").
    progress : callable, optional
        Called with each section's title before it runs.
    **overrides : float
        Parameter values applied on top.

    Returns
    -------
    ReportResult
        The written file, its figures and every section's data; see
        `maglev_match.present.report.ReportResult`.
    """
    from maglev_match.present.report import ReportSettings
    from maglev_match.present.report import study_report as _study_report

    if not t_end > 0:
        raise ParameterError("t_end", t_end, "the horizon must be > 0 s")
    base = resolve_params(params, config=config, **overrides)
    settings = ReportSettings.quick_settings() if quick else ReportSettings()
    settings = ReportSettings(**{**settings.as_dict(), "include_vehicle": vehicle,
                                 "t_end": t_end})
    name = label or (params if isinstance(params, str) else "parameter set")
    return _study_report(base, out, settings, label=name, progress=progress)


def report_sections() -> int:
    """The number of sections of a study report (for numbered progress lines)."""
    from maglev_match.present.report import study_sections

    return len(study_sections())


def _section_keys() -> tuple[str, ...]:
    from maglev_match.present.reproduce import SECTIONS

    return tuple(k for k, _, _ in SECTIONS)


#: The sections of the reproduction: fig4, fig5, fig6-8, fig11-13, fig12, variants.
REPRODUCE_SECTIONS = ("fig4", "fig5", "fig6-8", "fig11-13", "fig12", "variants")


def reproduce(out: str | Path, *, quick: bool = False, only: Sequence[str] | None = None,
              progress: Callable[[str], None] | None = None) -> tuple[Any, list]:
    """The paper's figures (Figs. 4-8, 11-13) and claims recomputed with the printed
    defaults (`maglev-match reproduce`): writes reproduce.html, claims.csv, claims.json and
    figures/ into the folder ``out``.

    Parameters
    ----------
    out : str or Path
        The folder.
    quick : bool
        Coarse, fast settings (previews).
    only : sequence of str, optional
        The figure sections to include (:data:`REPRODUCE_SECTIONS`; default all).
    progress : callable, optional
        Called with each section's title before it runs.

    Returns
    -------
    (ReportResult, list of Claim)
    """
    from maglev_match.present.report import ReportSettings
    from maglev_match.present.reproduce import reproduce as _reproduce

    keys = _section_keys()
    for k in only or []:
        if k not in keys:
            raise ParameterError("only", k, f"no such section; choose from {', '.join(keys)}")
    settings = ReportSettings.quick_settings() if quick else ReportSettings()
    return _reproduce(Path(out), settings, only=list(only) if only else None,
                      progress=progress)
