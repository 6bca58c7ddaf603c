"""The paper's claims beside this software's values: the claim groups (beam values, Hopf
points, alpha1..alpha3, turnout beams; :data:`CLAIM_GROUPS`), each computed from a
:class:`~maglev_match.present.reproduce.study.Study` (:func:`compute_claims`; a group that
cannot be computed shows as "not computed"), the claims table (:func:`claims_table_html`)
and the Hopf point A1 its discussion rests on (:func:`hopf_a1`)."""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from typing import Any

from maglev_match.present.report.html import table_html
from maglev_match.present.report.sections_history import converges, outcome_text
from maglev_match.present.reproduce.paper import (
    PAPER,
    Claim,
    numeric_claim,
    qualitative_claim,
    relative_difference,
)
from maglev_match.present.reproduce.study import Study

log = logging.getLogger(__name__)

__all__ = ["CLAIM_GROUPS", "compute_claims", "claims_table_html", "hopf_a1"]


def _claim_guard(fn: Callable[[Study], list[Claim]], study: Study, label: str
                 ) -> list[Claim]:
    try:
        return fn(study)
    except Exception as exc:  # a claim that cannot be computed is shown as such
        log.warning("claims '%s' not computed: %s", label, exc)
        return [Claim(label, "-", f"{label} (group)", "-", "-", "not computed",
                      f"{type(exc).__name__}: {exc}")]


def _claims_beams(st: Study) -> list[Claim]:
    stiff, soft = st.preset("turnout-stiff"), st.preset("turnout-soft")
    out = [
        numeric_claim("omega1-stiff", "Sec. 5", "omega1 of the stiff turnout beam (EI = 2.26e10)",
                      PAPER["omega1_stiff"], float(stiff.omega1), "rad/s", digits=5),
        numeric_claim("omega2-stiff", "Sec. 5", "omega2, stiff beam", PAPER["omega2_stiff"],
                      stiff.omega_n(2), "rad/s", digits=5),
        numeric_claim("omega3-stiff", "Sec. 5", "omega3, stiff beam", PAPER["omega3_stiff"],
                      stiff.omega_n(3), "rad/s", digits=6),
        numeric_claim("omega1-soft", "Sec. 5", "omega1 of the soft turnout beam (EI = 1.96e10)",
                      PAPER["omega1_soft"], float(soft.omega1), "rad/s", digits=5),
        numeric_claim("omega2-soft", "Sec. 5", "omega2, soft beam", PAPER["omega2_soft"],
                      soft.omega_n(2), "rad/s", digits=6),
        numeric_claim("omega3-soft", "Sec. 5", "omega3, soft beam", PAPER["omega3_soft"],
                      soft.omega_n(3), "rad/s", digits=6),
        numeric_claim("sigma", "Sec. 5",
                      "force gain coefficient sigma (L = 18 m, l = 12.1 m, k = 12)",
                      PAPER["sigma"], float(soft.sigma), "1/kg", digits=4),
    ]
    w0_rounded = PAPER["sigma"] * (soft.m + soft.M) * soft.g / float(soft.omega1) ** 2
    out.append(numeric_claim(
        "w0-soft", "Sec. 5, eq. 25", "static deflection w0, soft beam", PAPER["w0_soft"],
        soft.w0, "mm", scale=1e3, digits=4,
        note=f"with sigma rounded to 4.7e-4 as printed, w0 = {w0_rounded * 1e3:.4f} mm"))
    return out


