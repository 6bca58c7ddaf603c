"""The data of a study report: how much work it does (:class:`ReportSettings`), what its
section functions share (:class:`ReportContext`), the signature of a section function
(``SectionFn``), a rendered section (:class:`SectionResult`), a section that cannot be
computed (:class:`SectionUnavailable`) and the written report (:class:`ReportResult`)."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from maglev_match.core.params import Params

__all__ = [
    "ReportSettings",
    "ReportContext",
    "SectionUnavailable",
    "SectionResult",
    "ReportResult",
    "SectionFn",
]


@dataclass(frozen=True)
class ReportSettings:
    """How much work a report does.

    quick : coarse settings (few continuation steps, short simulations) for tests/previews.
    t_end : simulation horizon (s) of the time histories.
    hopf_omega1_range : (min, max) of omega1 (rad/s) for the Hopf curve chart.
    hopf_sigma_range : (min, max) of sigma (1/kg) for the Hopf curve chart.
    cycle_ntst, cycle_max_steps : collocation mesh intervals and continuation steps.
    include_vehicle : also analyse model B (full vehicle, 40 states).
    """

    quick: bool = False
    t_end: float = 3.0
    hopf_omega1_range: tuple[float, float] = (40.0, 400.0)
    hopf_sigma_range: tuple[float, float] = (0.0, 2e-3)
    cycle_ntst: int = 60
    cycle_max_steps: int = 200
    include_vehicle: bool = True

    @classmethod
    def quick_settings(cls) -> ReportSettings:
        return cls(quick=True, t_end=1.5, cycle_ntst=30, cycle_max_steps=60,
                   include_vehicle=False)

    def as_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


@dataclass
class ReportContext:
    """What the section functions share: the output folder for figure files, the
    settings and a cache of intermediate results (e.g. Hopf points used by two sections)."""

    out_dir: Path
    settings: ReportSettings = field(default_factory=ReportSettings)
    cache: dict[str, Any] = field(default_factory=dict)
    prefix: str = ""

    def figure_path(self, stem: str) -> Path:
        """Where a figure named ``stem`` is written (suffix added by the saver)."""
        return self.out_dir / f"{self.prefix}{stem}"


class SectionUnavailable(Exception):
    """A section cannot be computed (a missing analysis module, a failed precondition)."""


@dataclass(frozen=True)
class SectionResult:
    """One rendered section of a report."""

    key: str
    title: str
    html: str
    figures: tuple[Path, ...]
    data: Any
    available: bool
    reason: str = ""
    seconds: float = 0.0


@dataclass(frozen=True)
class ReportResult:
    """A written report: the HTML file, its figure files and every section's data."""

    path: Path
    sections: tuple[SectionResult, ...]
    figures: tuple[Path, ...]
    seconds: float

    @property
    def headline(self) -> dict[str, Any] | None:
        """The matching-index section's headline (model A): chi, its basis, its reading and
        chi by the paper's definition, as the section shows them (None when that section
        is missing or could not be computed)."""
        for s in self.sections:
            if s.key == "matching" and s.available and isinstance(s.data, dict):
                d = s.data.get("unit", s.data)
                return {k: d.get(k) for k in ("chi", "reading_basis", "reading", "chi_paper")}
        return None

    @property
    def unavailable(self) -> list[tuple[str, str]]:
        """(section key, reason) of the sections that could not be computed."""
        return [(s.key, s.reason) for s in self.sections if not s.available]


SectionFn = Callable[[Params, ReportContext], tuple[str, Sequence[Path], Any]]
