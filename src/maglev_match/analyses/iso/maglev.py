"""The headline index of a maglev model as the evaluator of an iso-chi curve: one
:func:`~maglev_match.analyses.matching.matching_index` per (p1, p2), warm-started from the
nearest design evaluated so far (``near=``: its solved critical disturbances are continued
instead of searched again), read into a :class:`~maglev_match.analyses.iso.records.Sample`; and the
exact gradient of each part there (:meth:`MaglevChi.gradient`), from the index's analytic
sensitivities (:func:`~maglev_match.analyses.sensitivity.index_sensitivity`: the paper
part through the cycle's parameter derivative, the simulated part through the implicit
derivative of the solved grazing or basin-boundary condition)."""

from __future__ import annotations

import math

import numpy as np

from maglev_match.analyses.iso.records import Sample
from maglev_match.analyses.matching import Case, MatchingIndex, matching_index
from maglev_match.core.params import ParameterError, Params

__all__ = ["MaglevChi", "sample_of"]

_PAPER_STATUS = {Case.UNSTABLE_CYCLE: "cycle", Case.NO_CYCLE_WITHIN_LIMITS: "rule",
                 Case.UNSTABLE_EQUILIBRIUM: "unstable"}


def sample_of(idx: MatchingIndex) -> Sample:
    """The parts of a computed index as a curve sample: the deciding part, the simulated
    part's direction (the one whose size is h_simulation), its mechanism and whether that
    size was solved or only bracketed."""
    paper = "failed" if not idx.converged else _PAPER_STATUS.get(idx.case, "failed")
    chi = float(idx.chi) if idx.converged else float("nan")
    if idx.simulation is None:
        return Sample(chi, float(idx.chi_paper), None, "paper", paper_status=paper,
                      simulation_status="off", reason=idx.message, state=idx)
    if idx.simulation.get("status") == "skipped":
        return Sample(chi, float(idx.chi_paper), None, "paper", paper_status=paper,
                      simulation_status="skipped", reason=idx.simulation.get("reason", ""),
                      state=idx)
    if idx.chi_simulation is None:
        return Sample(chi, float(idx.chi_paper), None, str(idx.reading_basis),
                      paper_status=paper, simulation_status="inconclusive",
                      reason="the simulation was inconclusive", state=idx)
    key = "up" if idx.h_simulation_up == idx.h_simulation else "down"
    crit = idx.critical_up if key == "up" else idx.critical_down
    mech = idx.mechanism_up if key == "up" else idx.mechanism_down
    info = idx.simulation.get(key, {})
    status = "solved" if crit is not None and crit.solved else "bracketed"
    if info.get("status") == "all_return":
        status = "solved"  # the whole gap range returns: h_simulation is the range itself
    return Sample(chi, float(idx.chi_paper), float(idx.chi_simulation),
                  str(idx.reading_basis), None if mech is None else str(mech), key,
                  paper, status, reason=idx.message, state=idx)


class MaglevChi:
    """Callable (p1, p2) -> :class:`Sample` of the headline index of ``model`` at ``base``
    with ``names`` set to (p1, p2); ``simulate`` False: the paper's chi only. Each call
    continues the simulated part from the index of the nearest design evaluated so far
    (``warm``; nearest in the largest relative change of the two parameters): the tracer
    jumps (the backward direction starts at the first point, the corrector probes both
    sides of the curve), so the previous call is not always the closest."""

    def __init__(self, base: Params, names: tuple[str, str], *, model: str = "unit",
                 simulate: bool = True, warm: bool = True) -> None:
        self.base, self.names, self.model = base, names, model
        self.simulate, self.warm = simulate, warm
        self.done: list[tuple[float, float, MatchingIndex]] = []  # (p1, p2, its index)

    def nearest(self, v1: float, v2: float) -> MatchingIndex | None:
        """The index of the evaluated design nearest (v1, v2), None before the first."""
        def distance(item: tuple[float, float, MatchingIndex]) -> float:
            return max(abs(item[0] - v1) / max(abs(v1), 1e-300),
                       abs(item[1] - v2) / max(abs(v2), 1e-300))

        return min(self.done, key=distance)[2] if self.done else None

    def __call__(self, v1: float, v2: float) -> Sample:
        try:
            p = self.base.replace(**{self.names[0]: v1, self.names[1]: v2})
        except ParameterError as exc:
            return Sample(float("nan"), float("nan"), reason=f"not a valid parameter set: "
                          f"{exc}")
        near = self.nearest(v1, v2) if (self.warm and self.simulate) else None
        try:
            idx = matching_index(p, model=self.model, simulate=self.simulate,
                                 **({} if near is None else {"near": near}))
        except (ArithmeticError, ValueError, RuntimeError) as exc:
            # a numerical failure of the index at this point: reported on the point
            return Sample(float("nan"), float("nan"), reason=f"the index failed: {exc}")
        smp = sample_of(idx)
        if math.isfinite(smp.chi) and idx.critical_up is not None:
            self.done.append((float(v1), float(v2), idx))
        return smp

    def gradient(self, v1: float, v2: float, sample: Sample
                 ) -> tuple[dict[str, np.ndarray], str]:
        """The exact gradient (d/dp1, d/dp2, per unit of each parameter) of each part of
        the index in ``sample`` (this evaluator's answer at (v1, v2)) that has one:
        {"paper": ..., "simulation": ...} (a part without a derivative is left out), and a
        text saying why a part has none ('' when both have one or the part is not
        computed)."""
        from maglev_match.analyses.matching import MatchingIndex
        from maglev_match.analyses.sensitivity import (
            DerivativeStatus,
            engineering_names,
            index_sensitivity,
        )

        idx = sample.state
        if not isinstance(idx, MatchingIndex) or not idx.converged:
            return {}, "the index did not converge there"
        if self.base.tau > 0:  # (index_sensitivity refuses a delay, naming tau)
            return {}, ("with a delay (tau > 0) the index has no analytic derivative: the "
                        "sensitivities are of the delay-free models")
        known = engineering_names(self.base, self.model)
        missing = [n for n in self.names if n not in known]
        if missing:
            return {}, (f"{', '.join(missing)} has no analytic derivative of the index "
                        "(not one of the model's engineering parameters)")
        try:
            p = self.base.replace(**{self.names[0]: v1, self.names[1]: v2})
            sens = index_sensitivity(p, idx, boundaries=False, model=self.model)
        except (ArithmeticError, ValueError, RuntimeError) as exc:  # (LinAlgError too)
            return {}, f"the sensitivity run failed: {exc}"
        rows = [sens.row(n) for n in self.names]
        out: dict[str, np.ndarray] = {}
        why = []
        if sens.paper_status not in (None, DerivativeStatus.UNDEFINED,
                                     DerivativeStatus.UNAVAILABLE):
            g = np.array([r.dchi_paper for r in rows], float)
            if np.all(np.isfinite(g)):
                out["paper"] = g
        if "paper" not in out:
            why.append(f"paper part: no derivative ({sens.paper_status})")
        if idx.chi_simulation is not None:
            if all(r.dchi_simulation is not None for r in rows):
                g = np.array([r.dchi_simulation for r in rows], float)
                if np.all(np.isfinite(g)):
                    out["simulation"] = g
            if "simulation" not in out:
                why.append("simulated part: no derivative (its critical size is only "
                           "bracketed" + (f"; {sens.simulation_status}" if
                                          sens.simulation_status else "") + ")")
        return out, "; ".join(why)

