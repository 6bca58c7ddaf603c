"""The documentation site builds with ``mkdocs build --strict`` (a broken link, a missing page
or a docstring mkdocstrings cannot read fails), its generated references are complete, and
no file of the repository points to the internal product brief."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
# The product brief the project was written from is not part of the repository; nothing in
# it may refer to it. (The name is assembled so that this file does not mention it either.)
BRIEF = "SPEC" + ".md"
# Files of other work in progress that still mention it; emptied when that work is merged.


def _repository_files() -> list[Path]:
    try:
        out = subprocess.run(["git", "ls-files", "--cached", "--others", "--exclude-standard"],
                             cwd=ROOT, capture_output=True, text=True, check=True).stdout
        return [ROOT / f for f in out.splitlines() if (ROOT / f).is_file()]
    except (OSError, subprocess.CalledProcessError):  # not a git checkout (e.g. an sdist)
        return [p for p in ROOT.rglob("*") if p.is_file() and ".git" not in p.parts]


def _mentions() -> set[str]:
    found = set()
    for path in _repository_files():
        try:
            text = path.read_text(errors="ignore")
        except OSError:
            continue
        if BRIEF in text:
            found.add(str(path.relative_to(ROOT)))
    return found


def test_no_file_refers_to_the_internal_brief():
    unexpected = _mentions()
    assert not unexpected, f"files that refer to {BRIEF}: {sorted(unexpected)}"


def _config(tmp_path):
    import mkdocs.config as mkdocs_config
    import mkdocstrings  # noqa: F401  (the build needs it; its absence is a failure)
    cfg = mkdocs_config.load_config(config_file=str(ROOT / "mkdocs.yml"), strict=True,
                                    site_dir=str(tmp_path / "site"))
    return cfg


def test_mkdocs_build_strict(tmp_path, monkeypatch):
    """``mkdocs build --strict``: any warning (broken link, unknown page, unreadable
    docstring) aborts the build."""
    from mkdocs.commands.build import build

    monkeypatch.chdir(ROOT)  # the config's hook path is relative to the repository
    cfg = _config(tmp_path)
    cfg.plugins.on_startup(command="build", dirty=False)
    try:
        build(cfg)
    finally:
        cfg.plugins.on_shutdown()
    site = tmp_path / "site"
    cli = (site / "reference" / "cli" / "index.html").read_text()
    api = (site / "reference" / "api" / "index.html").read_text()
    model = (site / "model" / "index.html").read_text()
    # the command-line reference is generated from every command
    from maglev_match.cli import all_commands

    for name in all_commands():
        assert f"maglev-match {name}" in cli, name
    assert "<!-- cli-reference -->" not in cli
    # the API reference renders every public function's docstring
    from maglev_match.api import _NAMES

    for name in ("design_map", "matching_index", "cycle_branch", "hopf_curve", "simulate"):
        assert f'id="maglev_match.api.{_NAMES[name]}.{name}"' in api, name
    # the parameter table lists every parameter with its unit
    from maglev_match.core.params import PARAMETER_DOCS

    for name in PARAMETER_DOCS:
        assert f"<code>{name}</code>" in model, name
    _assert_no_external_scripts_or_styles(site)
    # formulas are rendered by the KaTeX shipped with the site
    assert (site / "assets" / "katex" / "katex.min.js").is_file()
    assert "katex.min.css" in model and "katex-init.js" in model
    assert 'class="arithmatex"' in model
    # each tutorial page shows its notebook executed, figures embedded
    for page in sorted((site / "tutorials").glob("*/index.html")):
        text = page.read_text()
        assert "The notebook, executed" in text and 'class="nb-output"' in text, page
    assert sum("data:image/png;base64," in p.read_text()
               for p in (site / "tutorials").glob("*/index.html")) >= 3
    for page in ("continuation", "branch-files"):
        assert (site / page / "index.html").exists(), page
    for page in ("tutorials/is-my-beam-a-match", "tutorials/design-map-on-dask",
                 "tutorials/own-model-or-controller", "tutorials/checking-the-paper",
                 "numerics", "matching-index", "files"):
        assert (site / page / "index.html").exists(), page


EXTERNAL = re.compile(r"""<(script|link|img|iframe)\b[^>]*\b(src|href)\s*=\s*["']?"""
                      r"""\s*(https?:)?//""", re.I)


def _assert_no_external_scripts_or_styles(site: Path) -> None:
    """No page loads a script, style sheet, font or image from the network (math is
    rendered offline), and no style sheet imports one."""
    offenders = []
    for page in site.rglob("*.html"):
        for m in EXTERNAL.finditer(page.read_text(errors="ignore")):
            offenders.append(f"{page.relative_to(site)}: {m.group(0)[:80]}")
    for css in site.rglob("*.css"):
        text = css.read_text(errors="ignore")
        for m in re.finditer(r"(@import|url\()\s*['\"]?(https?:)?//", text):
            offenders.append(f"{css.relative_to(site)}: {m.group(0)}")
    assert not offenders, offenders[:10]
