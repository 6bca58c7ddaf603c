"""The map's self-check: a seeded sample of its points recomputed by the point-wise index
and compared (:func:`spot_check`)."""

from __future__ import annotations

import json
import math
from typing import Any

import numpy as np

from maglev_match.analyses.maps.spec import BASIS_CODES, MapSpec, simulation_settings

__all__ = ["spot_check", "SPOT_CHECK_FRACTION", "SPOT_CHECK_MAX", "SPOT_CHECK_TOL"]

# self-check: share of points recomputed point-wise, at most this many, and the tolerance
# of the paper's h (relative: the map interpolates h between branch points)
SPOT_CHECK_FRACTION = 0.01
SPOT_CHECK_MAX = 12
SPOT_CHECK_TOL = 0.03


def spot_check(spec: MapSpec, data: dict[str, np.ndarray], *,
               fraction: float = SPOT_CHECK_FRACTION, max_points: int = SPOT_CHECK_MAX,
               seed: int = 0, tol: float = SPOT_CHECK_TOL,
               budget: float | None = None) -> dict[str, Any]:
    """Recompute a seeded random sample of the map's points with the point-wise index
    (:func:`maglev_match.analyses.matching.matching_index`, with the simulation when the map has it)
    and compare.

    ``fraction`` of the points, at least one and at most ``max_points`` (the cap keeps the
    check within about 10 % of the map's time). At each point:

    * the paper's h: |h_map - h_point| / h_point (0 when both are unstable; 1 when they
      disagree on stability), allowed ``tol`` (the map reads h off a branch continued
      along the row, the point-wise index off a branch continued to the point);
    * with the simulation, each direction's critical disturbance: |d_map - d_point| (m),
      allowed the search tolerance (both are brackets of that width around the critical
      size, so their midpoints differ by less);
    * the headline index chi = min(chi_paper, chi_simulation) against the point-wise
      min(chi_paper, chi_simulation): allowed the allowance of the part that decided it on
      both sides (the search tolerance / w0, or the relative tolerance of chi_paper), the
      larger of the two where the sides disagree on the part (min is 1-Lipschitz in each
      part).

    Unresolved map points are skipped (counted). ``budget`` (s): stop after the point
    during which the check's time exceeded it (at least one point is always checked); the
    sample order is seeded, so a shorter check is a prefix of a longer one. Returns the
    attributes stored on the dataset (``spot_check_records``: one row per point, the
    columns named in ``spot_check_columns``).
    """
    import time

    from maglev_match.analyses.matching import matching_index

    started = time.perf_counter()
    sim_tol = simulation_settings().tol
    ny, nx = data["stable"].shape
    n = max(1, min(max_points, math.ceil(fraction * nx * ny)))
    rng = np.random.default_rng(seed)
    flat = rng.choice(nx * ny, size=min(n, nx * ny), replace=False)
    worst = worst_sim = worst_head = 0.0
    worst_at = worst_sim_at = worst_head_at = None
    head_ok = True
    checked = skipped = 0
    records: list[list[float]] = []
    for f in (int(v) for v in flat):
        if budget is not None and checked and time.perf_counter() - started > budget:
            break
        i, j = divmod(f, nx)
        if not data["resolved"][i, j]:
            skipped += 1
            continue
        xv, yv = spec.x.values[j], spec.y.values[i]
        pt = matching_index(spec.point(xv, yv), simulate=spec.simulate)
        stable_map = bool(data["stable"][i, j])
        h_map = float(data["h"][i, j]) if stable_map else 0.0
        h_pt = float(pt.h)
        if stable_map != pt.stable or not math.isfinite(h_pt):
            diff = 1.0
        elif h_pt == 0.0:
            diff = 0.0 if h_map == 0.0 else 1.0
        else:
            diff = abs(h_map - h_pt) / abs(h_pt)
        rec = [float(xv), float(yv), h_map, h_pt, diff]
        if diff >= worst:
            worst, worst_at = diff, rec
        if spec.simulate:
            sims = []
            for key in ("up", "down"):
                d_map = float(data[f"h_simulation_{key}"][i, j])
                d_pt = getattr(pt, f"h_simulation_{key}")
                d_pt = math.nan if d_pt is None else float(d_pt)
                both_na = not stable_map and not pt.stable
                dd = 0.0 if both_na else abs(d_map - d_pt)
                dd = math.inf if math.isnan(dd) else dd
                sims += [d_map, d_pt]
                if dd >= worst_sim:
                    worst_sim, worst_sim_at = dd, (rec[:2], key, d_map, d_pt)
            chi_map = float(data["chi"][i, j])
            chi_pt = _headline(pt)
            # the part that decided the headline on both sides sets the allowance; where
            # the two sides disagree on it, the larger allowance (min is 1-Lipschitz)
            paper_allowed, sim_allowed = tol * abs(pt.chi_paper), sim_tol / float(pt.w0)
            by_sim_map = int(data["chi_basis"][i, j]) == BASIS_CODES["simulation"]
            by_sim_pt = (pt.chi_simulation is not None
                         and float(pt.chi_simulation) < float(pt.chi_paper))
            if by_sim_map and by_sim_pt:
                allowed = sim_allowed
            elif not by_sim_map and not by_sim_pt:
                allowed = paper_allowed
            else:
                allowed = max(paper_allowed, sim_allowed)
            if not stable_map and not pt.stable:
                dh = 0.0
            else:
                dh = abs(chi_map - chi_pt)
                dh = math.inf if math.isnan(dh) else dh
            ok = dh <= allowed
            head_ok = head_ok and ok
            rec += [*sims, chi_map, chi_pt, dh, allowed]
            if dh >= worst_head:
                worst_head, worst_head_at = dh, (rec[:2], chi_map, chi_pt, allowed)
        checked += 1
        records.append(rec)
    warnings = []
    if worst > tol and worst_at is not None:
        warnings.append(
            f"spot check: at {spec.x.name} = {worst_at[0]:.6g}, {spec.y.name} = {worst_at[1]:.6g} "
            f"the map gives h = {worst_at[2] * 1e3:.4g} mm and the point-wise index "
            f"{worst_at[3] * 1e3:.4g} mm (relative difference {worst:.3g} > {tol:g})")
    if spec.simulate and worst_sim > sim_tol and worst_sim_at is not None:
        (wx, wy), key, d_map, d_pt = worst_sim_at
        warnings.append(
            f"spot check: at {spec.x.name} = {wx:.6g}, {spec.y.name} = {wy:.6g} the map's "
            f"critical disturbance ({key}) is {d_map * 1e3:.5g} mm and the point-wise "
            f"search's {d_pt * 1e3:.5g} mm (difference > the search tolerance "
            f"{sim_tol * 1e3:g} mm)")
    if spec.simulate and not head_ok and worst_head_at is not None:
        (wx, wy), c_map, c_pt, allowed = worst_head_at
        warnings.append(
            f"spot check: at {spec.x.name} = {wx:.6g}, {spec.y.name} = {wy:.6g} the map's "
            f"headline chi = {c_map:.5g} and the point-wise index's {c_pt:.5g} differ by "
            f"more than the allowed {allowed:.3g}")
    columns = ["x", "y", "h_map", "h_point", "h_rel_diff"]
    if spec.simulate:
        columns += ["h_simulation_up_map", "h_simulation_up_point", "h_simulation_down_map",
                    "h_simulation_down_point", "chi_map", "chi_point", "chi_abs_diff",
                    "chi_allowed_diff"]
    passed = worst <= tol and (not spec.simulate or (worst_sim <= sim_tol and head_ok))
    out = {
        "spot_check_points": checked,
        "spot_check_planned": int(flat.size),
        "spot_check_seconds": round(time.perf_counter() - started, 3),
        "spot_check_skipped_unresolved": skipped,
        "spot_check_seed": seed,
        "spot_check_max_rel_diff": float(worst),
        "spot_check_tolerance": tol,
        "spot_check_passed": int(passed),
        "spot_check_columns": json.dumps(columns),
        "spot_check_records": json.dumps(records),
        "warnings": json.dumps(warnings),
    }
    if spec.simulate:
        out.update({
            "spot_check_simulation_max_diff": float(worst_sim),
            "spot_check_simulation_tolerance": sim_tol,
            "spot_check_headline_max_diff": float(worst_head),
            "spot_check_headline_passed": int(head_ok),
        })
    return out


def _headline(pt) -> float:
    """The headline index of a point-wise result: min(chi_paper, chi_simulation), or
    chi_paper when the simulation gave no number (not run, unstable, inconclusive)."""
    paper = float(pt.chi_paper)
    if not pt.stable:
        return math.nan
    if pt.chi_simulation is None:
        return paper
    return min(paper, float(pt.chi_simulation))
