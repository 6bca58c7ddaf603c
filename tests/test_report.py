"""HTML reports: self-contained (no network references, figures embedded), a section that
fails renders as a "not available" box, the claims' verdict rule, the variant search's root,
and the rendered page in headless Chromium (screenshot not blank; figures and the claims
table present in the DOM)."""

from __future__ import annotations

import base64
import re
import shutil
import subprocess
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest

from maglev_match.core.params import load_preset
from maglev_match.present.report import (
    ReportContext,
    ReportSettings,
    figure_html,
    run_section,
    study_report,
    table_html,
)

CHROMIUM_FLAGS = [
    "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync",
]


# ---------------------------------------------------------------------------------------
# helpers
# ---------------------------------------------------------------------------------------
class _Dom(HTMLParser):
    """Collects images, inline SVGs and the cells of the claims table."""

    def __init__(self) -> None:
        super().__init__()
        self.img_src: list[str] = []
        self.svgs = 0
        self.claim_rows: list[list[str]] = []
        self._in_claims = False
        self._in_tbody = False
        self._cell: list[str] | None = None
        self._row: list[str] | None = None

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "img":
            self.img_src.append(a.get("src") or "")
        elif tag == "svg":
            self.svgs += 1
        elif tag == "table" and "claims" in (a.get("class") or "").split():
            self._in_claims = True
        elif tag == "tbody" and self._in_claims:
            self._in_tbody = True
        elif tag == "tr" and self._in_tbody:
            self._row = []
        elif tag == "td" and self._row is not None:
            self._cell = []

    def handle_endtag(self, tag):
        if tag == "td" and self._cell is not None and self._row is not None:
            self._row.append("".join(self._cell).strip())
            self._cell = None
        elif tag == "tr" and self._row is not None:
            self.claim_rows.append(self._row)
            self._row = None
        elif tag == "tbody":
            self._in_tbody = False
        elif tag == "table":
            self._in_claims = False

    def handle_data(self, data):
        if self._cell is not None:
            self._cell.append(data)


def _parse(html: str) -> _Dom:
    d = _Dom()
    d.feed(html)
    return d


NETWORK_REF = re.compile(r"""(?:src|href)\s*=\s*["']?\s*(?:https?:)?//""", re.I)


def _assert_self_contained(html: str) -> _Dom:
    assert not NETWORK_REF.search(html), "the report refers to a network address"
    assert "http://" not in html and "https://" not in html
    dom = _parse(html)
    for src in dom.img_src:
        assert src.startswith("data:image/png;base64,"), src[:60]
    return dom


# ---------------------------------------------------------------------------------------
# unit checks
# ---------------------------------------------------------------------------------------
def test_figure_is_embedded_byte_for_byte(tmp_path):
    png = tmp_path / "f.png"
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots()
    ax.plot([0, 1], [1, 0])
    fig.savefig(png)
    plt.close(fig)
    frag = figure_html(png, "a <caption> & more")
    data = re.search(r'src="data:image/png;base64,([^"]+)"', frag).group(1)
    assert base64.b64decode(data) == png.read_bytes()
    assert "&lt;caption&gt; &amp; more" in frag  # escaped


def test_table_escapes_cells_and_formats_numbers():
    html = table_html(["a", "b"], [("<x>", 1.234567891), (None, float("nan"))])
    assert "&lt;x&gt;" in html and "<x>" not in html
    assert "1.2346" in html
    assert html.count("<tr>") == 3  # header + 2 rows


def test_failing_section_renders_not_available_box(tmp_path):
    ctx = ReportContext(out_dir=tmp_path)

    def broken(params, ctx):
        raise RuntimeError("continuation stalled")

    def missing(params, ctx):
        import maglev_match.no_such_module  # noqa: F401

    r = run_section("broken", "Broken", broken, load_preset("alpha1"), ctx)
    assert not r.available
    assert "not available: RuntimeError: continuation stalled" in r.html
    assert 'class="unavailable"' in r.html
    r2 = run_section("missing", "Missing", missing, load_preset("alpha1"), ctx)
    assert not r2.available and "not available" in r2.html and "no_such_module" in r2.reason


