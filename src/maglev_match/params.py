"""Parameter sets for the levitation unit, the beam and the full vehicle (SPEC.md section 2).

A :class:`Params` holds every input value in SI units. Values that the paper derives
(the levitation current ``i0``, the beam's modal frequencies ``omega_n``, the force gain
``sigma``, the static deflection ``w0``) are computed here, never typed into a preset.
``omega1``, ``sigma``, ``s`` and ``s0`` derive from the beam and vehicle geometry unless a
user sets them explicitly.

Presets are plain TOML files shipped in :mod:`maglev_match.presets`; user files use the
same format. Keys may stand at the top level or inside the organising tables ``[unit]``,
``[controller]``, ``[beam]``, ``[vehicle]`` and ``[limits]``.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

__all__ = [
    "Params",
    "ParameterError",
    "PARAMETER_DOCS",
    "available_presets",
    "load_params",
    "load_preset",
    "load_toml",
    "parse_assignment",
]

DEFAULT_PRESET = "turnout-soft"
SECTIONS = ("unit", "controller", "beam", "vehicle", "limits")
META_KEYS = ("name", "description")
# Values that are derived from geometry unless set explicitly.
DERIVABLE = ("omega1", "sigma", "s", "s0")
INTEGER_FIELDS = ("k", "n_modes")

# name -> (unit, meaning). Used for docs, the report's parameter table and error messages.
PARAMETER_DOCS: dict[str, tuple[str, str]] = {
    "m": ("kg", "levitation-frame mass carried by one levitation unit"),
    "M": ("kg", "car-body mass carried by one levitation unit"),
    "g": ("m/s^2", "gravity"),
    "ks": ("N/m", "secondary suspension stiffness per unit"),
    "cs": ("N s/m", "secondary suspension damping per unit"),
    "mu0": ("T m/A", "vacuum permeability"),
    "N": ("-", "coil turns"),
    "A": ("m^2", "pole area of one coil"),
    "c0": ("m", "rated gap"),
    "omega0": ("rad/s", "observer coefficient omega0"),
    "xi0": ("-", "observer coefficient xi0"),
    "kP": ("A/m", "gap feedback gain"),
    "kD": ("A s/m", "velocity feedback gain"),
    "ke": ("V/A", "current feedback gain"),
    "xi1": ("-", "beam modal damping ratio (all modes)"),
    "omega1": ("rad/s", "beam first modal circular frequency"),
    "sigma": ("1/kg", "force gain coefficient of the vehicle on the beam"),
    "gap_min": ("m", "lower physical gap limit"),
    "gap_max": ("m", "upper physical gap limit"),
    "L": ("m", "beam span (simply supported)"),
    "EI": ("N m^2", "beam bending stiffness"),
    "mbar": ("kg/m", "beam mass per length"),
    "l": ("m", "vehicle length"),
    "k": ("-", "number of basic levitation units of the vehicle"),
    "m_s": ("kg", "levitation-frame mass (full vehicle)"),
    "j_s": ("kg m^2", "levitation-frame pitch inertia"),
    "m_b": ("kg", "car-body mass (full vehicle)"),
    "j_b": ("kg m^2", "car-body pitch inertia"),
    "k2": ("N/m", "secondary suspension stiffness per frame"),
    "c2": ("N s/m", "secondary suspension damping per frame"),
    "s": ("m", "half distance between the two force centres of a frame"),
    "s0": ("m", "distance between neighbouring frame centres"),
    "n_modes": ("-", "number of beam modes in the full-vehicle model"),
}


class ParameterError(ValueError):
    """Invalid user input: names the field, the offending value and the rule it breaks."""

    def __init__(self, field_name: str, value: Any, rule: str):
        self.field = field_name
        self.value = value
        self.rule = rule
        super().__init__(f"parameter '{field_name}' = {value!r}: {rule}")


@dataclass(frozen=True)
class Params:
    """One vehicle-beam parameter set, SI units. Defaults: the paper's Appendix and the
    soft turnout beam (L = 18 m, mbar = 1920 kg/m, EI = 1.96e10 N m^2, l = 12.1 m, k = 12)."""

    # levitation unit (model A)
    m: float = 550.0
    M: float = 1150.0
    g: float = 9.8
    ks: float = 12_000.0
    cs: float = 900.0
    mu0: float = 4e-7 * math.pi
    N: float = 360.0
    A: float = 0.0184
    c0: float = 0.008
    # controller
    omega0: float = 130.0
    xi0: float = 2.0
    kP: float = 5000.0
    kD: float = 150.0
    ke: float = 25.0
    # beam
    xi1: float = 0.005
    L: float = 18.0
    EI: float = 1.96e10
    mbar: float = 1920.0
    l: float = 12.1
    k: int = 12
    omega1: float | None = None
    sigma: float | None = None
    # limits
    gap_min: float = 0.0
    gap_max: float = 0.018
    # full vehicle (model B)
    m_s: float = 2200.0
    j_s: float = 1377.0
    m_b: float = 13_800.0
    j_b: float = 159_365.0
    k2: float = 48_000.0
    c2: float = 3600.0
    s: float | None = None
    s0: float | None = None
    n_modes: int = 3
    # bookkeeping: which derivable values the user set explicitly
    explicit: frozenset[str] = field(default=frozenset(), compare=True, repr=False)

    def __post_init__(self) -> None:
        explicit = set(self.explicit)
        for name in DERIVABLE:
            if getattr(self, name) is not None:
                explicit.add(name)
        object.__setattr__(self, "explicit", frozenset(explicit))
        _validate_inputs(self)
        if self.omega1 is None:
            object.__setattr__(self, "omega1", self.beam_omega_n(1))
        if self.sigma is None:
            object.__setattr__(self, "sigma", self.beam_sigma())
        if self.s is None:
            object.__setattr__(self, "s", self.l / 12.0)
        if self.s0 is None:
            object.__setattr__(self, "s0", self.l / 3.0)
        _validate_derived(self)

    # ----- derived values -------------------------------------------------------------
    @property
    def K(self) -> float:
        """mu0 N^2 A, the magnet constant (T m^3/A ... SI: N m^2/A^2)."""
        return self.mu0 * self.N**2 * self.A

    @property
    def i0(self) -> float:
        """Levitation current of one unit (A): c0/N sqrt(2 (m+M) g / (mu0 A))."""
        return self.c0 / self.N * math.sqrt(2.0 * (self.m + self.M) * self.g / (self.mu0 * self.A))

    @property
    def i0_vehicle(self) -> float:
        """Equilibrium current of one levitation point of the full vehicle (A):
        K (i/c0)^2 = (m_s/2 + m_b/6) g."""
        return self.c0 * math.sqrt(self.point_load_vehicle / self.K)

    @property
    def point_load_vehicle(self) -> float:
        """Weight carried by one levitation point of the full vehicle (N)."""
        return (self.m_s / 2.0 + self.m_b / 6.0) * self.g

    def beam_omega_n(self, n: int) -> float:
        """Modal circular frequency of mode n of the simply supported beam (rad/s)."""
        return (n * math.pi / self.L) ** 2 * math.sqrt(self.EI / self.mbar)

    def omega_n(self, n: int) -> float:
        """Modal frequency used by the models (rad/s): n^2 omega1, so an explicit omega1
        scales all modes as an Euler-Bernoulli beam would."""
        return n**2 * float(self.omega1)  # type: ignore[arg-type]

    def beam_sigma(self) -> float:
        """Force gain coefficient (1/kg): 8 k L / (pi^2 l^2 mbar) sin^2(pi l / (2 L))."""
        return (
            8.0 * self.k * self.L / (math.pi**2 * self.l**2 * self.mbar)
            * math.sin(math.pi * self.l / (2.0 * self.L)) ** 2
        )

    @property
    def w0(self) -> float:
        """Static beam deflection under one unit (m): sigma (m+M) g / omega1^2."""
        return float(self.sigma) * (self.m + self.M) * self.g / float(self.omega1) ** 2

    @property
    def derived(self) -> dict[str, float]:
        """The derived values, for display."""
        return {
            "i0": self.i0,
            "omega1": float(self.omega1),  # type: ignore[arg-type]
            "sigma": float(self.sigma),  # type: ignore[arg-type]
            "w0": self.w0,
            **{f"omega{n}": self.omega_n(n) for n in range(2, self.n_modes + 1)},
        }

    # ----- editing ----------------------------------------------------------------------
    def replace(self, **changes: Any) -> Params:
        """A copy with some values changed. Derivable values (omega1, sigma, s, s0) that
        were not set explicitly are derived again from the new geometry."""
        for name in changes:
            if name not in FIELD_NAMES:
                raise ParameterError(name, changes[name], _unknown_rule())
        values = self.as_input_dict()
        values.update(changes)
        return make_params(values)

    def as_input_dict(self) -> dict[str, Any]:
        """The values a user set or defaulted, with non-explicit derivables left out."""
        out: dict[str, Any] = {}
        for f in dataclasses.fields(self):
            if f.name == "explicit":
                continue
            if f.name in DERIVABLE and f.name not in self.explicit:
                continue
            out[f.name] = getattr(self, f.name)
        return out

    def as_dict(self) -> dict[str, float]:
        """Every value, derived ones resolved (for JSON and reports)."""
        out = {n: getattr(self, n) for n in FIELD_NAMES}
        out["i0"] = self.i0
        out["w0"] = self.w0
        return out


FIELD_NAMES: tuple[str, ...] = tuple(
    f.name for f in dataclasses.fields(Params) if f.name != "explicit"
)


def _unknown_rule() -> str:
    return "unknown parameter; known names are: " + ", ".join(FIELD_NAMES)


def _positive(p: Params, *names: str) -> None:
    for n in names:
        v = getattr(p, n)
        if v is not None and not v > 0:
            raise ParameterError(n, v, "must be > 0")


def _nonnegative(p: Params, *names: str) -> None:
    for n in names:
        v = getattr(p, n)
        if v is not None and not v >= 0:
            raise ParameterError(n, v, "must be >= 0")


def _validate_inputs(p: Params) -> None:
    for f in dataclasses.fields(p):
        if f.name == "explicit":
            continue
        v = getattr(p, f.name)
        if v is None:
            continue
        if isinstance(v, bool) or not isinstance(v, int | float):
            raise ParameterError(f.name, v, "must be a number")
        if not math.isfinite(v):
            raise ParameterError(f.name, v, "must be a finite number")
    for n in INTEGER_FIELDS:
        v = getattr(p, n)
        if float(v) != int(v):
            raise ParameterError(n, v, "must be a whole number")
    _positive(p, "m", "M", "g", "ks", "mu0", "N", "A", "c0", "omega0", "xi0", "ke",
              "L", "EI", "mbar", "l", "k", "m_s", "j_s", "m_b", "j_b", "k2", "s")
    _nonnegative(p, "cs", "c2", "kP", "kD", "s0", "gap_min")
    if not 0 <= p.xi1 < 1:
        raise ParameterError("xi1", p.xi1, "a damping ratio must lie in [0, 1)")
    if p.omega1 is not None and not 0 < p.omega1 <= 1e5:
        raise ParameterError("omega1", p.omega1, "must lie in (0, 1e5] rad/s")
    if p.sigma is not None and not 0 <= p.sigma <= 0.1:
        raise ParameterError(
            "sigma", p.sigma,
            "must lie in [0, 0.1] 1/kg (an equivalent beam mass 1/sigma of at least 10 kg)",
        )
    if not p.gap_min < p.c0 < p.gap_max:
        bad = "gap_max" if p.c0 >= p.gap_max else "gap_min"
        raise ParameterError(
            bad, getattr(p, bad), f"the gap limits [gap_min, gap_max] must contain c0 = {p.c0}"
        )
    if p.l > p.L:
        raise ParameterError("l", p.l, f"the vehicle must fit on the beam: l <= L = {p.L}")
    if not 1 <= p.n_modes <= 20:
        raise ParameterError("n_modes", p.n_modes, "must be a whole number in 1..20")


def _validate_derived(p: Params) -> None:
    reach = float(p.s0) + float(p.s)  # type: ignore[arg-type]
    if reach >= p.L / 2:
        raise ParameterError(
            "s0", p.s0, f"the levitation points (s0 + s = {reach:g} m from mid-span) must lie on "
            f"the beam: s0 + s < L/2 = {p.L / 2:g} m",
        )


def make_params(values: dict[str, Any]) -> Params:
    """Build a validated :class:`Params` from a flat mapping of names to values."""
    clean: dict[str, Any] = {}
    for name, v in values.items():
        if name not in FIELD_NAMES:
            raise ParameterError(name, v, _unknown_rule())
        if name in INTEGER_FIELDS and isinstance(v, float) and v.is_integer():
            v = int(v)
        clean[name] = v
    return Params(**clean)


def _flatten(doc: dict[str, Any], source: str) -> dict[str, Any]:
    flat: dict[str, Any] = {}
    for key, value in doc.items():
        if key in META_KEYS:
            continue
        if isinstance(value, dict):
            if key not in SECTIONS:
                raise ParameterError(
                    key, "[table]", f"unknown section in {source}; allowed: {', '.join(SECTIONS)}"
                )
            for k2, v2 in value.items():
                if k2 in flat:
                    raise ParameterError(k2, v2, f"given twice in {source}")
                flat[k2] = v2
        else:
            if key in flat:
                raise ParameterError(key, value, f"given twice in {source}")
            flat[key] = value
    for name, v in flat.items():
        if name not in FIELD_NAMES:
            raise ParameterError(name, v, f"unknown parameter in {source}; known names are: "
                                 + ", ".join(FIELD_NAMES))
    return flat


def available_presets() -> list[str]:
    """Names of the presets shipped with the package."""
    folder = resources.files("maglev_match") / "presets"
    return sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith(".toml"))


def _preset_values(name: str) -> dict[str, Any]:
    if name not in available_presets():
        raise ParameterError("preset", name, "no such preset; available: "
                             + ", ".join(available_presets()))
    text = (resources.files("maglev_match") / "presets" / f"{name}.toml").read_text()
    return _flatten(tomllib.loads(text), f"preset '{name}'")


def load_toml(path: str | Path) -> dict[str, Any]:
    """Flat parameter values from a user TOML file (validated names, not yet values)."""
    path = Path(path)
    if not path.is_file():
        raise ParameterError("config", str(path), "file does not exist")
    try:
        doc = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise ParameterError("config", str(path), f"not valid TOML: {exc}") from None
    return _flatten(doc, str(path))


def load_preset(name: str = DEFAULT_PRESET) -> Params:
    """A shipped preset as a validated :class:`Params`."""
    return make_params(_preset_values(name))


def parse_assignment(text: str) -> tuple[str, float]:
    """Parse ``NAME=VALUE`` from the command line."""
    if "=" not in text:
        raise ParameterError("--set", text, "expected NAME=VALUE, e.g. kD=120")
    name, raw = (s.strip() for s in text.split("=", 1))
    if name not in FIELD_NAMES:
        raise ParameterError(name, raw, _unknown_rule())
    try:
        value: float = float(raw)
    except ValueError:
        raise ParameterError(name, raw, "must be a number") from None
    return name, value


def load_params(
    preset: str | None = DEFAULT_PRESET,
    config: str | Path | None = None,
    sets: list[str] | dict[str, float] | None = None,
) -> Params:
    """Preset, then a user TOML file, then NAME=VALUE overrides, each on top of the last."""
    values: dict[str, Any] = _preset_values(preset) if preset else {}
    if config is not None:
        values.update(load_toml(config))
    if sets:
        items = sets.items() if isinstance(sets, dict) else (parse_assignment(s) for s in sets)
        for name, v in items:
            if name not in FIELD_NAMES:
                raise ParameterError(name, v, _unknown_rule())
            values[name] = v
    return make_params(values)
