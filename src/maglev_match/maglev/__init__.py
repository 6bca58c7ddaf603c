"""Physics only: the maglev vector fields as pure JAX functions, no solver code."""

from maglev_match.maglev.unit import unit_system
from maglev_match.maglev.vehicle import vehicle_system

__all__ = ["unit_system", "vehicle_system", "build_system"]


def build_system(params, model: str = "unit", limited: bool = False, *,
                 tau_max: float | None = None):
    """The :class:`~maglev_match.dynamics.system.System` of model ``'unit'`` (A) or
    ``'vehicle'`` (B) for a parameter set: the ODE when ``params.tau = 0``, the discretised
    delay system (:mod:`maglev_match.dynamics.delay`) when ``params.tau > 0`` or when
    ``tau_max`` asks for a delay axis up to that value."""
    if model == "unit":
        return unit_system(params, limited=limited, tau_max=tau_max)
    if model == "vehicle":
        return vehicle_system(params, limited=limited, tau_max=tau_max)
    from maglev_match.core.params import ParameterError

    raise ParameterError("model", model, "must be 'unit' or 'vehicle'")
