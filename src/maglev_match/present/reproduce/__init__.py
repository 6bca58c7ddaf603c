"""The paper's figures and claims recomputed with the printed defaults.

:func:`reproduce` writes one self-contained HTML file (plus PNG/SVG figures and the claims
as CSV/JSON) with

* the claims table: each numeric or qualitative statement of the paper beside what this
  software computes with the printed equations and parameters (presets ``turnout-soft``,
  ``turnout-stiff``, ``alpha1``..``alpha3``; nothing tuned), and a verdict
  agree / differ with the size of the difference;
* the figures the paper's text describes: Fig. 4 (Hopf curve in (omega1, sigma)), Fig. 5
  (cycle bifurcation diagrams along omega1 at sigma = 4e-4 and along sigma at
  omega1 = 100 rad/s), Figs. 6-8 (model A time histories at alpha1..alpha3 from the paper's
  initial beam deflections), Figs. 11-13 (model B pressed onto the free beam on both turnout
  beams, q1(0) = 3 mm, and the unstable cycle that decides h);
* a short discussion of which single parameter change (controller gains kP, kD, ke,
  observer omega0, xi0, beam damping xi1) would move the Hopf point A1 (along omega1 at
  sigma = 4e-4) into (100, 105) rad/s, where the paper's alpha1/alpha2 statements need it,
  found by root finding on the largest real part of the eigenvalues, offered as the
  variant presets ``paper-variant-<parameter>``.

Verdict rule for numbers: "agree" when the relative difference is within 1 % (the paper
prints 3 to 4 digits), "close" within 5 %, otherwise "differ"; qualitative statements agree
or differ. The difference is always shown.

The modules of this package, each one subject; every name is also importable from here:

* ``paper``: the paper's printed values, a claim and the verdict rule;
* ``variants``: the single-parameter variants search and the variant presets;
* ``study``: the computations shared by the figures and the claims;
* ``claims``: the claims computed and compared, the claims table;
* ``sections``: the paper's figures redrawn and the variants section;
* this module: :data:`SECTIONS` and :func:`reproduce`, the HTML, CSV and JSON outputs.
"""

from __future__ import annotations

import csv
import json
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

from maglev_match.core.io import atomic_open, atomic_write_text
from maglev_match.present.report.base import (
    ReportContext,
    ReportResult,
    ReportSettings,
    SectionResult,
)
from maglev_match.present.report.html import render, write_report
from maglev_match.present.report.study import run_section
from maglev_match.present.reproduce.claims import (
    CLAIM_GROUPS,
    claims_table_html,
    compute_claims,
    hopf_a1,
)
from maglev_match.present.reproduce.paper import (
    PAPER,
    Claim,
    numeric_claim,
    qualitative_claim,
    relative_difference,
)
from maglev_match.present.reproduce.sections import (
    section_fig4,
    section_fig5,
    section_fig6_8,
    section_fig11_13,
    section_fig12,
    section_variants,
)
from maglev_match.present.reproduce.study import Study
from maglev_match.present.reproduce.variants import (
    VARIANT_PARAMS,
    VARIANT_TARGET,
    VARIANT_WINDOW,
    VariantResult,
    shipped_variant_value,
    variant_preset_text,
    variant_search,
)

__all__ = [
    "Claim",
    "VariantResult",
    "PAPER",
    "reproduce",
    "compute_claims",
    "variant_search",
    "variant_preset_text",
    "claims_table_html",
    "SECTIONS",
    "CLAIM_GROUPS",
    "Study",
    "VARIANT_PARAMS",
    "VARIANT_TARGET",
    "VARIANT_WINDOW",
    "numeric_claim",
    "qualitative_claim",
    "relative_difference",
    "hopf_a1",
    "shipped_variant_value",
    "section_fig4",
    "section_fig5",
    "section_fig6_8",
    "section_fig11_13",
    "section_fig12",
    "section_variants",
]

#: (key, title, function) of the figure sections, in order
SECTIONS: tuple[tuple[str, str, Callable[[Study, ReportContext], tuple[str, list[Path], Any]]],
                ...] = (
    ("fig4", "Fig. 4: Hopf curve in (omega1, sigma)", section_fig4),
    ("fig5", "Fig. 5: cycle bifurcation diagrams", section_fig5),
    ("fig6-8", "Figs. 6-8: time histories at alpha1, alpha2, alpha3", section_fig6_8),
    ("fig11-13", "Figs. 11 and 13: the full vehicle on the turnout beams", section_fig11_13),
    ("fig12", "Fig. 12: the unstable cycle that decides h (soft turnout beam)", section_fig12),
    ("variants", "Which single parameter change would reconcile the differences", section_variants),
)


def reproduce(
    out_dir: str | Path,
    settings: ReportSettings | None = None,
    only: Sequence[str] | None = None,
    claim_groups: Sequence[str] | None = None,
    progress: Callable[[str], None] | None = None,
) -> tuple[ReportResult, list[Claim]]:
    """Recompute the paper's figures and claims with the printed defaults; write
    ``reproduce.html``, ``claims.csv``, ``claims.json`` and the figures into ``out_dir``.

    only : keys of the figure sections to include (default all of ``SECTIONS``).
    claim_groups : labels of ``CLAIM_GROUPS`` to evaluate (default all).
    """
    t0 = time.perf_counter()
    settings = settings or ReportSettings()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    fig_dir = out / "figures"
    fig_dir.mkdir(exist_ok=True)
    ctx = ReportContext(out_dir=fig_dir, settings=settings)
    study = Study(settings)
    results: list[SectionResult] = []
    for key, title, fn in SECTIONS:
        if only is not None and key not in only:
            continue
        if progress is not None:
            progress(title)
        results.append(run_section(key, title, lambda p, c, fn=fn: fn(study, c), None, ctx))
    if progress is not None:
        progress("claims table")
    tc = time.perf_counter()
    claims = compute_claims(study, claim_groups)
    counts = {k: sum(1 for c in claims if c.verdict == k)
              for k in ("agree", "close", "differ", "not computed")}
    summary = ", ".join(f"{n} {k}" for k, n in counts.items() if n)
    claims_html = render("reproduce_claims.html.j2", n_claims=len(claims), summary=summary,
                         a1=hopf_a1(study), table=claims_table_html(claims))
    claims_section = SectionResult("claims", "Claims table", claims_html, (),
                                   [asdict(c) for c in claims], True, "",
                                   time.perf_counter() - tc)
    with atomic_open(out / "claims.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["key", "source", "claim", "paper", "ours", "verdict", "difference", "note"])
        for c in claims:
            w.writerow([c.key, c.source, c.claim, c.paper, c.ours, c.verdict, c.difference,
                        c.note])
    atomic_write_text(out / "claims.json", json.dumps([asdict(c) for c in claims], indent=2))
    intro = render("reproduce_intro.html.j2")
    report = write_report(out / "reproduce.html", "maglev-match: reproduction of the paper",
                          intro, [claims_section, *results],
                          {"command": "reproduce", **settings.as_dict(),
                           "sections": list(only) if only else "all",
                           "claim groups": list(claim_groups) if claim_groups else "all"},
                          None, t0)
    return report, claims
