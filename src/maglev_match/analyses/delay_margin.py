"""The practical margin of the controller's delay: how far beyond the critical delay the
levitation still holds.

At the critical delay tau_c the equilibrium loses stability in a Hopf bifurcation. The
sign of the first Lyapunov coefficient alone says little in practice: a supercritical
point (l1 < 0) gives stable cycles beyond tau_c, but on the maglev unit they exist only up
to a fold of cycles (LPC) a few per cent further, where they meet the unstable cycles and
disappear, and the motion beyond reaches the gap limits; or the stable cycle may touch a
physical limit (the coil current reaching zero, a gap limit) before its fold. The practical
margin is the delay up to which a small, stable oscillation within the limits exists:

* subcritical (l1 > 0): tau_c itself (no stable cycle beyond it);
* supercritical: the smaller of the fold of the stable cycles and the delay at which a
  stable cycle first touches a physical limit, both located on the branch of cycles
  continued from the critical delay in tau (:func:`maglev_match.dynamics.cycles.cycle_branch`
  on the discretised delay system, the limits of the model as its contacts);
* None with the reason when neither is found before the branch ends (the reason says
  how it ended).
"""

from __future__ import annotations

from typing import Any

from maglev_match.maglev.base import MaglevModel

__all__ = ["practical_delay_margin"]


def practical_delay_margin(m: MaglevModel, tau_c: float | None, kind: str | None, *,
                           ntst: int = 40, ncol: int = 4, max_steps: int = 120
                           ) -> dict[str, Any]:
    """The practical margin of the delay of model ``m`` beyond its critical delay ``tau_c``
    (s) with the Hopf point's ``kind`` (see the module). Keys: value (s or None), basis
    ("hopf", "fold", "limit" or None), fold (s or None), limit (s or None), limit_name,
    reason (one sentence), steps."""
    out: dict[str, Any] = {"value": None, "basis": None, "fold": None, "limit": None,
                           "limit_name": None, "reason": "", "steps": 0}
    if tau_c is None or not tau_c > 0:
        out["reason"] = "no critical delay: no margin beyond it to compute"
        return out
    if kind != "supercritical":
        out.update(value=float(tau_c), basis="hopf",
                   reason="the Hopf point at the critical delay is not supercritical: no "
                   "stable cycle exists beyond it, so the margin is the critical delay")
        return out
    from maglev_match.dynamics.cycles import cycle_branch
    from maglev_match.dynamics.delay import delay_hopf_points

    reach = 1.5 * float(tau_c)
    system = m.system(tau_max=reach)
    scan = delay_hopf_points(system, "tau", 0.0, reach)
    hopfs = [h for h in scan.points if h.converged]
    if not hopfs:
        out["reason"] = "the critical delay's Hopf point was not found again on the " \
            "discretised system"
        return out
    hp = min(hopfs, key=lambda h: abs(h.value - tau_c))
    br = cycle_branch(system, hp, "tau", limits=m.cycle_limits(True), ntst=ntst, ncol=ncol,
                      max_steps=max_steps)
    out["steps"] = len(br.points)
    stable_at = {i: c.stable for i, c in enumerate(br.points)}
    for sp in br.special_points:
        kind_ = str(sp.type)
        if sp.located != "solved":
            continue
        before_stable = stable_at.get(sp.step, False)
        if kind_ == "LPC" and out["fold"] is None and before_stable:
            out["fold"] = float(sp.value)
        elif kind_ == "contact" and out["limit"] is None and before_stable:
            out["limit"], out["limit_name"] = float(sp.value), str(sp.detail or "a limit")
    found = [(v, b) for v, b in ((out["fold"], "fold"), (out["limit"], "limit"))
             if v is not None]
    if found:
        value, basis = min(found, key=lambda vb: abs(vb[0] - tau_c))
        out.update(value=value, basis=basis)
        if basis == "fold":
            out["reason"] = (f"the stable cycles born at the critical delay fold back at "
                             f"tau = {value * 1e3:.6g} ms ({100 * (value / tau_c - 1):+.3g} %); "
                             "beyond it no small oscillation is left and the motion leaves "
                             "for the limits")
        else:
            out["reason"] = (f"the stable cycle born at the critical delay touches "
                             f"{out['limit_name']} at tau = {value * 1e3:.6g} ms "
                             f"({100 * (value / tau_c - 1):+.3g} %)")
    else:
        out["reason"] = (f"neither a fold of the stable cycles nor a limit touched by them "
                         f"was found: the branch ended ({br.stopped_reason})")
    return out
