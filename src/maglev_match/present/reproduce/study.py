"""The computations of the reproduction, done once and shared by its figures and its
claims (:class:`Study`): the presets, stability summaries, the cycle diagrams of Fig. 5,
the Hopf curves of Fig. 4, the time histories, the matching indices and the variants."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from maglev_match.core.params import Params, load_preset
from maglev_match.present.report.base import ReportSettings
from maglev_match.present.report.sections_cycles import cycle_diagram, hopf_curves
from maglev_match.present.report.sections_history import run_time_history
from maglev_match.present.report.sections_stability import stability_summary
from maglev_match.present.reproduce.variants import (
    VARIANT_PARAMS,
    VariantResult,
    variant_search,
)

__all__ = ["Study"]


@dataclass
class _Cache:
    values: dict[str, Any] = field(default_factory=dict)

    def get(self, key: str, make: Callable[[], Any]) -> Any:
        if key not in self.values:
            self.values[key] = make()
        return self.values[key]


class Study:
    """Lazily computed results shared by the figures and the claims."""

    def __init__(self, settings: ReportSettings):
        self.settings = settings
        self.cache = _Cache()

    def preset(self, name: str) -> Params:
        return self.cache.get(f"preset:{name}", lambda: load_preset(name))

    def stability(self, name: str, model: str = "unit") -> dict[str, Any]:
        return self.cache.get(f"stab:{name}:{model}",
                              lambda: stability_summary(self.preset(name), model))

    def diagram(self, param: str) -> Any:
        """Fig. 5a (omega1 at sigma = 4e-4) or 5b (sigma at omega1 = 100), from alpha1."""
        def make():
            p = self.preset("alpha1")
            if param == "omega1":
                return cycle_diagram(p, "omega1", 40.0, 400.0, self.settings)
            return cycle_diagram(p, "sigma", 1e-5, 2e-3, self.settings)

        return self.cache.get(f"diagram:{param}", make)

    def curves(self) -> list[Any]:
        return self.cache.get("curves", lambda: hopf_curves(self.preset("alpha1"),
                                                            self.settings))

    def unit_run(self, name: str, x5: float) -> tuple[Any, Any]:
        t_end = 3.0 if self.settings.quick else 5.0
        return self.cache.get(f"unit:{name}:{x5}", lambda: run_time_history(
            self.preset(name), "unit", t_end, x5=x5))

    def vehicle_run(self, name: str, q1: float | None) -> tuple[Any, Any]:
        t_end = 2.0 if self.settings.quick else 4.0
        return self.cache.get(f"vehicle:{name}:{q1}", lambda: run_time_history(
            self.preset(name), "vehicle", t_end, initial="pressed", q1=q1))

    def matching(self, name: str) -> Any:
        from maglev_match.analyses.matching import matching_index

        return self.cache.get(f"matching:{name}", lambda: matching_index(
            self.preset(name), simulate=not self.settings.quick))

    def variants(self) -> list[VariantResult]:
        return self.cache.get("variants", lambda: [variant_search(n) for n in VARIANT_PARAMS])
