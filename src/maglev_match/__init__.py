"""maglev-match: stability, Hopf bifurcations, limit cycles and the vehicle-track beam
matching index chi = h / w0 for EMS maglev systems."""

from maglev_match import jax_setup  # noqa: F401  (float64 before any model is built)
from maglev_match.params import ParameterError, Params, load_params, load_preset

__version__ = "0.1.0"
__all__ = ["Params", "ParameterError", "load_params", "load_preset", "__version__"]