def test_numeric_claim_verdict_rule():
    from maglev_match.present.reproduce import numeric_claim

    assert numeric_claim("k", "s", "c", 100.0, 100.5, "x").verdict == "agree"
    assert numeric_claim("k", "s", "c", 100.0, 97.0, "x").verdict == "close"
    c = numeric_claim("k", "s", "c", 100.0, 131.0, "x")
    assert c.verdict == "differ" and "+31" in c.difference and "+31.00 %" in c.difference


def test_beam_claims_are_the_geometry_formulas():
    """The beam claims report omega_n = (n pi / L)^2 sqrt(EI / mbar) and
    w0 = sigma (m + M) g / omega1^2 computed here independently."""
    from maglev_match.present.reproduce import Study, compute_claims

    claims = {c.key: c for c in compute_claims(Study(ReportSettings.quick_settings()),
                                               ["beam values"])}
    soft = load_preset("turnout-soft")
    om1 = (np.pi / 18.0) ** 2 * np.sqrt(1.96e10 / 1920.0)
    assert float(claims["omega1-soft"].ours.split()[0]) == pytest.approx(om1, rel=1e-4)
    sigma = 8 * 12 * 18.0 / (np.pi**2 * 12.1**2 * 1920.0) * np.sin(np.pi * 12.1 / 36.0) ** 2
    w0 = sigma * (soft.m + soft.M) * soft.g / om1**2
    assert float(claims["w0-soft"].ours.split()[0]) == pytest.approx(w0 * 1e3, rel=1e-3)
    assert all(c.verdict in ("agree", "close", "differ") for c in claims.values())


def test_variant_search_finds_a_stability_boundary():
    """The kD value returned puts a root of max Re(lambda) at (102.5 rad/s, 4e-4): the
    equilibrium changes stability across it (checked by eigenvalues on both sides)."""
    from maglev_match.dynamics.equilibria import stability
    from maglev_match.maglev.models import build_system
    from maglev_match.present.reproduce import VARIANT_TARGET, variant_search

    v = variant_search("kD", n_scan=21)
    assert v.value is not None
    base = load_preset("turnout-soft").replace(omega1=VARIANT_TARGET, sigma=4e-4)

    def max_re(kd):
        return stability(build_system(base.replace(kD=kd), "unit")).max_real_part

    assert abs(max_re(v.value)) < 1e-6
    d = 1e-3 * v.value
    assert np.sign(max_re(v.value - d)) != np.sign(max_re(v.value + d))
    assert v.a1 == pytest.approx(VARIANT_TARGET, abs=0.5)


def test_cli_report_rejects_non_html_output(tmp_path):
    from maglev_match.cli import main

    assert main(["report", "--out", str(tmp_path / "r.txt")]) == 2
    assert main(["reproduce", "--out", str(tmp_path / "x"), "--only", "fig99"]) == 2


# ---------------------------------------------------------------------------------------
# whole reports
# ---------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def reproduce_report(tmp_path_factory):
    """A cheap reproduction: the beam-value claims and Figs. 6-8 (model A runs)."""
    from maglev_match.present.reproduce import reproduce

    out = tmp_path_factory.mktemp("repro")
    report, claims = reproduce(out, ReportSettings.quick_settings(), only=["fig6-8"],
                               claim_groups=["beam values"])
    return report, claims


def test_reproduce_report_is_self_contained(reproduce_report):
    report, claims = reproduce_report
    html = report.path.read_text()
    dom = _assert_self_contained(html)
    assert len(dom.img_src) == 3  # Figs. 6, 7, 8
    assert len(dom.claim_rows) == len(claims) > 0
    assert (report.path.parent / "claims.csv").read_text().count("\n") == len(claims) + 1
    for f in report.figures:
        assert f.exists() and f.stat().st_size > 0
    assert {f.suffix for f in report.figures} == {".png", ".svg"}
    assert "maglev-match" in html and "quick" in html  # version and settings footer


def test_study_report_is_self_contained(tmp_path):
    settings = ReportSettings.quick_settings()
    res = study_report(load_preset("alpha3"), tmp_path / "study.html", settings, "alpha3",
                       only=["parameters", "stability", "root-locus"])
    html = res.path.read_text()
    dom = _assert_self_contained(html)
    assert len(dom.img_src) == 1 and not res.unavailable
    assert "rad/s" in html and "kP" in html  # parameter table with units


