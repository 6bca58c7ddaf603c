"""One error path for the whole command line: every bad input typed by a user ends in one
line naming the option or field, exit code 2, no traceback, before any computation.

The property tests drive :func:`maglev_match.cli.main` in-process with generated bad
values for every bounded numerical option, every parameter, config files and output
paths. All generated values are invalid by construction, so each case stops while the
command line or the parameters are checked (milliseconds, no numerical work)."""

from __future__ import annotations

import contextlib
import io
import math
import os
import re
import time
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import maglev_match.api as stability_cli  # the CLI asks the API for every result
from maglev_match.cli import CLICK_EXCEPTIONS, app, main
from maglev_match.cli.common import NTST_MIN
from maglev_match.core.params import RANGES

FAST = settings(max_examples=40, deadline=None, derandomize=True,
                suppress_health_check=[HealthCheck.function_scoped_fixture,
                                       HealthCheck.too_slow])

MAP_AXES = ["--x", "omega1=100:120:3", "--y", "sigma=3e-4:4e-4:2"]
# (command args before the option, option, low, high, low open, integer)
NUMERIC = [
    (["root-locus"], "--steps", 2, 20_000, False, True),
    (["root-locus"], "--from", None, None, False, False),
    (["hopf"], "--steps", 2, 20_000, False, True),
    (["hopf"], "--to", None, None, False, False),
    (["hopf-curve"], "--scan-steps", 2, 20_000, False, True),
    (["hopf-curve"], "--grid", 0, 400, False, True),
    (["hopf-curve"], "--max-step", 0.0, 1.0, True, False),
    (["cycles"], "--from", None, None, False, False),
    (["cycles"], "--scan", 3, 20_000, False, True),
    (["cycles"], "--ntst", NTST_MIN, 2000, False, True),
    (["cycles"], "--ncol", 2, 7, False, True),
    (["cycles"], "--max-steps", 1, 100_000, False, True),
    (["simulate"], "--t", 0.0, 1e5, True, False),
    (["simulate"], "--x5", -1.0, 1.0, False, False),
    (["simulate"], "--q1", -1.0, 1.0, False, False),
    (["simulate"], "--rtol", 0.0, 0.1, True, False),
    (["simulate"], "--atol", 0.0, 0.1, True, False),
    (["simulate"], "--n-save", 2, 1_000_000, False, True),
    (["map", *MAP_AXES], "--workers", 0, 256, False, True),
    (["map", *MAP_AXES], "--rows-per-tile", 1, 10_000, False, True),
    (["map", *MAP_AXES], "--ntst", NTST_MIN, 2000, False, True),
    (["report"], "--t-end", 0.0, 1e5, True, False),
    # the Monte Carlo and design counts (issue 24: --monte-carlo 99999999999999999999 reached
    # numpy, --workers -1 hung, --seed -1 was an internal error)
    (["index", "--scatter", "EI=3"], "--monte-carlo", 2, 1_000_000, False, True),
    (["index", "--scatter", "EI=3", "--monte-carlo", "4"], "--workers", 0, 256, False, True),
    (["index", "--scatter", "EI=3", "--monte-carlo", "4"], "--seed", 0, 2**32 - 1, False,
     True),
    (["sensitivity", "--scatter", "EI=3", "--monte-carlo", "4"], "--workers", 0, 256, False,
     True),
    (["design", "--vary", "EI=5e9:4e10", "--minimize", "EI"], "--workers", 0, 256, False,
     True),
    (["design", "--vary", "EI=5e9:4e10", "--minimize", "EI"], "--grid", 2, 50, False, True),
    (["design", "--vary", "EI=5e9:4e10", "--minimize", "EI"], "--starts", 1, 100, False,
     True),
]
NOT_A_NUMBER = st.text(alphabet="abcxyz,;:/_ []{}'\"\\", min_size=1, max_size=12).filter(
    lambda s: s.strip() != "")


def run(argv: list[str]) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(argv)
    return code, out.getvalue(), err.getvalue()


def assert_clean_usage_error(argv, code, err, *names):
    lines = err.strip().splitlines()
    assert code == 2, (argv, code, err)
    assert "Traceback" not in err, (argv, err)
    assert len(lines) == 1, (argv, err)
    assert any(_names(err, n) for n in names), (argv, err)


def _names(err: str, name: str) -> bool:
    """An option appears as a word (--ntst); a parameter as 'kD' or as kD = value."""
    if name.startswith("--"):
        return re.search(rf"(?<![\w-]){re.escape(name)}(?![\w-])", err) is not None
    return f"'{name}'" in err or f"{name} = " in err