def _claims_hopf(st: Study) -> list[Claim]:
    out = []
    da, db = st.diagram("omega1"), st.diagram("sigma")
    a1 = [hp for hp, _ in da.branches]
    a2 = [hp for hp, _ in db.branches]
    if a1:
        hp = a1[0]
        others = ", ".join(f"{h.value:.4g} ({h.kind})" for h in a1[1:])
        out.append(qualitative_claim(
            "A1", "Fig. 5a", "Hopf point A1 along omega1 at sigma = 4e-4 is subcritical",
            "subcritical; value not printed (alpha1 = 100 stable implies A1 > 100 rad/s)",
            f"A1 = {hp.value:.5g} rad/s, l1 = {hp.l1:.3g} ({hp.kind})"
            + (f"; further Hopf points: {others}" if others else ""),
            hp.kind == "subcritical", note="the paper gives no number for A1"))
    else:
        out.append(Claim("A1", "Fig. 5a", "Hopf point A1 along omega1 at sigma = 4e-4",
                         "subcritical", "no Hopf point in [40, 400] rad/s", "differ", "-"))
    if a2:
        hp, br = next((h, b) for h, b in db.branches if h is a2[0])
        lpc = [sp for sp in br.special_points if sp.type == "LPC"]
        fold = (f"; the cycle branch folds (LPC) at sigma = {lpc[0].value:.4g} and continues "
                "as an unstable cycle to lower sigma") if lpc else ""
        out.append(qualitative_claim(
            "A2", "Fig. 5b", "Hopf point A2 along sigma at omega1 = 100 rad/s is subcritical",
            "subcritical; value not printed (alpha1's 4e-4 stable implies A2 > 4e-4)",
            f"A2 = {hp.value:.4g} 1/kg, l1 = {hp.l1:.3g} ({hp.kind}){fold}",
            hp.kind == "subcritical",
            difference="-" if hp.kind == "subcritical" else
            "supercritical at A2 (close to a generalised Hopf point)",
            note="the paper gives no number for A2"))
    # the tangency value at omega1 = 100
    contact = [c for c in db.limit_contacts()]
    if contact:
        sig = contact[0][1]
        sp = next(sp for _, b in db.branches for sp in b.special_points if sp.type == "contact")
        gx, gn = sp.extrema["gap_deviation"]
        out.append(numeric_claim("tangency", "Sec. 4 (Fig. 5b)",
                                 "sigma where the unstable cycle touches the gap limit, "
                                 "omega1 = 100",
                                 PAPER["sigma_tangency"], sig, "1e-4 1/kg", scale=1e4, digits=3,
                                 note=f"cycle there: max {gx * 1e3:.3g} mm, min {gn * 1e3:.3g} mm "
                                 f"({sp.detail or 'limit'})"))
    else:
        lows = [b.values.min() for _, b in db.branches if b.points]
        reason = "; ".join(b.stopped_reason for _, b in db.branches)
        out.append(Claim(
            "tangency", "Sec. 4 (Fig. 5b)",
            "sigma where the unstable cycle touches the gap limit, omega1 = 100",
            "about 0.7e-4 1/kg",
            "no contact found" + (f" down to sigma = {min(lows):.3g}" if lows else "")
            + f" (branch stopped: {reason})", "not computed", "-"))
    # subcritical in the engineering range, from the Hopf curve
    try:
        curves = st.curves()
        (wl, wh), (sl, sh) = PAPER["engineering_omega1"], PAPER["engineering_sigma"]
        inside = [(pt.values, pt.l1) for c in curves for pt in c.points
                  if wl <= pt.values[0] <= wh and sl <= pt.values[1] <= sh]
        n_sub = sum(1 for _, l1 in inside if l1 > 0)
        if inside:
            holds = n_sub == len(inside)
            out.append(qualitative_claim(
                "engineering-range", "Sec. 4 (Figs. 4, 5)",
                "Hopf bifurcations in the engineering range (omega1 40-190 rad/s, sigma "
                "2-6e-4) are subcritical", "subcritical",
                f"{n_sub} of {len(inside)} Hopf-curve points in the range have l1 > 0",
                holds))
        gh = [sp for c in curves for sp in c.special_points if sp.type == "GH"]
        out.append(Claim(
            "codim2", "Fig. 4", "codimension-two points on the Hopf curve",
            "three junctions a, b, c between segments I-IV (values not printed)",
            "; ".join(f"{sp.type} at ({sp.values[0]:.4g}, {sp.values[1]:.3g})"
                      for c in curves for sp in c.special_points) or "none",
            "agree" if len(gh) == 3 else "differ",
            f"{len(gh)} generalised Hopf points found vs 3 junctions",
            "searched within omega1 {:g}-{:g} rad/s, sigma {:g}-{:g} 1/kg".format(
                *st.settings.hopf_omega1_range, *st.settings.hopf_sigma_range)))
    except Exception as exc:  # the Hopf curve is optional for the other claims
        out.append(Claim("engineering-range", "Sec. 4", "subcritical in the engineering range",
                         "subcritical", "-", "not computed", f"{type(exc).__name__}: {exc}"))
    # b1 != b2: asymmetric amplitudes where the cycle touches the limit (Fig. 5a)
    ca = da.limit_contacts()
    if ca:
        hp_v, val, _ = ca[0]
        br = next(b for h, b in da.branches if h.value == hp_v)
        sp = next(s for s in br.special_points if s.type == "contact")
        gx, gn = sp.extrema["gap_deviation"]
        out.append(qualitative_claim(
            "b1-b2", "Fig. 5a", "upper and lower amplitudes where the unstable cycle touches "
            "the limit differ (electromagnetic force asymmetric)", "b1 != b2",
            f"at omega1 = {val:.4g} rad/s: max {gx * 1e3:.3g} mm, min {gn * 1e3:.3g} mm",
            abs(abs(gx) - abs(gn)) > 1e-4))
    return out


