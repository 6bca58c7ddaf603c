"""The study report of one vehicle-beam pair: running a section (a failure becomes a "not
available: <reason>" box, so a report always renders; :func:`run_section`), the sections
in order (:func:`study_sections`) and the report itself (:func:`study_report`)."""

from __future__ import annotations

import logging
import time
import traceback
from collections.abc import Callable, Sequence
from pathlib import Path

from maglev_match.core.params import Params
from maglev_match.present.report.base import (
    ReportContext,
    ReportResult,
    ReportSettings,
    SectionFn,
    SectionResult,
    SectionUnavailable,
)
from maglev_match.present.report.html import note_html, render, write_report
from maglev_match.present.report.sections_cycles import (
    section_bifurcation_diagrams,
    section_hopf_curve,
)
from maglev_match.present.report.sections_history import section_time_history
from maglev_match.present.report.sections_index import section_matching, section_sensitivity
from maglev_match.present.report.sections_stability import (
    section_parameters,
    section_root_locus,
    section_stability,
)

log = logging.getLogger(__name__)

__all__ = ["run_section", "study_sections", "study_report"]


def run_section(key: str, title: str, fn: SectionFn, params: Params,
                ctx: ReportContext) -> SectionResult:
    """Run one section function; a failure becomes a "not available: <reason>" box."""
    t0 = time.perf_counter()
    try:
        fragment, figures, data = fn(params, ctx)
        return SectionResult(key, title, fragment, tuple(Path(f) for f in figures), data,
                             True, "", time.perf_counter() - t0)
    except SectionUnavailable as exc:
        reason = str(exc)
    except ImportError as exc:
        reason = f"analysis module not installed yet ({exc})"
    except Exception as exc:  # the report must always render; the reason is shown and logged
        reason = f"{type(exc).__name__}: {exc}"
        log.debug("section %s failed:\n%s", key, traceback.format_exc())
    log.warning("report section '%s' not available: %s", key, reason)
    box = note_html(f"not available: {reason}", "unavailable")
    return SectionResult(key, title, box, (), None, False, reason, time.perf_counter() - t0)


def study_sections() -> list[tuple[str, str, SectionFn]]:
    """(key, title, function) of the study report's sections, in order."""
    return [
        ("parameters", "Parameters", section_parameters),
        ("stability", "Stability and eigenvalues", section_stability),
        ("root-locus", "Root locus along omega1", section_root_locus),
        ("hopf-curve", "Hopf curve in (omega1, sigma)", section_hopf_curve),
        ("cycles", "Bifurcation diagrams through the design point",
         section_bifurcation_diagrams),
        ("time-history", "Time history after the typical disturbance", section_time_history),
        ("matching", "Matching index h, w0, chi", section_matching),
        ("sensitivity", "Sensitivities of the index", section_sensitivity),
    ]


def study_report(
    params: Params,
    out: str | Path,
    settings: ReportSettings | None = None,
    label: str = "",
    only: Sequence[str] | None = None,
    progress: Callable[[str], None] | None = None,
) -> ReportResult:
    """Write the self-contained HTML study report of one vehicle-beam pair.

    Parameters
    ----------
    params : the parameter set.
    out : the HTML file; figures (PNG + SVG) are written to ``<stem>_figures/`` beside it.
    settings : :class:`ReportSettings` (``ReportSettings.quick_settings()`` for previews).
    label : a name for the study (e.g. the preset name), shown in the title.
    only : keys of the sections to include (default: all of :func:`study_sections`).
    progress : called with each section's title before it runs.
    """
    t0 = time.perf_counter()
    settings = settings or ReportSettings()
    out = Path(out)
    fig_dir = out.parent / f"{out.stem}_figures"
    fig_dir.mkdir(parents=True, exist_ok=True)
    ctx = ReportContext(out_dir=fig_dir, settings=settings)
    results = []
    for key, title, fn in study_sections():
        if only is not None and key not in only:
            continue
        if progress is not None:
            progress(title)
        results.append(run_section(key, title, fn, params, ctx))
    name = label or "parameter set"
    intro = render("study_intro.html.j2", name=name, params=params)
    return write_report(out, f"maglev-match study report: {name}", intro, results,
                        {"label": name, **settings.as_dict()}, params, t0)
