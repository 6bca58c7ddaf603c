"""Vertical guideway irregularities for the models at speed (physics and input only).

A profile z_r(x) (m, downward positive like the beam deflection; x in m along the guideway,
measured from the first span's left support, negative on the approach) is added to the
beam's deflection under every levitation point: the gap becomes c = c0 + u - w - z_r, the
same profile under every point, delayed by their spacing. The unit (whose load is the
vehicle's k units spread over its length l) sees the mean of z_r over its footprint, as it
sees the mean deflection.

Every profile is a sum of two parts, which the vector field evaluates in closed form:

* a spectral part sum_k a_k cos(kappa_k x + phi_k) over the whole guideway (the sinusoid:
  one wave; the random profile: many);
* a part per span: on span n (1-based; 0 is the approach, spans + 1 the ground after the
  last span), z = c0_n + c1_n xi + c2_n xi^2 with xi the distance from the span's left
  support (joint steps, support settlement, pre-camber).

Kinds (:func:`parse_irregularity`):

``sine:wavelength=W,amplitude=A``
    z = A sin(2 pi x / W).
``joint:step=S``
    every span S lower than the one before (a step S at every joint, the approach at 0):
    z = S n on span n. Its mean slope S / L is a gradient the vehicle follows; what it feels
    repeats every span.
``settlement:depth=S[,support=J]``
    support J (0 .. spans; default the middle one) lowered by S; the spans either side
    tilted (rigid ground beyond the abutments).
``camber:amplitude=A``
    every span curved upward, a parabola with A at mid-span and 0 at the supports.
``random:class=low|high[,seeds=N][,seed0=K][,lmin=..][,lmax=..][,waves=..]``
    a stationary Gaussian profile with the German high-speed track spectrum
    (:data:`PSD_CLASSES`), drawn by a spectral sum with seeded random phases over the
    wavelength band [lmin, lmax] (m).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from maglev_match.core import jax_setup  # noqa: F401  (float64 on)
from maglev_match.core.params import ParameterError, load_toml_table

__all__ = ["Irregularity", "PSD_CLASSES", "parse_irregularity", "target_psd",
           "irregularity_from_table", "irregularity_in_config",
           "PROFILE_NAMES", "profile_names", "profile_under", "KINDS"]

KINDS = ("sine", "joint", "settlement", "camber", "random")

#: The German high-speed track spectrum of the vertical profile (one-sided, in the spatial
#: circular frequency Omega, rad/m): S(Omega) = A Omega_c^2 / ((Omega^2 + Omega_r^2)
#: (Omega^2 + Omega_c^2)) m^2/(rad/m), Omega_c = 0.8246 rad/m, Omega_r = 0.0206 rad/m,
#: A = 4.032e-7 m rad ("low": low interference) or 1.080e-6 m rad ("high": high
#: interference). Variance = integral over Omega > 0.
PSD_CLASSES = {"low": 4.032e-7, "high": 1.080e-6}
OMEGA_C = 0.8246
OMEGA_R = 0.0206

#: The per-span and spectral entries appended to a model's parameter vector.
PROFILE_NAMES = ("x_origin", "zA0", "zA1", "zA2", "zB0", "zB1", "zB2")


def profile_names(waves: int) -> tuple[str, ...]:
    """The names of the profile's entries of the parameter vector: :data:`PROFILE_NAMES`,
    then per wave a_k cos(phi_k), kappa_k and a_k sin(phi_k)."""
    return PROFILE_NAMES + tuple(f"wave_{q}_{k + 1}" for q in ("a_cos", "kappa", "a_sin")
                                 for k in range(waves))


def target_psd(omega, cls: str) -> np.ndarray:
    """The one-sided PSD S(Omega) (m^2 / (rad/m)) of the class at Omega (rad/m)."""
    A = PSD_CLASSES[cls]
    w = np.asarray(omega, float)
    return A * OMEGA_C**2 / ((w**2 + OMEGA_R**2) * (w**2 + OMEGA_C**2))


@dataclass(frozen=True)
class Irregularity:
    """A guideway irregularity (see the module docstring). Lengths in m."""

    kind: str
    amplitude: float = 0.0  # sine, camber (m); joint step; settlement depth
    wavelength: float = 0.0  # sine (m)
    support: int | None = None  # settlement: the lowered support (0 .. spans)
    cls: str = "low"  # random
    seeds: int = 1
    seed0: int = 0
    lmin: float = 2.0
    lmax: float = 200.0
    waves: int = 400
    text: str = field(default="", compare=False)
    #: where it was given, the prefix of the field in an error: '--irregularity' or
    #: 'FILE [irregularity]' (a --config TOML file)
    source: str = field(default="--irregularity", compare=False)

    @property
    def n_waves(self) -> int:
        return self.waves if self.kind == "random" else 1

    @property
    def seed_list(self) -> tuple[int, ...]:
        return tuple(range(self.seed0, self.seed0 + (self.seeds if self.kind == "random" else 1)))

    def describe(self) -> str:
        if self.kind == "sine":
            return (f"sinusoid, wavelength {self.wavelength:g} m, amplitude "
                    f"{self.amplitude * 1e3:g} mm")
        if self.kind == "joint":
            return f"a step of {self.amplitude * 1e3:g} mm at every span joint"
        if self.kind == "settlement":
            return f"support {self.support if self.support is not None else 'middle'} " \
                   f"lowered by {self.amplitude * 1e3:g} mm"
        if self.kind == "camber":
            return f"pre-camber {self.amplitude * 1e3:g} mm at mid-span"
        return (f"random, German track spectrum '{self.cls}' (A = {PSD_CLASSES[self.cls]:g} "
                f"m rad), wavelengths {self.lmin:g} to {self.lmax:g} m, {self.waves} waves, "
                f"seeds {self.seed0}..{self.seed0 + self.seeds - 1}")

    def band(self) -> tuple[float, float]:
        """(Omega_min, Omega_max) rad/m of the random profile."""
        return 2 * math.pi / self.lmax, 2 * math.pi / self.lmin

    def wave_vectors(self, seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(amplitudes a_k (m), wavenumbers kappa_k (rad/m), phases phi_k) of the spectral
        part: z = sum a_k cos(kappa_k x + phi_k). The random profile: Omega_k the midpoints
        of ``waves`` equal bands dOmega over the band, a_k = sqrt(2 S(Omega_k) dOmega)
        (so that the variance is the integral of S over the band), phi_k uniform on
        [0, 2 pi) from numpy's PCG64 generator seeded with ``seed``."""
        if self.kind == "sine":
            return (np.array([self.amplitude]), np.array([2 * math.pi / self.wavelength]),
                    np.array([-math.pi / 2]))
        if self.kind != "random":
            return np.zeros(1), np.ones(1), np.zeros(1)
        lo, hi = self.band()
        d = (hi - lo) / self.waves
        om = lo + d * (np.arange(self.waves) + 0.5)
        phase = np.random.default_rng(int(seed)).uniform(0.0, 2 * math.pi, self.waves)
        return np.sqrt(2.0 * target_psd(om, self.cls) * d), om, phase

    def span_poly(self, n: int, spans: int, L: float) -> np.ndarray:
        """(c0, c1, c2) of span n (0: the approach; spans + 1: the ground after)."""
        a = self.amplitude
        if self.kind == "joint":
            return np.array([a * max(n, 0), 0.0, 0.0])
        if self.kind == "camber" and 1 <= n <= spans:
            return np.array([0.0, -4.0 * a / L, 4.0 * a / L**2])
        if self.kind == "settlement":
            j = spans // 2 if self.support is None else self.support
            if n == j and 1 <= n <= spans:
                return np.array([0.0, a / L, 0.0])
            if n == j + 1 and 1 <= n <= spans:
                return np.array([a, -a / L, 0.0])
        return np.zeros(3)

    def vector(self, passage: int, spans: int, L: float, seed: int) -> np.ndarray:
        """The profile entries of the parameter vector during passage ``passage`` (1-based:
        slot A is span passage - 1, slot B span passage): x_origin, the two slots'
        polynomials, then a_k cos(phi_k), kappa_k, a_k sin(phi_k) (the phases enter as
        these products, so that the vector field needs no sine or cosine of them)."""
        amp, kap, ph = self.wave_vectors(seed)
        return np.concatenate([[(passage - 2) * L], self.span_poly(passage - 1, spans, L),
                               self.span_poly(passage, spans, L), amp * np.cos(ph), kap,
                               amp * np.sin(ph)])

    def zero_vector(self) -> np.ndarray:
        w = self.n_waves
        return np.concatenate([np.zeros(7), np.zeros(w), np.ones(w), np.zeros(w)])

    def profile(self, x, spans: int, L: float, seed: int) -> np.ndarray:
        """z_r at the positions x (m) (numpy, for figures and checks)."""
        x = np.asarray(x, float)
        amp, kap, ph = self.wave_vectors(seed)
        z = np.cos(np.multiply.outer(x, kap) + ph) @ amp
        n = np.floor(x / L).astype(int) + 1
        n = np.where(x < 0, 0, np.minimum(n, spans + 1))
        c = np.array([self.span_poly(int(k), spans, L) for k in n])
        xi = x - (n - 1) * L
        return z + c[:, 0] + c[:, 1] * xi + c[:, 2] * xi**2

    def check(self, spans: int | None = None, dx_resolved: float | None = None):
        """Validate (ParameterError naming field, value, rule). ``dx_resolved``: the
        shortest wavelength (m) the sampling of the runs resolves at the speed."""
        for name, val in (("amplitude", self.amplitude), ("wavelength", self.wavelength),
                          ("lmin", self.lmin), ("lmax", self.lmax)):
            if not math.isfinite(val):
                raise ParameterError(f"{self.source} {name}", val, "must be finite")
            if val < 0:
                raise ParameterError(f"{self.source} {name}", val, "must be >= 0")
        if self.kind == "sine" and not self.wavelength > 0:
            raise ParameterError(f"{self.source} wavelength", self.wavelength, "must be > 0")
        if self.kind == "random":
            if not 0 < self.lmin < self.lmax:
                raise ParameterError(f"{self.source} lmin", self.lmin,
                                     f"must be > 0 and below lmax = {self.lmax:g} m")
            if not 1 <= self.waves <= 5000:
                raise ParameterError(f"{self.source} waves", self.waves,
                                     "must be a whole number from 1 to 5000")
            if not 1 <= self.seeds <= 1000:
                raise ParameterError(f"{self.source} seeds", self.seeds,
                                     "must be a whole number from 1 to 1000")
            if self.seed0 < 0:
                raise ParameterError(f"{self.source} seed0", self.seed0, "must be >= 0")
        if self.kind == "settlement" and spans is not None and self.support is not None \
                and not 0 <= self.support <= spans:
            raise ParameterError(f"{self.source} support", self.support,
                                 f"must be a support of the guideway, 0 to {spans}")
        if dx_resolved is not None:
            short = self.wavelength if self.kind == "sine" else (
                self.lmin if self.kind == "random" else None)
            if short is not None and short < dx_resolved:
                field_ = "wavelength" if self.kind == "sine" else "lmin"
                raise ParameterError(f"{self.source} {field_}", short,
                                     f"is shorter than the {dx_resolved:.4g} m the sampling "
                                     "resolves at this speed (8 samples per wavelength)")
        return self