@st.composite
def bad_numeric(draw):
    """A command, one of its bounded options and a value that breaks the bound."""
    prefix, option, lo, hi, lo_open, integer = draw(st.sampled_from(NUMERIC))
    choices = [st.sampled_from(["nan", "inf", "-inf", "1e400"]), NOT_A_NUMBER]
    if hi is not None:
        choices.append(st.floats(min_value=hi, exclude_min=True, allow_infinity=False,
                                 max_value=1e300).map(lambda v: str(int(v)) if integer
                                                      and v < 1e18 else repr(v)))
    if lo is not None:
        choices.append(st.floats(max_value=lo, exclude_max=not lo_open, min_value=-1e300)
                       .map(lambda v: str(int(math.floor(v))) if integer and abs(v) < 1e18
                            else repr(v)))
    if integer:
        choices.append(st.floats(min_value=0.1, max_value=1e3).filter(
            lambda v: not v.is_integer()).map(repr))
    value = draw(st.one_of(*choices))
    return [*prefix, f"{option}={value}"], option


@FAST
@given(case=bad_numeric())
def test_bad_numeric_option_is_one_line_exit_2(case):
    argv, option = case
    t = time.perf_counter()
    code, _, err = run(argv)
    assert_clean_usage_error(argv, code, err, option)
    assert time.perf_counter() - t < 20


@st.composite
def bad_parameter(draw):
    """--set NAME=VALUE with VALUE outside the parameter's finite range or not a number."""
    name = draw(st.sampled_from(sorted(RANGES) + ["omega1", "sigma", "xi1"]))
    explicit_rules = {"omega1": (0.0, 1e5), "sigma": (0.0, 0.1), "xi1": (0.0, 1.0)}
    lo, hi = RANGES[name] if name in RANGES else explicit_rules[name]
    value = draw(st.one_of(
        st.floats(min_value=hi, exclude_min=True, max_value=1e300, allow_infinity=False),
        st.floats(max_value=lo, exclude_max=True, min_value=-1e300, allow_infinity=False),
        st.sampled_from(["nan", "inf", "-inf", "1e999", "1" * 401]),
        NOT_A_NUMBER.filter(lambda s: "=" not in s),
    ))
    command = draw(st.sampled_from([["stability"], ["index", "--no-simulation"],
                                    ["simulate"], ["hopf"], ["root-locus"]]))
    text = value if isinstance(value, str) else repr(value)
    return [*command, "--set", f"{name}={text}"], name


@FAST
@given(case=bad_parameter())
def test_bad_parameter_is_one_line_exit_2(case):
    argv, name = case
    code, _, err = run(argv)
    # the rule may be stated on the parameter or on the one it is checked against
    # (l <= L, gap_min < c0 < gap_max); both appear in the message
    assert_clean_usage_error(argv, code, err, name)


@st.composite
def bad_config(draw, tmp):
    kind = draw(st.sampled_from(["binary", "utf16", "deep", "bigint", "text", "section",
                                 "nested_table", "directory", "devnull", "fifo", "missing",
                                 "toml_syntax"]))
    path = tmp / f"c_{kind}_{draw(st.integers(0, 10**9))}.toml"
    field = "config"
    if kind == "binary":
        path.write_bytes(b"\xff\xfe\x00" + draw(st.binary(min_size=0, max_size=200)))
    elif kind == "utf16":
        path.write_bytes("kD = 120.0\n".encode("utf-16"))
    elif kind == "deep":
        n = draw(st.integers(9, 100_000))
        path.write_text("kD = " + "[" * n + "]" * n + "\n")
    elif kind == "bigint":
        digits = draw(st.integers(400, 4000))
        path.write_text(f"kD = {'7' * digits}\n")
        field = "kD"
    elif kind == "text":
        path.write_text(f'kP = "{draw(NOT_A_NUMBER.filter(lambda s: chr(34) not in s and chr(92) not in s))}"\n')  # noqa: E501
        field = "kP"
    elif kind == "section":
        path.write_text("[motor]\nkD = 1\n")
        field = "motor"
    elif kind == "nested_table":
        path.write_text("[beam.inner]\nEI = 1\n")
        field = "inner"
    elif kind == "directory":
        path.mkdir()
    elif kind == "devnull":
        path = Path("/dev/null")
    elif kind == "fifo":
        os.mkfifo(path)
    elif kind == "toml_syntax":
        path.write_text(draw(st.sampled_from(["kD = = 3\n", "[beam\n", "kD 3\n", "= 1\n"])))
    command = draw(st.sampled_from([["stability"], ["index", "--no-simulation"],
                                    ["hopf"]]))
    return [*command, "--config", str(path)], field


@FAST
@given(data=st.data())
def test_bad_config_file_is_one_line_exit_2(tmp_path_factory, data):
    tmp = tmp_path_factory.mktemp("cfg")
    argv, field = data.draw(bad_config(tmp))
    code, _, err = run(argv)
    assert_clean_usage_error(argv, code, err, field)


OUT_COMMANDS = [
    (["root-locus"], "auto"), (["hopf-curve"], "auto"), (["cycles"], "auto"),
    (["simulate"], "csv"), (["map", *MAP_AXES], "file"), (["report"], "html"),
]


