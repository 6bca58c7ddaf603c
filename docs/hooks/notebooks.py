"""mkdocs hook: the tutorial notebooks, executed, on their tutorial pages.

A page holding the marker ``<!-- notebook -->`` gets, in its place, the notebook it names
(``examples/NN-....ipynb``) as stored in the repository, i.e. executed and saved with its
outputs (``docs/figures/run_notebooks.py``): markdown cells as text, code cells as Python
blocks, text outputs as output blocks and figures embedded as PNG data (no file, no
network). The tests execute every notebook again (tests/test_notebooks.py), so what a page
shows is what the code gives.
"""

from __future__ import annotations

import html
import re
from pathlib import Path

MARKER = "<!-- notebook -->"
ROOT = Path(__file__).resolve().parents[2]


def _text(output) -> str:
    if output.get("output_type") == "stream":
        return "".join(output.get("text", ""))
    data = output.get("data", {})
    return "".join(data.get("text/plain", ""))


def render_notebook(path: Path) -> str:
    """The notebook as Markdown: its cells and their stored outputs."""
    import nbformat

    nb = nbformat.read(path, as_version=4)
    parts = [f"## The notebook, executed\n\n*`{path.relative_to(ROOT)}` as stored, with "
             "the outputs of its last run.*\n"]
    for cell in nb.cells:
        if cell.cell_type == "markdown":
            # the notebook's headings sit one level below this section
            parts.append(re.sub(r"^(#{1,5}) ", r"#\1 ", cell.source, flags=re.M))
            continue
        if cell.cell_type != "code" or not cell.source.strip():
            continue
        parts.append(f"```python\n{cell.source}\n```")
        for out in cell.get("outputs", []):
            png = out.get("data", {}).get("image/png") if "data" in out else None
            if png:
                # the full content width (the stored figures are about 1200 px wide; at
                # the browser's default size their labels were too small to read)
                parts.append(f'<figure class="nb-figure"><img alt="figure drawn by the cell '
                             f'above" style="width:100%;max-width:none;height:auto" '
                             f'src="data:image/png;base64,{"".join(png.split())}">'
                             "</figure>")
                continue
            text = _text(out).rstrip()
            if text:
                parts.append('<pre class="nb-output"><code>' + html.escape(text)
                             + "</code></pre>")
    return "\n\n".join(parts) + "\n"


def on_page_markdown(markdown: str, page, config, files) -> str:
    if MARKER not in markdown:
        return markdown
    m = re.search(r"examples/([\w.-]+\.ipynb)", markdown)
    if m is None:
        raise ValueError(f"{page.file.src_path}: {MARKER} but no examples/*.ipynb named")
    return markdown.replace(MARKER, render_notebook(ROOT / "examples" / m.group(1)))