_FIELDS = {
    "sine": {"wavelength": "wavelength", "amplitude": "amplitude"},
    "joint": {"step": "amplitude"},
    "settlement": {"depth": "amplitude", "support": "support"},
    "camber": {"amplitude": "amplitude"},
    "random": {"class": "cls", "seeds": "seeds", "seed0": "seed0", "lmin": "lmin",
               "lmax": "lmax", "waves": "waves"},
}
_REQUIRED = {"sine": ("wavelength", "amplitude"), "joint": ("step",),
             "settlement": ("depth",), "camber": ("amplitude",), "random": ("class",)}
_INTS = ("seeds", "seed0", "waves", "support")


def parse_irregularity(text: str | Irregularity | None) -> Irregularity | None:
    """``KIND:NAME=VALUE,...`` (lengths in m) to an :class:`Irregularity` (None for None or
    ''). Raises ParameterError naming the field, the value and the rule."""
    if text is None or isinstance(text, Irregularity):
        return text
    s = str(text).strip()
    if not s:
        return None
    kind, _, rest = s.partition(":")
    items = []
    for item in (r for r in rest.split(",") if r.strip()):
        name, eq, value = item.partition("=")
        items.append((name.strip().lower(), value.strip(), item.strip(), bool(eq)))
    return _build(kind.strip().lower(), items, s, "--irregularity", s)