def _claims_alpha(st: Study) -> list[Claim]:
    out = []
    da = st.diagram("omega1")
    # alpha1: stable, surrounded by an unstable cycle
    s1 = st.stability("alpha1")
    surrounded = any(
        (~b.stable).any() and b.values.min() <= 100.0 <= b.values.max()
        for _, b in da.branches if b.points)
    out.append(qualitative_claim(
        "alpha1-structure", "Sec. 4", "alpha1 = [100, 4e-4]: stable equilibrium inside an "
        "unstable cycle", "stable + unstable cycle",
        f"{'stable' if s1['stable'] else 'unstable'} (max Re {s1['max_real_part']:.3g} 1/s); "
        f"unstable cycle at omega1 = 100: {'yes' if surrounded else 'no'}",
        s1["stable"] and surrounded))
    x5a, x5b = PAPER["x5_alpha1"]
    sim, _ = st.unit_run("alpha1", x5a)
    out.append(qualitative_claim("alpha1-small", "Fig. 6", "alpha1, x5(0) = -1.5 mm converges",
                                 "converges", outcome_text(sim), converges(sim)))
    sim, _ = st.unit_run("alpha1", x5b)
    if sim.outcome == "collision":
        out.append(numeric_claim("alpha1-large", "Fig. 6", "alpha1, x5(0) = -2.2 mm collides at",
                                 PAPER["t_collide_alpha1"], sim.collision_time, "s", digits=3,
                                 note=outcome_text(sim)))
    else:
        out.append(qualitative_claim("alpha1-large", "Fig. 6", "alpha1, x5(0) = -2.2 mm collides",
                                     "collides at about 1.62 s", outcome_text(sim), False))
    s2 = st.stability("alpha2")
    out.append(qualitative_claim(
        "alpha2-stability", "Sec. 4", "alpha2 = [105, 5e-4]: equilibrium unstable", "unstable",
        f"{'stable' if s2['stable'] else 'unstable'} (max Re {s2['max_real_part']:.3g} 1/s)",
        not s2["stable"],
        difference="-" if not s2["stable"] else
        f"stable by a margin of {-s2['max_real_part']:.3g} 1/s"))
    sim, _ = st.unit_run("alpha2", PAPER["x5_alpha2"])
    if sim.outcome == "collision":
        out.append(numeric_claim("alpha2-run", "Fig. 7", "alpha2, x5(0) = -0.1 mm collides at",
                                 PAPER["t_collide_alpha2"], sim.collision_time, "s", digits=3,
                                 note=outcome_text(sim)))
    else:
        out.append(qualitative_claim("alpha2-run", "Fig. 7", "alpha2, x5(0) = -0.1 mm collides",
                                     "collides at about 1.16 s", outcome_text(sim), False))
    s3 = st.stability("alpha3")
    sim, _ = st.unit_run("alpha3", PAPER["x5_alpha3"])
    out.append(qualitative_claim(
        "alpha3", "Fig. 8", "alpha3 = [85, 3.7e-4]: stable; x5(0) = -4 mm converges",
        "stable, converges",
        f"{'stable' if s3['stable'] else 'unstable'}; {outcome_text(sim)}",
        s3["stable"] and converges(sim)))
    return out


