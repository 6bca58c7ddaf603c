"""The HTML of the reports: the Jinja2 environment over the templates in
``maglev_match/templates/report/`` (autoescaping on, so a value can never inject markup),
rendering a template, the table/figure/note helpers (figures embedded as base64 PNG; the
PNG and SVG files written beside the report), the software version, and assembling and
writing the self-contained document (inline styles, no ``http://`` or ``https://``
reference; the footer records the software version and the settings)."""

from __future__ import annotations

import base64
import datetime as _dt
import functools
import html
import json
import platform
import subprocess
import time
from collections.abc import Iterable, Sequence
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from maglev_match.core.io import atomic_write_text
from maglev_match.present.report.base import ReportResult

if TYPE_CHECKING:
    from maglev_match.core.params import Params
    from maglev_match.present.report.base import ReportContext, SectionResult

__all__ = [
    "TEMPLATES",
    "CSS",
    "fmt",
    "esc",
    "environment",
    "render",
    "table_html",
    "figure_html",
    "note_html",
    "formatted_rows",
    "save_and_embed",
    "software_version",
    "assemble_html",
    "write_report",
]


def fmt(value: Any, digits: int = 5) -> str:
    """Numbers for tables: ``digits`` significant digits, '-' for None/NaN."""
    if value is None:
        return "-"
    if isinstance(value, bool | np.bool_):
        return "yes" if value else "no"
    if isinstance(value, int | np.integer):
        return str(int(value))
    if isinstance(value, float | np.floating):
        if not np.isfinite(value):
            return "-"
        return f"{float(value):.{digits}g}"
    if isinstance(value, complex | np.complexfloating):
        z = complex(value)
        sign = "+" if z.imag >= 0 else "-"
        return f"{z.real:.{digits}g} {sign} {abs(z.imag):.{digits}g}j"
    return str(value)


def esc(text: Any) -> str:
    return html.escape(str(text), quote=True)


#: the report templates (``maglev_match/templates/report``), found as package data
TEMPLATES = resources.files("maglev_match") / "templates" / "report"
CSS = (TEMPLATES / "report.css").read_text()  # the page's inline style sheet


@functools.cache
def environment():
    """The Jinja2 environment of the report templates: autoescaping on, the number format
    :func:`fmt` and ``mm`` (metres -> millimetres) available in every template."""
    import jinja2

    env = jinja2.Environment(loader=jinja2.FileSystemLoader(str(TEMPLATES)),
                             autoescape=True, trim_blocks=True, lstrip_blocks=True,
                             undefined=jinja2.StrictUndefined)
    env.globals.update(fmt=fmt, mm=lambda v: None if v is None else float(v) * 1e3)
    return env


def render(template: str, **context: Any) -> str:
    """Render one template of ``templates/report`` with ``context``."""
    return str(environment().get_template(template).render(**context))


def _macros():
    return environment().get_template("macros.html.j2").module


def table_html(
    header: Sequence[str],
    rows: Iterable[Sequence[Any]],
    css_class: str = "",
    raw_columns: Sequence[int] = (),
    row_classes: Sequence[str] | None = None,
    column_classes: dict[int, str] | None = None,
) -> str:
    """An HTML table (template macro ``table``); cells are formatted by :func:`fmt` and
    escaped, except the columns in ``raw_columns`` (already HTML); ``column_classes``
    gives a CSS class to the cells of some columns."""
    from markupsafe import Markup

    cells = [[Markup(str(c)) if j in raw_columns else fmt(c) for j, c in enumerate(row)]
             for row in rows]
    return str(_macros().table(list(header), cells, css_class, list(row_classes or []),
                               dict(column_classes or {})))


def figure_html(png_path: Path, caption: str, alt: str | None = None) -> str:
    """A figure embedded as a base64 PNG (no file reference in the HTML)."""
    data = base64.b64encode(Path(png_path).read_bytes()).decode("ascii")
    return str(_macros().figure(data, caption, alt or caption))


def note_html(text: str, kind: str = "note") -> str:
    """A highlighted paragraph (kind: 'note', 'warning' or 'unavailable')."""
    return str(_macros().note(text, kind))


def formatted_rows(rows: Iterable[Sequence[Any]]) -> list[tuple[str, ...]]:
    """Table rows with every cell formatted by :func:`fmt` (the templates' tables escape
    but do not format)."""
    return [tuple(fmt(c) for c in r) for r in rows]


def save_and_embed(fig: Any, ctx: ReportContext, stem: str, caption: str
                   ) -> tuple[str, list[Path]]:
    """Save a matplotlib figure as PNG + SVG in the report folder and return the embedded
    HTML and the written files."""
    from maglev_match.plots import save_figure

    files = save_figure(fig, ctx.figure_path(stem))
    png = next(f for f in files if f.suffix == ".png")
    return figure_html(png, caption), files


def software_version() -> dict[str, str]:
    """Package version, git commit (when run from a checkout), Python, NumPy, JAX."""
    import maglev_match

    info = {"maglev-match": maglev_match.__version__, "python": platform.python_version(),
            "numpy": np.__version__}
    try:
        import jax
        import scipy

        info["jax"] = jax.__version__
        info["scipy"] = scipy.__version__
    except ImportError:  # pragma: no cover
        pass
    try:
        here = Path(__file__).resolve().parent
        rev = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=here,
                             capture_output=True, text=True, timeout=5)
        if rev.returncode == 0 and rev.stdout.strip():
            info["git commit"] = rev.stdout.strip()
    except (OSError, subprocess.SubprocessError):
        pass
    info["platform"] = platform.platform()
    return info


def assemble_html(title: str, intro_html: str, sections: Sequence[SectionResult],
                  settings: dict[str, Any], params: Params | None = None) -> str:
    """The complete self-contained HTML document (template ``page.html.j2``)."""
    from markupsafe import Markup

    version = software_version()
    stamp = _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%d %H:%M:%S UTC")
    footer_rows = [(k, v) for k, v in version.items()]
    footer_rows.append(("generated", stamp))
    footer_rows += [(f"setting: {k}", json.dumps(v)) for k, v in settings.items()]
    if params is not None:
        changed = ", ".join(sorted(params.explicit)) or "none"
        footer_rows.append(("explicitly set derivable values", changed))
    footer_rows.append(("section run times (s)", ", ".join(
        f"{s.key} {s.seconds:.1f}" for s in sections)))
    footer = table_html(["item", "value"], footer_rows, "footer-table")
    return render("page.html.j2", title=title, intro=Markup(intro_html),
                  sections=sections, footer=Markup(footer),
                  quick=bool(settings.get("quick"))) + "\n"


def write_report(path: Path, title: str, intro_html: str, sections: Sequence[SectionResult],
                 settings: dict[str, Any], params: Params | None = None,
                 t_start: float | None = None) -> ReportResult:
    """Write the HTML file and return a :class:`ReportResult`."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(path, assemble_html(title, intro_html, sections, settings, params))
    figures = tuple(f for s in sections for f in s.figures)
    seconds = time.perf_counter() - t_start if t_start is not None else 0.0
    return ReportResult(path=path, sections=tuple(sections), figures=figures, seconds=seconds)