def irregularity_from_table(table: Any, source: str = "[irregularity]") -> Irregularity:
    """The ``[irregularity]`` table of a TOML config (``kind = "sine"``, then the fields of
    that kind by the names of the command line: ``wavelength = 25.0``, ``amplitude =
    1e-3``, ``class = "low"``, ``seeds = 2`` ...) to an :class:`Irregularity`, through the
    same checks as ``--irregularity`` (:func:`parse_irregularity`); ``source`` names the
    table in errors. Its ``text`` is the equivalent ``KIND:NAME=VALUE,...``. A one-entry
    array of tables (``[[irregularity]]``) is taken as that entry; a run has one profile."""
    if isinstance(table, list):
        if len(table) != 1:
            raise ParameterError(source, f"{len(table)} entries",
                                 "a run takes one guideway irregularity; give one table")
        table = table[0]
    if not isinstance(table, dict):
        raise ParameterError(source, _short(table), "must be a table: [irregularity] with "
                             "kind = \"...\" and the fields of that kind")
    if "kind" not in table:
        raise ParameterError(f"{source} kind", None, "missing; the kind must be one of "
                             + ", ".join(KINDS))
    kind = table["kind"]
    if not isinstance(kind, str):
        raise ParameterError(f"{source} kind", _short(kind), "must be a string, one of "
                             + ", ".join(KINDS))
    items = [(str(k).strip().lower(), v, None, True) for k, v in table.items() if k != "kind"]
    text = kind.strip().lower() + ":" + ",".join(f"{k}={v}" for k, v, _, _ in items)
    return _build(kind.strip().lower(), items, text, source, _short(dict(table)))


