"""Every tutorial notebook in examples/ executes from top to bottom without an error, so the
tutorials never rot. The notebooks carry their own checks (asserts on what they show)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

nbformat = pytest.importorskip("nbformat")
nbclient = pytest.importorskip("nbclient")

ROOT = Path(__file__).resolve().parents[1]
NOTEBOOKS = sorted((ROOT / "examples").glob("*.ipynb"))


def test_there_is_one_notebook_per_tutorial():
    tutorials = sorted((ROOT / "docs" / "tutorials").glob("*.md"))
    assert len(NOTEBOOKS) == len(tutorials) == 4
    for page in tutorials:
        names = [nb.name for nb in NOTEBOOKS if f"examples/{nb.name}" in page.read_text()]
        assert len(names) == 1, f"{page.name} must name exactly one notebook of examples/"


def test_notebooks_are_stored_executed_with_their_outputs():
    """The notebooks are saved after a full run (docs/figures/run_notebooks.py): every code
    cell ran, in order, without an error, and the figures they draw are stored, so the
    tutorial pages (and a reader on GitHub) see the outputs. test_notebook_executes below
    runs them again, so the stored outputs cannot hide a notebook that no longer runs."""
    for path in NOTEBOOKS:
        nb = nbformat.read(path, as_version=4)
        cells = [c for c in nb.cells if c.cell_type == "code" and c.source.strip()]
        counts = [c.execution_count for c in cells]
        assert None not in counts and counts == sorted(counts), f"{path.name}: not run in order"
        assert not any(o.output_type == "error" for c in cells for o in c.outputs), path.name
        assert any(c.outputs for c in cells), f"{path.name}: stored without outputs"
    figures = [path.name for path in NOTEBOOKS
               if any("image/png" in o.get("data", {}) for c in nbformat.read(path, 4).cells
                      if c.cell_type == "code" for o in c.outputs)]
    assert len(figures) >= 3, f"figures stored only in {figures}"


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_notebook_executes(path, tmp_path, monkeypatch):
    # the kernel imports the package from this checkout and draws without a display
    src = str(ROOT / "src")
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(
        [src, *filter(None, [os.environ.get("PYTHONPATH")])]))
    monkeypatch.setenv("MPLBACKEND", "Agg")
    nb = nbformat.read(path, as_version=4)
    client = nbclient.NotebookClient(
        nb, timeout=600, kernel_name="python3", resources={"metadata": {"path": str(tmp_path)}},
    )
    client.execute()
    errors = [o for c in nb.cells if c.cell_type == "code" for o in c.outputs
              if o.output_type == "error"]
    assert not errors


def test_the_first_tutorial_shows_the_headline_index_of_index():
    """The executed first tutorial prints the same headline chi, basis and reading as the
    API (and so as `index`, tests/test_matching.py): the docs do not hand out the paper's
    chi as the answer (issue 31)."""
    import maglev_match as mm

    nb = nbformat.read(ROOT / "examples" / "01-is-my-beam-a-match.ipynb", as_version=4)
    printed = "".join(o.get("text", "") for c in nb.cells if c.cell_type == "code"
                      for o in c.outputs)
    res = mm.matching_index("turnout-soft")
    assert f"chi = {res.chi:.3f} (headline, from the {res.reading_basis}): {res.reading}" \
        in printed
    assert f"chi_paper = {res.chi_paper:.3f}" in printed