def _chromium() -> str | None:
    return shutil.which("chromium") or shutil.which("chromium-browser")


def test_report_renders_in_headless_chromium(reproduce_report, tmp_path):
    exe = _chromium()
    if exe is None:
        pytest.skip("chromium is not on PATH (Debian package 'chromium'; .ci/run installs it "
                    "in CI)")
    report, claims = reproduce_report
    url = report.path.resolve().as_uri()
    shot = tmp_path / "shot.png"
    common = [exe, *CHROMIUM_FLAGS, f"--user-data-dir={tmp_path / 'profile'}"]
    subprocess.run([*common, f"--screenshot={shot}", "--window-size=1200,3000", url],
                   capture_output=True, timeout=120, check=False)
    assert shot.exists() and shot.stat().st_size > 0
    import matplotlib.image

    img = matplotlib.image.imread(str(shot))
    assert img.shape[0] >= 1000 and img.shape[1] >= 1000
    rgb = img[..., :3]
    assert rgb.std() > 0.05  # not a blank page
    assert (rgb.mean(axis=2) < 0.5).mean() > 0.001  # some dark pixels (text, lines)

    dom_run = subprocess.run([*common, "--dump-dom", url], capture_output=True, text=True,
                             timeout=120, check=False)
    dom = _parse(dom_run.stdout)
    assert len(dom.img_src) + dom.svgs >= 3
    assert all(len(s) > 1000 for s in dom.img_src)  # real embedded images
    assert len(dom.claim_rows) == len(claims) > 0
    for row in dom.claim_rows:
        assert len(row) == 7
        assert all(cell for cell in row[:6]), row  # claim, paper, ours, verdict, difference
        assert row[4] in ("agree", "close", "differ", "not computed")


@pytest.mark.parametrize("param", ["kD", "ke", "omega0"])
def test_variant_presets_reconcile_the_papers_stability_statements(param):
    """Each shipped paper-variant preset changes one value of turnout-soft, and with it
    the paper's qualitative statements hold for model A: alpha1 = [100, 4e-4] stable,
    alpha2 = [105, 5e-4] unstable, alpha3 = [85, 3.7e-4] stable, the stiff turnout beam
    unstable and the soft one stable."""
    from maglev_match.dynamics.equilibria import stability
    from maglev_match.maglev.models import build_system

    variant, soft = load_preset(f"paper-variant-{param}"), load_preset("turnout-soft")
    changed = {k for k, v in variant.as_dict().items() if v != soft.as_dict()[k]}
    assert changed == {param}

    def stable(p):
        return stability(build_system(p, "unit")).stable

    assert stable(variant.replace(omega1=100.0, sigma=4e-4))
    assert not stable(variant.replace(omega1=105.0, sigma=5e-4))
    assert stable(variant.replace(omega1=85.0, sigma=3.7e-4))
    assert not stable(variant.replace(EI=2.26e10))
    assert stable(variant)


@pytest.mark.slow
def test_report_command_renders_every_section(tmp_path, capsys):
    """`maglev-match report --quick`: every section computed (none 'not available'), the
    figure files written, the HTML self-contained."""
    import json

    from maglev_match.cli import main

    out = tmp_path / "alpha1.html"
    assert main(["report", "--preset", "alpha1", "--quick", "--no-vehicle", "--out", str(out),
                 "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert {k: v["reason"] for k, v in summary["sections"].items() if not v["available"]} == {}
    assert {"parameters", "stability", "root-locus", "hopf-curve", "cycles", "time-history",
            "matching", "sensitivity"} <= set(summary["sections"])
    for f in summary["figures"]:
        assert Path(f).stat().st_size > 0
    dom = _assert_self_contained(out.read_text())
    assert len(dom.img_src) == len([f for f in summary["figures"] if f.endswith(".png")]) >= 5
    # the top of a quick report says that its index is the paper's, not the headline
    html = out.read_text()
    assert html.index("Quick preview (--quick)") < html.index('<section id="matching"')