def irregularity_in_config(config: str | Path | None) -> Irregularity | None:
    """The guideway irregularity of a user TOML file's ``[irregularity]`` table (None
    without a file or a table)."""
    if config is None:
        return None
    table = load_toml_table(config, "irregularity")
    if table is None:
        return None
    return irregularity_from_table(table, f"{config} [irregularity]")


def _short(value: Any) -> Any:
    r = repr(value)
    return value if len(r) <= 80 else r[:77] + "..."


def _build(kind: str, items: list, text: str, source: str, whole: Any) -> Irregularity:
    """The one validation of a profile given as (kind, [(name, value, the item as typed,
    whether it had a value)]): values are strings from the command line or TOML values
    from a config file; ``source`` prefixes the field in errors."""
    if kind not in _FIELDS:
        raise ParameterError(source if source == "--irregularity" else f"{source} kind",
                             whole if source == "--irregularity" else kind,
                             "the kind must be one of " + ", ".join(KINDS)
                             + (" (KIND:NAME=VALUE,...)" if source == "--irregularity"
                                else ""))
    vals: dict = {}
    for name, value, raw, has_value in items:
        if not has_value or name not in _FIELDS[kind]:
            takes = ", ".join((f"{n}=VALUE" if source == "--irregularity" else n)
                              for n in _FIELDS[kind])
            if source == "--irregularity":
                raise ParameterError(source, raw, f"'{kind}' takes {takes}")
            raise ParameterError(f"{source} {name}", _short(value),
                                 f"unknown field: '{kind}' takes kind, {takes}")
        attr = _FIELDS[kind][name]
        if attr == "cls":
            if not isinstance(value, str) or value not in PSD_CLASSES:
                raise ParameterError(f"{source} class", _short(value),
                                     "must be one of " + ", ".join(PSD_CLASSES))
            vals[attr] = value
        elif name in _INTS:
            if isinstance(value, int) and not isinstance(value, bool):
                vals[attr] = value
                continue
            try:
                if not isinstance(value, str):
                    raise ValueError
                vals[attr] = int(value)
            except ValueError:
                raise ParameterError(f"{source} {name}", _short(value),
                                     "must be a whole number") from None
        else:
            if isinstance(value, int | float) and not isinstance(value, bool):
                vals[attr] = float(value)
                continue
            try:
                if not isinstance(value, str):
                    raise ValueError
                vals[attr] = float(value)
            except ValueError:
                raise ParameterError(f"{source} {name}", _short(value),
                                     "must be a number (m)") from None
    for need in _REQUIRED[kind]:
        if _FIELDS[kind][need] not in vals:
            if source == "--irregularity":
                raise ParameterError(source, text, f"'{kind}' needs {need}=VALUE")
            raise ParameterError(f"{source} {need}", None, f"missing: '{kind}' needs {need}")
    return Irregularity(kind=kind, text=text, source=source, **vals).check()


