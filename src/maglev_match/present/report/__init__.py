"""Self-contained HTML study reports: one HTML file per study.

A report is a list of *sections*. Each section is produced by a small function
``section(params, ctx) -> (html_fragment, figure_files, data)``; :func:`run_section` calls it
and, if the analysis it needs raises or is not available, renders a clear
"not available: <reason>" box instead (and logs the reason), so a report always renders.

The HTML comes from Jinja2 templates in ``maglev_match/templates/report/`` (the page, its
style sheet, the table/figure/note macros and the larger sections), rendered with
autoescaping, so a value can never inject markup. The file needs no network: figures are
embedded as base64 PNG (the SVG and PNG files are also written beside the report), styles
are inline, and no element refers to an ``http://`` or ``https://`` address. The footer
records the software version and the settings that produced the report.

:func:`study_report` assembles the report for one vehicle-beam pair: parameters with units,
stability and eigenvalues (models A and B), the root locus along omega1, the Hopf curve in
the (omega1, sigma) plane with the design point, the cycle bifurcation diagrams through the
design point, the time history after the typical disturbance (the vehicle pressed onto the
free beam, x5(0) = -w0) and the matching index h, w0, chi with its reading.

The modules of this package, each one subject; every name is also importable from here:

* ``base``: the data (:class:`ReportSettings`, :class:`ReportContext`,
  :class:`SectionResult`, :class:`SectionUnavailable`, :class:`ReportResult`);
* ``html``: the templates, the table/figure/note helpers, assembling and writing the page;
* ``sections_stability``: parameters, stability and eigenvalues, root locus;
* ``sections_cycles``: cycle bifurcation diagrams and the Hopf curve;
* ``sections_history``: time histories;
* ``sections_index``: the matching index and its sensitivities;
* ``study``: running the sections and the study report.
"""

from __future__ import annotations

from maglev_match.present.report.base import (
    ReportContext,
    ReportResult,
    ReportSettings,
    SectionFn,
    SectionResult,
    SectionUnavailable,
)
from maglev_match.present.report.html import (
    CSS,
    TEMPLATES,
    assemble_html,
    environment,
    esc,
    figure_html,
    fmt,
    formatted_rows,
    note_html,
    render,
    save_and_embed,
    software_version,
    table_html,
    write_report,
)
from maglev_match.present.report.sections_cycles import (
    PARAM_LABEL,
    CycleDiagram,
    cycle_diagram,
    cycle_diagram_figure,
    cycle_diagram_table,
    hopf_curve_figure,
    hopf_curve_table,
    hopf_curves,
    section_bifurcation_diagrams,
    section_hopf_curve,
    stability_region,
)
from maglev_match.present.report.sections_history import (
    SETTLED_FRACTION,
    converges,
    fitted_window,
    late_amplitude,
    outcome_text,
    run_time_history,
    section_time_history,
    time_history_figure,
)
from maglev_match.present.report.sections_index import (
    BASIS_TEXT,
    matching_rows,
    section_matching,
    section_sensitivity,
    sensitivity_rows,
    side_by_side_rows,
)
from maglev_match.present.report.sections_stability import (
    EIGEN_ROWS,
    eigen_rows,
    eigen_table_html,
    params_table_html,
    section_parameters,
    section_root_locus,
    section_stability,
    stability_summary,
)
from maglev_match.present.report.study import run_section, study_report, study_sections

__all__ = [
    # the data and the study report
    "ReportSettings",
    "ReportContext",
    "SectionResult",
    "SectionUnavailable",
    "ReportResult",
    "SectionFn",
    "run_section",
    "study_sections",
    "study_report",
    # the HTML
    "TEMPLATES",
    "CSS",
    "fmt",
    "esc",
    "environment",
    "render",
    "figure_html",
    "table_html",
    "note_html",
    "formatted_rows",
    "save_and_embed",
    "assemble_html",
    "write_report",
    "software_version",
    # the sections and what the reproduction shares with them
    "params_table_html",
    "section_parameters",
    "stability_summary",
    "eigen_rows",
    "eigen_table_html",
    "EIGEN_ROWS",
    "section_stability",
    "section_root_locus",
    "CycleDiagram",
    "cycle_diagram",
    "PARAM_LABEL",
    "cycle_diagram_figure",
    "cycle_diagram_table",
    "section_bifurcation_diagrams",
    "hopf_curves",
    "stability_region",
    "hopf_curve_figure",
    "hopf_curve_table",
    "section_hopf_curve",
    "run_time_history",
    "late_amplitude",
    "converges",
    "outcome_text",
    "SETTLED_FRACTION",
    "fitted_window",
    "time_history_figure",
    "section_time_history",
    "matching_rows",
    "side_by_side_rows",
    "BASIS_TEXT",
    "section_matching",
    "sensitivity_rows",
    "section_sensitivity",
]