def _claims_turnout(st: Study) -> list[Claim]:
    out = []
    for name, want in (("turnout-stiff", False), ("turnout-soft", True)):
        sa = st.stability(name, "unit")
        word = "stable" if want else "unstable"
        out.append(qualitative_claim(
            f"{name}-A", "Sec. 5", f"{name}: model A equilibrium {word}", word,
            f"{'stable' if sa['stable'] else 'unstable'} (max Re {sa['max_real_part']:.3g} 1/s)",
            sa["stable"] == want))
        if st.settings.include_vehicle:
            sb = st.stability(name, "vehicle")
            out.append(qualitative_claim(
                f"{name}-B", "Sec. 5", f"{name}: full vehicle (model B) {word}", word,
                f"{'stable' if sb['stable'] else 'unstable'} (max Re "
                f"{sb['max_real_part']:.3g} 1/s)", sb["stable"] == want))
    mi = st.matching("turnout-stiff")
    both = (f"chi_paper = {mi.chi_paper:.3g} ({mi.case})"
            + ("" if mi.chi_simulation is None else
               f"; chi_simulation = {mi.chi_simulation:.3g}; headline chi = {mi.chi:.3g}"))
    out.append(qualitative_claim("chi-stiff", "Sec. 5", "turnout-stiff: chi = 0", "chi = 0", both,
                                 mi.chi == 0,
                                 difference="-" if mi.chi == 0 else "neither the paper's chi nor "
                                 "chi_simulation is 0: the equilibrium is stable"))
    mi = st.matching("turnout-soft")
    # the paper's h and chi against both readings: its definition (the smooth cycle) and the
    # simulated critical disturbance (the limits on), saying which one agrees
    out.append(numeric_claim("h-soft", "Sec. 5, Fig. 12", "turnout-soft: h, against the paper's "
                             "definition (max gap deviation on the smooth model's unstable cycle)",
                             PAPER["h_soft"], mi.h, "mm", scale=1e3, digits=3,
                             note=_matching_note(mi)))
    out.append(_against_simulation("h-soft-sim", "turnout-soft: h, against the simulated "
                                   "critical disturbance h_simulation (limits on)",
                                   PAPER["h_soft"], mi.h_simulation, "mm", 1e3, mi))
    out.append(numeric_claim("chi-soft", "Sec. 5", "turnout-soft: chi = h / w0, against the "
                             "paper's definition chi_paper", PAPER["chi_soft"], mi.chi_paper, "",
                             digits=3, note=_which_agrees(mi)))
    out.append(_against_simulation("chi-soft-sim", "turnout-soft: chi, against chi_simulation "
                                   "(the headline index here: the smaller of the two)",
                                   PAPER["chi_soft"], mi.chi_simulation, "", 1.0, mi))
    if st.settings.include_vehicle:
        sim, _ = st.vehicle_run("turnout-stiff", None)
        out.append(qualitative_claim(
            "fig11", "Fig. 11", "turnout-stiff, vehicle pressed onto the free beam: diverges",
            "diverges", outcome_text(sim), sim.outcome == "collision"))
        sim_a, _ = st.vehicle_run("turnout-soft", None)
        sim_b, _ = st.vehicle_run("turnout-soft", PAPER["q1_fig13b"])
        out.append(Claim(
            "fig13", "Fig. 13", "turnout-soft, model B pressed onto the free beam: converges "
            "with q1(0) = 0 (a); response with q1(0) = 3 mm (b)",
            "(a) converges; (b) shown in the figure, outcome not stated in the text",
            f"(a) {outcome_text(sim_a)}; (b) {outcome_text(sim_b)}",
            "agree" if converges(sim_a) else "differ",
            "-" if converges(sim_a) else "opposite outcome for (a)",
            "the text says small initial values converge and large ones diverge, without "
            "saying which of (a), (b) is which"))
    return out