# ---------------------------------------------------------------------------------------
# the profile under the loads, in the vector field (JAX)
# ---------------------------------------------------------------------------------------
def _poly_integral(c, a, b):
    def P(x):
        return c[0] * x + c[1] * x**2 / 2 + c[2] * x**3 / 3

    return P(b) - P(a)


def _poly_value(c, x):
    return c[0] + c[1] * x + c[2] * x**2


#: up to this many waves the spectral sum is evaluated term by term; above, blocked
#: (:func:`_wave_sum`)
DIRECT_WAVES = 16


def _wave_sum(x, ca, kap, sa):
    """(sum_k a_k cos(kappa_k x + phi_k), sum_k a_k sin(kappa_k x + phi_k)) at the
    positions x (n,), from ca = a cos(phi), sa = a sin(phi) and equally spaced wavenumbers
    kappa_k = kappa_0 + k d (the random profile's band midpoints; one wave for the
    sinusoid). Above :data:`DIRECT_WAVES` waves the sum is blocked: with k = m B + j
    (B about sqrt(N)), exp(i kappa_k x) = exp(i (kappa_0 + m B d) x) exp(i j d x), so the
    N terms need the sines and cosines of B + M angles instead of N (the same sum, rounded
    differently: each angle is still computed directly, not by repeated multiplication).
    ``ca`` and ``sa`` hold S sets of coefficients (S, N) (the profile and its rate, say);
    the sums are (S, n) each, the sines and cosines shared by the sets."""
    n_w = kap.shape[0]
    if n_w <= DIRECT_WAVES:
        ang = kap[None, :] * x[:, None]
        c, s = jnp.cos(ang)[None], jnp.sin(ang)[None]  # (1, n, N)
        cs, ss = ca[:, None, :], sa[:, None, :]
        return jnp.sum(c * cs - s * ss, axis=2), jnp.sum(s * cs + c * ss, axis=2)
    B = math.isqrt(n_w - 1) + 1
    M = -(-n_w // B)
    pad = M * B - n_w
    d = (kap[-1] - kap[0]) / (n_w - 1)
    S, n = ca.shape[0], x.shape[0]
    cr = jnp.pad(ca, ((0, 0), (0, pad))).reshape(S * M, B)
    ci = jnp.pad(sa, ((0, 0), (0, pad))).reshape(S * M, B)
    aj = (d * x)[:, None] * jnp.arange(B)[None, :]  # (n, B)
    am = x[:, None] * (kap[0] + (B * d) * jnp.arange(M))[None, :]  # (n, M)
    # sum over j of c_smj exp(i j d x), real and imaginary parts, as one matrix product
    # (n, 2B) @ (2B, 2SM): one call instead of one per part and set
    e = jnp.concatenate([jnp.cos(aj), jnp.sin(aj)], axis=1)
    C = jnp.concatenate([jnp.concatenate([cr, ci], axis=0),
                         jnp.concatenate([-ci, cr], axis=0)], axis=1)
    sm = jnp.dot(e, C.T).reshape(n, 2, S, M)
    sr, si = sm[:, 0], sm[:, 1]  # (n, S, M)
    emr, emi = jnp.cos(am)[:, None, :], jnp.sin(am)[:, None, :]
    return jnp.sum(emr * sr - emi * si, axis=2).T, jnp.sum(emr * si + emi * sr, axis=2).T


def profile_under(t, p_kin, p_prof, lay_front, lay_length, L, waves: int, point: bool):
    """(z_r, dz_r/dt) (n_loads,) under each load at passage time t: the profile at each
    point load, or its mean over each spread load's footprint. The spectral sum's rate
    comes in closed form from the same sines and cosines (d/dt exp(i kappa x) =
    i kappa v exp(i kappa x)), the span pieces' rate by forward differentiation."""
    v, x_front = p_kin[0], p_kin[1]
    n_loads = lay_front.shape[0]
    fb = p_kin[4:4 + n_loads]
    rb = p_kin[4 + n_loads:4 + 2 * n_loads]
    x0 = p_prof[0]
    cA, cB = p_prof[1:4], p_prof[4:7]
    ca = p_prof[7:7 + waves]
    kap = p_prof[7 + waves:7 + 2 * waves]
    sa = p_prof[7 + 2 * waves:7 + 3 * waves]

    def front(tt):
        return x_front + v * tt + lay_front  # local to slot A

    xf = front(t)
    if point:
        # z = Re sum c e^{i kappa x}; dz/dt = -v Im sum kappa c e^{i kappa x}
        re, im = _wave_sum(x0 + xf, jnp.stack([ca, kap * ca]), kap, jnp.stack([sa, kap * sa]))

        def piece(tt):
            x = front(tt)
            return jnp.where(fb > 0.5, _poly_value(cB, x - L), _poly_value(cA, x))

        pz, pzd = jax.jvp(piece, (t,), (jnp.ones_like(t),))
        return re[0] + pz, -v * im[1] + pzd
    # the mean over the footprint: sum_k a_k (sin(kappa_k xf + phi_k) - sin(kappa_k xr +
    # phi_k)) / kappa_k / lay_length; its rate v sum_k a_k (cos(kappa_k xf + phi_k) -
    # cos(kappa_k xr + phi_k)) / lay_length
    n = xf.shape[0]
    re, im = _wave_sum(jnp.concatenate([x0 + xf, x0 + xf - lay_length]),
                       jnp.stack([ca / kap, ca]), kap, jnp.stack([sa / kap, sa]))
    spec = (im[0, :n] - im[0, n:]) / lay_length
    spec_rate = v * (re[1, :n] - re[1, n:]) / lay_length

    def piece(tt):
        xf = front(tt)
        xr = xf - lay_length
        a_a, b_a = xr, jnp.where(fb > 0.5, L, xf)
        a_b, b_b = jnp.where(rb > 0.5, xr - L, 0.0), xf - L
        ia = jnp.where(rb > 0.5, 0.0, _poly_integral(cA, a_a, b_a))
        ib = jnp.where(fb > 0.5, _poly_integral(cB, a_b, b_b), 0.0)
        return (ia + ib) / lay_length

    pz, pzd = jax.jvp(piece, (t,), (jnp.ones_like(t),))
    return spec + pz, spec_rate + pzd

