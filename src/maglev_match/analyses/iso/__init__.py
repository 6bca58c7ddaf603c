"""Iso-chi design curves: the level set headline chi(p1, p2) = target continued in two
parameters (`maglev-match iso-curve`).

* :mod:`~maglev_match.analyses.iso.records`: the records (an evaluation, a point, a special
  point, the traced curve);
* :mod:`~maglev_match.analyses.iso.trace`: the continuation for any evaluator of chi and
  its two parts (pseudo-arclength predictor, corrector along the gradient, step control,
  the start, the switches of the deciding part and the mechanism changes located);
* :mod:`~maglev_match.analyses.iso.maglev`: the maglev models' headline index as that
  evaluator (warm-started from the previous point);
* :mod:`~maglev_match.analyses.iso.curve`: the result (:class:`IsoChiCurve`) and
  :func:`iso_chi_curve`.
"""

from __future__ import annotations

from maglev_match.analyses.iso.curve import (
    POINT_STATUSES,
    IsoChiCurve,
    continue_iso_curve,
    finite_target,
    iso_chi_curve,
    read_iso_curve,
)
from maglev_match.analyses.iso.maglev import MaglevChi, sample_of
from maglev_match.analyses.iso.trace import (
    IsoPoint,
    IsoSpecial,
    Sample,
    Traced,
    TraceSettings,
    extend_iso,
    trace_iso,
)

__all__ = ["IsoChiCurve", "iso_chi_curve", "continue_iso_curve", "read_iso_curve",
           "finite_target", "POINT_STATUSES", "MaglevChi",
           "sample_of", "IsoPoint", "IsoSpecial", "Sample", "TraceSettings", "Traced",
           "trace_iso", "extend_iso"]
