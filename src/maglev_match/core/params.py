"""Parameter sets for the levitation unit, the beam and the full vehicle.

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
import os
import stat
import tomllib
import warnings
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

__all__ = [
    "Params",
    "ParameterError",
    "refuse_delay",
    "ParameterWarning",
    "RANGES",
    "PARAMETER_DOCS",
    "valid_range",
    "param_ranges",
    "format_range",
    "available_presets",
    "load_params",
    "load_preset",
    "load_toml",
    "load_toml_table",
    "parse_assignment",
]

DEFAULT_PRESET = "turnout-soft"
SECTIONS = ("unit", "controller", "beam", "vehicle", "limits")
META_KEYS = ("name", "description", "base")
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
    "tau": ("s", "delay of the outer control loop (gap and velocity feedback act on observer "
            "outputs this old; 0: no delay)"),
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


# Finite ranges of the input values, [low, high] in SI units. They are wide (several orders
# of magnitude around every shipped preset) but keep every product and quotient the models
# form (forces K (i/c)^2, stiffnesses over masses, the levitation current) far inside double
# precision: beyond them values like m = 1e300 or c0 = 1e-300 overflow or underflow to
# inf/0 and the eigenvalue and ODE solvers see NaN. Zero is allowed where the lower bound is 0.
RANGES: dict[str, tuple[float, float]] = {
    "m": (1e-3, 1e7), "M": (1e-3, 1e7), "g": (1e-3, 1e3), "ks": (1e-6, 1e10),
    "cs": (0.0, 1e9), "mu0": (1e-9, 1e-3), "N": (1.0, 1e6), "A": (1e-8, 1e2),
    "c0": (1e-6, 1.0), "omega0": (1e-3, 1e6), "xi0": (1e-4, 1e3), "kP": (0.0, 1e8),
    "kD": (0.0, 1e7), "ke": (1e-6, 1e6), "L": (0.1, 1e4), "EI": (1e-3, 1e15),
    "mbar": (1e-3, 1e7), "l": (1e-2, 1e4), "k": (1, 10_000), "gap_max": (0.0, 1.0),
    "m_s": (1e-3, 1e8), "j_s": (1e-3, 1e10), "m_b": (1e-3, 1e8), "j_b": (1e-3, 1e10),
    "k2": (1e-6, 1e10), "c2": (0.0, 1e9), "s": (1e-4, 1e4), "s0": (0.0, 1e4),
    "tau": (0.0, 1.0),
}
# Sign rules of the inputs (checked first, with their own message).
POSITIVE = ("m", "M", "g", "ks", "mu0", "N", "A", "c0", "omega0", "xi0", "ke",
            "L", "EI", "mbar", "l", "k", "m_s", "j_s", "m_b", "j_b", "k2", "s")
NONNEGATIVE = ("cs", "c2", "kP", "kD", "s0", "gap_min", "tau")
#: the shortest delay of the outer loop other than 0 (s)
TAU_MIN = 1e-9
# Ranges of the values that may also be set directly (omega1, sigma) or have a rule of their
# own (xi1): the same rules as _validate_inputs states in words.
_SPECIAL_RANGES: dict[str, tuple[float, float]] = {
    "omega1": (math.ulp(0.0), 1e5),  # (0, 1e5] rad/s
    "sigma": (0.0, 0.1),  # [0, 0.1] 1/kg
    "xi1": (0.0, math.nextafter(1.0, 0.0)),  # [0, 1)
}


def valid_range(name: str) -> tuple[float, float] | None:
    """The closed interval [lo, hi] (SI units) in which the value of parameter ``name`` is
    valid, by the same rules :class:`Params` checks: the finite ranges of :data:`RANGES`,
    positive quantities (lo the smallest positive double: "> 0"), non-negative ones, a
    damping ratio in [0, 1), omega1 in (0, 1e5] rad/s, sigma in [0, 0.1] 1/kg. None for a
    name without a rule (e.g. gap_max's coupling to c0 is not a range of its own).

    Models declare these as their parameters' valid ranges
    (:attr:`maglev_match.dynamics.system.System.param_ranges`), so that a continuation or a
    Newton refinement that wanders out of them (e.g. to a negative beam frequency) stops
    and says so instead of reporting a converged but meaningless point."""
    if name in _SPECIAL_RANGES:
        return _SPECIAL_RANGES[name]
    lo, hi = RANGES.get(name, (-math.inf, math.inf))
    if name in POSITIVE:
        lo = max(lo, math.ulp(0.0))
    elif name in NONNEGATIVE:
        lo = max(lo, 0.0)
    if not (math.isfinite(lo) or math.isfinite(hi)):
        return None
    return (float(lo), float(hi))


def param_ranges(names) -> dict[str, tuple[float, float]]:
    """:func:`valid_range` of every name that has one (for a model's parameter vector)."""
    return {n: r for n in names if (r := valid_range(n)) is not None}


def format_range(lo: float, hi: float) -> str:
    """A valid range in words: '(0, 1e+05]' for a positive quantity, '[0, 0.1]', ..."""
    left = "(0" if lo == math.ulp(0.0) else f"[{lo:g}"
    right = "1)" if hi == math.nextafter(1.0, 0.0) else f"{hi:g}]"
    return f"{left}, {right}"


# Inputs from which each derived value is computed (named in its error message).
DERIVED_FROM: dict[str, tuple[str, ...]] = {
    "omega1": ("L", "EI", "mbar"),
    "sigma": ("k", "L", "l", "mbar"),
    "w0": ("sigma", "m", "M", "g", "omega1"),
    "i0": ("c0", "N", "m", "M", "g", "mu0", "A"),
}
# Largest static deflection accepted, as a fraction of the span: the beam model is linear
# (Euler-Bernoulli), valid for deflections small against the span.
W0_MAX_FRACTION = 0.1
I0_MAX = 1e5  # A: the levitation current of one unit (a coil carries tens of amperes)
# Limits on user TOML files: size, nesting depth.
CONFIG_MAX_BYTES = 1_000_000
CONFIG_MAX_DEPTH = 8


class ParameterWarning(UserWarning):
    """A parameter combination that is valid but probably not what the user meant (e.g. a
    beam value given while omega1 is set explicitly and so does not depend on it)."""


class ParameterError(ValueError):
    """Invalid user input: names the field, the offending value and the rule it breaks."""

    def __init__(self, field_name: str, value: Any, rule: str):
        self.field = field_name
        self.value = value
        self.rule = rule
        name = str(field_name)
        if not name.isprintable():  # invisible characters shown as escapes, and said
            name = repr(name)[1:-1]
            rule = f"{rule} (the name contains invisible characters, shown escaped)"
        super().__init__(f"parameter '{name}' = {value!r}: {rule}")


def refuse_delay(params: Params, what: str) -> None:
    """``what`` is computed for the delay-free models only: a parameter set with a delay
    (tau > 0) is refused, naming tau, before any work."""
    if params.tau > 0:
        raise ParameterError("tau", params.tau, f"{what} are computed for the delay-free "
                             "models only: set tau = 0 (the delay itself is studied with "
                             "stability, hopf --param tau and index)")


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
    tau: float = 0.0  # delay of the outer loop (s); 0 gives the delay-free models exactly
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
            raise ParameterError(f.name, _short(v), "must be a number")
        try:
            finite = math.isfinite(v)
        except OverflowError:  # an int too large for a float (e.g. 401 digits in TOML)
            finite = False
        if not finite:
            raise ParameterError(f.name, _short(v), "must be a finite number")
    for n in INTEGER_FIELDS:
        v = getattr(p, n)
        if float(v) != int(v):
            raise ParameterError(n, v, "must be a whole number")
    _positive(p, *POSITIVE)
    _nonnegative(p, *NONNEGATIVE)
    if 0 < p.tau < TAU_MIN:
        raise ParameterError("tau", p.tau, f"must be 0 (no delay) or at least {TAU_MIN:g} s: a "
                             "shorter delay is far below the model's time scales, and its "
                             "discretisation (entries ~ 1/tau) loses accuracy and, further "
                             "down, overflows")
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
    for name, (lo, hi) in RANGES.items():
        v = getattr(p, name)
        if v is not None and not lo <= v <= hi:
            unit = PARAMETER_DOCS[name][0]
            raise ParameterError(
                name, v, f"must lie in [{lo:g}, {hi:g}] {unit} (the range in which the "
                "model's arithmetic stays finite and physical)",
            )


def _short(v: Any) -> Any:
    """A value for an error message: long texts and huge integers cut to a readable size."""
    text = repr(v)
    if len(text) <= 60:
        return v
    return text[:40] + f"... ({len(text)} characters)"


def _from(p: Params, name: str) -> str:
    parts = []
    for n in DERIVED_FROM[name]:
        unit = PARAMETER_DOCS[n][0]
        parts.append(f"{n} = {float(getattr(p, n)):.4g}" + (f" {unit}" if unit != "-" else ""))
    return ", ".join(parts)


def _validate_derived(p: Params) -> None:
    """Derived values (omega1, sigma from the beam; w0; i0) against their rules, naming the
    inputs they came from."""
    if "omega1" not in p.explicit and not 0 < p.omega1 <= 1e5:  # type: ignore[operator]
        raise ParameterError(
            "omega1", p.omega1, f"derived from {_from(p, 'omega1')}; must lie in (0, 1e5] "
            "rad/s: change these beam values or set omega1 directly",
        )
    if "sigma" not in p.explicit and not 0 <= p.sigma <= 0.1:  # type: ignore[operator]
        raise ParameterError(
            "sigma", p.sigma, f"derived from {_from(p, 'sigma')}; must lie in [0, 0.1] 1/kg: "
            "change these values or set sigma directly",
        )
    try:
        w0 = p.w0
    except (ZeroDivisionError, OverflowError):
        w0 = math.inf
    w0_max = W0_MAX_FRACTION * p.L
    if not 0 <= w0 <= w0_max:
        raise ParameterError(
            "w0", w0, f"the static deflection sigma (m+M) g / omega1^2, from {_from(p, 'w0')}, "
            f"must lie in [0, {w0_max:g}] m ({W0_MAX_FRACTION:g} L: the beam model is linear)",
        )
    try:
        i0 = p.i0
    except (ZeroDivisionError, OverflowError, ValueError):
        i0 = math.inf
    if not 0 < i0 <= I0_MAX:
        raise ParameterError(
            "i0", i0, f"the levitation current, from {_from(p, 'i0')}, must lie in "
            f"(0, {I0_MAX:g}] A",
        )
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


def _flatten(doc: dict[str, Any], source: str, skip: tuple[str, ...] = ()) -> dict[str, Any]:
    flat: dict[str, Any] = {}
    for key, value in doc.items():
        if key in META_KEYS or key in skip:
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


@dataclass(frozen=True)
class PresetInfo:
    """What a shipped preset is: its description, the preset it derives from (``base``,
    None for a root preset) and the values it changes relative to that base, as
    name -> (base value, this preset's value); derived values (omega1, sigma, w0) compare
    as computed."""

    name: str
    description: str
    base: str | None
    changes: dict[str, tuple[float, float]]


def preset_info(name: str) -> PresetInfo:
    """The :class:`PresetInfo` of a shipped preset (its TOML keys ``description`` and
    ``base``)."""
    if name not in available_presets():
        raise ParameterError("preset", name, "no such preset; available: "
                             + ", ".join(available_presets()))
    doc = tomllib.loads((resources.files("maglev_match") / "presets" / f"{name}.toml")
                        .read_text())
    base = doc.get("base")
    changes: dict[str, tuple[float, float]] = {}
    if base is not None:
        a, b = load_preset(base), load_preset(name)
        for key in [*FIELD_NAMES, "w0"]:
            if key == "explicit":
                continue
            va, vb = getattr(a, key), getattr(b, key)
            if isinstance(va, int | float) and isinstance(vb, int | float) and not (
                    math.isclose(float(va), float(vb), rel_tol=1e-12, abs_tol=0.0)):
                changes[key] = (float(va), float(vb))
    return PresetInfo(name=name, description=str(doc.get("description", "")),
                      base=base, changes=changes)


def load_toml(path: str | Path) -> dict[str, Any]:
    """Flat parameter values from a user TOML file (validated names, not yet values).

    The file must be a regular file of at most :data:`CONFIG_MAX_BYTES` bytes of UTF-8 text,
    nested at most :data:`CONFIG_MAX_DEPTH` levels deep; anything else (a folder, a device
    such as /dev/null, a FIFO, binary or UTF-16 data) is a :class:`ParameterError`.
    The ``[irregularity]`` table (:data:`CONFIG_TABLES`) is not a parameter: the commands
    at speed read it (:func:`load_toml_table`), the others leave it alone.
    """
    return _flatten(_read_toml(path), str(path), skip=CONFIG_TABLES)


#: Tables of a user TOML file that are inputs of some commands, not parameters: the guideway
#: irregularity of `speed` and `simulate --speed` (maglev_match.maglev.irregularity).
CONFIG_TABLES = ("irregularity",)


def load_toml_table(path: str | Path, name: str) -> Any:
    """The raw value of the top-level key ``name`` (one of :data:`CONFIG_TABLES`) of a
    user TOML file, None if absent; the file is checked as by :func:`load_toml`, its
    parameters included."""
    doc = _read_toml(path)
    _flatten(doc, str(path), skip=CONFIG_TABLES)
    return doc.get(name)


def _read_toml(path: str | Path) -> dict[str, Any]:
    path = Path(path)
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise ParameterError("config", str(path), "file does not exist") from None
    except OSError as exc:
        raise ParameterError("config", str(path), f"cannot be read: {exc.strerror}") from None
    if stat.S_ISDIR(st.st_mode):
        raise ParameterError("config", str(path), "is a folder; give a TOML file")
    if not stat.S_ISREG(st.st_mode):
        raise ParameterError("config", str(path), "is not a regular file (a device, FIFO or "
                             "socket); give a TOML file")
    if st.st_size > CONFIG_MAX_BYTES:
        raise ParameterError("config", str(path), f"is {st.st_size} bytes; a parameter file "
                             f"has at most {CONFIG_MAX_BYTES} bytes")
    try:
        with open(path, "rb") as fh:
            raw = fh.read(CONFIG_MAX_BYTES + 1)
    except OSError as exc:
        raise ParameterError("config", str(path), f"cannot be read: {exc.strerror}") from None
    if len(raw) > CONFIG_MAX_BYTES:
        raise ParameterError("config", str(path), f"a parameter file has at most "
                             f"{CONFIG_MAX_BYTES} bytes")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ParameterError("config", str(path), f"is not UTF-8 text (byte {exc.start}); "
                             "save it as UTF-8") from None
    if "\x00" in text:
        raise ParameterError("config", str(path), "contains NUL bytes: not a text file")
    depth = _max_nesting(text)
    if depth > CONFIG_MAX_DEPTH:
        raise ParameterError("config", str(path), f"nested {depth} levels deep; at most "
                             f"{CONFIG_MAX_DEPTH} are allowed")
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ParameterError("config", str(path), f"not valid TOML: {exc}") from None
    except RecursionError:
        raise ParameterError("config", str(path), "nested too deeply") from None
    return doc


def _max_nesting(text: str) -> int:
    """Upper bound of the bracket nesting depth of a TOML text (brackets inside strings are
    counted too, so this can over-estimate; used only to refuse absurd nesting before the
    recursive parser sees it)."""
    depth = best = 0
    for ch in text:
        if ch in "[{":
            depth += 1
            best = max(best, depth)
        elif ch in "]}":
            depth = max(0, depth - 1)
    return best


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
        raise ParameterError(name, _short(raw), "must be a number") from None
    return name, value


def load_params(
    preset: str | None = DEFAULT_PRESET,
    config: str | Path | None = None,
    sets: list[str] | dict[str, float] | None = None,
) -> Params:
    """Preset, then a user TOML file, then NAME=VALUE overrides, each on top of the last."""
    values: dict[str, Any] = _preset_values(preset) if preset else {}
    user: set[str] = set()
    if config is not None:
        from_file = load_toml(config)
        values.update(from_file)
        user |= set(from_file)
    if sets:
        items = sets.items() if isinstance(sets, dict) else (parse_assignment(s) for s in sets)
        for name, v in items:
            if name not in FIELD_NAMES:
                raise ParameterError(name, v, _unknown_rule())
            values[name] = v
            user.add(name)
    params = make_params(values)
    warn_overridden(params, user)
    return params


def warn_overridden(params: Params, given: set[str] | frozenset[str]) -> None:
    """Warn (:class:`ParameterWarning`) when the user gave beam values that an explicitly set
    omega1 or sigma makes irrelevant: e.g. ``--set omega1=100 --set EI=3e10`` keeps
    omega1 = 100 whatever EI is."""
    for derived in ("omega1", "sigma"):
        if derived not in params.explicit:
            continue
        ignored = [n for n in DERIVED_FROM[derived] if n in given]
        if ignored:
            shown = ", ".join(f"{n} = {getattr(params, n):g}" for n in ignored)
            warnings.warn(
                f"{derived} = {getattr(params, derived):g} is set explicitly, so {shown} "
                f"does not change it ({derived} derives from "
                f"{', '.join(DERIVED_FROM[derived])} only when it is not set)",
                ParameterWarning, stacklevel=2,
            )