@FAST
@given(data=st.data())
def test_bad_output_path_is_refused_before_work(tmp_path_factory, data):
    tmp = tmp_path_factory.mktemp("out")
    plain = tmp / "plain.txt"
    plain.write_text("x")
    (tmp / "adir.csv").mkdir()
    (tmp / "adir.html").mkdir()
    (tmp / "adir.nc").mkdir()
    prefix, kind = data.draw(st.sampled_from(OUT_COMMANDS))
    suffix = {"auto": "", "csv": ".csv", "file": ".nc", "html": ".html"}[kind]
    choices = [str(plain / f"sub{suffix}"), str(plain / "a" / f"b{suffix}"),
               f"/proc/maglev{suffix}", f"/sys/x/y{suffix}"]
    if kind != "auto":
        choices.append(str(tmp / f"adir{suffix}"))
    path = data.draw(st.sampled_from(choices))
    argv = [*prefix, "--out", path]
    t = time.perf_counter()
    code, _, err = run(argv)
    assert_clean_usage_error(argv, code, err, "--out")
    assert time.perf_counter() - t < 20


@FAST
@given(name=st.text(alphabet="abcdefghijklmnopqrstuvwxyz-", min_size=1, max_size=15),
       command=st.sampled_from(["stability", "hopf", "cycles", "simulate", "index", "map",
                                "report", "root-locus", "hopf-curve"]))
def test_unknown_option_is_one_line_exit_2(name, command):
    option = "--zz" + name
    argv = [command, option]
    code, _, err = run(argv)
    assert_clean_usage_error(argv, code, err, option)


@pytest.mark.parametrize("argv,fragment", [
    (["frobnicate"], "frobnicate"),
    (["map"], "--x"),
    (["simulate", "--t", "abc"], "--t"),
    (["map", *MAP_AXES, "--workers", "abc"], "--workers"),
    (["map", *MAP_AXES, "--scheduler", "not-an-address"], "--scheduler"),
    (["map", *MAP_AXES, "--scheduler", "tcp://localhost:99999"], "--scheduler"),
    (["stability", "--set"], "--set"),
])
def test_usage_errors_name_the_option(argv, fragment):
    code, _, err = run(argv)
    assert code == 2 and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1 and fragment in err


def test_typer_raises_the_click_classes_we_catch():
    """typer bundles its own click (typer._click); its exceptions must be the ones main()
    handles, else every usage error is a traceback."""
    with pytest.raises(CLICK_EXCEPTIONS) as info:
        app(args=["stability", "--frobnicate"], standalone_mode=False)
    assert info.value.exit_code == 2


def test_no_arguments_prints_help_exit_2():
    code, out, err = run([])
    assert code == 2 and "Usage" in out + err and "Traceback" not in err


def test_version():
    from maglev_match import __version__

    code, out, _ = run(["--version"])
    assert code == 0 and out.strip() == f"maglev-match {__version__}"


def test_brackets_in_messages_are_kept(tmp_path):
    code, _, err = run(["stability", "--set", "gap_max=0.005"])
    assert code == 2 and "[gap_min, gap_max]" in err
    f = tmp_path / "s.toml"
    f.write_text("[motor]\nkD = 1\n")
    code, _, err = run(["stability", "--config", str(f)])
    assert code == 2 and "'[table]'" in err


def test_derived_values_name_their_inputs():
    code, _, err = run(["stability", "--set", "mbar=0.01"])
    assert code == 2 and "'sigma'" in err and "mbar = 0.01" in err
    code, _, err = run(["stability", "--set", "EI=1e15", "--set", "mbar=1e-3"])
    assert code == 2 and "'omega1'" in err and "EI = 1e+15" in err
    code, _, err = run(["index", "--no-simulation", "--set", "sigma=0"])
    assert code == 2 and "'sigma'" in err and "w0" in err


def test_explicit_omega1_with_beam_data_warns_naming_both():
    code, _, err = run(["stability", "--set", "omega1=100", "--set", "EI=3e10", "--json"])
    assert code == 0
    assert "warning:" in err and "omega1 = 100" in err and "EI = 3e+10" in err


def test_unexpected_exception_is_one_line_exit_1(monkeypatch):
    def boom(*a, **k):
        raise ZeroDivisionError("float division by zero")

    monkeypatch.setattr(stability_cli, "stability", boom)
    code, _, err = run(["stability"])
    assert code == 1
    assert len(err.strip().splitlines()) == 1
    assert "ZeroDivisionError" in err and "report" in err and "--debug" in err
    assert "Traceback" not in err
    with pytest.raises(ZeroDivisionError):
        run(["stability", "--debug"])


def test_disk_full_is_one_line_exit_1(monkeypatch):
    def full(*a, **k):
        raise OSError(28, "No space left on device", "/data/root_locus.csv")

    monkeypatch.setattr(stability_cli, "stability", full)
    code, _, err = run(["stability"])
    assert code == 1 and "Traceback" not in err
    # (issue 24: the message says "disk full" and what is kept, not "system error")
    assert len(err.strip().splitlines()) == 1
    assert err.startswith("error: disk full: cannot write /data/root_locus.csv (No space left "
                          "on device); earlier files are unchanged")
