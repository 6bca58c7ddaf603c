"""Parameter sets: derived values against the paper's printed digits, and every
validation rule fed a bad value."""

import math

import pytest

from maglev_match.core.params import (
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
    # independent arithmetic from the sigma formula with the beam values
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


# ----- finite ranges, derived values, config files (issue: hardening) ----------------------
import os  # noqa: E402
import warnings  # noqa: E402

from maglev_match.core.params import RANGES, ParameterWarning, load_toml  # noqa: E402


@pytest.mark.parametrize("name,value", [
    ("m", 1e300), ("g", 1e308), ("kD", 1e308), ("c0", 1e-300), ("A", 1e-300),
    ("N", 1e-300), ("kP", 1e300), ("EI", 1e30), ("mu0", 1e-200), ("j_b", 1e200),
])
def test_overflow_and_underflow_values_are_refused(name, value):
    """Values whose products overflow or underflow double precision never reach numpy."""
    with pytest.raises(ParameterError) as err:
        load_params("turnout-soft", sets={name: value})
    assert err.value.field == name and "must lie in" in str(err.value)


def test_every_preset_lies_inside_the_ranges():
    for name in available_presets():
        p = load_preset(name)
        for field_name, (lo, hi) in RANGES.items():
            assert lo <= getattr(p, field_name) <= hi, (name, field_name)


def test_range_corners_never_overflow():
    """Every corner of the ranges of the values in i0, w0, omega1 and sigma is either
    accepted with finite derived values or refused by a rule (never an OverflowError,
    ZeroDivisionError or an inf/NaN that reaches the solvers)."""
    import itertools

    names = ("m", "M", "g", "c0", "N", "A", "mu0", "EI", "mbar", "L")
    accepted = 0
    for corner in itertools.product((0, 1), repeat=len(names)):
        sets = {n: RANGES[n][k] for n, k in zip(names, corner, strict=True)}
        sets["gap_max"] = 1.0
        sets["l"] = min(12.1, sets["L"])
        try:
            p = load_params("turnout-soft", sets=sets)
        except ParameterError:
            continue
        accepted += 1
        assert all(math.isfinite(v) for v in p.derived.values()), sets
    assert accepted > 0


@pytest.mark.parametrize("sets,derived,inputs", [
    ({"mbar": 1e-2}, "sigma", ("k = 12", "mbar = 0.01")),
    ({"k": 10_000}, "sigma", ("k = 1e+04",)),
    ({"EI": 1e15, "mbar": 1e-3}, "omega1", ("EI = 1e+15", "mbar = 0.001")),
    ({"omega1": 1.0}, "w0", ("omega1 = 1",)),
])
def test_derived_values_checked_naming_their_inputs(sets, derived, inputs):
    with pytest.raises(ParameterError) as err:
        load_params("turnout-soft", sets=sets)
    assert err.value.field == derived
    for text in inputs:
        assert text in str(err.value)


def test_explicit_omega1_with_beam_value_warns_naming_both():
    with pytest.warns(ParameterWarning, match=r"omega1 = 100 .* EI = 3e\+10"):
        p = load_params("turnout-soft", sets=["omega1=100", "EI=3e10"])
    assert p.omega1 == 100.0
    with pytest.warns(ParameterWarning) as record:
        load_params("alpha1", sets=["mbar=2500"])
    assert {str(w.message).split()[0] for w in record} == {"omega1", "sigma"}
    with warnings.catch_warnings():
        warnings.simplefilter("error", ParameterWarning)
        load_params("turnout-soft", sets=["EI=3e10"])  # derived: no warning
        load_params("alpha1", sets=["kD=120"])  # not a beam value: no warning


@pytest.mark.parametrize("kind,fragment", [
    ("utf16", "not UTF-8"), ("binary", "not UTF-8"), ("nul", "NUL"),
    ("deep", "nested"), ("bigint", "finite"), ("directory", "folder"),
    ("devnull", "not a regular file"), ("fifo", "not a regular file"), ("huge", "bytes"),
])
def test_config_files_that_are_not_small_utf8_toml(tmp_path, kind, fragment):
    f = tmp_path / "c.toml"
    if kind == "utf16":
        f.write_bytes("kD = 120.0\n".encode("utf-16"))
    elif kind == "binary":
        f.write_bytes(bytes(range(256)))
    elif kind == "nul":
        f.write_bytes(b"kD = 1\x00\n")
    elif kind == "deep":
        f.write_text("kD = " + "[" * 100_000 + "]" * 100_000 + "\n")
    elif kind == "bigint":
        f.write_text("kD = " + "9" * 401 + "\n")
    elif kind == "directory":
        f.mkdir()
    elif kind == "devnull":
        f = "/dev/null"
    elif kind == "fifo":
        os.mkfifo(f)
    elif kind == "huge":
        f.write_text("# " + "x" * 2_000_000 + "\n")
    with pytest.raises(ParameterError) as err:
        load_toml(f) if kind != "bigint" else load_params("turnout-soft", config=f)
    assert fragment in str(err.value)
    assert err.value.field in ("config", "kD")
    assert len(str(err.value)) < 400  # a 401-digit value is shortened in the message
