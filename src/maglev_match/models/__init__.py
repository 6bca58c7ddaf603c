"""Physics only: the maglev vector fields as pure JAX functions, no solver code."""

from maglev_match.models.unit import unit_system
from maglev_match.models.vehicle import vehicle_system

__all__ = ["unit_system", "vehicle_system", "build_system"]


def build_system(params, model: str = "unit", limited: bool = False):
    """The :class:`~maglev_match.dynamics.system.System` of model ``'unit'`` (A) or
    ``'vehicle'`` (B) for a parameter set."""
    if model == "unit":
        return unit_system(params, limited=limited)
    if model == "vehicle":
        return vehicle_system(params, limited=limited)
    from maglev_match.params import ParameterError

    raise ParameterError("model", model, "must be 'unit' or 'vehicle'")
