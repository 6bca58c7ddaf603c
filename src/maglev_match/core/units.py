"""The one table of units: every quantity the commands print, draw or save, with the unit
it is stored in and the unit it is shown in.

Two rules, one table:

* **Files for programs** (JSON, netCDF, CSV) hold SI values. A netCDF variable carries its
  unit in the ``units`` attribute; a CSV column carries it in its header, ``name (unit)``
  (:func:`header`).
* **Text and figures for people** show each quantity in its *display* unit, the same one in
  every command, report and figure (:func:`shown`, :func:`label`): gaps and deflections in
  mm, gap rates in mm/s, currents in A, frequencies in rad/s.

So a gap rate is ``m/s`` in every file and ``mm/s`` in every figure and text line, never one
in one figure and the other in the next. Parameters keep the SI units of
:data:`maglev_match.core.params.PARAMETER_DOCS` everywhere, except w0, a deflection, shown in mm.

A units library (pint) was considered: the package converts only by powers of ten between
two fixed units per quantity, which this table states in a dozen lines; pint would add a
dependency and an import of ~0.3 s to every command.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Unit", "QUANTITIES", "unit", "si_unit", "shown", "label", "header", "scale"]


@dataclass(frozen=True)
class Unit:
    """A quantity's stored (SI) unit and its display unit.

    si : the SI unit of files (JSON, netCDF, CSV), e.g. ``"m/s"``.
    display : the unit of text and figures, e.g. ``"mm/s"``.
    scale : display value = SI value x scale (1e3 for m -> mm).
    """

    si: str
    display: str
    scale: float = 1.0


_MM = Unit("m", "mm", 1e3)
_MM_S = Unit("m/s", "mm/s", 1e3)

#: Quantity name -> :class:`Unit`. Names are those of the result fields, dataset variables
#: and CSV columns that hold the quantity.
QUANTITIES: dict[str, Unit] = {
    # gaps, deflections and their rates
    "gap": _MM,
    "gap_deviation": _MM,
    "gap_max": _MM,
    "gap_min": _MM,
    "gap_deviation_max": _MM,
    "gap_deviation_min": _MM,
    "gap_dev_max": _MM,
    "gap_dev_min": _MM,
    "gap_rate": _MM_S,
    "beam_deflection": _MM,
    "x5": _MM,
    "q1": _MM,
    "h": _MM,
    "h_simulation": _MM,
    "w0": _MM,
    "amplitude": _MM,
    # currents
    "current": Unit("A", "A"),
    "current_min": Unit("A", "A"),
    "current_max": Unit("A", "A"),
    # time and frequency
    "time": Unit("s", "s"),
    "period": Unit("s", "s"),
    "frequency": Unit("rad/s", "rad/s"),
    "frequency_hz": Unit("Hz", "Hz"),
    "omega": Unit("rad/s", "rad/s"),
    # eigenvalues and the stability margin
    "eigenvalue_real": Unit("1/s", "1/s"),
    "eigenvalue_imag": Unit("rad/s", "rad/s"),
    "re": Unit("1/s", "1/s"),
    "im": Unit("rad/s", "rad/s"),
    "max_real_part": Unit("1/s", "1/s"),
    "margin": Unit("1/s", "1/s"),
    "crossing_speed": Unit("1/s per parameter unit", "1/s per parameter unit"),
    # dimensionless
    "chi": Unit("1", "-"),
    "chi_simulation": Unit("1", "-"),
    "damping_ratio": Unit("1", "-"),
    "multiplier": Unit("1", "-"),
}


def _lookup(name: str) -> Unit | None:
    if name in QUANTITIES:
        return QUANTITIES[name]
    from maglev_match.core.params import PARAMETER_DOCS

    if name in PARAMETER_DOCS:
        u = PARAMETER_DOCS[name][0]
        return Unit(u, u)
    return None


def unit(name: str) -> str:
    """The display unit of ``name`` ('' when the table does not know it)."""
    u = _lookup(name)
    return "" if u is None else u.display


def si_unit(name: str) -> str:
    """The SI unit of ``name`` in files ('' when the table does not know it)."""
    u = _lookup(name)
    return "" if u is None else u.si


def scale(name: str) -> float:
    """Display value per SI value of ``name`` (1 when unknown)."""
    u = _lookup(name)
    return 1.0 if u is None else u.scale


def shown(name: str, value):
    """An SI value (or array) of ``name`` in its display unit."""
    return value * scale(name)


def label(name: str, text: str | None = None) -> str:
    """An axis label or table heading: ``text (display unit)``; ``text`` defaults to
    ``name``. Dimensionless quantities get no unit."""
    u = unit(name)
    text = name if text is None else text
    return f"{text} ({u})" if u not in ("", "-", "1") else text


def header(name: str) -> str:
    """A CSV column header: ``name (SI unit)``; ``name`` alone when dimensionless or
    unknown."""
    u = si_unit(name)
    return f"{name} ({u})" if u not in ("", "1", "-") else name
