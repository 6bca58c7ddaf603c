"""Ride comfort: Sperling's ride index Wz for vertical vibration.

Sperling's index (Sperling & Betzhold 1956, "Beitrag zur Beurteilung des Fahrkomforts in
Schienenfahrzeugen", Glasers Annalen 80; in English in Garg & Dukkipati, *Dynamics of
railway vehicle systems*, Academic Press 1984, ch. 12) rates a sinusoidal vibration of
acceleration amplitude a (cm/s^2) and frequency f (Hz) as::

    Wz = 0.896 (a^3 F(f) / f)^(1/10)

with the frequency correction factor F(f) for *vertical* vibration (the table of Sperling
and Betzhold, as given by Garg & Dukkipati)::

    F(f) = 0.325 f^2     for 0.5 <= f < 5.9 Hz
    F(f) = 400 / f^2     for 5.9 <= f < 20 Hz
    F(f) = 1             for 20 <= f <= 30 Hz

The table starts at 0.5 Hz. Lines below it are rated here with the same 0.325 f^2 law
(their weight vanishes as f -> 0) instead of being dropped: at speed the span-passing
frequency v / L sweeps through 0.5 Hz, and dropping a line there made the index jump where
nothing physical changes (on an 18 m span at 30 and 35 km/h, 0.46 and 0.54 Hz, both next to
the car body's 0.5 Hz mode). Lines above 30 Hz are left out.

Sperling's original statement uses the displacement amplitude z (cm) instead,
Wz = 2.7 (z^3 f^5 F(f))^(1/10); with a = (2 pi f)^2 z the two are the same formula, since
0.896 (2 pi)^(6/10) = 2.70. A vibration made of several frequencies is rated by the
10th-power sum of the ratings of its spectral lines, Wz = (sum_i Wz_i^10)^(1/10) (same
sources).

Reading (Sperling's scale): 1 just noticeable; 2 clearly noticeable; 2.5 more pronounced but
not unpleasant; 3 strong, irregular, but still tolerable; 3.25 very irregular; 3.5 extremely
irregular, unpleasant, annoying, prolonged exposure intolerable; 4 extremely unpleasant,
prolonged exposure harmful.

For a periodic signal the spectral lines are exact: the acceleration of a periodic response
of period T sampled at N equally spaced times over one period has the lines f_k = k / T with
amplitudes 2 |X_k| / N (X the discrete Fourier transform), exactly for a band-limited signal
(:func:`sperling_of_periodic`).
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "F_MIN",
    "F_MAX",
    "sperling_weighting",
    "sperling_line",
    "sperling_of_lines",
    "sperling_of_periodic",
    "sperling_reading",
]

F_MIN = 0.5  # Hz, lowest frequency of the weighting table (lines below: same f^2 law)
F_MAX = 30.0  # Hz, highest frequency rated
CM = 100.0  # cm per m

SCALE = ((1.0, "just noticeable"), (2.0, "clearly noticeable"),
         (2.5, "more pronounced but not unpleasant"),
         (3.0, "strong, irregular, but still tolerable"), (3.25, "very irregular"),
         (3.5, "extremely irregular, unpleasant, annoying"),
         (4.0, "extremely unpleasant, prolonged exposure harmful"))


def sperling_weighting(f) -> np.ndarray:
    """The vertical frequency correction factor F(f) (module docstring); NaN outside
    (0, 30] Hz."""
    f = np.asarray(f, float)
    out = np.where(f < 5.9, 0.325 * f**2, np.where(f < 20.0, 400.0 / np.maximum(f, 1e-300)**2,
                                                     1.0))
    return np.where((f > 0) & (f <= F_MAX), out, np.nan)


def sperling_line(amplitude, f) -> np.ndarray:
    """Wz of one sinusoidal vertical acceleration: ``amplitude`` in m/s^2 (converted to
    cm/s^2), ``f`` in Hz; 0 outside the rated band."""
    a = np.abs(np.asarray(amplitude, float)) * CM
    f = np.asarray(f, float)
    F = sperling_weighting(f)
    with np.errstate(invalid="ignore", divide="ignore"):
        w = 0.896 * (a**3 * F / f) ** 0.1
    return np.where(np.isfinite(w), w, 0.0)


def sperling_of_lines(amplitudes, freqs) -> float:
    """Wz of a sum of sinusoids (amplitudes in m/s^2, frequencies in Hz): the 10th-power sum
    of the lines' ratings."""
    w = sperling_line(amplitudes, freqs)
    if w.size == 0 or not np.any(w > 0):
        return 0.0
    m = float(np.max(w))
    return float(m * np.sum((w / m) ** 10) ** 0.1)


def sperling_of_periodic(acc, period: float) -> tuple[float, np.ndarray, np.ndarray]:
    """Wz of a periodic vertical acceleration sampled at N equally spaced times over one
    period (m/s^2; the sample at t = period, equal to the first, left out), and its spectral
    lines (frequencies in Hz, amplitudes in m/s^2)."""
    a = np.asarray(acc, float)
    n = a.size
    if n < 4 or not period > 0:
        return 0.0, np.zeros(0), np.zeros(0)
    X = np.fft.rfft(a)
    k = np.arange(1, X.size)
    amp = 2.0 * np.abs(X[1:]) / n
    if n % 2 == 0:  # the Nyquist line is counted once
        amp[-1] *= 0.5
    f = k / period
    return sperling_of_lines(amp, f), f, amp


def sperling_reading(wz: float) -> str:
    """Sperling's words for a ride index (module docstring)."""
    if not np.isfinite(wz):
        return "unknown"
    if wz < 1.0:
        return "below the threshold of noticeability (Wz < 1)"
    text = SCALE[0][1]
    for level, words in SCALE:
        if wz >= level:
            text = words
    return text