def _against_simulation(key: str, claim: str, paper: float, ours: float | None, unit: str,
                        scale: float, mi: Any) -> Claim:
    """A claim against the simulated reading (or 'not computed' without the simulation)."""
    if ours is None:
        return Claim(key, "Sec. 5", claim, f"{paper * scale:.3g} {unit}".strip(),
                     "not computed (no simulation: --quick)", "differ", "-",
                     "the simulated critical disturbance was not run")
    return numeric_claim(key, "Sec. 5", claim, paper, ours, unit, scale=scale, digits=3,
                         note=_which_agrees(mi))


def _which_agrees(mi: Any) -> str:
    """Which of the two readings the paper's chi = 4.15 sits next to."""
    if mi.chi_simulation is None:
        return "chi_simulation not computed; the headline is the paper's chi"
    r_p = abs(relative_difference(mi.chi_paper, PAPER["chi_soft"]))
    r_s = abs(relative_difference(mi.chi_simulation, PAPER["chi_soft"]))
    near, far = (("chi_simulation", "chi_paper") if r_s < r_p else ("chi_paper",
                                                                    "chi_simulation"))
    mech = mi.mechanism_down if (mi.h_simulation is not None
                                 and mi.h_simulation == mi.h_simulation_down) else mi.mechanism_up
    return (f"the paper's chi = {PAPER['chi_soft']:g} agrees with {near} "
            f"({min(r_p, r_s):.1%} off), not with {far} ({max(r_p, r_s):.1%} off); "
            f"chi_paper = {mi.chi_paper:.4g}, chi_simulation = {mi.chi_simulation:.4g} "
            f"(h_simulation decided by {mech}); the headline chi = {mi.chi:.4g}")


def _matching_note(mi: Any) -> str:
    parts = [f"case {mi.case}"]
    if mi.hopf_param is not None and mi.hopf_value is not None:
        parts.append(f"cycle from the Hopf point {mi.hopf_param} = {mi.hopf_value:.5g}")
    if mi.h_simulation is not None:
        parts.append(f"simulation cross-check (critical |x5(0)|, smaller direction): "
                     f"{mi.h_simulation * 1e3:.3g} mm")
    if mi.current_reverses:
        parts.append("the coil current would reverse on the cycle (smooth model)")
    return "; ".join(parts)


CLAIM_GROUPS: tuple[tuple[str, Callable[[Study], list[Claim]]], ...] = (
    ("beam values", _claims_beams),
    ("Hopf points", _claims_hopf),
    ("alpha1..alpha3", _claims_alpha),
    ("turnout beams", _claims_turnout),
)


def compute_claims(study: Study, groups: Sequence[str] | None = None) -> list[Claim]:
    """Every claim of the paper beside our value (groups: see ``CLAIM_GROUPS``)."""
    out: list[Claim] = []
    for label, fn in CLAIM_GROUPS:
        if groups is None or label in groups:
            out.extend(_claim_guard(fn, study, label))
    return out


def claims_table_html(claims: Sequence[Claim]) -> str:
    """The claims table (one row per claim, the verdict coloured)."""
    rows, classes = [], []
    for c in claims:
        rows.append((c.source, c.claim, c.paper, c.ours, c.verdict, c.difference, c.note))
        classes.append({"agree": "agree", "close": "partly"}.get(c.verdict, "differ"))
    return table_html(["source", "claim", "paper", "ours", "verdict", "difference", "note"],
                      rows, "claims", row_classes=classes, column_classes={4: "verdict"})


def hopf_a1(study: Study) -> float | None:
    """The Hopf point A1 along omega1 at sigma = 4e-4 (when Fig. 5a's diagram has been
    computed): the fact the claims section's discussion of the stability differences
    rests on."""
    d = study.cache.values.get("diagram:omega1")
    if d is None or not d.branches:
        return None
    return float(d.branches[0][0].value)
