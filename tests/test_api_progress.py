"""Progress of long API calls (issue 31: API calls ran silent for minutes): on in a
notebook or an interactive session, off in scripts, switched by show_progress or
MAGLEV_MATCH_PROGRESS, replaced by the caller's own callbacks."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

import maglev_match as mm
from maglev_match.api import progress as api_progress

ROOT = Path(__file__).resolve().parents[1]
LINE = "maglev-match ["


@pytest.fixture(autouse=True)
def automatic(monkeypatch):
    monkeypatch.delenv("MAGLEV_MATCH_PROGRESS", raising=False)
    yield
    mm.show_progress(None)


def test_off_in_a_script_on_when_asked_and_by_the_environment(monkeypatch, capsys):
    assert not api_progress.progress_shown()  # pytest: not interactive, no kernel
    mm.matching_index("turnout-soft", simulate=False)
    assert capsys.readouterr().err == ""
    mm.show_progress(True)
    res = mm.matching_index("turnout-soft", simulate=False)
    err = capsys.readouterr().err
    assert LINE in err and "the paper's index of model A" in err
    mm.show_progress(None)
    monkeypatch.setenv("MAGLEV_MATCH_PROGRESS", "1")
    assert api_progress.progress_shown()
    mm.show_progress(False)  # the process setting wins over the environment
    assert mm.matching_index("turnout-soft", simulate=False).chi == res.chi
    assert capsys.readouterr().err == ""
    with pytest.raises(mm.ParameterError, match="on"):
        mm.show_progress("yes")


def test_the_callers_callbacks_replace_the_display(capsys):
    mm.show_progress(True)
    seen: list[str] = []
    mm.matching_index("turnout-soft", simulate=False, stage=seen.append)
    assert seen and seen[0].startswith("the paper's index of model A")
    assert capsys.readouterr().err == ""
    mm.matching_index("turnout-soft", simulate=False, stage=False)
    assert capsys.readouterr().err == ""


def test_a_map_shows_its_stages_and_a_bar_of_its_tiles(capsys):
    mm.show_progress(True)
    kw = dict(x=("omega1", 90.0, 110.0, 2), y=("sigma", 4e-4, 5e-4, 4), simulate=False,
              rows_per_tile=1, workers=0)
    ds = mm.design_map("turnout-soft", **kw)
    err = capsys.readouterr().err
    assert "map omega1 x sigma, paper's index only (--no-simulation): 4 tiles" in err
    assert "maglev-match map: " in err and "4/4" in err  # the bar, at its end
    counts: list[tuple[int, int]] = []
    again = mm.design_map("turnout-soft", progress=lambda d, t: counts.append((d, t)), **kw)
    err = capsys.readouterr().err
    assert counts[-1] == (4, 4) and "4/4" not in err and "4 tiles" in err
    assert (again["chi"].values == ds["chi"].values).all()


def test_on_by_itself_in_a_jupyter_kernel(tmp_path):
    nbformat = pytest.importorskip("nbformat")
    nbclient = pytest.importorskip("nbclient")
    nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell(
        "import maglev_match as mm\n"
        "res = mm.matching_index('turnout-soft', simulate=False)\n"
        "print(round(res.chi, 3))")])
    env = {"PYTHONPATH": os.pathsep.join([str(ROOT / "src"),
                                          *filter(None, [os.environ.get("PYTHONPATH")])]),
           "MPLBACKEND": "Agg"}
    old = {k: os.environ.get(k) for k in env}
    os.environ.update(env)
    os.environ.pop("MAGLEV_MATCH_PROGRESS", None)
    try:
        nbclient.NotebookClient(nb, timeout=600, kernel_name="python3",
                                resources={"metadata": {"path": str(tmp_path)}}).execute()
    finally:
        for k, v in old.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
    outs = nb.cells[0].outputs
    err = "".join(o.get("text", "") for o in outs if o.get("name") == "stderr")
    out = "".join(o.get("text", "") for o in outs if o.get("name") == "stdout")
    assert "the paper's index of model A" in err and LINE in err
    assert out.strip() == "9.562"


def test_an_imported_kernel_module_is_not_a_kernel(monkeypatch):
    """Another test file (or a tool that starts kernels elsewhere) may have imported
    ipykernel and IPython into this process: progress stays off without a running shell."""
    pytest.importorskip("IPython")
    import ipykernel  # noqa: F401

    assert not api_progress.progress_shown()
