"""Parameter sets: derived values against the paper's printed digits, and every
validation rule fed a bad value."""

import math

import pytest

from maglev_match.params import (
    ParameterError,
    available_presets,
    load_params,
    load_preset,
    parse_assignment,
)


def test_presets_shipped():
    assert {"turnout-soft", "turnout-stiff", "alpha1", "alpha2", "alpha3"} <= set(
        available_presets()
    )


def test_levitation_current_matches_paper():
    assert round(load_preset("turnout-soft").i0, 2) == 26.68


def test_beam_frequencies_match_paper():
    soft, stiff = load_preset("turnout-soft"), load_preset("turnout-stiff")
    assert round(stiff.omega1, 2) == 104.51
    assert round(soft.omega1, 2) == 97.33
    # higher modes as printed: 418.04, 940.591 and 389.307, 875.941 rad/s
    assert round(stiff.omega_n(2), 2) == 418.04
    assert round(stiff.omega_n(3), 1) == 940.6
    assert round(soft.omega_n(2), 1) == 389.3
    assert round(soft.omega_n(3), 1) == 875.9


def test_sigma_matches_paper():
    assert round(load_preset("turnout-soft").sigma, 5) == 4.7e-4


def test_static_deflection_formula():
    p = load_preset("turnout-soft")
    expected = p.sigma * (p.m + p.M) * p.g / p.omega1**2
    assert p.w0 == pytest.approx(expected, rel=1e-15)
    # independent arithmetic from the SPEC formula with the beam values
    w1 = (math.pi / 18.0) ** 2 * math.sqrt(1.96e10 / 1920.0)
    sig = 8 * 12 * 18.0 / (math.pi**2 * 12.1**2 * 1920.0) * math.sin(math.pi * 12.1 / 36.0) ** 2
    assert p.w0 == pytest.approx(sig * 1700 * 9.8 / w1**2, rel=1e-12)


def test_explicit_omega1_sigma_override_derivation():
    p = load_params("turnout-soft", sets=["omega1=100", "sigma=4e-4"])
    assert p.omega1 == 100.0 and p.sigma == 4e-4
    assert p.omega_n(2) == 400.0


def test_replace_rederives_unless_explicit():
    p = load_preset("turnout-soft")
    q = p.replace(EI=2.26e10)
    assert round(q.omega1, 2) == 104.51
    r = load_params("alpha1").replace(EI=2.26e10)
    assert r.omega1 == 100.0  # explicit value kept


def test_user_toml_file(tmp_path):
    f = tmp_path / "mine.toml"
    f.write_text('name = "mine"\n[controller]\nkD = 120.0\n[beam]\nEI = 2.0e10\n')
    p = load_params("turnout-soft", config=f)
    assert p.kD == 120.0 and p.EI == 2.0e10


@pytest.mark.parametrize(
    "name,value,fragment",
    [
        ("m", -1.0, "must be > 0"),
        ("M", 0.0, "must be > 0"),
        ("c0", 0.0, "must be > 0"),
        ("ks", -5.0, "must be > 0"),
        ("k2", 0.0, "must be > 0"),
        ("EI", -1.0, "must be > 0"),
        ("mbar", 0.0, "must be > 0"),
        ("cs", -1.0, "must be >= 0"),
        ("kD", -1.0, "must be >= 0"),
        ("m", float("nan"), "finite"),
        ("kP", float("inf"), "finite"),
        ("xi1", 1.5, "damping ratio"),
        ("omega1", -3.0, "(0, 1e5]"),
        ("sigma", -1e-4, "[0, 0.1]"),
        ("sigma", 0.5, "[0, 0.1]"),
        ("gap_max", 0.005, "must contain c0"),
        ("gap_min", 0.009, "must contain c0"),
        ("l", 30.0, "fit on the beam"),
        ("n_modes", 2.5, "whole number"),
        ("n_modes", 0, "1..20"),
        ("s0", 8.9, "must lie on the beam"),
    ],
)
def test_validation_names_field_value_rule(name, value, fragment):
    with pytest.raises(ParameterError) as err:
        load_params("turnout-soft", sets={name: value})
    msg = str(err.value)
    assert f"'{name}'" in msg
    assert fragment in msg
    assert err.value.field == name


def test_unknown_key_on_command_line():
    with pytest.raises(ParameterError, match="unknown parameter"):
        parse_assignment("omega=3")


def test_bad_number_on_command_line():
    with pytest.raises(ParameterError, match="must be a number"):
        parse_assignment("kD=abc")


def test_missing_equals_sign():
    with pytest.raises(ParameterError, match="NAME=VALUE"):
        parse_assignment("kD")


def test_unknown_key_in_file(tmp_path):
    f = tmp_path / "bad.toml"
    f.write_text("[beam]\nEJ = 1e10\n")
    with pytest.raises(ParameterError, match="'EJ'.*unknown parameter"):
        load_params("turnout-soft", config=f)


def test_unknown_section_in_file(tmp_path):
    f = tmp_path / "bad.toml"
    f.write_text("[motor]\nkD = 1\n")
    with pytest.raises(ParameterError, match="unknown section"):
        load_params("turnout-soft", config=f)


def test_text_value_in_file(tmp_path):
    f = tmp_path / "bad.toml"
    f.write_text('kD = "fast"\n')
    with pytest.raises(ParameterError, match="'kD'.*must be a number"):
        load_params("turnout-soft", config=f)


def test_missing_file():
    with pytest.raises(ParameterError, match="does not exist"):
        load_params("turnout-soft", config="/nonexistent/x.toml")


def test_invalid_toml(tmp_path):
    f = tmp_path / "bad.toml"
    f.write_text("kD = = 3\n")
    with pytest.raises(ParameterError, match="not valid TOML"):
        load_params("turnout-soft", config=f)


def test_unknown_preset():
    with pytest.raises(ParameterError, match="no such preset"):
        load_preset("turnout-medium")
