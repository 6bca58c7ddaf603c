"""The maglev models by name, with the words that describe them: a light table (no NumPy,
no JAX), so that the command line can check ``--model`` and label its output before any
numerical module loads.

Each entry is the :class:`ModelInfo` of one :class:`~maglev_match.maglev.base.MaglevModel`
subclass (its class attribute ``info``); :mod:`maglev_match.maglev.models` maps the names to
the classes.
"""

from __future__ import annotations

from dataclasses import dataclass

from maglev_match.core.params import ParameterError

__all__ = ["ModelInfo", "CATALOG", "MODEL_NAMES", "DEFAULT_MODEL", "model_info", "names_text"]


@dataclass(frozen=True)
class ModelInfo:
    """What a maglev model is called and how its parts are named.

    name : the key (``--model NAME``, ``model="NAME"``). letter : the paper's letter ("A").
    title : what it is ("one levitation unit"). points : its levitation points (1 or more).
    w0_text : what its static deflection w0 is, in words.
    disturbance_labels : the two directions of the index's disturbance (beam up / down).
    beam_params : the beam's modal parameters it takes (omega1, and model A's sigma).
    plane : the default plane of its Hopf curve.
    """

    name: str
    letter: str
    title: str
    points: int
    w0_text: str
    disturbance_labels: tuple[str, str]
    beam_params: tuple[str, ...]
    plane: tuple[str, str]

    @property
    def label(self) -> str:
        """'model A (one levitation unit)'."""
        return f"model {self.letter} ({self.title})"

    @property
    def short(self) -> str:
        """'model A'."""
        return f"model {self.letter}"


CATALOG: dict[str, ModelInfo] = {
    "unit": ModelInfo(
        name="unit", letter="A", title="one levitation unit", points=1,
        w0_text="static beam deflection",
        disturbance_labels=("beam up, x5(0) < 0", "beam down, x5(0) > 0"),
        beam_params=("omega1", "sigma"), plane=("omega1", "sigma")),
    "vehicle": ModelInfo(
        name="vehicle", letter="B", title="full vehicle, six levitation points", points=6,
        w0_text="static mid-span beam deflection under the vehicle",
        disturbance_labels=("beam lifted towards the free beam", "beam pushed down"),
        beam_params=("omega1",), plane=("omega1", "kD")),
}

#: the names of the maglev models, in the order the help lists them
MODEL_NAMES: tuple[str, ...] = tuple(CATALOG)
#: the model of a command or call that names none
DEFAULT_MODEL = "unit"


def model_info(name: str, field: str = "model") -> ModelInfo:
    """The :class:`ModelInfo` of ``name``; a :class:`ParameterError` naming ``field`` for a
    name that is not a maglev model."""
    try:
        return CATALOG[str(name)]
    except KeyError:
        raise ParameterError(field, name, f"must be {names_text()}") from None


def names_text() -> str:
    """"'unit' or 'vehicle'": the names, for messages."""
    quoted = [f"'{n}'" for n in MODEL_NAMES]
    return quoted[0] if len(quoted) == 1 else ", ".join(quoted[:-1]) + " or " + quoted[-1]
