"""Guideway irregularities at speed: the moving unit over a profile against the closed-form
frequency response of model A on a rigid guideway, the random profile against its PSD, zero
amplitude against the smooth run, joint steps repeating every span, and the linear route's
rms against the simulated one."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal

from maglev_match.analyses.speed.irregular import (
    footprint_factor,
    irregular_sweep,
    linear_gap_rms,
    rigid_gap_response,
    wilson_interval,
)
from maglev_match.analyses.speed.spans import simulate_over_spans
from maglev_match.api.inputs import resolve_params
from maglev_match.core.params import ParameterError
from maglev_match.maglev.irregularity import Irregularity, parse_irregularity, target_psd

KMH = 1 / 3.6


@pytest.fixture(scope="module")
def soft():
    return resolve_params("turnout-soft")


@pytest.fixture(scope="module")
def stiff_one_mode(soft):
    """A very stiff guideway (EI x 1000, one mode per span: omega1 ~ 3000 rad/s)."""
    return resolve_params("turnout-soft", EI=soft.EI * 1e3, n_modes=1)


def _steady_amplitude(t, d, omega):
    M = np.stack([np.cos(omega * t), np.sin(omega * t), np.ones_like(t)], 1)
    c = np.linalg.lstsq(M, d, rcond=None)[0]
    return float(np.hypot(c[0], c[1]))


def test_small_sinusoid_on_a_stiff_guideway_follows_the_standstill_frequency_response(
        stiff_one_mode):
    p = stiff_one_mode
    v, lam, a = 100 * KMH, 20.0, 2e-5
    spans = 20
    prof = parse_irregularity(f"sine:wavelength={lam},amplitude={a}")
    smooth = simulate_over_spans(p, "unit", v, spans, overlay=False)
    run = simulate_over_spans(p, "unit", v, spans, profile=prof)
    assert run.outcome == "ok"
    T = p.L / v
    keep = run.t >= (spans - 4) * T  # the last four spans: the transient has died out
    d = (run.gap_deviation - smooth.gap_deviation)[keep, 0]
    omega = 2 * math.pi * v / lam
    amp = _steady_amplitude(run.t[keep], d, omega)
    # closed form: model A linearised on a rigid guideway, times the footprint's mean
    expected = (abs(rigid_gap_response(p, omega)[0])
                * footprint_factor(p, v, 2 * math.pi / lam) * a)
    assert amp == pytest.approx(expected, rel=1e-3)
    # the footprint factor matters here (0.5): a point-like reading would be far off
    assert footprint_factor(p, v, 2 * math.pi / lam) < 0.6


def test_random_profile_reproduces_its_psd():
    prof = parse_irregularity("random:class=high,lmin=2,lmax=200,waves=400")
    dx = 0.25
    x = np.arange(0.0, 40_000.0, dx)
    z = prof.profile(x, spans=10**7, L=18.0, seed=3)
    # Welch estimate (one-sided, per cycle/m) converted to per rad/m
    f, P = signal.welch(z, fs=1.0 / dx, nperseg=8192)
    om, S = 2 * math.pi * f, P / (2 * math.pi)
    # octave bands inside the resolved band, well away from its edges
    edges = 2 * math.pi / np.array([100.0, 50.0, 25.0, 12.5, 6.25, 4.0])
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        m = (om >= lo) & (om < hi)
        est = np.trapezoid(S[m], om[m])
        fine = np.linspace(om[m][0], om[m][-1], 4001)
        target = np.trapezoid(target_psd(fine, "high"), fine)
        assert est == pytest.approx(target, rel=0.05), (lo, hi)
    # the variance is the integral of the PSD over the band
    lo, hi = prof.band()
    fine = np.linspace(lo, hi, 200_001)
    assert np.var(z) == pytest.approx(np.trapezoid(target_psd(fine, "high"), fine), rel=0.02)


@pytest.mark.parametrize("waves", [1, 16, 17, 64, 400])
def test_blocked_spectral_sum_equals_the_sum_term_by_term(waves):
    """The vector field's spectral sum (blocked above DIRECT_WAVES waves: the sines and
    cosines of about 2 sqrt(N) angles instead of N) equals sum_k a_k cos(kappa_k x + phi_k)
    and its sine companion term by term over 730 m of guideway, to 1e-12 of the profile's
    rms (the same sum, rounded differently)."""
    import jax.numpy as jnp

    from maglev_match.maglev.irregularity import _wave_sum

    prof = parse_irregularity(f"random:class=high,waves={waves}")
    amp, kap, ph = prof.wave_vectors(7)
    x = np.linspace(-30.0, 700.0, 1501)
    ang = np.multiply.outer(x, kap) + ph
    c, s = _wave_sum(jnp.asarray(x), jnp.asarray(amp * np.cos(ph))[None], jnp.asarray(kap),
                     jnp.asarray(amp * np.sin(ph))[None])  # one set of coefficients
    c, s = c[0], s[0]
    rms = math.sqrt(float(np.sum(amp ** 2)) / 2)
    assert np.max(np.abs(np.asarray(c) - np.cos(ang) @ amp)) < 1e-12 * rms
    assert np.max(np.abs(np.asarray(s) - np.sin(ang) @ amp)) < 1e-12 * rms


@pytest.mark.parametrize("waves", [1, 17, 400])
@pytest.mark.parametrize("point", [True, False])
def test_profile_rate_is_the_derivative_of_the_profile(waves, point):
    """The rate of the profile under the loads (the spectral part in closed form from the
    same sines and cosines) equals the forward-mode derivative of the profile itself, for
    point loads (model B) and footprint means (the unit), over a passage with a
    pre-camber in the span pieces."""
    import jax
    import jax.numpy as jnp

    from maglev_match.maglev.irregularity import profile_under

    prof = parse_irregularity("sine:wavelength=7.3,amplitude=0.002" if waves == 1
                              else f"random:class=high,waves={waves}")
    camber = parse_irregularity("camber:amplitude=0.003")
    L, v = 25.0, 30.0
    pp = prof.vector(3, 6, L, 5)
    pp[1:7] = camber.vector(3, 6, L, 5)[1:7]  # the span pieces of a pre-camber
    n = 6 if point else 1
    front = jnp.asarray(np.linspace(0.0, 12.0, n) if point else [0.0])
    length = jnp.zeros(6) if point else jnp.asarray([2.4])
    for t in (0.05, 0.31, 0.77):
        pk = jnp.asarray(np.concatenate([[v, 1.3, 1.0, 1.0],
                                         (np.asarray(front) + 1.3 + v * t > L) * 1.0,
                                         (np.asarray(front) + 1.3 + v * t - (0 if point
                                                                             else 2.4) > L)
                                         * 1.0]))

        def z(tt, pk=pk):
            return profile_under(tt, pk, jnp.asarray(pp), front, length, L, prof.n_waves,
                                 point)[0]

        value, rate = profile_under(jnp.asarray(t), pk, jnp.asarray(pp), front, length, L,
                                    prof.n_waves, point)
        _, forward = jax.jvp(z, (jnp.asarray(t),), (jnp.asarray(1.0),))
        scale = float(np.max(np.abs(np.asarray(forward)))) + 1e-30
        assert np.max(np.abs(np.asarray(rate) - np.asarray(forward))) < 1e-10 * scale
        assert np.all(np.isfinite(np.asarray(value)))


def test_zero_amplitude_reproduces_the_smooth_run_exactly(soft):
    v = 80 * KMH
    smooth = simulate_over_spans(soft, "unit", v, 3, overlay=False)
    zero = simulate_over_spans(soft, "unit", v, 3,
                               profile=parse_irregularity("sine:wavelength=10,amplitude=0"))
    assert np.array_equal(smooth.t, zero.t)
    assert np.array_equal(smooth.gap_deviation, zero.gap_deviation)
    assert np.array_equal(smooth.current, zero.current)
    assert np.array_equal(smooth.midspan, zero.midspan, equal_nan=True)


def test_joint_steps_give_a_response_repeating_every_span(stiff_one_mode):
    p = stiff_one_mode
    v, step, spans = 100 * KMH, 1e-4, 24
    smooth = simulate_over_spans(p, "unit", v, spans, overlay=False)
    run = simulate_over_spans(p, "unit", v, spans, profile=parse_irregularity(f"joint:step={step}"))
    d = (run.gap_deviation - smooth.gap_deviation)[:, 0]
    T = p.L / v
    n = int(np.sum((run.t >= (spans - 2) * T) & (run.t < (spans - 1) * T)))
    last = d[(run.t >= (spans - 1) * T) & (run.t < spans * T)][:n]
    before = d[(run.t >= (spans - 2) * T) & (run.t < (spans - 1) * T)][:n]
    swing = np.ptp(last)
    assert swing > 0.05 * step  # the joints are felt ...
    assert np.max(np.abs(last - before)) < 2e-3 * swing  # ... and the response repeats
    # its fundamental is the span-passing frequency
    spec = np.abs(np.fft.rfft(last - last.mean()))
    assert int(np.argmax(spec)) == 1


def test_linear_route_agrees_with_the_simulated_rms(stiff_one_mode):
    p = resolve_params("turnout-soft", EI=stiff_one_mode.EI / 100, n_modes=1)
    prof = parse_irregularity("random:class=low,seeds=4,lmin=4,lmax=100,waves=64")
    sweep = irregular_sweep(p, "unit", [120 * KMH], prof, spans=12, warmup=2)
    sim = sweep.column("gap_rms_profile")[0]
    se = sweep.column("gap_rms_profile_se")[0]
    lin = sweep.column("gap_rms_linear")[0]
    assert lin == pytest.approx(linear_gap_rms(p, 120 * KMH, prof))
    assert abs(sim - lin) < 3 * se + 0.02 * lin
    assert sweep.column("contacts")[0] == 0
    assert sweep.column("p_contact_high")[0] == pytest.approx(wilson_interval(0, 4)[1])


def test_wilson_interval_closed_forms():
    lo, hi = wilson_interval(0, 10)
    z2 = 1.959963984540054**2
    assert lo == 0.0 and hi == pytest.approx(z2 / (10 + z2))
    lo, hi = wilson_interval(5, 10)
    assert 0.5 - lo == pytest.approx(hi - 0.5)


@pytest.mark.parametrize("text, field", [
    ("sine:wavelength=10,amplitude=-1e-3", "amplitude"),
    ("sine:wavelength=nan,amplitude=1e-3", "wavelength"),
    ("sine:wavelength=0,amplitude=1e-3", "wavelength"),
    ("bumpy:amplitude=1", "--irregularity"),
    ("random:class=medium", "class"),
    ("random:class=low,seeds=2.5", "seeds"),
    ("random:class=low,lmin=50,lmax=20", "lmin"),
    ("joint:size=1e-3", "--irregularity"),
    ("camber", "--irregularity"),
])
def test_bad_irregularities_name_the_field(text, field):
    with pytest.raises(ParameterError) as e:
        parse_irregularity(text)
    assert field in str(e.value)


def test_wavelength_below_the_sampling_is_refused(soft):
    with pytest.raises(ParameterError, match="wavelength.*resolves"):
        irregular_sweep(soft, "unit", [150 * KMH], "sine:wavelength=0.05,amplitude=1e-4",
                        spans=2)


def test_api_sweep_carries_the_irregular_readouts_and_they_round_trip(tmp_path):
    import xarray as xr

    from maglev_match import api

    sweep = api.speed_sweep("turnout-soft", model="unit", kmh=(0, 90, 90), critical=False,
                            irregularity="joint:step=0.002", irregular_spans=4)
    ir = sweep.irregular
    assert list(ir.speeds) == [pytest.approx(90 * KMH)]  # v = 0 has no run
    ds = ir.to_xarray()
    path = tmp_path / "irr.nc"
    ds.to_netcdf(path, engine="h5netcdf")
    back = xr.open_dataset(path, engine="h5netcdf")
    for k in ("gap_rms", "gap_max", "wz", "daf", "p_contact_high"):
        assert float(back[k].values[0]) == pytest.approx(ir.column(k)[0], rel=1e-12)
        assert back[k].attrs["units"]
    assert back.attrs["irregularity"] == ir.profile.describe()
    files = ir.plot(tmp_path / "irr.png")
    assert all(f.exists() for f in files)
    # a deterministic profile: one run, no standard error, no linear route
    assert ir.column("runs")[0] == 1 and np.isnan(ir.column("gap_rms_linear")[0])
    assert ir.column("gap_rms")[0] > 0


class _Cosine(Irregularity):
    """A sinusoid of phase 0 (A cos(2 pi x / W)): A where the run starts."""

    def wave_vectors(self, seed):
        return (np.array([self.amplitude]), np.array([2 * math.pi / self.wavelength]),
                np.zeros(1))


@pytest.mark.parametrize("model", ["unit", "vehicle"])
def test_runs_start_on_the_profile(model):
    """A cosine of 1 mm and wavelength 10 km is, over a few spans, a uniform offset of 1 mm
    where the run starts: the vehicle starts on it (every point raised and moving with it),
    so the gaps move by micrometres from the smooth run's; jumping onto it would move them
    by 1 mm at the start."""
    p = resolve_params("turnout-stiff", n_modes=1)
    prof = _Cosine(kind="sine", amplitude=1e-3, wavelength=1e4)
    assert prof.profile(np.array([0.0]), 2, p.L, 0)[0] == pytest.approx(1e-3)
    smooth = simulate_over_spans(p, model, 100 * KMH, 2, overlay=False)
    run = simulate_over_spans(p, model, 100 * KMH, 2, profile=prof)
    assert run.outcome == "ok"
    d = np.abs(run.gap_deviation - smooth.gap_deviation).max()
    assert d < 5e-6, d


def test_zero_amplitude_reproduces_the_smooth_vehicle_run_exactly():
    p = resolve_params("turnout-soft")
    smooth = simulate_over_spans(p, "vehicle", 120 * KMH, 2, overlay=False)
    zero = simulate_over_spans(p, "vehicle", 120 * KMH, 2,
                               profile=Irregularity(kind="camber", amplitude=0.0))
    assert np.array_equal(smooth.gap_deviation, zero.gap_deviation)
    assert np.array_equal(smooth.body_acceleration, zero.body_acceleration)


def test_the_moving_models_linearisation_is_model_a_closed_form_for_the_unit(soft):
    from maglev_match.analyses.speed.irregular import profile_gap_response

    v = 100 * KMH
    kap = np.array([0.05, 0.3, 1.0, 2.5])
    H = profile_gap_response(soft, "unit", v, kap)[0]
    ref = np.abs(rigid_gap_response(soft, kap * v)) * footprint_factor(soft, v, kap)
    np.testing.assert_allclose(np.abs(H), ref, rtol=1e-9)


def test_linear_route_of_the_vehicle_agrees_with_its_simulated_rms():
    p = resolve_params("turnout-soft", n_modes=1)
    prof = parse_irregularity("random:class=low,seeds=4,lmin=4,lmax=100,waves=32")
    sweep = irregular_sweep(p, "vehicle", [120 * KMH], prof, spans=8, warmup=2)
    sim = sweep.column("gap_rms_profile")[0]
    se = sweep.column("gap_rms_profile_se")[0]
    lin = sweep.column("gap_rms_linear")[0]
    assert abs(sim - lin) < 3 * se + 0.02 * lin, (sim, se, lin)


def test_simulate_at_speed_over_an_irregular_guideway_writes_and_prints_it(tmp_path):
    import contextlib
    import io
    import json

    import xarray as xr

    from maglev_match.cli import main

    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(io.StringIO()):
        code = main(["simulate", "--speed", "100", "--spans", "2", "--set", "n_modes=1",
                     "--irregularity", "random:class=high,waves=16,seeds=3", "--seed", "2",
                     "--out", str(tmp_path), "--json"])
    assert code == 0
    summary = json.loads(out.getvalue())
    assert summary["irregularity"].endswith("this run: seed 2")
    ds = xr.open_dataset(tmp_path / "simulation_unit_speed.nc", engine="h5netcdf")
    assert ds.attrs["irregularity"] == summary["irregularity"]
    # the profile moves the gaps: a different run from the smooth one
    smooth = simulate_over_spans(resolve_params("turnout-soft", n_modes=1), "unit",
                                 100 * KMH, 2, overlay=False)
    assert np.max(np.abs(ds["gap_deviation"].values - smooth.gap_deviation)) > 1e-5
